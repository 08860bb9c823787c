"""Ensembles against a loop of single fits: ``identify(..., keys=K)`` beside K calls ``identify(..., key=k)``.

    python benchmarks/ensembles.py --record emps|rig [--models elman,lugre,elman:map] [--sizes 1,8]
        [--loop-fits N] [--rounds 1] [--rollouts] [--tag gpu] [--append] [--quick] [--out DIR] [--data-dir DIR]

Every ``identify`` default, float32, warm: K single fits one after another (or ``--loop-fits`` N
of them, the loop then K times their median, "est.") and the ensemble with the same keys, its
time over one fit's in wall and CPU time and per stage, and member i against the fit with key i.
``NAME:map`` runs the gradient stage's members one after another (bit-identical to single fits).
``--rollouts``: each stage's CPU time for one key and K keys, and the floor under those ratios,
the cost per candidate of P candidates at once (J, and the networks' J and gradient).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # not on sys.path under `jaxfric bench`
from _harness import (add_output_arguments, cell, command, friction_record, machine, markdown_table,  # noqa: E402
                      read_csv, results_dir, skipped, tagged, timed, write_csv, write_report)

import jax  # noqa: E402
import numpy as np  # noqa: E402

ROLLOUT_BATCHES = (1, 8, 25, 64, 200)


def merge(old: list[dict], new: list[dict], keys: tuple[str, ...]) -> list[dict]:
    """``old`` with the rows of ``new`` added, a new row replacing an old one with the same ``keys``."""
    fresh = {tuple(r[k] for k in keys) for r in new}
    return [r for r in old if tuple(r[k] for k in keys) not in fresh] + new


def options(model: str, quick: bool) -> dict:
    """``identify`` keywords: every default, or tiny budgets with ``--quick``. A model
    written ``elman:map`` runs its gradient stage's members one after another
    (``GradientRefinement(batching="map")``, bit-identical members)."""
    import jaxfric as jf
    from jaxfric.identification import GradientRefinement
    from jaxfric.identification._api import FAST_REFINE_STEPS

    name, _, layout = model.partition(":")
    kw = {"refine": GradientRefinement(max_steps=10 if quick else FAST_REFINE_STEPS, batching=layout)} if layout else {}
    if not quick:
        return kw
    if name.startswith("elman"):
        return {"solver": jf.MAPSO(lattice_size=8, num_generations=3), "refine": GradientRefinement(max_steps=10), **kw}
    return {"solver": jf.mapso_nmds(lattice_size=3, num_generations=5, nm_max_steps=40, nm_max_evals=40), **kw}


def compare_members(ens, singles) -> dict:
    """Member i of the ensemble ``ens`` against ``singles[i]`` (the fit with key i)."""
    n, e, sol = len(singles), ens.ensemble, ens.solution
    j_one = np.array([s.metrics["cost"] for s in singles])
    j_ens = np.asarray(e["J"][:n], np.float64)
    v_one = np.array([float((s.metrics.get("valid") or {}).get("mse_percent", np.nan)) for s in singles])
    v_ens = np.asarray([np.nan if x is None else x for x in e["valid_mse_percent"][:n]], np.float64)
    global_bitwise = sum(bool(np.array_equal(np.asarray(sol.value[i]), np.asarray(s.solution.value))
                              and np.array_equal(np.asarray(sol.f[i]), np.asarray(s.solution.f)))
                         for i, s in enumerate(singles))
    theta_bitwise = sum(bool(np.array_equal(np.asarray(e["theta"][i]), np.asarray(s.theta)))
                        for i, s in enumerate(singles))
    return {
        "members_checked": n, "global_bitwise": global_bitwise, "theta_bitwise": theta_bitwise,
        "rel_dJ": float(np.max(np.abs(j_ens - j_one) / np.abs(j_one))),
        "d_valid_mse": float(np.nanmax(np.abs(v_ens - v_one))) if n else float("nan"),
        "J_spread": float(j_one.max() / j_one.min() - 1.0) if n > 1 else float("nan"),
    }


def measure(model: str, data, k: int, rounds: int, quick: bool, loop_fits: int | None) -> dict:
    from jaxfric.identification import identify

    kw, name = options(model, quick), model.partition(":")[0]
    n = k if loop_fits is None else max(1, min(loop_fits, k))
    first_one = timed(lambda: identify(name, data, key=0, **kw))[1]
    first_ens = timed(lambda: identify(name, data, keys=jax.random.split(jax.random.key(0), k), **kw))[1]
    acc = {c: [] for c in ("one", "one_cpu", "loop", "loop_cpu", "ens", "ens_cpu", "g1", "gk", "r1", "rk", "cmp")}
    stage = lambda fit, name: float(fit.timings.get(name, 0.0))  # noqa: E731
    for r in range(rounds):
        keys = jax.random.split(jax.random.key(100 + r), k)
        singles = [timed(lambda key=key: identify(name, data, key=key, **kw)) for key in keys[:n]]
        fit, wall, cpu = timed(lambda: identify(name, data, keys=keys, **kw))
        acc["one"] += [s[1] for s in singles]
        acc["one_cpu"] += [s[2] for s in singles]
        acc["loop"].append(k / n * sum(s[1] for s in singles))  # estimated from n of its K fits when n < K
        acc["loop_cpu"].append(k / n * sum(s[2] for s in singles))
        acc["ens"].append(wall)
        acc["ens_cpu"].append(cpu)
        acc["g1"] += [stage(s[0], "run_s") for s in singles]
        acc["r1"] += [stage(s[0], "refine_run_s") for s in singles]
        acc["gk"].append(stage(fit, "run_s"))
        acc["rk"].append(stage(fit, "refine_run_s"))
        acc["cmp"].append(compare_members(fit, [s[0] for s in singles]))
    med = statistics.median
    ratio = lambda a, b: med(acc[a]) / med(acc[b]) if med(acc[b]) > 0 else float("nan")  # noqa: E731
    cmp = acc["cmp"]
    return {
        "model": model, "K": k, "rounds": rounds, "loop_fits": n, "one_fit_s": med(acc["one"]),
        "ensemble_s": med(acc["ens"]), "loop_s": med(acc["loop"]), "loop_estimated": n < k,
        "ensemble_over_one": ratio("ens", "one"), "loop_over_ensemble": ratio("loop", "ens"),
        "one_fit_cpu_s": med(acc["one_cpu"]), "ensemble_cpu_s": med(acc["ens_cpu"]),
        "ensemble_over_one_cpu": ratio("ens_cpu", "one_cpu"),
        "global_one_s": med(acc["g1"]), "global_ensemble_s": med(acc["gk"]), "global_over_one": ratio("gk", "g1"),
        "gradient_one_s": med(acc["r1"]), "gradient_ensemble_s": med(acc["rk"]),
        "gradient_over_one": ratio("rk", "r1"), "first_one_s": first_one, "first_ensemble_s": first_ens,
        **{c: sum(x[c] for x in cmp) for c in ("members_checked", "global_bitwise", "theta_bitwise")},
        "member_max_rel_dJ": max(c["rel_dJ"] for c in cmp),
        "member_max_d_valid_mse": max(c["d_valid_mse"] for c in cmp),
        "J_spread_over_keys": max(c["J_spread"] for c in cmp),
    }


# ------------------------------------------------------------------ the floor
def _median_cpu(fn, reps: int) -> float:
    jax.block_until_ready(fn())
    ts = []
    for _ in range(reps):
        c = time.process_time()
        jax.block_until_ready(fn())
        ts.append(time.process_time() - c)
    return statistics.median(ts)


def _stages(model_name: str, data):
    """``identify``'s default plan of ``model_name`` on ``data``, as its own stage functions
    see it: ``(model, solver, refine, box, objective)``."""
    import jax.numpy as jnp

    from jaxfric.identification import stages
    from jaxfric.identification._api import _plan, resolve_model

    model = resolve_model(model_name, None)
    solver, refine, head = _plan(model, "jaxfric", None, None)
    records = stages.records_stage(data)
    return (model, solver, refine, stages.box_stage(model, records),
            stages.objective_stage(model, records, jnp.float32, head))


def rollout_costs(model_name: str, data, reps: int) -> list[dict]:
    """CPU time of the global stage's evaluation (J of P candidates at once, on the data
    that stage sees) per candidate, and for the networks of the gradient stage's J and
    gradient for 1 and K networks on the whole training window."""
    import jax.numpy as jnp

    model, _, refine, bounds, obj = _stages(model_name, data)
    lo, hi = bounds.lower, bounds.upper
    rng = np.random.default_rng(0)
    thetas = jnp.asarray(lo + (hi - lo) * rng.random((max(ROLLOUT_BATCHES), lo.size)), jnp.float32)
    cost = jax.jit(jax.vmap(obj.cost, (0, None)))

    def row(what, p, fn):
        t = _median_cpu(fn, reps)
        return {"model": model_name, "what": what, "P": p, "ms": 1e3 * t, "us_per_candidate": 1e6 * t / p}

    samples = int(obj.data_global.y.shape[0])
    rows = [row(f"J of P candidates ({samples} samples)", p, lambda p=p: cost(thetas[:p], obj.data_global))
            for p in ROLLOUT_BATCHES]
    if refine is not None and model.needs_scaling:
        grad = jax.jit(jax.vmap(jax.value_and_grad(obj.cost), (0, None)))
        one = jax.jit(jax.value_and_grad(obj.cost))
        samples = int(obj.data.y.shape[0])
        rows.append(row(f"J and gradient, one network ({samples} samples)", 1, lambda: one(thetas[0], obj.data)))
        rows += [row(f"J and gradient, P networks side by side ({samples} samples)", p,
                     lambda p=p: grad(thetas[:p], obj.data)) for p in (2, 8)]
    return rows


def stage_costs(model_name: str, data, k: int) -> list[dict]:
    """CPU time of the global and the gradient stage (``identify``'s own stage functions,
    defaults, warm) for one key and for K keys: where an ensemble's time goes."""
    import jax.numpy as jnp

    from jaxfric.identification import stages

    _, solver, refine, bounds, obj = _stages(model_name, data)
    keys = jax.random.split(jax.random.key(7), k)

    def glob(members):
        return stages.global_stage(obj, solver, bounds, members, dtype=jnp.float32)[0]

    def grad(members, sol):
        return stages.gradient_stage(refine, obj, sol.value, bounds, jnp.float32, ensemble=members.members is not None)

    one, many = stages.resolve_keys(keys[0]), stages.resolve_keys(None, keys)
    grad(one, glob(one)), grad(many, glob(many))  # compiled
    rows = []
    for name in ("global", "gradient") if refine is not None else ("global",):
        cpu = {}
        for label, members in (("one", one), ("ensemble", many)):
            sol = glob(members) if name == "gradient" else None
            c = time.process_time()
            glob(members) if name == "global" else grad(members, sol)
            cpu[label] = time.process_time() - c
        rows.append({"model": model_name, "K": k, "stage": name, "one_cpu_s": cpu["one"],
                     "ensemble_cpu_s": cpu["ensemble"], "ratio": cpu["ensemble"] / cpu["one"]})
    return rows


