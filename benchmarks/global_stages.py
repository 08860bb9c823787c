"""Global stages compared on the main job: MAPSO vs CMA-ES vs PSO, each followed by the same
Nelder–Mead stage, at equal evaluation budgets.

The Elman network (N = 30, 180 parameters) and LuGre by :func:`jaxfric.identify`
(``solver=chain(global, NM)``; the ENN then runs identify's gradient stage) on ``rig``
(``jaxfric.rig.synthetic_friction_data``) and ``emps`` (``DATA_EMPS.mat``, SOURCE.md's recipe
with the published M, every 10th sample, last 20 % validation). MAPSO runs
``--generations`` (LuGre, 5×5) or ``--enn-generations`` (ENN, 8×8); PSO and CMA-ES get at most
its evaluations; above ``LARGE_MODEL_PARAMS`` parameters CMA-ES is ``Sep_CMA_ES`` (full
CMA-ES's eigendecomposition takes 0.2–0.9 s per generation at 180 parameters).

    python benchmarks/global_stages.py [--data rig,emps] [--models lugre,elman] [--keys 5] [--quick]
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # not on sys.path under `jaxfric bench`
from _harness import (about, add_output_arguments, emps_file, fit_cells, machine, markdown_table, results_dir,  # noqa: E402
                      timed, write_report)

import jax  # noqa: E402
import numpy as np  # noqa: E402

import jaxfric as jf  # noqa: E402
from jaxfric.identification._api import LARGE_MODEL_PARAMS, NAMED_MODEL_DEFAULTS  # noqa: E402

EMPS_MASS = 95.1089  # kg, SOURCE.md (IDIM-LS reference)


def emps_record(path: Path, decimate: int = 10, drop: int = 50):
    """Velocity, force-balance friction and dt of EMPS (SOURCE.md's recipe)."""
    import scipy.io
    import scipy.signal

    m = scipy.io.loadmat(path)
    t, qm, vir = (np.ravel(m[k]).astype(np.float64) for k in ("t", "qm", "vir"))
    gtau = float(np.ravel(m["gtau"])[0])
    dt = float(np.median(np.diff(t)))
    v = np.gradient(scipy.signal.filtfilt(*scipy.signal.butter(4, 100.0, fs=1.0 / dt), qm), dt)
    sl = slice(drop, len(t) - drop, decimate)
    return v[sl], (gtau * vir - EMPS_MASS * np.gradient(v, dt))[sl], dt * decimate


def datasets(names):
    out = {}
    if "rig" in names:
        out["rig"] = jf.rig.synthetic_friction_data(jax.random.key(0))
    if "emps" in names:
        p = emps_file()
        if p is not None:
            v, f, dt = emps_record(p)
            out["emps"] = jf.FrictionData.from_arrays(v, f, dt, train_fraction=0.8)
        else:
            print("EMPS data not found: skipped (set JAXFRIC_DATA)", flush=True)
    return out


def cma_strategy(n: int) -> str:
    """Full CMA-ES for small models, the diagonal Sep-CMA-ES for the networks (module docstring)."""
    return "Sep_CMA_ES" if n > LARGE_MODEL_PARAMS else "CMA_ES"


def solvers(model_name: str, n: int, generations: int, nm_evals: int):
    """The three chains at equal global budgets (MAPSO's evaluation count)."""
    lattice = 8 if n > LARGE_MODEL_PARAMS else 5
    mapso = jf.MAPSO(lattice_size=lattice, num_generations=generations)
    budget = mapso.evaluations()
    pso = jf.PSO(num_particles=lattice**2, num_generations=max(1, budget // lattice**2 - 1))
    strategy = cma_strategy(n)
    cma = jf.Evosax(strategy, num_generations=1)
    cma = jf.Evosax(strategy, num_generations=max(1, (budget - 1) // cma.population(n)))
    nm = jf.NelderMead(max_steps=200 * n, max_evals=nm_evals)
    label = "Sep-CMA-ES" if strategy == "Sep_CMA_ES" else "CMA-ES"
    return budget, {"MAPSO": jf.chain(mapso, nm), label: jf.chain(cma, nm),
                    "PSO": jf.chain(pso, nm)}


def run(data_name, data, model_name, keys, generations, nm_evals):
    """Yields one row per (global stage, key)."""
    model = jf.models.get(model_name, **NAMED_MODEL_DEFAULTS.get(model_name, {}))
    budget, chains = solvers(model_name, model.num_params, generations[model.num_params > LARGE_MODEL_PARAMS],
                             nm_evals)
    for label, solver in chains.items():
        for i, k in enumerate(keys):
            with warnings.catch_warnings(action="ignore", category=RuntimeWarning):
                fit, wall, _ = timed(lambda: jf.identify(model_name, data, solver=solver, key=int(k)))
            valid, train = fit_cells(fit)["valid"], fit_cells(fit)["train"]
            yield {
                "data": data_name, "model": model_name, "global": label, "key": int(k),
                "budget_global": budget, "num_evals_global": fit.stages[0]["num_evals"],
                "num_evals": sum(s.get("num_evals", 0) for s in fit.stages),
                "J_global": fit.stages[0]["J"], "J": fit.metrics["cost"],
                "train_mse_pct": train, "valid_mse_pct": valid,
                "compile_s": fit.timings.get("compile_s", float("nan")),
                "run_s": fit.timings.get("run_s", float("nan")), "wall_s": wall,
            }


def write(out: Path, rows, a):
    lines = [
        "# Global stages on the main job: MAPSO vs CMA-ES vs PSO, then the same Nelder–Mead",
        "",
        f"`python benchmarks/global_stages.py --data {a.data} --models {a.models} --keys {a.keys} "
        f"--generations {a.generations} --enn-generations {a.enn_generations} --nm-evals {a.nm_evals}`. "
        + about(__doc__) + " CMA-ES: evosax, population 4 + ⌊3 ln D⌋, box-scaled σ₀ = 0.3; then "
        f"NelderMead(max_evals={a.nm_evals}); then, for the ENN only, identify's default gradient stage (500 BFGS "
        f"steps on the training window). Keys 0..{a.keys - 1}. Median [min – max] over keys; global evals: min–max "
        f"over keys (CMA-ES ends early when its step size underflows). Run s: median over keys of the global + "
        f"Nelder–Mead run without compilation (identify's timing; the BFGS stage's time not included).",
        "",
        f"Machine: {a.machine} (at the start; timings noisy), jaxfric {jf.__version__}."
        + (" **--quick smoke budgets, not results.**" if a.quick else ""),
        "",
    ]
    groups = {}
    for r in rows:
        groups.setdefault((r["data"], r["model"], r["global"]), []).append(r)

    def mm(rs, key):  # median [min – max] over keys
        v = np.asarray([r[key] for r in rs], float)
        return f"{np.median(v):.3g} [{v.min():.3g} – {v.max():.3g}]"

    def span(rs):  # global evaluations, min–max over keys
        ev = sorted({int(r["num_evals_global"]) for r in rs})
        return str(ev[0]) if len(ev) == 1 else f"{ev[0]}–{ev[-1]}"

    table = [{"data": d, "model": m, "global stage": g, "global evals": span(rs),
              "valid MSE %": mm(rs, "valid_mse_pct"), "train MSE %": mm(rs, "train_mse_pct"),
              "J after global": mm(rs, "J_global"), "J final": mm(rs, "J"),
              "run s": f"{np.median([r['run_s'] for r in rs]):.1f}"} for (d, m, g), rs in groups.items()]
    lines.append(markdown_table(table))
    write_report(out, "global_stages", lines, rows, float_format="", echo=False)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", default="rig,emps")
    p.add_argument("--models", default="lugre,elman")
    p.add_argument("--keys", type=int, default=5)
    p.add_argument("--generations", type=int, default=100, help="MAPSO generations (LuGre)")
    p.add_argument("--enn-generations", type=int, default=50,
                   help="MAPSO generations for the ENN (identify's default network pipeline uses 50)")
    p.add_argument("--nm-evals", type=int, default=1000)
    add_output_arguments(p, "rig, LuGre, 1 key, tiny budgets (smoke test)")
    a = p.parse_args(argv)
    if a.quick:
        a.data, a.models, a.keys, a.generations, a.enn_generations, a.nm_evals = "rig", "lugre", 1, 3, 2, 50
    a.out = results_dir(a.out, quick=a.quick)
    a.machine = machine()
    rows = []
    for dname, data in datasets(a.data.split(",")).items():
        for model_name in a.models.split(","):
            for row in run(dname, data, model_name, range(a.keys), (a.generations, a.enn_generations), a.nm_evals):
                rows.append(row)
                print(" ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()), flush=True)
                write(a.out, rows, a)  # partial results survive an interruption


if __name__ == "__main__":
    main()
