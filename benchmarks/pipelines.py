"""ENN (N = 30) identification pipelines side by side, on the simulated rig and on real recordings.

    python benchmarks/pipelines.py --record rig|emps|oring [--seeds K] [--paper-seeds K]
        [--skip jaxfric,paper,de_nm] [--quick] [--out DIR] [--data-dir DIR]

Same record and split, float32: ``jaxfric`` (``identify("elman", data, key=k)``, every default),
``paper`` (``method="paper"``), ``DE → NM`` (scipy's differential evolution on the same jitted
cost with the swarm's evaluations, then Nelder–Mead with ``NM_EVALS_PER_BFGS_STEP`` evaluations per
BFGS step of the default) and the least-squares baseline; compilation timed apart.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/ is not on sys.path under `jaxfric bench`
from _harness import (add_output_arguments, command, fit_cells, friction_record, machine,  # noqa: E402
                      markdown_table, results_dir, skipped, spread, timed, write_report)
from baselines import ls_coulomb_viscous  # noqa: E402

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
#: Nelder–Mead evaluations granted per BFGS step of the jaxfric pipeline (DE → NM row).
NM_EVALS_PER_BFGS_STEP = 6


def run_identify(data, key, method, quick):
    from jaxfric.identification import identify

    kw = {}
    if quick:
        import jaxfric as jf
        from jaxfric.identification import GradientRefinement

        kw = ({"solver": jf.MAPSO(lattice_size=8, num_generations=3),
               "refine": GradientRefinement(max_steps=10)} if method == "jaxfric" else
              {"solver": jf.mapso_nmds(lattice_size=8, num_generations=3, nm_max_steps=50, nm_max_evals=50)})
    with warnings.catch_warnings(action="ignore", category=RuntimeWarning):
        fit, _, cpu = timed(lambda: identify("elman", data, key=key, method=method, **kw))
    return {"cpu_s": cpu, **fit_cells(fit),
            "evals": sum(s.get("num_evals", 0) for s in fit.stages),
            "steps": sum(s.get("num_steps", 0) for s in fit.stages)}


def run_de_nm(data, seed, quick):
    """scipy DE on the first GLOBAL_STAGE_SAMPLES samples, then scipy Nelder–Mead on all."""
    import scipy.optimize

    from jaxfric.fit import predict
    from jaxfric.identification import _api
    from jaxfric.identification._data import as_record
    from jaxfric.identification._objective import OutputErrorCost, cost_data, fit_scalers
    from jaxfric._timing import Stopwatch
    from jaxfric.metrics import friction_metrics

    rec = as_record(data)
    model = _api.resolve_model("elman", None)
    scalers = fit_scalers(model, rec)
    full = cost_data(model, rec, scalers, jnp.float32)
    m = min(_api.GLOBAL_STAGE_SAMPLES, rec.n_train)
    head = full.__class__(u=full.u[:m], y=full.y[:m], dt=full.dt, inv_norm=full.inv_norm)
    cost = OutputErrorCost(model)
    batch = jax.jit(jax.vmap(cost, (0, None)))
    single = jax.jit(cost)
    lo, hi = model.bounds()
    n = lo.size
    gens = 3 if quick else _api.FAST_GENERATIONS_BLACK_BOX
    budget_global = _api.default_solver(model).evaluations() if not quick else 8 * 8 * 3
    nm_evals = 50 if quick else NM_EVALS_PER_BFGS_STEP * _api.FAST_REFINE_STEPS
    # popsize·n members; maxiter so that (maxiter + 1)·popsize·n ≈ the swarm's budget
    maxiter = max(1, budget_global // n - 1)

    def f_batch(x):  # scipy's vectorized form: x is (n, S)
        y = np.asarray(batch(jnp.asarray(x.T, jnp.float32), head), np.float64)
        return np.where(np.isfinite(y), y, np.inf)

    def f_one(x):
        y = float(single(jnp.asarray(x, jnp.float32), full))
        return y if np.isfinite(y) else np.inf

    cpu0 = time.process_time()
    with Stopwatch() as sw:
        de = scipy.optimize.differential_evolution(
            f_batch, list(zip(lo, hi)), popsize=1, maxiter=maxiter, vectorized=True, polish=False,
            updating="deferred", seed=seed, init="latinhypercube", tol=0.0)
        nm = scipy.optimize.minimize(f_one, de.x, method="Nelder-Mead",
                                     options={"maxfev": nm_evals, "maxiter": nm_evals, "adaptive": True})
    theta = np.clip(nm.x, lo, hi) if nm.fun <= de.fun else de.x
    y = np.asarray(predict(model, jnp.asarray(theta, jnp.float32), scalers, rec.velocity, rec.dt))
    k = rec.n_train
    return {"valid": friction_metrics(rec.friction[k:], y[k:])["mse_percent"],
            "train": friction_metrics(rec.friction[:k], y[:k])["mse_percent"],
            "run_s": sw.run_s, "compile_s": sw.compile_s, "cpu_s": time.process_time() - cpu0,
            # scipy counts a vectorised population call once; count the members
            "evals": int((de.nit + 1) * n + nm.nfev), "steps": 0,
            "de_generations": int(de.nit), "gens_ref": gens}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--record", choices=("rig", "emps", "oring"), default="rig")
    p.add_argument("--seeds", type=int, default=None, help="keys for jaxfric and DE→NM (rig 5, else 1)")
    p.add_argument("--paper-seeds", type=int, default=None, help="keys for the paper pipeline (default: --seeds)")
    p.add_argument("--data-dir", default=None, help="folder of DATA_EMPS.mat or pneumatic_seal_friction")
    add_output_arguments(p, "tiny budgets (smoke test)")
    p.add_argument("--skip", default="", help="comma list of pipelines to skip: jaxfric,paper,de_nm")
    p.add_argument("--tag", default="", help="suffix of the output names (pipelines_<record><tag>.md)")
    args = p.parse_args(argv)
    data, desc = friction_record(args.record, args.data_dir)
    if data is None:
        return skipped("pipelines", desc)
    seeds = args.seeds or (5 if args.record == "rig" else 1)
    paper_seeds = args.paper_seeds or seeds
    out = results_dir(args.out, quick=args.quick)
    skip = set(filter(None, args.skip.split(",")))
    from jaxfric.metrics import friction_metrics

    v, f, n = np.asarray(data.velocity), np.asarray(data.friction), int(data.n_train)
    y, coef = ls_coulomb_viscous(v, f, n)  # the least-squares baseline
    rows = [{"pipeline": "LS asymmetric Coulomb + viscous + offset", "seed": "", "run_s": 0.0, "compile_s": 0.0,
             "valid": friction_metrics(f[n:], y[n:])["mse_percent"],
             "train": friction_metrics(f[:n], y[:n])["mse_percent"], "evals": "", "steps": ""}]
    print(f"{args.record}: {data.n_samples} samples, {n} train; LS baseline valid {rows[0]['valid']:.3f} %", flush=True)
    t0 = time.time()
    for name, count in [("jaxfric", seeds), ("paper", paper_seeds), ("de_nm", seeds)]:
        for seed in range(0 if name in skip else count):
            r = run_de_nm(data, seed, args.quick) if name == "de_nm" else run_identify(data, seed, name, args.quick)
            r.update(pipeline=name, seed=seed)
            rows.append(r)
            print(f"{name:8s} seed {seed}: valid {r['valid']:.3f} %  train {r['train']:.3f} %  "
                  f"run {r['run_s']:.1f} s  compile {r['compile_s']:.1f} s  cpu {r['cpu_s']:.1f} s  "
                  f"evals {r['evals']}", flush=True)
            # after every row, so a run stopped by a time limit still leaves its results
            write(out, args, desc, rows, coef, time.time() - t0)
    write(out, args, desc, rows, coef, time.time() - t0)
    return 0


LABELS = {"jaxfric": "ENN N = 30, jaxfric default (MAPSO G = 50 on ≤ 2000 samples → BFGS 500)",
          "paper": "ENN N = 30, paper (MAPSO–NMDS, `method=\"paper\"`)",
          "de_nm": "ENN N = 30, scipy DE → Nelder–Mead (same budget as jaxfric)"}


def write(out, args, desc, rows, c, wall):
    keys = ["pipeline", "seed", "valid", "train", "run_s", "compile_s", "cpu_s", "evals", "steps"]
    stem = f"pipelines_{args.record}{args.tag}"
    lines = [f"# ENN identification pipelines: {desc}", "",
             f"Generated by `{command('pipelines.py')}` (see its docstring). Machine: "
             f"{machine()} (at the end), float32. MSE % = 100·mean(e²)/var(F) on the window. Run time excludes "
             "compilation; cells are mean (min–max) over keys; the first key also paid the compile time shown. "
             "CPU [s] = the process's CPU time over the call (all threads; compilation included for the first "
             "key): unlike wall time it hardly depends on what else runs, and the rollouts are sequential, so on "
             "an idle machine the wall time of a key served from the jit cache is at most about its CPU time.", ""]
    groups = {}
    for r in rows:
        groups.setdefault(r["pipeline"], []).append(r)
    lines.append(markdown_table([
        {"pipeline": LABELS.get(name, name), "keys": len(rs) if name in LABELS else "–",
         "MSE % valid": spread([r["valid"] for r in rs]), "MSE % train": spread([r["train"] for r in rs]),
         "run [s]": spread([r["run_s"] for r in rs]) if name in LABELS else "–",
         "compile [s] (first key)": f"{rs[0]['compile_s']:.1f}", "CPU [s] (last key)": f"{rs[-1].get('cpu_s', 0.0):.1f}",
         "evaluations": rs[0]["evals"]} for name, rs in groups.items()]))
    lines += ["", f"LS baseline on the training window: Fv+ = {c[0]:.4g}, Fv− = {c[1]:.4g}, Fc+ = {c[2]:.4g}, "
              f"Fc− = {c[3]:.4g}, offset = {c[4]:.4g} (SI units).", ""]
    lines.append(f"Benchmark wall time: {wall:.0f} s.")
    write_report(out, stem, lines, [{k: r.get(k, "") for k in keys} for r in rows], echo=False)


if __name__ == "__main__":
    sys.exit(main())
