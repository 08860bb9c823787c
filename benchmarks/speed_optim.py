"""Optimiser throughput against the peers users would otherwise pick, same run.

30-D Rosenbrock (``--function``: another), 100 agents: jaxfric PSO and MAPSO against pyswarms'
GlobalBestPSO (vectorised NumPy objective) and evosax's PSO, Nelder–Mead against SciPy's;
evaluations per second in ``--repeats`` rounds after a warm-up, every implementation once per
round, in turn, ratios to the peer taken round by round (median). ``--short`` (issue 47): one
default ``minimise`` call each (PSO at ``--short-generations``, MAPSO at the first) against
pyswarms at the same generations, each call split into its fixed cost (a one-generation
call), the objective alone on its evaluations (the ceiling) and the solver's own work.

    python benchmarks/speed_optim.py --dtype float64 [--function ackley] [--short] [--quick]
"""

from __future__ import annotations

import argparse
import functools
import importlib.util
import logging
import statistics
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/ is not on sys.path under `jaxfric bench`
from _harness import (Case, add_output_arguments, machine, results_dir, run_round_robin, tagged,  # noqa: E402
                      write_report, x64 as enable_x64)
from baselines import NUMPY_BATCH, numpy_batch  # noqa: E402

PYSWARMS = "pyswarms GlobalBestPSO (numpy)"
OBJECTIVE = "objective alone, jaxfric's compilation (the ceiling)"
SCIPY_NM = "scipy Nelder-Mead (adaptive)"


def pyswarms_once(a, lo, hi, f_batch, generations):
    """``once(r)``: one pyswarms GlobalBestPSO run (c1 = c2 = 2, w = 0.7, velocities
    clamped to 0.2 box widths) of ``generations``: ``(evaluations, [best f])``."""
    import pyswarms as ps

    def once(r):
        opt = ps.single.GlobalBestPSO(
            a.agents, a.dim, options={"c1": 2.0, "c2": 2.0, "w": 0.7},
            bounds=(lo.astype(float), hi.astype(float)), velocity_clamp=(-0.2 * (hi - lo)[0], 0.2 * (hi - lo)[0]))
        return a.agents * (generations + 1), np.array([opt.optimize(f_batch, generations, verbose=False)[0]])
    return once


def objective_once(a, lo, hi, obj, f_batch, evals, numpy=False):
    """``once(r)``: the objective alone on ``evals`` fresh points, batch by batch (``a.agents``
    a batch) as a single run evaluates them, compiled with the solvers' options — no run that
    calls it can do more evaluations per second — or, ``numpy``, NumPy's twin (pyswarms' side).
    Vmapped runs evaluate larger batches, which XLA may vectorise otherwise."""
    import jaxfric as jf

    dt = np.dtype(a.dtype)
    batches = max(evals // a.agents, 1)
    points = jnp.asarray(np.random.default_rng(3).uniform(lo, hi, (batches, a.agents, a.dim)), dt)
    if numpy:
        points = np.asarray(points)
        return lambda r: (batches * a.agents, np.array([sum(f_batch(x).min() for x in points)]))
    f_pop = jax.vmap(lambda x: obj(x, None))

    @functools.partial(jax.jit, compiler_options=jf.compiler_options("solver") or None)
    def alone(X):
        return jax.lax.scan(lambda c, x: (c + jnp.min(f_pop(x)), None), jnp.zeros((), dt), X)[0]

    return lambda r: (batches * a.agents, np.array([float(alone(points))]))


def jax_once(obj, solver, bounds, batched=0, calls=1, int_key=False):
    """``once(r)``: one ``minimise`` call (``batched`` seeds: one ``minimise_many`` call;
    ``calls``: as many ``minimise`` calls; ``int_key``: ``key=1000 + r``, as a user writes it),
    ``(evaluations, best f values)``."""
    import jaxfric as jf

    def once(r):
        key = 1000 + r if int_key else jax.random.key(1000 + r)
        if batched:
            s = jf.minimise_many(obj, solver, bounds, keys=jax.random.split(key, batched))
        elif calls > 1:  # the same runs one call each (minimise_many against minimise)
            s = [jf.minimise(obj, solver, bounds, key=k) for k in jax.random.split(key, calls)]
            s = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *s)
        else:
            s = jf.minimise(obj, solver, bounds, key=key)
        jax.block_until_ready(s)
        return int(np.sum(np.asarray(s.stats["num_evals"]))), np.asarray(s.f)

    return once


