"""CMA-ES with and without IPOP restarts, beside pycma's IPOP-CMA-ES.

Every solver gets ``--budget`` × D evaluations on 14 test functions at D = 2, 5, 10 (float64),
3 seeds each; a run succeeds when it ends with |f − f*| < 1e-5. ``jaxfric CMA-ES``:
``Evosax("CMA_ES", restarts=0)``; ``jaxfric IPOP-CMA-ES``: ``restarts=R``; ``pycma IPOP-CMA-ES``:
``cma.fmin2(..., restarts=R, incpopsize=2)`` on the unit box from a uniform random start (a new
one at each restart), σ0 = 0.3 box widths, its ``ftarget`` only stopping a successful run early.
Functions: jaxfric.functions' sphere, Schwefel 1.2, 2.21, 2.22, Rosenbrock, Rastrigin, Ackley,
Griewank and Levy, Zakharov, Styblinski–Tang, Michalewicz (m = 10), Dixon–Price, Schwefel 2.26;
one program per dimension and solver serves every function (``lax.switch``).

    python benchmarks/cmaes_restarts.py [--quick]    # pycma (pip install cma): benchmark only
"""

from __future__ import annotations

import argparse
import importlib.metadata
import importlib.util
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # not on sys.path under `jaxfric bench`
from _harness import add_output_arguments, cell, command, machine, markdown_table, results_dir, write_report, x64  # noqa: E402

x64()  # the script's choice: |f − f*| < 1e-5 needs it
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxfric as jf  # noqa: E402
from jaxfric import functions as F  # noqa: E402

SUCCESS = 1e-5


# ------------------------------------------------------------ extra test functions
def levy(x):
    w = 1.0 + (x - 1.0) / 4.0
    return (jnp.sin(jnp.pi * w[0]) ** 2
            + jnp.sum((w[:-1] - 1.0) ** 2 * (1.0 + 10.0 * jnp.sin(jnp.pi * w[:-1] + 1.0) ** 2))
            + (w[-1] - 1.0) ** 2 * (1.0 + jnp.sin(2.0 * jnp.pi * w[-1]) ** 2))


def zakharov(x):
    s = jnp.sum(0.5 * jnp.arange(1, x.shape[0] + 1, dtype=x.dtype) * x)
    return jnp.sum(x * x) + s**2 + s**4


def styblinski_tang(x):
    return 0.5 * jnp.sum(x**4 - 16.0 * x**2 + 5.0 * x)


def michalewicz(x):
    i = jnp.arange(1, x.shape[0] + 1, dtype=x.dtype)
    return -jnp.sum(jnp.sin(x) * jnp.sin(i * x * x / jnp.pi) ** 20)


def dixon_price(x):
    i = jnp.arange(2, x.shape[0] + 1, dtype=x.dtype)
    return (x[0] - 1.0) ** 2 + jnp.sum(i * (2.0 * x[1:] ** 2 - x[:-1]) ** 2)


def schwefel_2_26(x):
    return 418.9828872724338 * x.shape[0] - jnp.sum(x * jnp.sin(jnp.sqrt(jnp.abs(x))))


#: Michalewicz's minima (m = 10) by dimension (Vanaret et al. 2020 for D = 5, 10).
MICHALEWICZ_MIN = {2: -1.8013034100985537, 5: -4.687658179, 10: -9.66015171564}


def problems():
    """``(name, fn, (lo, hi), f*(D))`` for every function."""
    out = []
    for name in ("sphere", "schwefel_1_2", "schwefel_2_21", "schwefel_2_22", "rosenbrock",
                 "rastrigin", "ackley", "griewank"):
        t = F.get(name)
        out.append((name, t.fn, (-t.half_width, t.half_width), lambda d: 0.0))
    return out + [("levy", levy, (-10.0, 10.0), lambda d: 0.0), ("zakharov", zakharov, (-5.0, 10.0), lambda d: 0.0),
                  ("styblinski_tang", styblinski_tang, (-5.0, 5.0), lambda d: -39.16616570377142 * d),
                  ("michalewicz", michalewicz, (0.0, np.pi), lambda d: MICHALEWICZ_MIN[d]),
                  ("dixon_price", dixon_price, (-10.0, 10.0), lambda d: 0.0),
                  ("schwefel_2_26", schwefel_2_26, (-500.0, 500.0), lambda d: 0.0)]


# ------------------------------------------------------------------- the solvers
def jaxfric_runs(solver, probs, dim, seeds, budget):
    """Every problem of ``probs`` at ``dim``, ``seeds`` runs each (one minimise_many call
    per problem, one program for all): rows of results."""
    fns = [p[1] for p in probs]

    def objective(y, index):
        return jax.lax.switch(index, fns, y)

    rows = []
    keys = jax.random.split(jax.random.key(2026), seeds)
    for i, (name, _, (lo, hi), fstar) in enumerate(probs):
        lower, upper = np.full(dim, lo), np.full(dim, hi)
        t0 = time.perf_counter()
        sol = jf.minimise_many(objective, solver, (lower, upper), keys=keys, args=jnp.asarray(i, jnp.int32))
        jax.block_until_ready(sol)
        seconds = (time.perf_counter() - t0) / seeds
        for s in range(seeds):
            f = float(sol.f[s])
            rows.append(dict(function=name, dim=dim, seed=s, f=f, f_star=fstar(dim),
                             error=abs(f - fstar(dim)), evals=int(sol.stats["num_evals"][s]),
                             restarts=int(sol.state.restarts[s]), seconds=seconds))
    return rows