_fmt = cell(".3g")


def report(rows, floor, args, desc: str, runs: list[str], costs=()) -> str:
    """The Markdown page of a run (``rows`` as :func:`measure` returns them)."""
    rows = [{**r, "loop_shown": f"{r['loop_s']:.3g}" + (" est." if r["loop_estimated"] else ""),
             "bitwise": f"{r['global_bitwise']}/{r['members_checked']}, {r['theta_bitwise']}/{r['members_checked']}"}
            for r in rows]
    columns = {"model": "model", "K": "K", "one_fit_s": "one fit [s]", "ensemble_s": "ensemble [s]",
               "ensemble_over_one": "ensemble / one fit", "loop_shown": "loop of K [s]",
               "loop_over_ensemble": "loop / ensemble", "ensemble_over_one_cpu": "ensemble / one fit, CPU time",
               "global_over_one": "global stage: ensemble / one", "gradient_over_one": "gradient stage: ensemble / one",
               "bitwise": "members bitwise (global stage, θ)", "member_max_rel_dJ": "members: max rel. ΔJ",
               "member_max_d_valid_mse": "members: max Δ valid. MSE [points]",
               "J_spread_over_keys": "J spread over keys", "first_one_s": "first fit [s]",
               "first_ensemble_s": "first ensemble [s]"}
    lines = [
        f"# Ensembles against a loop of single fits ({args.record}{', ' + args.tag if args.tag else ''})", "",
        f"Record: {desc}. Every `identify` default{' (--quick: tiny budgets)' if args.quick else ''}, "
        "float32. Run(s), each row from the last run that measured it:", "", *[f"* {r}" for r in runs], "",
        f"Machine: {machine()}; device {getattr(jax.devices()[0], 'device_kind', '')}. Warm wall times, medians "
        f"over {args.rounds} round(s); 'CPU time' is the process's CPU seconds (steadier on a loaded machine).",
        "Stage columns: the global (derivative-free) stage's and the gradient stage's run time (compilation "
        "apart), ensemble over one fit. Members: member i against the single fit with key i — how many equal it to "
        "the bit after the global stage and at the end, the largest relative difference of the training cost J and "
        "of the validation MSE; 'J spread over keys' (max/min − 1 over the single fits) gives their scale."
        + (" 'est.': the loop's time as K times the median of the single fits timed."
           if any(r["loop_estimated"] for r in rows) else ""),
        "", markdown_table(rows, list(columns), headers=list(columns.values()), fmt=_fmt), ""]
    if costs:
        lines += ["## Where the time goes: each stage's CPU time", "",
                  "`identify`'s global and gradient stages run alone (defaults, warm), one key against K keys; "
                  "process CPU seconds, steadier than wall time on a loaded machine.", "",
                  markdown_table(list(costs), ["model", "K", "stage", "one_cpu_s", "ensemble_cpu_s", "ratio"],
                                 headers=["model", "K", "stage", "one key, CPU [s]", "K keys, CPU [s]", "K keys / one"],
                                 fmt=_fmt), ""]
    if floor:
        lines += ["## The floor: cost per candidate against batch size", "",
                  "CPU time of the global stage's evaluation (J of P candidates at once, `vmap` of the cost, on the "
                  "samples that stage sees) and, for the network, of the gradient stage's J and gradient; medians. "
                  "Where the cost per candidate does not fall as P grows, the stage is bound by arithmetic, and K "
                  "members cost K times one run whatever their layout.", "",
                  markdown_table(floor, ["model", "what", "P", "ms", "us_per_candidate"],
                                 headers=["model", "what", "P", "ms", "µs per candidate"], fmt=_fmt), ""]
    return "\n".join(lines)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--record", choices=("emps", "rig"), default="emps")
    p.add_argument("--models", default="elman,lugre", help="model names; NAME:map: members one after another")
    p.add_argument("--sizes", "--keys", dest="sizes", default="1,8", help="ensemble sizes K")
    p.add_argument("--loop-fits", type=int, default=None, help="single fits timed per round (default K)")
    p.add_argument("--rounds", type=int, default=1, help="timed rounds (medians over them)")
    p.add_argument("--rollouts", action="store_true", help="also the stages' CPU times and the per-candidate floor")
    p.add_argument("--data-dir", default=None, help="folder of DATA_EMPS.mat")
    add_output_arguments(p, "tiny budgets (smoke test)", tag=True)
    p.add_argument("--note", default="", help="a sentence for the report (e.g. the machine's load)")
    p.add_argument("--append", action="store_true", help="keep the existing files' rows (a new row of the same "
                   "model and K replaces one) and runs")
    args = p.parse_args(argv)
    data, desc = friction_record(args.record, args.data_dir)
    if data is None:
        return skipped("ensembles", desc)
    out = results_dir(args.out, quick=args.quick)
    rows, floor, costs = [], [], []
    with warnings.catch_warnings(action="ignore"):
        for model in args.models.split(","):
            for k in (int(s) for s in args.sizes.split(",")):
                row = measure(model, data, k, args.rounds, args.quick, args.loop_fits)
                rows.append(row)
                print(f"{model} K={k}: one fit {row['one_fit_s']:.2f} s, ensemble {row['ensemble_s']:.2f} s "
                      f"({row['ensemble_over_one']:.2f}x, {row['ensemble_over_one_cpu']:.2f}x in CPU time)", flush=True)
            if args.rollouts and ":" not in model:
                floor += rollout_costs(model, data, reps=3 if args.quick else 9)
                costs += [c for k in (int(s) for s in args.sizes.split(",")) if k > 1 and not args.quick
                          for c in stage_costs(model, data, k)]
    stem = tagged(f"ensembles_{args.record}", args.tag)
    runs = [f"`{command('ensembles.py')}`" + (f": {args.note}" if args.note else "")]
    notes = out / f"{stem}.runs"
    if args.append:
        rows = merge(read_csv(out / f"{stem}.csv"), rows, ("model", "K"))
        floor = merge(read_csv(out / f"{stem}_floor.csv"), floor, ("model", "what", "P"))
        costs = merge(read_csv(out / f"{stem}_stages.csv"), costs, ("model", "K", "stage"))
        runs = (notes.read_text().splitlines() if notes.is_file() else []) + runs
        rows.sort(key=lambda r: (str(r["model"]), int(r["K"])))
    notes.write_text("\n".join(runs) + "\n")
    for part, extra in (("floor", floor), ("stages", costs)):
        if extra:
            write_csv(extra, out / f"{stem}_{part}.csv")
    write_report(out, stem, report(rows, floor, args, desc, runs, costs), rows, echo=False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
