"""Friction identification on the simulated rig: the paper's ENN study (docs/algorithms.md §12).

    python benchmarks/friction.py [--seeds 3] [--budgets 500,1000] [--quick] [--out DIR]

``--seeds`` keys per configuration on one simulated record, the paper's solver
(:func:`jaxfric.identification.paper_solver`) and a gradient stage, one row before and one after
it: the Elman context-weight box (``identify``'s default comes from here), N = 20, 30, 40, ENN
against LuGre, and MAPSO generations (the default against ``--budgets``), beside the paper's.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # not on sys.path under `jaxfric bench`
from _harness import (add_output_arguments, command, machine, markdown_table, results_dir, spread,  # noqa: E402
                      write_csv, write_report)

import jax  # noqa: E402
import numpy as np  # noqa: E402

PAPER_NEURONS = {20: 0.3277, 30: 0.2632, 40: 0.2377}
BOXES = (1.0, 2.0, 5.0)
METRICS = [f"{k}_{w}" for k in ("mse_percent", "max_abs", "fit_percent") for w in ("train", "valid", "all")]


def solver(model, quick, generations=None, mapso_only=False):
    import jaxfric as jf
    from jaxfric.identification import paper_solver

    s = paper_solver(model)
    if quick:
        s = jf.mapso_nmds(lattice_size=3, num_generations=5, sl_generations=2, nm_max_steps=200, nm_max_evals=200)
    elif generations is not None:
        s = jf.MAPSONMDS(mapso=jf.MAPSO(lattice_size=s.mapso.lattice_size, num_generations=generations),
                         nelder_mead=s.nelder_mead)
    return s.mapso if mapso_only else s


def run(config, model, seed, data, args, generations=None, mapso_only=False) -> list[dict]:
    """Two rows of one identification: after the global stages and after the gradient stage."""
    from jaxfric.identification import GradientRefinement, identify

    big = model.num_params > 20
    refine = GradientRefinement(method="bfgs", max_steps=50 if args.quick else 2000) if big else \
        GradientRefinement(method="lm", max_steps=200)
    fit = identify(model, data, key=jax.random.key(seed), solver=solver(model, args.quick, generations, mapso_only),
                   refine=refine, dtype=np.float32)
    t = fit.timings
    first = fit.stages[0] if mapso_only else next(s for s in fit.stages if s["stage"] == "nelder_mead")
    name = "MAPSO" if mapso_only else "MAPSO–NMDS"
    base = {"config": config, "seed": seed, "model": type(model).__name__, "neurons": getattr(model, "neurons", ""),
            "context_weight_bound": getattr(model, "context_weight_bound", ""), "num_params": fit.num_params}
    rows = [dict(base, method="MAPSO only" if mapso_only else name, J=first["J"], time_run_s=t["run_s"],
                 time_compile_s=t["compile_s"], **{k: first.get(k) for k in METRICS}),
            dict(base, method=f"{name} + {refine.method.upper()}", J=fit.stages[-1]["J"],
                 time_run_s=t["run_s"] + t["refine_run_s"], time_compile_s=t["compile_s"] + t["refine_compile_s"],
                 **{k: fit.stages[-1].get(k) for k in METRICS})]
    print(f"  {config:<22} key {seed} {name}: " + " -> ".join(f"{s['stage']} J={s['J']:.3g}" for s in fit.stages)
          + f" | valid {fit.metrics['valid']['mse_percent']:.3f} %", flush=True)
    return rows


def plan(args):
    """``(config, model, key, generations, mapso_only)`` of every run, in order."""
    from jaxfric.identification import NAMED_MODEL_DEFAULTS
    from jaxfric.models import Elman, LuGre

    rb = NAMED_MODEL_DEFAULTS["elman"]["context_weight_bound"]
    seeds = range(1 if args.quick else args.seeds)
    n_main = 4 if args.quick else 30
    yield from ((f"N={n_main} r<={box:g}", Elman(neurons=n_main, context_weight_bound=box), s, None, only)
                for box in BOXES for s in seeds for only in (False, True))
    yield from ((f"N={n} r<={rb:g}", Elman(neurons=n, context_weight_bound=rb), s, None, False)
                for n in (() if args.quick else (20, 40)) for s in seeds)
    yield from ((f"N=30 r<={rb:g} G={g}", Elman(neurons=30, context_weight_bound=rb), s, g, False)
                for g in ([] if args.quick or not args.budgets else [int(g) for g in args.budgets.split(",")])
                for s in seeds)
    yield from (("LuGre", LuGre(), s, None, False) for s in seeds)


def report(rows, args, wall) -> str:
    from jaxfric.identification import DEFAULT_GENERATIONS_BLACK_BOX

    groups: dict = {}
    for r in rows:
        groups.setdefault((r["config"], r["method"]), []).append(r)
    table = []
    for (config, method), rs in groups.items():
        n = rs[0]["neurons"]
        diverged = sum(r["mse_percent_valid"] > max(10 * r["mse_percent_train"], 5.0) for r in rs)
        table.append({"configuration": config, "method": method, "keys": len(rs),
                      "MSE % train": spread([r["mse_percent_train"] for r in rs]),
                      "MSE % valid": spread([r["mse_percent_valid"] for r in rs]),
                      "MAX valid [N]": spread([r["max_abs_valid"] for r in rs], 1),
                      "FIT % valid": spread([r["fit_percent_valid"] for r in rs], 2),
                      "#params": rs[0]["num_params"], "run [s]": spread([r["time_run_s"] for r in rs], 1),
                      "diverged on valid": f"{diverged}/{len(rs)}",
                      "paper MSE %": PAPER_NEURONS.get(n, "–") if method == "MAPSO–NMDS" else "–"})
    mean = {k: float(np.mean([r["mse_percent_valid"] for r in rs])) for k, rs in groups.items()}
    main = f"N={4 if args.quick else 30} r<=1"
    lines = []
    for enn, lug in (("MAPSO–NMDS", "MAPSO–NMDS"), ("MAPSO–NMDS + BFGS", "MAPSO–NMDS + LM")):
        if (main, enn) in mean and ("LuGre", lug) in mean:
            e, g = mean[(main, enn)], mean[("LuGre", lug)]
            lines.append(f"ENN {enn} {e:.3f} % against LuGre {lug} {g:.3f} %: {100 * (1 - e / g):.1f} % lower "
                         "(paper: 95.6 %, LuGre above 5 %).")
    return "\n".join([
        "# Friction identification on the simulated rig (`benchmarks/friction.py`)", "",
        f"Generated by `{command('friction.py')}` in {wall:.0f} s"
        + (" — **--quick smoke budgets, not results**" if args.quick else "") + ". "
        "Record: `jaxfric.rig.synthetic_friction_data(jax.random.key(0))`, 1600 training / 400 "
        "validation samples; float32; cells are mean (min–max) over keys. "
        f"Solver: the paper's (MAPSO 8×8, G = {DEFAULT_GENERATIONS_BLACK_BOX} for the networks, 5×5, G = 200 for "
        "LuGre, then Nelder–Mead with fminsearch's budget); 'MAPSO only' runs are separate runs with the same "
        "MAPSO; '+ BFGS' (at most 2000 steps) and '+ LM' (200 steps) are the same run's gradient stage. "
        "MAX = max|e| [N]; FIT % = 100·(1 − ‖e‖/‖F − mean F‖); diverged: validation MSE above 10× the "
        "training MSE and above 5 %. `r<=b`: the Elman context-weight box; `G=`: MAPSO generations.", "",
        f"Machine: {machine()}.", "", markdown_table(table), "", *lines, ""])


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, default=3, help="optimiser keys per configuration (--quick: 1)")
    p.add_argument("--budgets", default="500,1000", help="MAPSO generations compared with the default ('' = none)")
    add_output_arguments(p, "N = 4, one key, tiny budgets (smoke test)")
    args = p.parse_args(argv)
    from jaxfric import rig

    out = results_dir(args.out, quick=args.quick)
    t0 = time.perf_counter()
    data = rig.synthetic_friction_data(jax.random.key(0))
    rows = []
    for config, model, seed, generations, mapso_only in plan(args):
        rows += run(config, model, seed, data, args, generations, mapso_only)
        write_csv(rows, out / "friction.csv")  # a stopped run keeps what finished
    write_report(out, "friction", report(rows, args, time.perf_counter() - t0), echo=False)


if __name__ == "__main__":
    main()
