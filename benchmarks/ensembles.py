"""Ensembles against a loop of single fits: ``identify(..., keys=K)`` beside K calls ``identify(..., key=k)``.

Usage::

    python benchmarks/ensembles.py --record emps            # DATA_EMPS.mat, 1 kHz (default)
    python benchmarks/ensembles.py --record rig             # jaxfric.rig.synthetic_friction_data
    ... [--models elman,lugre] [--sizes 1,8] [--rounds 1] [--quick] [--out DIR] [--data-dir DIR]

For each model (every ``identify`` default; float32) and ensemble size K, one round
times, side by side on the same machine and in the same process:

* the K single fits ``identify(model, data, key=keys[i])`` one after another (the loop);
* the ensemble ``identify(model, data, keys=keys)`` with the same K keys.

Both paths are compiled before the rounds (first calls reported apart), so the
medians are warm wall times. The table gives one fit's time (median of the loop's
fits), the ensemble's, their ratio (the price of K members in single fits; the
target on a 2-core CPU: ENN K = 8 at most 3, LuGre at most 2) and the loop's time
over the ensemble's. It also checks member i against the single fit with key i
(largest relative difference of the training cost J over the members).

Writes ``ensembles_<record>.md`` and ``.csv`` into ``--out`` (default
``benchmarks/results``; ``--quick``: tiny budgets, ``benchmarks/results/quick``).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
import warnings
from pathlib import Path

try:
    import jaxfric  # noqa: F401
except ImportError:  # running from a source checkout without installing
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/ is not on sys.path under `jaxfric bench`
from _harness import markdown_table, results_dir, write_csv  # noqa: E402

HERE = Path(__file__).resolve().parent
DATA_ROOT = Path(os.environ.get("JAXFRIC_SHARED_DATA", HERE.parents[1] / "shared" / "data"))


def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--record", choices=("emps", "rig"), default="emps")
    p.add_argument("--models", default="elman,lugre", help="comma list of model names")
    p.add_argument("--sizes", default="1,8", help="comma list of ensemble sizes K")
    p.add_argument("--rounds", type=int, default=1, help="timed rounds (medians over them)")
    p.add_argument("--data-dir", default=None, help="folder of DATA_EMPS.mat")
    p.add_argument("--quick", action="store_true", help="tiny budgets, written to results/quick/")
    p.add_argument("--out", default=None)
    p.add_argument("--note", default="", help="a sentence for the report (e.g. the machine's load)")
    return p.parse_args(argv)


def load(args):
    from jaxfric import rig

    if args.record == "rig":
        return rig.synthetic_friction_data(jax.random.key(0)), "simulated rig, key 0 (2000 samples, 128 Hz)"
    path = Path(args.data_dir or DATA_ROOT / "emps") / "DATA_EMPS.mat"
    if not path.is_file():
        return None, f"no EMPS file at {path}"
    return (rig.emps_friction_data(rig.load_emps(path)),
            "EMPS estimation file at 1 kHz (DATA_EMPS.mat, 24 741 samples, 80 % training)")


def options(model: str, quick: bool) -> dict:
    """``identify`` keywords: every default, or tiny budgets with ``--quick``."""
    if not quick:
        return {}
    import jaxfric as jf
    from jaxfric.identification import GradientRefinement

    if model.startswith("elman"):
        return {"solver": jf.MAPSO(lattice_size=8, num_generations=3),
                "refine": GradientRefinement(max_steps=10)}
    return {"solver": jf.mapso_nmds(lattice_size=3, num_generations=5, nm_max_steps=40, nm_max_evals=40)}


def timed(fn):
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c


def measure(model: str, data, k: int, rounds: int, quick: bool) -> dict:
    from jaxfric.identification import identify

    kw = options(model, quick)
    first_one = timed(lambda: identify(model, data, key=0, **kw))[1]
    first_ens = timed(lambda: identify(model, data, keys=jax.random.split(jax.random.key(0), k), **kw))[1]
    one, one_cpu, loop, loop_cpu, ens, ens_cpu, diff = [], [], [], [], [], [], []
    for r in range(rounds):
        keys = jax.random.split(jax.random.key(100 + r), k)
        singles = [timed(lambda key=key: identify(model, data, key=key, **kw)) for key in keys]
        fit, wall, cpu = timed(lambda: identify(model, data, keys=keys, **kw))
        one += [s[1] for s in singles]
        one_cpu += [s[2] for s in singles]
        loop.append(sum(s[1] for s in singles))
        loop_cpu.append(sum(s[2] for s in singles))
        ens.append(wall)
        ens_cpu.append(cpu)
        j_one = np.array([s[0].metrics["cost"] for s in singles])
        diff.append(float(np.max(np.abs(np.asarray(fit.ensemble["J"]) - j_one) / np.abs(j_one))))
    med = statistics.median
    return {
        "model": model, "K": k, "rounds": rounds,
        "one_fit_s": med(one), "ensemble_s": med(ens), "loop_s": med(loop),
        "ensemble_over_one": med(ens) / med(one), "loop_over_ensemble": med(loop) / med(ens),
        "one_fit_cpu_s": med(one_cpu), "ensemble_cpu_s": med(ens_cpu),
        "ensemble_over_one_cpu": med(ens_cpu) / med(one_cpu),
        "first_one_s": first_one, "first_ensemble_s": first_ens,
        "member_max_rel_dJ": max(diff),
    }


def _fmt(x) -> str:
    return f"{x:.3g}" if isinstance(x, float) else str(x)


def report(rows, args, desc: str) -> str:
    """The Markdown page of a run (``rows`` as :func:`measure` returns them)."""
    columns = ["model", "K", "one_fit_s", "ensemble_s", "ensemble_over_one", "loop_s", "loop_over_ensemble",
               "ensemble_over_one_cpu", "member_max_rel_dJ", "first_one_s", "first_ensemble_s"]
    headers = ["model", "K", "one fit [s]", "ensemble [s]", "ensemble / one fit", "loop of K [s]",
               "loop / ensemble", "ensemble / one fit, CPU time", "members: max rel. ΔJ",
               "first fit [s]", "first ensemble [s]"]
    return "\n".join([
        f"# Ensembles against a loop of single fits ({args.record})",
        "",
        f"Record: {desc}. Every `identify` default{' (--quick: tiny budgets)' if args.quick else ''}, "
        f"float32. Command: `python benchmarks/ensembles.py --record {args.record}"
        f"{' --quick' if args.quick else ''}`.",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"jax {jax.__version__} on {jax.default_backend()}. Warm wall times, medians over "
        f"{args.rounds} round(s); 'CPU time' is the process's CPU seconds (steadier on a loaded machine)."
        + (f" {args.note}" if args.note else ""),
        "'members: max rel. ΔJ': member i's training cost J against the single fit with key i.",
        "",
        markdown_table(rows, columns, headers=headers, fmt=_fmt),
        "",
    ])


def main(argv=None):
    args = parse(argv)
    data, desc = load(args)
    if data is None:
        print(f"ensembles: {desc}; skipped, nothing written.", file=sys.stderr)
        return 0
    out = results_dir(args.out, quick=args.quick)
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for model in args.models.split(","):
            for k in (int(s) for s in args.sizes.split(",")):
                row = measure(model, data, k, args.rounds, args.quick)
                rows.append(row)
                print(f"{model} K={k}: one fit {row['one_fit_s']:.2f} s, ensemble {row['ensemble_s']:.2f} s "
                      f"({row['ensemble_over_one']:.2f}x one fit, {row['ensemble_over_one_cpu']:.2f}x in CPU "
                      f"time, loop/ensemble {row['loop_over_ensemble']:.2f}), members' max rel dJ "
                      f"{row['member_max_rel_dJ']:.2g}", flush=True)
    stem = f"ensembles_{args.record}"
    write_csv(rows, out / f"{stem}.csv")
    (out / f"{stem}.md").write_text(report(rows, args, desc))
    print(f"wrote {out / stem}.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