def timed_rounds(cases: list[Case], rounds: int) -> None:
    """:func:`_harness.run_round_robin` with pyswarms' per-run log silenced."""
    logging.disable(logging.CRITICAL)
    try:
        run_round_robin(cases, rounds)
    finally:
        logging.disable(logging.NOTSET)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--function", choices=sorted(NUMPY_BATCH), default="rosenbrock")
    for name, default in (("--dim", 30), ("--agents", 100), ("--generations", 500), ("--nm-evals", 20000),
                          ("--repeats", 7), ("--seeds", 8)):  # --repeats: timed rounds, every implementation once each
        p.add_argument(name, type=int, default=default)
    p.add_argument("--dtype", choices=["float32", "float64"], default="float32")
    add_output_arguments(p, "5-D, 16 agents, 10 generations (short: 10 and 20), 1 round", tag=True)
    p.add_argument("--short", action="store_true", help="the short default runs (speed_optim_short.md) instead")
    p.add_argument("--short-generations", default="100,300", help="PSO's generations in --short (MAPSO runs the first)")
    a = p.parse_args(argv)
    if a.quick:
        a.dim, a.agents, a.generations, a.nm_evals, a.repeats, a.seeds = 5, 16, 10, 200, 1, 2
        a.short_generations = "10,20"
    x64 = a.dtype == "float64"
    if x64:
        enable_x64()
    import scipy.optimize

    import jaxfric as jf
    from jaxfric import functions as F

    side = int(round(a.agents**0.5))
    if side * side != a.agents:
        p.error("--agents must be a perfect square (MAPSO's lattice)")
    lo, hi = F.get(a.function).bounds(a.dim, np.dtype(a.dtype))
    obj, f_batch = F.objective(a.function), numpy_batch(a.function)
    out = results_dir(a.out, quick=a.quick)
    if a.short:
        return short_runs(a, lo, hi, obj, f_batch, x64, out)
    pso = jf.PSO(num_particles=a.agents, num_generations=a.generations)
    mapso = jf.MAPSO(lattice_size=side, num_generations=a.generations)
    nm = jf.NelderMead(max_evals=a.nm_evals, max_steps=10 * a.nm_evals, atol=0.0, rtol=0.0)
    many = f"{a.seeds} seeds vmapped"
    cases = [Case(label, once, x64=x64) for label, once in [
        ("jaxfric PSO", jax_once(obj, pso, (lo, hi))), ("jaxfric MAPSO", jax_once(obj, mapso, (lo, hi))),
        (f"jaxfric PSO, {many}", jax_once(obj, pso, (lo, hi), batched=a.seeds)),
        (f"jaxfric MAPSO, {many}", jax_once(obj, mapso, (lo, hi), batched=a.seeds)),
        # minimise_many over the seeds against the same runs one call each (issue 15.5)
        (f"jaxfric PSO, {a.seeds} x minimise", jax_once(obj, pso, (lo, hi), calls=a.seeds)),
        (f"jaxfric MAPSO, {a.seeds} x minimise", jax_once(obj, mapso, (lo, hi), calls=a.seeds))]]
    if importlib.util.find_spec("evosax"):  # the bench extra
        cases.append(Case(f"evosax PSO, {many}", evosax_once(a, lo, hi, obj), x64=x64))
    # the objective alone on as many points as one PSO run evaluates caps the single-run rows' ratio to pyswarms
    evals = a.agents * (a.generations + 1)
    x0 = np.random.default_rng(0).uniform(lo, hi)
    opts = dict(maxfev=a.nm_evals, maxiter=10 * a.nm_evals, xatol=0.0, fatol=0.0, adaptive=True)
    scalar = scipy.optimize.rosen if a.function == "rosenbrock" else (lambda x: float(f_batch(x[None])[0]))

    def scipy_once(r):
        res = scipy.optimize.minimize(scalar, x0, method="Nelder-Mead", options=opts)
        return int(res.nfev), np.array([res.fun])

    cases += [Case(PYSWARMS, pyswarms_once(a, lo, hi, f_batch, a.generations), x64=x64),
              Case(OBJECTIVE, objective_once(a, lo, hi, obj, f_batch, evals), x64=x64),
              Case("objective alone, NumPy (pyswarms's side)",
                   objective_once(a, lo, hi, obj, f_batch, evals, numpy=True), x64=x64),
              Case("jaxfric Nelder-Mead", jax_once(obj, nm, (lo, hi)), x64=x64), Case(SCIPY_NM, scipy_once, x64=x64)]
    timed_rounds(cases, a.repeats)
    by = {c.label: c for c in cases}
    rows = [_row(c, by[SCIPY_NM if "Nelder" in c.label else PYSWARMS]) for c in cases]
    # the batched comparisons, round by round: vmapped seeds against one call each, and against evosax
    ratios = [f"minimise_many / {a.seeds} x minimise, {name} (evals/s): "
              + _spread(_round_ratios(by[f"jaxfric {name}, {many}"], by[f"jaxfric {name}, {a.seeds} x minimise"]))
              for name in ("PSO", "MAPSO")]
    if (evo := by.get(f"evosax PSO, {many}")) is not None:
        mine = by[f"jaxfric PSO, {many}"]
        f_mine, f_evo = (float(np.median(c.results[0][1])) for c in (mine, evo))
        ratios.append(f"jaxfric PSO / evosax PSO, {many} (evals/s): {_spread(_round_ratios(mine, evo))}; "
                      f"median final f {f_mine:.3g} vs {f_evo:.3g} at equal evaluations")
    ratios.append(f"ceiling: the objective alone (XLA) over pyswarms (evals/s): "
                  f"{_spread(_round_ratios(by[OBJECTIVE], by[PYSWARMS]))}; no single run can exceed it")
    lines = [
        "# Optimiser throughput against peers", "",
        f"{a.dim}-D {a.function}, {a.agents} agents, {a.generations} generations, {a.dtype}; Nelder–Mead budget "
        f"{a.nm_evals} evaluations. {a.repeats} timed rounds after a warm-up; each round runs every implementation "
        f"once, in turn, so load from other processes hits all alike. s: the median over rounds. × peer: "
        f"evaluations per second over the peer's (pyswarms for swarms, scipy for Nelder–Mead) in the same round, "
        f"median over rounds (lowest–highest round in brackets). Best f (first timed round) is not comparable "
        f"across swarm rows (different coefficients; evosax's PSO is unbounded, with per-particle coefficients).", "",
        f"Machine: {machine()}, device {jax.devices()[0].device_kind}. "
        f"Re-run: `python benchmarks/speed_optim.py{' --dtype float64' if x64 else ''}`.", "",
        "| implementation | evals | s (median) | evals/s | × peer | compile s | best f |",
        "|---|---|---|---|---|---|---|",
        *(f"| {r['implementation']} | {r['evals']} | {r['seconds']:.3f} | {r['evals_per_s']:.3g} | "
          f"{r['ratio_vs_peer']:.1f} ({r['ratio_min']:.1f}–{r['ratio_max']:.1f}) | "
          f"{r['compile_s']:.1f} | {r['best_f']:.3g} |" for r in rows),
        "", *(f"- {r}" for r in ratios)]
    stem = tagged("speed_optim" + (f"_{a.function}" if a.function != "rosenbrock" else ""), a.tag)
    write_report(out, stem, lines, rows, float_format="")


