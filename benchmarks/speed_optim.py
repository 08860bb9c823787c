"""Optimiser throughput against the peers users would otherwise pick, same run.

30-D Rosenbrock (``--function`` picks another test function), 100 agents: jaxfric
PSO and MAPSO (10×10 lattice) against pyswarms' GlobalBestPSO (numpy, vectorised
objective); jaxfric Nelder–Mead against ``scipy.optimize.minimize(method="Nelder-Mead")``. Function evaluations per second,
median over ``--repeats`` timed runs after one warm-up (compile time reported
apart). Batched rows run ``--seeds`` independent jaxfric runs in one vmapped call
(:func:`jaxfric.minimise_many`), the way Table 1 uses the library.

Writes ``speed_optim.md`` and ``speed_optim.csv`` to ``--out``.

    python benchmarks/speed_optim.py
    python benchmarks/speed_optim.py --dtype float64
    python benchmarks/speed_optim.py --function ackley   # writes speed_optim_ackley.md
"""

from __future__ import annotations

import argparse
import csv
import logging
import platform
import sys
import time
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/ is not on sys.path under `jaxfric bench`
from _harness import results_dir  # noqa: E402
from baselines import NUMPY_BATCH  # noqa: E402


def median_time(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--function", choices=sorted(NUMPY_BATCH), default="rosenbrock")
    p.add_argument("--dim", type=int, default=30)
    p.add_argument("--agents", type=int, default=100)
    p.add_argument("--generations", type=int, default=500)
    p.add_argument("--nm-evals", type=int, default=20000)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--seeds", type=int, default=8)
    p.add_argument("--dtype", choices=["float32", "float64"], default="float32")
    p.add_argument("--out", default=None,
                   help="output folder (default benchmarks/results)")
    p.add_argument("--tag", default="", help="suffix for the output files (e.g. gpu)")
    a = p.parse_args(argv)
    if a.dtype == "float64":
        jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import scipy.optimize

    import jaxfric as jf
    from jaxfric import functions as F

    side = int(round(a.agents**0.5))
    if side * side != a.agents:
        p.error("--agents must be a perfect square (MAPSO's lattice)")
    dt = np.dtype(a.dtype)
    lo, hi = F.get(a.function).bounds(a.dim, dt)
    obj = F.objective(a.function)
    f_batch = NUMPY_BATCH[a.function]
    probe = np.random.default_rng(1).uniform(lo, hi, (4, a.dim)).astype(np.float64)
    with jax.enable_x64(True):  # the NumPy version must be the same function
        ref = np.asarray(jax.vmap(lambda x: obj(x, None))(jnp.asarray(probe, jnp.float64)))
    np.testing.assert_allclose(f_batch(probe), ref, rtol=1e-9, atol=1e-9)
    rows = []

    def jax_row(label, solver, batched=False, once=None):
        keys = jax.random.split(jax.random.key(0), a.seeds)

        def default_once(k=[0]):
            k[0] += 1
            if batched:
                s = jf.minimise_many(obj, solver, (lo, hi), keys=jax.random.split(jax.random.key(k[0]), a.seeds))
            else:
                s = jf.minimise(obj, solver, (lo, hi), key=jax.random.key(k[0]))
            jax.block_until_ready(s)
            return s

        once = once or default_once
        t0 = time.perf_counter()
        sol = once()
        first = time.perf_counter() - t0
        run = median_time(once, a.repeats)
        evals = int(np.sum(np.asarray(sol.stats["num_evals"])))
        best = float(np.min(np.asarray(sol.f)))
        rows.append(dict(implementation=label, evals=evals, seconds=run, evals_per_s=evals / run,
                         compile_s=max(first - run, 0.0), best_f=best,
                         median_f=float(np.median(np.asarray(sol.f)))))
        del keys

    pso = jf.PSO(num_particles=a.agents, num_generations=a.generations)
    mapso = jf.MAPSO(lattice_size=side, num_generations=a.generations)
    nm = jf.NelderMead(max_evals=a.nm_evals, max_steps=10 * a.nm_evals, atol=0.0, rtol=0.0)
    jax_row("jaxfric PSO", pso)
    jax_row("jaxfric MAPSO", mapso)
    jax_row(f"jaxfric PSO, {a.seeds} seeds vmapped", pso, batched=True)
    jax_row(f"jaxfric MAPSO, {a.seeds} seeds vmapped", mapso, batched=True)

    # minimise_many over the seeds against the same runs one call each (issue 15.5)
    def one_by_one(solver, label):
        def once(k=[100]):
            k[0] += 1
            sols = [jf.minimise(obj, solver, (lo, hi), key=key)
                    for key in jax.random.split(jax.random.key(k[0]), a.seeds)]
            jax.block_until_ready(sols)
            return jax.tree_util.tree_map(lambda *x: jnp.stack(x), *sols)

        jax_row(label, solver, once=once)

    one_by_one(pso, f"jaxfric PSO, {a.seeds} x minimise")
    one_by_one(mapso, f"jaxfric MAPSO, {a.seeds} x minimise")

    # evosax's PSO (ask/tell in one lax.scan, vmapped over the seeds) at jaxfric PSO's
    # evaluation count: P (G + 1)
    try:
        from evosax.algorithms import PSO as EvosaxPSO
    except ImportError:  # pragma: no cover - the bench extra is not installed
        EvosaxPSO = None
    if EvosaxPSO is not None:
        es = EvosaxPSO(population_size=a.agents, solution=jnp.zeros(a.dim, dt))
        params = es.default_params
        f_pop = jax.vmap(lambda x: obj(x, None))
        lo_j, hi_j = jnp.asarray(lo), jnp.asarray(hi)

        @jax.jit
        def evosax_runs(key):
            def run(k):
                k0, k1 = jax.random.split(k)
                pop = jax.random.uniform(k0, (a.agents, a.dim), dt, lo_j, hi_j)
                state = es.init(k0, pop, f_pop(pop), params)

                def gen(state, kk):
                    x, state = es.ask(kk, state, params)
                    return es.tell(kk, x, f_pop(x), state, params)[0], None

                state, _ = jax.lax.scan(gen, state, jax.random.split(k1, a.generations))
                return state.best_fitness

            return jax.vmap(run)(jax.random.split(key, a.seeds))

        def evosax_once(k=[200]):
            k[0] += 1
            return jax.block_until_ready(evosax_runs(jax.random.key(k[0])))

        t0 = time.perf_counter()
        bests = evosax_once()
        first = time.perf_counter() - t0
        run = median_time(evosax_once, a.repeats)
        evals = a.seeds * a.agents * (a.generations + 1)
        rows.append(dict(implementation=f"evosax PSO, {a.seeds} seeds vmapped", evals=evals, seconds=run,
                         evals_per_s=evals / run, compile_s=max(first - run, 0.0),
                         best_f=float(np.min(np.asarray(bests))),
                         median_f=float(np.median(np.asarray(bests)))))

    import pyswarms as ps

    logging.disable(logging.CRITICAL)  # pyswarms logs every run

    def pyswarms_once():
        opt = ps.single.GlobalBestPSO(
            a.agents, a.dim, options={"c1": 2.0, "c2": 2.0, "w": 0.7},
            bounds=(lo.astype(float), hi.astype(float)), velocity_clamp=(-0.2 * (hi - lo)[0], 0.2 * (hi - lo)[0]),
        )
        return opt.optimize(f_batch, a.generations, verbose=False)

    run = median_time(pyswarms_once, a.repeats)
    best = pyswarms_once()[0]
    rows.append(dict(implementation="pyswarms GlobalBestPSO (numpy)", evals=a.agents * (a.generations + 1),
                     seconds=run, evals_per_s=a.agents * (a.generations + 1) / run, compile_s=0.0, best_f=float(best)))
    logging.disable(logging.NOTSET)

    jax_row("jaxfric Nelder-Mead", nm)
    x0 = np.random.default_rng(0).uniform(lo, hi)
    opts = dict(maxfev=a.nm_evals, maxiter=10 * a.nm_evals, xatol=0.0, fatol=0.0, adaptive=True)

    scalar = scipy.optimize.rosen if a.function == "rosenbrock" else (lambda x: float(f_batch(x[None])[0]))

    def scipy_nm():
        return scipy.optimize.minimize(scalar, x0, method="Nelder-Mead", options=opts)

    res = scipy_nm()
    run = median_time(scipy_nm, max(1, a.repeats // 2))
    rows.append(dict(implementation="scipy Nelder-Mead (adaptive)", evals=int(res.nfev), seconds=run,
                     evals_per_s=res.nfev / run, compile_s=0.0, best_f=float(res.fun)))

    by = {r["implementation"]: r for r in rows}
    ref_pso = by["pyswarms GlobalBestPSO (numpy)"]["evals_per_s"]
    ref_nm = by["scipy Nelder-Mead (adaptive)"]["evals_per_s"]
    for r in rows:
        ref = ref_nm if "Nelder" in r["implementation"] else ref_pso
        r["ratio_vs_peer"] = r["evals_per_s"] / ref
        r.setdefault("median_f", r["best_f"])
    # the batched comparisons: vmapped seeds against one call each, and against evosax
    ratios = []
    for name in ("PSO", "MAPSO"):
        many = by.get(f"jaxfric {name}, {a.seeds} seeds vmapped")
        calls = by.get(f"jaxfric {name}, {a.seeds} x minimise")
        if many and calls:
            ratios.append(f"minimise_many / {a.seeds} x minimise, {name} (evals/s): "
                          f"{many['evals_per_s'] / calls['evals_per_s']:.2f}")
    evo = by.get(f"evosax PSO, {a.seeds} seeds vmapped")
    mine = by.get(f"jaxfric PSO, {a.seeds} seeds vmapped")
    if evo and mine:
        ratios.append(f"jaxfric PSO / evosax PSO, {a.seeds} seeds vmapped (evals/s): "
                      f"{mine['evals_per_s'] / evo['evals_per_s']:.2f}; median final f "
                      f"{mine['median_f']:.3g} vs {evo['median_f']:.3g} at equal evaluations")
    out = results_dir(a.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = ("speed_optim" + (f"_{a.function}" if a.function != "rosenbrock" else "")
            + (f"_{a.tag}" if a.tag else ""))
    with open(out / f"{stem}.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    dev = jax.devices()[0]
    lines = [
        "# Optimiser throughput against peers",
        "",
        f"{a.dim}-D {a.function}, {a.agents} agents, {a.generations} generations, {a.dtype}; "
        f"Nelder–Mead budget {a.nm_evals} evaluations. Median of {a.repeats} timed runs after a "
        "warm-up; every row measured in the same run. Ratio: evaluations per second over the "
        "peer's (pyswarms for swarms, scipy for Nelder–Mead). Best f is not comparable across "
        "swarm rows (different coefficients; evosax's PSO is unbounded, with per-particle "
        "coefficients).",
        "",
        f"Machine: {platform.processor() or platform.machine()}, device {dev.device_kind} "
        f"({jax.default_backend()}), jax {jax.__version__}, Python {sys.version.split()[0]}. "
        f"Re-run: `python benchmarks/speed_optim.py{' --dtype float64' if a.dtype == 'float64' else ''}`.",
        "",
        "| implementation | evals | s (median) | evals/s | × peer | compile s | best f |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['implementation']} | {r['evals']} | {r['seconds']:.3f} | {r['evals_per_s']:.3g} | "
            f"{r['ratio_vs_peer']:.1f} | {r['compile_s']:.1f} | {r['best_f']:.3g} |"
        )
    lines += [""] + [f"- {r}" for r in ratios]
    (out / f"{stem}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    del jnp


if __name__ == "__main__":
    main()