def pycma_runs(probs, dim, seeds, budget, restarts):
    import cma

    rows = []
    for name, fn, (lo, hi), fstar in probs:
        f_batch = jax.jit(jax.vmap(fn))
        width = hi - lo
        for s in range(seeds):
            rng = np.random.default_rng(1000 * s + dim)
            count = [0]

            def f(U):  # a generation at once (fmin2's parallel_objective)
                count[0] += len(U)
                return [float(v) for v in np.asarray(f_batch(jnp.asarray(lo + np.asarray(U) * width)))]

            t0 = time.perf_counter()
            opts = {"bounds": [0.0, 1.0], "maxfevals": budget, "seed": 1 + s + 100 * dim,
                    "verbose": -9, "ftarget": fstar(dim) + 0.9 * SUCCESS}
            _, es = cma.fmin2(None, lambda: rng.uniform(0.0, 1.0, dim), 0.3, opts,
                              restarts=restarts, incpopsize=2, parallel_objective=f)
            fbest = float(es.result.fbest) if es.result.fbest is not None else np.inf
            rows.append(dict(function=name, dim=dim, seed=s, f=fbest, f_star=fstar(dim),
                             error=abs(fbest - fstar(dim)), evals=count[0],
                             restarts=None, seconds=time.perf_counter() - t0))
    return rows


# ---------------------------------------------------------------------- reporting
def summary(rows, solvers):
    out = []
    for label in solvers:
        mine = [r for r in rows if r["solver"] == label]
        solved = lambda at: f"{sum(r['success'] for r in at)}/{len(at)}"  # noqa: E731
        out.append({"solver": label, **{f"D={d}": solved([r for r in mine if r["dim"] == d])
                                        for d in sorted({r["dim"] for r in mine})},
                    "solved": solved(mine), "success_%": 100.0 * sum(r["success"] for r in mine) / max(len(mine), 1),
                    "max_evals": max(r["evals"] for r in mine), "s_per_run": float(np.median([r["seconds"] for r in mine]))})
    return out


def per_function(rows, solvers):
    table = {}
    for r in rows:
        t = table.setdefault((r["function"], r["dim"]), {"function": r["function"], "D": r["dim"]})
        t[r["solver"]] = t.get(r["solver"], 0) + int(r["success"])
    return list(table.values())


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_output_arguments(p, quick_help="2-D, 4 functions, budget 2000·D (results/quick/)")
    p.add_argument("--dims", default="2,5,10")
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--budget", type=int, default=10_000, help="evaluations per dimension")
    p.add_argument("--restarts", type=int, default=9, help="IPOP restarts (both IPOPs)")
    p.add_argument("--no-pycma", action="store_true")
    a = p.parse_args(argv)
    dims = [2] if a.quick else [int(d) for d in a.dims.split(",")]
    budget_per_dim = 2000 if a.quick else a.budget
    probs = problems()
    if a.quick:
        probs = [q for q in probs if q[0] in ("sphere", "rastrigin", "levy", "schwefel_2_26")]
    out = results_dir(a.out, quick=a.quick)

    pycma = not a.no_pycma and importlib.util.find_spec("cma") is not None
    rows = []
    t_start = time.perf_counter()
    for dim in dims:
        budget = budget_per_dim * dim
        G = (budget - 1) // jf.Evosax("CMA_ES", num_generations=1).population(dim)
        runs = {label: lambda r=r: jaxfric_runs(jf.Evosax("CMA_ES", num_generations=G, restarts=r), probs, dim,
                                                 a.seeds, budget)
                for label, r in (("jaxfric CMA-ES", 0), ("jaxfric IPOP-CMA-ES", a.restarts))}
        if pycma:
            runs["pycma IPOP-CMA-ES"] = lambda: pycma_runs(probs, dim, a.seeds, budget, a.restarts)
        for label, run in runs.items():
            t0 = time.perf_counter()
            got = [{"solver": label, **r, "success": bool(r["error"] < SUCCESS)} for r in run()]
            rows += got
            print(f"D={dim} {label}: {sum(r['success'] for r in got)}/{len(got)} "
                  f"in {time.perf_counter() - t0:.0f} s", flush=True)
    solvers = list(dict.fromkeys(r["solver"] for r in rows))
    fmt = cell(".3g")
    text = "\n\n".join([
        "# CMA-ES restarts (IPOP) beside pycma",
        f"Command: `{command('cmaes_restarts.py', argv)}` ({time.perf_counter() - t_start:.0f} s). Machine: {machine()} (at the end).",
        f"evosax {importlib.metadata.version('evosax')}, pycma "
        f"{importlib.metadata.version('cma') if pycma else '(not run)'}, float64. {len(probs)} functions × D ∈ "
        f"{dims} × {a.seeds} seeds; budget {budget_per_dim}·D evaluations for every solver; success: |f − f*| < "
        f"{SUCCESS:g} at the end; IPOP restarts R = {a.restarts} (population up to P·2^R), for jaxfric and pycma "
        f"alike. See the script's docstring for the settings.", markdown_table(summary(rows, solvers), fmt=fmt),
        "`solved`: successful runs; `max_evals`: the most evaluations any run used (pycma stops at the target, "
        "jaxfric spends the whole budget); `s_per_run`: median wall seconds per run (jaxfric's include its "
        "compilation, one program per dimension, spread over that dimension's runs; a loaded 2-core machine).",
        "Successful seeds per function and dimension:", markdown_table(per_function(rows, solvers), fmt=fmt),
    ])
    write_report(out, "cmaes_restarts", text, rows)


if __name__ == "__main__":
    main()