def evosax_once(a, lo, hi, obj):
    """``once(r)``: evosax's PSO (ask/tell in one ``lax.scan``, vmapped over the seeds) at
    jaxfric PSO's evaluation count, P (G + 1)."""
    from evosax.algorithms import PSO as EvosaxPSO

    dt = np.dtype(a.dtype)
    es = EvosaxPSO(population_size=a.agents, solution=jnp.zeros(a.dim, dt))
    params, f_pop = es.default_params, jax.vmap(lambda x: obj(x, None))

    @jax.jit
    def runs(key):
        def run(k):
            k0, k1 = jax.random.split(k)
            pop = jax.random.uniform(k0, (a.agents, a.dim), dt, jnp.asarray(lo), jnp.asarray(hi))
            state = es.init(k0, pop, f_pop(pop), params)

            def gen(state, kk):
                x, state = es.ask(kk, state, params)
                return es.tell(kk, x, f_pop(x), state, params)[0], None

            return jax.lax.scan(gen, state, jax.random.split(k1, a.generations))[0].best_fitness

        return jax.vmap(run)(jax.random.split(key, a.seeds))

    return lambda r: (a.seeds * a.agents * (a.generations + 1),
                      np.asarray(jax.block_until_ready(runs(jax.random.key(2000 + r)))))


def short_runs(a, lo, hi, obj, f_batch, x64, out):
    """Issue 47's short runs: one default ``minimise`` call each against pyswarms at the
    same generations, and where each call's time goes (see the module docstring)."""
    import jaxfric as jf

    side = int(round(a.agents**0.5))
    gens = [int(g) for g in a.short_generations.split(",")]

    def solver(name, g):
        return (jf.PSO(num_particles=a.agents, num_generations=g) if name == "PSO"
                else jf.MAPSO(lattice_size=side, num_generations=g))

    cases: list[Case] = []
    for name, g in [("PSO", g) for g in gens] + [("MAPSO", gens[0])]:
        meta, run, fixed = {"name": name, "g": g}, solver(name, g), solver(name, 1)
        cases += [Case(f"jaxfric {name}, {g} generations", jax_once(obj, run, (lo, hi), int_key=True), x64=x64,
                       meta={"kind": "run", **meta}),
                  Case(f"jaxfric {name}, 1 generation (the call's fixed cost)",
                       jax_once(obj, fixed, (lo, hi), int_key=True), x64=x64, meta={"kind": "fixed", **meta}),
                  Case(f"objective alone, {name} {g} generations' evaluations",
                       objective_once(a, lo, hi, obj, f_batch, run.evaluations()), x64=x64,
                       meta={"kind": "ceiling", **meta})]
    cases += [Case(f"{PYSWARMS}, {g} generations", pyswarms_once(a, lo, hi, f_batch, g), meta={"kind": "peer", "g": g})
              for g in sorted(set(gens))]
    timed_rounds(cases, a.repeats)
    peer = {c.meta["g"]: c for c in cases if c.meta["kind"] == "peer"}
    rows, split = [], []
    for c in cases:
        ref, ratios = peer[c.meta["g"]], _round_ratios(c, peer[c.meta["g"]])
        rows.append(dict(implementation=c.label, evals=c.results[0][0], seconds=c.median,
                         evals_per_s=c.results[0][0] / c.median, ratio_vs_pyswarms=statistics.median(ratios),
                         ratio_min=min(ratios), ratio_max=max(ratios), first_s=c.first))
        if c.meta["kind"] != "run":
            continue
        same = {d.meta["kind"]: d for d in cases if d.meta.get("name") == c.meta["name"] and d.meta["g"] == c.meta["g"]}
        total, fixed, ceil = c.median, same["fixed"].median, same["ceiling"].median
        split.append(f"{c.label}: {1e3 * total:.1f} ms a call = {1e3 * fixed:.1f} ms the call's "
                     f"fixed cost (a 1-generation call: Python, checks, dispatch, the start) + "
                     f"{1e3 * ceil:.1f} ms the objective alone on the run's evaluations + "
                     f"{1e3 * max(total - fixed - ceil, 0.0):.1f} ms the solver's own work; "
                     f"{statistics.median(ratios):.2f}× pyswarms' evaluations per second, the ceiling "
                     f"{c.results[0][0] / (fixed + ceil) / (ref.results[0][0] / ref.median):.2f}× "
                     "with no solver work at all")
    lines = [
        "# Short runs: one default `minimise` call each", "",
        f"{a.dim}-D {a.function}, {a.agents} agents, {a.dtype}, the default call (`jf.minimise(fn, "
        f"jf.PSO(num_particles=100, num_generations=G), bounds, key=k)`, a new key each round, the program "
        f"compiled by the warm-up) as a benchmarking user makes it, against pyswarms' GlobalBestPSO at the same "
        f"generations. {a.repeats} timed rounds after a warm-up, every row once per round in turn; s: the median "
        f"over rounds; × pyswarms: evaluations per second over pyswarms' at the same generations in the same "
        f"round, median (lowest–highest). The 1-generation rows are the call's fixed cost; the objective-alone "
        f"rows evaluate the run's points in batches of 100, compiled as the solvers are (no run can be faster).", "",
        f"Machine: {machine()} (at the end), device {jax.devices()[0].device_kind}. "
        f"Re-run: `python benchmarks/speed_optim.py --dtype {a.dtype} --short`.", "",
        "| implementation | evals | s (median) | evals/s | × pyswarms | first call s |",
        "|---|---|---|---|---|---|",
        *(f"| {r['implementation']} | {r['evals']} | {r['seconds']:.4f} | {r['evals_per_s']:.3g} | "
          f"{r['ratio_vs_pyswarms']:.2f} ({r['ratio_min']:.2f}–{r['ratio_max']:.2f}) | {r['first_s']:.2f} |"
          for r in rows),
        "", "Where a call's time goes (medians):", "", *(f"- {x}" for x in split)]
    write_report(out, tagged("speed_optim_short", a.tag), lines, rows, float_format="")


def _round_ratios(case: Case, peer: Case) -> list[float]:
    """Evaluations per second of ``case`` over ``peer``'s, one ratio per timed round."""
    evals, peer_evals = case.results[0][0], peer.results[0][0]
    return [(evals / t) / (peer_evals / tp) for t, tp in zip(case.times, peer.times)]


def _spread(ratios: list[float]) -> str:
    return f"{statistics.median(ratios):.2f} (rounds {min(ratios):.2f}–{max(ratios):.2f})"


def _row(case: Case, peer: Case) -> dict:
    """A table row: the first timed round's evaluations and best f, the median round
    time, and the ratio to ``peer`` round by round."""
    (evals, f), ratios = case.results[0], _round_ratios(case, peer)
    return dict(implementation=case.label, evals=evals, seconds=case.median, evals_per_s=evals / case.median,
                compile_s=max(case.first - case.median, 0.0), best_f=float(np.min(f)), median_f=float(np.median(f)),
                ratio_vs_peer=statistics.median(ratios), ratio_min=min(ratios), ratio_max=max(ratios))


if __name__ == "__main__":
    main()
