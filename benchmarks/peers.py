"""jaxfric against the libraries users would otherwise pick (issue 6), every row in one run.

Five sections, all measured in the same process, medians over repeats, compile time
reported apart from run time (PEERS.md §(b), §1.6, §2, §5):

1. **Test functions** (30-D Rosenbrock and Ackley, 100 agents, equal evaluation
   budgets): jaxfric PSO and MAPSO against pyswarms ``GlobalBestPSO`` (configured as
   jaxfric's PSO: w 0.9 → 0.4, c1 = c2 = 2, clamp 0.2·range, clip at the bounds) and
   scipy ``differential_evolution(vectorized=True, updating="deferred")`` (its
   ``nfev`` counts vectorised *calls*, so the objective is wrapped to count rows);
   jaxfric Nelder–Mead against scipy's. Single runs, and 8 seeds in one vmapped
   call for jaxfric. Implementations are timed round-robin so load from other
   processes on a shared machine hits all alike.
2. **Friction-model rollouts** (64 candidates × 1600 samples): the ENN rows come from
   ``benchmarks/rollout_speed.py`` (its ``run()``); LuGre (exact zero-order-hold
   update) is timed here against a NumPy reference written below, per step as
   MATLAB code would run it, with the coefficients hoisted, and as a scalar
   per-candidate loop. float32 and float64 (``jax.enable_x64`` around each case).
3. **End to end**: ENN identification (30 neurons, the synthetic rig record) with
   ``jaxfric.identify`` (default MAPSO–NMDS) against scipy (differential evolution,
   then Nelder–Mead from its best point) at the same evaluation budget, driving the
   *same* cost (identify's scaled output-error MSE, float32), which scipy calls
   through a jitted JAX function: batched for DE's vectorised calls, one candidate
   per call for Nelder–Mead. A scipy + NumPy-objective time is estimated from the
   section 2 medians.
4. **Compile time** of ``minimise`` (MAPSO–NMDS, 30-D Rosenbrock) and of ``identify``
   (ENN 30 neurons, default solver): jax.monitoring's trace / lowering / XLA
   compile spans of the first call, and first-call minus second-call wall time.
   Measured first, on cold caches.
5. **Scan efficiency**: the ENN rollout's neuron-steps per second as a fraction of a
   recurrence-free kernel doing the same tanh and multiply-add work vectorised over
   time (context replaced by an input XLA can vectorise freely).

An appendix reproduces ``benchmarks/speed_optim.py``'s own table (called through its
``main(argv)``) as a cross-check of section 1.

Usage::

    python benchmarks/peers.py                 # full run (~6 min on a loaded 2-core CPU)
    python benchmarks/peers.py --quick         # tiny sizes, smoke test (~25 s CPU, < 1 min wall)
    python benchmarks/peers.py --tag gpu --sections 1,2,3,4,5 --e2e-rounds 1 \
        --no-stage-diagnostics                 # on a GPU machine: writes peers_gpu.*

Writes ``peers[_TAG].md``, ``peers[_TAG].csv`` and ``peers[_TAG].png`` to ``--out``
(default ``benchmarks/results``; ``benchmarks/results/quick`` with ``--quick``).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import functools
import logging
import math
import os
import platform
import statistics
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import rollout_speed  # noqa: E402  (section 2 ENN rows)
import speed_optim  # noqa: E402  (appendix)
from _harness import (Case, add_output_arguments, render, render_blocks, results_dir,  # noqa: E402
                      run_round_robin, write_csv)
from baselines import NUMPY_BATCH, lugre_numpy_hoisted, lugre_numpy_per_step, lugre_python_loop  # noqa: E402

import jaxfric as jf  # noqa: E402
from jaxfric import functions as F  # noqa: E402
from jaxfric.fit import predict  # noqa: E402
from jaxfric.identification import OutputErrorCost, as_record, identify, paper_solver  # noqa: E402
from jaxfric.identification._objective import cost_data  # noqa: E402
from jaxfric.identification._timing import Stopwatch  # noqa: E402
from jaxfric.metrics import friction_metrics  # noqa: E402
from jaxfric.models import Elman  # noqa: E402
from jaxfric.optim.driver import _batching  # noqa: E402
from jaxfric.optim.sharding import resolve_devices  # noqa: E402

PROSE = render_blocks("peers.md.in")  # the report's explanatory text, apart from the measuring code

TARGETS = {
    "pso": 3.0,  # PSO and MAPSO evals/s >= 3x pyswarms
    "nm": 5.0,  # Nelder-Mead >= 5x scipy
    "rollout_vec": 5.0,  # batched ENN rollout >= 5x NumPy vectorised
    "rollout_loop": 100.0,  # ... and >= 100x the per-candidate loop
    "scan": 0.5,  # scan efficiency >= 50 %
    "compile": 10.0,  # identify compile <= 10 s
}


# ----------------------------------------------------------------------- sizes
@dataclass
class Sizes:
    dim: int = 30
    agents: int = 100
    generations: int = 500
    nm_evals: int = 20000
    repeats: int = 11
    slow_repeats: int = 5
    seeds: int = 8
    functions: tuple = ("rosenbrock", "ackley")
    nm_vmap: bool = True  # diagnostic row: Nelder-Mead seeds through vmap instead of lax.map
    batched_mapso: bool = True
    batched_nm: bool = True
    overhead_row: bool = True  # diagnostic row: minimise()'s fixed cost per call
    hybrid_compile: bool = True
    stage_diagnostics: bool = True  # §3: identify's stages timed apart
    e2e_rounds: int = 2  # §3: jaxfric and scipy runs, alternated
    neurons: int = 30
    id_samples: int = 2000
    id_solver: object = None  # None: identify's default
    hybrid: object = None  # None: MAPSONMDS()
    lugre_loop_candidates: int = 64
    scan_samples: int = 1600
    scan_candidates: int = 64
    scan_rounds: int = 15
    scan_diagnostics: bool = True
    appendix: bool = True


def quick_sizes() -> Sizes:
    """Tiny sizes: every section runs, compile time dominates (a smoke test)."""
    tiny = jf.MAPSONMDS(mapso=jf.MAPSO(lattice_size=3, num_generations=3, sl_size=1),
                        nelder_mead=jf.NelderMead(max_steps=60, max_evals=60))
    return Sizes(
        dim=10, agents=16, generations=20, nm_evals=300, repeats=2, slow_repeats=1, seeds=2,
        functions=("rosenbrock",), nm_vmap=False, batched_mapso=False, batched_nm=False,
        overhead_row=False, hybrid_compile=False, stage_diagnostics=False, e2e_rounds=1,
        neurons=4, id_samples=400,
        id_solver=tiny, hybrid=tiny, lugre_loop_candidates=4, scan_samples=400, scan_rounds=3,
        scan_diagnostics=False, appendix=False,
    )


# --------------------------------------------------------------------- timing
class CompileSpans:
    """Sum of jax.monitoring compile spans by phase (trace, lower, XLA compile), this thread."""

    EVENTS = {
        "/jax/core/compile/jaxpr_trace_duration": "trace",
        "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
        "/jax/core/compile/backend_compile_duration": "xla",
    }

    def __init__(self):
        self.total = {"trace": 0.0, "lower": 0.0, "xla": 0.0}
        self.count = {"trace": 0, "lower": 0, "xla": 0}
        self._thread = threading.get_ident()

    def _listen(self, event, start_time, end_time, **kwargs):
        phase = self.EVENTS.get(event)
        if phase and threading.get_ident() == self._thread:
            self.total[phase] += float(end_time) - float(start_time)
            self.count[phase] += 1

    def __enter__(self):
        self._thread = threading.get_ident()
        jax.monitoring.register_event_time_span_listener(self._listen)
        return self

    def __exit__(self, *exc):
        jax.monitoring.unregister_event_time_span_listener(self._listen)
        return False


class RowCounter:
    """Counts true objective evaluations (rows), whatever the call convention."""

    def __init__(self, fn, vectorised_columns=False):
        self.fn, self.cols, self.n, self.calls = fn, vectorised_columns, 0, 0

    def __call__(self, x):
        x = np.asarray(x)
        self.calls += 1
        if x.ndim == 1:
            self.n += 1
            return self.fn(x[None, :])[0]
        rows = x.T if self.cols else x  # scipy DE passes (D, S)
        self.n += rows.shape[0]
        return self.fn(rows)


# ------------------------------------------------------------------- helpers
def fmt(x, spec=".3g"):
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return format(x, spec)


def load_now() -> float:
    try:
        return os.getloadavg()[0]
    except OSError:  # pragma: no cover
        return float("nan")


def rate_row(section, case, impl, dtype, c: Case, evals, best=None, **extra):
    return dict(section=section, case=case, implementation=impl, dtype=dtype,
                evals=evals, seconds=c.median, evals_per_s=evals / c.median,
                first_call_s=c.first, compile_s=max(c.first - c.median, 0.0),
                calls=len(c.times), best_f=best, **extra)


# --------------------------------------------------------- section 1: test fns
def section_test_functions(sz: Sizes, rows: list, log) -> None:
    import pyswarms as ps
    import scipy.optimize as so


    P, D, G, NM = sz.agents, sz.dim, sz.generations, sz.nm_evals
    side = int(round(math.sqrt(P)))
    assert side * side == P, "agents must be a perfect square (MAPSO lattice)"
    pso = jf.PSO(num_particles=P, num_generations=G)
    budget = pso.evaluations()
    per_gen = jf.MAPSO(lattice_size=side, num_generations=1).evaluations() - P
    mapso = jf.MAPSO(lattice_size=side, num_generations=max(1, round((budget - P) / per_gen)))
    nm = jf.NelderMead(max_evals=NM, max_steps=10 * NM, atol=0.0, rtol=0.0)
    adaptive = D >= 10  # jaxfric switches to Gao-Han coefficients from n = 10

    for fname in sz.functions:
        log(f"[1] {fname}: {D}-D, {P} agents, budget {budget} evaluations")
        tf, obj, fb = F.get(fname), F.objective(fname), NUMPY_BATCH[fname]
        lo, hi = tf.bounds(D, np.float32)
        lo64, hi64 = lo.astype(np.float64), hi.astype(np.float64)
        vmax = 0.2 * float(hi64[0] - lo64[0])

        def x0_of(r):
            return np.random.default_rng(100 + max(r, 0)).uniform(lo64, hi64).astype(np.float32)

        def jf_single(solver, use_x0=False):
            def once(r):
                kw = {"y0": x0_of(r)} if use_x0 else {}
                s = jf.minimise(obj, solver, (lo, hi), key=jax.random.key(1000 + r), **kw)
                return {"evals": int(s.stats["num_evals"]), "f": [float(s.f)]}
            return once

        def jf_batch(solver, batching="auto"):
            def once(r):
                keys = jax.random.split(jax.random.key(2000 + r), sz.seeds)
                s = jf.minimise_many(obj, solver, (lo, hi), keys=keys, batching=batching)
                return {"evals": int(np.sum(s.stats["num_evals"])), "f": np.asarray(s.f, float).tolist()}
            return once

        def pyswarms_once(r):
            np.random.seed(max(r, 0))  # pyswarms draws from the global NumPy state
            cnt = RowCounter(fb)
            opt = ps.single.GlobalBestPSO(
                P, D, options={"c1": 2.0, "c2": 2.0, "w": 0.9}, bounds=(lo64, hi64),
                oh_strategy={"w": "lin_variation"}, bh_strategy="nearest",
                velocity_clamp=(-vmax, vmax), vh_strategy="zero")
            logging.disable(logging.CRITICAL)
            try:
                cost, _ = opt.optimize(lambda X: cnt(X), G + 1, verbose=False)  # G+1 iterations = P(G+1) evals
            finally:
                logging.disable(logging.NOTSET)
            return {"evals": cnt.n, "f": [float(cost)]}

        def de_once(r):
            cnt = RowCounter(fb, vectorised_columns=True)
            init = np.random.default_rng(300 + max(r, 0)).uniform(lo64, hi64, (P, D))
            res = so.differential_evolution(
                cnt, list(zip(lo64, hi64)), maxiter=G, init=init, tol=0.0, atol=0.0,
                polish=False, vectorized=True, updating="deferred", rng=max(r, 0))
            return {"evals": cnt.n, "f": [float(res.fun)], "nfev_reported": int(res.nfev)}

        def scipy_nm_once(r):
            scalar = so.rosen if fname == "rosenbrock" else (lambda x: float(fb(x[None, :])[0]))
            cnt = RowCounter(lambda X: np.array([scalar(X[0])]))
            res = so.minimize(cnt, x0_of(r).astype(np.float64), method="Nelder-Mead",
                              bounds=so.Bounds(lo64, hi64),
                              options=dict(maxfev=NM, maxiter=10 * NM, xatol=0.0, fatol=0.0, adaptive=adaptive))
            return {"evals": cnt.n, "f": [float(res.fun)]}

        slow = sz.slow_repeats
        cases = [
            Case("jaxfric PSO", jf_single(pso), meta=dict(kind="pso", peer="pyswarms")),
            Case("jaxfric MAPSO (10x10 lattice)" if side == 10 else f"jaxfric MAPSO ({side}x{side})",
                 jf_single(mapso), meta=dict(kind="mapso", peer="pyswarms")),
            Case(f"jaxfric PSO, {sz.seeds} seeds vmapped", jf_batch(pso), meta=dict(kind="pso_batch", peer="pyswarms")),
            Case("pyswarms GlobalBestPSO (NumPy, same PSO settings)", pyswarms_once, meta=dict(kind="pyswarms")),
            Case("scipy differential_evolution (vectorized, deferred)", de_once, meta=dict(kind="de", peer="pyswarms")),
            Case("jaxfric Nelder-Mead", jf_single(nm, use_x0=True), meta=dict(kind="nm", peer="scipy_nm")),
            Case(f"scipy Nelder-Mead ({'adaptive, ' if adaptive else ''}bounds)", scipy_nm_once, meta=dict(kind="scipy_nm")),
        ]
        if sz.batched_mapso:
            cases.insert(3, Case(f"jaxfric MAPSO, {sz.seeds} seeds vmapped", jf_batch(mapso), max_rounds=slow,
                                 meta=dict(kind="mapso_batch", peer="pyswarms")))
        # What minimise_many's batching="auto" picks for Nelder-Mead here (not re-derived).
        one_cpu = _batching("auto", nm, resolve_devices(None)) == "map"
        if sz.batched_nm:
            how = "lax.map on one CPU" if one_cpu else "vmapped"
            cases.insert(len(cases) - 1, Case(f"jaxfric Nelder-Mead, {sz.seeds} seeds (minimise_many: {how})",
                                              jf_batch(nm), max_rounds=slow, meta=dict(kind="nm_batch", peer="scipy_nm")))
        if sz.overhead_row and fname == sz.functions[0]:
            one_gen = jf.PSO(num_particles=P, num_generations=1)
            cases.append(Case("(diagnostic) jaxfric PSO with 1 generation: minimise()'s fixed cost per call",
                              jf_single(one_gen), meta=dict(kind="overhead")))
        if sz.nm_vmap and one_cpu and fname == sz.functions[0]:  # elsewhere 'auto' is vmap
            cases.insert(len(cases) - 1 - int(sz.overhead_row),
                         Case(f"(diagnostic) jaxfric Nelder-Mead, {sz.seeds} seeds vmapped (batching='vmap')",
                              jf_batch(nm, "vmap"), max_rounds=slow, meta=dict(kind="nm_vmap", peer="scipy_nm")))
        run_round_robin(cases, sz.repeats)
        rates = {}
        for c in cases:
            evals = statistics.median([res["evals"] for res in c.results])
            rates[c.meta["kind"]] = evals / c.median
        for c in cases:
            evals = int(statistics.median([res["evals"] for res in c.results]))
            fs = [f for res in c.results for f in res["f"]]
            peer = c.meta.get("peer")
            row = rate_row("1", fname, c.label, "float64" if c.meta["kind"] in ("pyswarms", "de", "scipy_nm") else "float32",
                           c, evals, best=float(np.median(fs)), best_f_min=float(np.min(fs)), kind=c.meta["kind"])
            row["ratio"] = rates[c.meta["kind"]] / rates[peer] if peer else None
            row["ratio_to"] = {"pyswarms": "pyswarms", "scipy_nm": "scipy NM"}.get(peer)
            if c.meta["kind"] == "de":
                row["note"] = f"scipy nfev = {c.results[-1]['nfev_reported']} (calls), true evals = {evals}"
            rows.append(row)


# ------------------------------------------------------------ section 2: rollout
def section_rollouts(sz: Sizes, rows: list, quick: bool, log) -> None:
    log("[2] ENN rollouts (benchmarks/rollout_speed.py run())")
    rs = rollout_speed.run(quick=quick)
    by = {(r["model"], r["impl"], r["dtype"]): r["median"] for r in rs}
    P = rollout_speed.CANDIDATES
    for r in rs:
        if r["model"] != "Elman":
            continue
        row = dict(section="2", case=f"ENN N={rollout_speed.NEURONS}, {P}x{rollout_speed.SAMPLES}",
                   implementation=r["impl"], dtype=r["dtype"], evals=P, seconds=r["median"],
                   evals_per_s=P / r["median"], first_call_s=r["first"], calls=r["n"])
        row["ratio_vec"] = by[("Elman", rollout_speed.NP_VEC, r["dtype"])] / r["median"]
        row["ratio_loop"] = by[("Elman", rollout_speed.NP_LOOP, r["dtype"])] / r["median"]
        rows.append(row)

    log("[2] LuGre rollouts")
    rng = np.random.default_rng(0)
    _, _, _, lugre, v, th = rollout_speed._inputs(rng)  # same workload as rollout_speed
    dt = 1.0 / rollout_speed.FS
    with jax.enable_x64(True):
        phys = {k: np.asarray(x, np.float64) for k, x in lugre.to_physical(jnp.asarray(th)).items()}
        ref = np.asarray(lugre.simulate_batch(jnp.asarray(th), jnp.asarray(v), dt))
    np.testing.assert_allclose(lugre_numpy_per_step(phys, v, dt), ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())
    np.testing.assert_allclose(lugre_numpy_hoisted(phys, v, dt), ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())
    sub = {k: x[:2] for k, x in phys.items()}
    np.testing.assert_allclose(lugre_python_loop(sub, v, dt), ref[:2], rtol=1e-9, atol=1e-9 * np.abs(ref).max())

    cases = []
    for x64, dname, ndt in ((False, "float32", np.float32), (True, "float64", np.float64)):
        with jax.enable_x64(x64):
            dtype = jnp.float64 if x64 else jnp.float32
            thj, vj = jnp.asarray(th, dtype), jnp.asarray(v, dtype)
            fn = jax.jit(lambda t, x: lugre.simulate_batch(t, x, dt))
            fn(thj, vj).block_until_ready()  # compile with x64 in this state
        cases.append(Case("JAX simulate_batch (exact ZOH, lax.scan)",
                          (lambda r, fn=fn, a=(thj, vj): fn(*a).block_until_ready()),
                          x64=x64, per_round=10, meta=dict(dtype=dname, kind="jax")))
        cases.append(Case("NumPy reference, per step (MATLAB-style), vectorised over candidates",
                          (lambda r, d=ndt: lugre_numpy_per_step(phys, v, dt, d)), meta=dict(dtype=dname, kind="np_step")))
        cases.append(Case("NumPy reference, coefficients hoisted, vectorised over candidates",
                          (lambda r, d=ndt: lugre_numpy_hoisted(phys, v, dt, d)), per_round=3,
                          meta=dict(dtype=dname, kind="np_hoist")))
    nloop = sz.lugre_loop_candidates
    loop_p = {k: x[:nloop] for k, x in phys.items()}
    cases.append(Case(f"Python scalar loop per candidate (math){'' if nloop == P else f', {nloop} candidates scaled'}",
                      (lambda r: lugre_python_loop(loop_p, v, dt)), max_rounds=max(1, sz.slow_repeats),
                      meta=dict(dtype="float64", kind="py_loop", scale=P / nloop)))
    run_round_robin(cases, max(3, sz.scan_rounds))
    med = {}
    for c in cases:
        med[(c.meta["kind"], c.meta["dtype"])] = c.median * c.meta.get("scale", 1.0)
    for c in cases:
        d, k = c.meta["dtype"], c.meta["kind"]
        t = med[(k, d)]
        row = dict(section="2", case=f"LuGre, {P}x{rollout_speed.SAMPLES}", implementation=c.label, dtype=d,
                   evals=P, seconds=t, evals_per_s=P / t, first_call_s=c.first, calls=len(c.times) * c.per_round)
        if k == "jax":
            row["ratio_vec"] = med[("np_step", d)] / t
            row["ratio_hoisted"] = med[("np_hoist", d)] / t
            row["ratio_loop"] = med[("py_loop", "float64")] / t
        rows.append(row)


# ------------------------------------------------- sections 3 + 4: identify
def make_data(sz: Sizes, quick: bool):
    if not quick:
        from jaxfric.rig import synthetic_friction_data

        return synthetic_friction_data(jax.random.key(0))
    # Tiny record without the rig simulator (its compile would dominate a smoke test).
    from jaxfric.rig import FrictionData

    n, fs = sz.id_samples, 128.0
    t = np.arange(n) / fs
    v = 0.01 * np.sin(2 * np.pi * 0.2 * t) + 0.004 * np.sin(2 * np.pi * 0.53 * t)
    p = {"sigma0": [1e6], "sigma1": [300.0], "sigma2": [2e3], "Fc": [200.0], "Fs": [300.0], "vs": [0.005]}
    f = lugre_numpy_hoisted(p, v, 1.0 / fs)[0] + np.random.default_rng(0).normal(0, 2.0, n)
    return FrictionData.from_arrays(v, f, 1.0 / fs)


def section_compile_hybrid(sz: Sizes, rows: list, log) -> None:
    log("[4] compile time: minimise(MAPSO-NMDS, 30-D Rosenbrock)")
    solver = sz.hybrid if sz.hybrid is not None else jf.MAPSONMDS()
    lo, hi = F.get("rosenbrock").bounds(30, np.float32)
    obj = F.objective("rosenbrock")
    out = {}
    for call in (1, 2):
        with CompileSpans() as spans, Stopwatch() as sw:
            sol = jf.minimise(obj, solver, (lo, hi), key=jax.random.key(call))
        out[call] = (sw, spans, sol)
    (sw1, sp1, sol), (sw2, _, _) = out[1], out[2]
    rows.append(dict(section="4", case="minimise(MAPSONMDS, 30-D Rosenbrock)", implementation="jaxfric",
                     dtype="float32", first_call_s=sw1.wall_s, second_call_s=sw2.wall_s,
                     first_minus_second_s=sw1.wall_s - sw2.wall_s, compile_s=sw1.compile_s,
                     trace_s=sp1.total["trace"], lower_s=sp1.total["lower"], xla_s=sp1.total["xla"],
                     xla_compiles=sp1.count["xla"], recompiles_second=sw2.num_compiles,
                     evals=int(sol.stats["num_evals"]), best_f=float(sol.f)))


def section_identify(sz: Sizes, rows: list, quick: bool, log) -> None:
    import scipy.optimize as so

    log("[3/4] identify: data")
    data = make_data(sz, quick)
    opts = {"neurons": sz.neurons}
    log("[3/4] identify ENN, first call (compiles)")
    with CompileSpans() as sp1, Stopwatch() as sw1:
        f1 = identify("elman", data, key=1, solver=sz.id_solver, model_options=opts)

    # ---- scipy driving the same cost
    model = f1.model
    record = as_record(data, None)
    scalers = (f1.velocity_scaler, f1.friction_scaler)
    dtype = jnp.dtype(f1.settings["dtype"])
    cdata = cost_data(model, record, scalers, dtype)
    cost = OutputErrorCost(model)
    # scipy's objective compiled with the options jaxfric's own rollouts use (the
    # faster choice on this CPU): the peer gets the same kernels, not slower ones.
    jit = functools.partial(jax.jit, compiler_options=jf.compiler_options("rollout") or None)
    one = jit(cost)
    many = jit(jax.vmap(cost, in_axes=(0, None)))
    j_check = float(one(jnp.asarray(f1.theta, dtype), cdata))
    assert abs(j_check - f1.metrics["cost"]) <= 1e-3 * abs(f1.metrics["cost"]) + 1e-7, (j_check, f1.metrics["cost"])

    def f_batch(X):
        return np.asarray(many(jnp.asarray(X, dtype), cdata), np.float64)

    def f_one(x):
        return float(one(jnp.asarray(x, dtype), cdata))

    lo, hi = model.bounds(f1.box)
    pop = (sz.id_solver or paper_solver(model)).mapso.num_agents
    n_global = f1.stages[0]["num_evals"]
    # a gradient refinement stage (the default pipeline) counts steps, not evaluations
    n_local = sum(st.get("num_evals", 0) for st in f1.stages) - n_global
    de_gens = max(1, math.ceil((n_global - pop) / pop))
    f_batch(np.tile((lo + hi) / 2, (2, 1)))
    f_one((lo + hi) / 2)  # compile both before timing
    n = record.n_train

    def val_metrics(theta):
        y_hat = np.asarray(predict(model, jnp.asarray(theta, dtype), scalers, record.velocity, record.dt), np.float64)
        return (friction_metrics(record.friction[:n], y_hat[:n])["mse_percent"],
                friction_metrics(record.friction[n:], y_hat[n:])["mse_percent"])

    # Alternate jaxfric and scipy runs (other keys/seeds each round) so load hits both alike.
    for rnd in range(sz.e2e_rounds):
        log(f"[3] round {rnd + 1}: jaxfric identify")
        with Stopwatch() as sw:
            fit = identify("elman", data, key=2 + rnd, solver=sz.id_solver, model_options=opts)
        if rnd == 0:
            rows.append(dict(section="4", case=f"identify(ENN {sz.neurons} neurons, default solver)"
                             if sz.id_solver is None else f"identify(ENN {sz.neurons} neurons, tiny solver)",
                             implementation="jaxfric", dtype=f1.settings["dtype"],
                             first_call_s=sw1.wall_s, second_call_s=sw.wall_s,
                             first_minus_second_s=sw1.wall_s - sw.wall_s, compile_s=f1.timings["compile_s"],
                             trace_s=sp1.total["trace"], lower_s=sp1.total["lower"], xla_s=sp1.total["xla"],
                             xla_compiles=sp1.count["xla"], recompiles_second=sw.num_compiles,
                             evals=sum(st.get("num_evals", 0) for st in f1.stages)))
        id_evals = sum(st.get("num_evals", 0) for st in fit.stages)
        rows.append(dict(section="3", case="ENN identification", round=rnd + 1,
                         implementation=f"jaxfric identify (MAPSO-NMDS), key {2 + rnd}",
                         dtype=fit.settings["dtype"], evals=id_evals, evals_global=fit.stages[0]["num_evals"],
                         evals_local=id_evals - fit.stages[0]["num_evals"],
                         seconds=fit.timings["run_s"], total_s=fit.timings["total_s"], compile_s=fit.timings["compile_s"],
                         J=fit.metrics["cost"], mse_train=fit.metrics["train"]["mse_percent"],
                         mse_valid=fit.metrics["valid"]["mse_percent"], evals_per_s=id_evals / fit.timings["run_s"]))

        log(f"[3] round {rnd + 1}: scipy DE + Nelder-Mead on the same cost")
        seed = 7 + rnd
        cnt_de = RowCounter(f_batch, vectorised_columns=True)
        init = np.random.default_rng(seed).uniform(lo, hi, (pop, lo.shape[0]))
        t0 = time.perf_counter()
        de = so.differential_evolution(cnt_de, list(zip(lo, hi)), maxiter=de_gens, init=init, tol=0.0, atol=0.0,
                                       polish=False, vectorized=True, updating="deferred", rng=seed)
        t_de = time.perf_counter() - t0
        cnt_nm = RowCounter(lambda X: np.array([f_one(X[0])]))
        t0 = time.perf_counter()
        nmres = so.minimize(cnt_nm, de.x, method="Nelder-Mead", bounds=so.Bounds(lo, hi),
                            options=dict(maxfev=n_local, maxiter=n_local, xatol=1e-8, fatol=1e-8,
                                         adaptive=lo.shape[0] >= 10))
        t_nm = time.perf_counter() - t0
        theta = nmres.x if nmres.fun <= de.fun else de.x
        m_train, m_valid = val_metrics(theta)
        evals = cnt_de.n + cnt_nm.n
        rows.append(dict(section="3", case="ENN identification", round=rnd + 1,
                         implementation=f"scipy DE (vectorized, deferred) -> scipy Nelder-Mead, jitted JAX cost, seed {seed}",
                         dtype=str(dtype), evals=evals, evals_global=cnt_de.n, evals_local=cnt_nm.n,
                         seconds=t_de + t_nm, seconds_global=t_de, seconds_local=t_nm, total_s=t_de + t_nm,
                         J=float(min(nmres.fun, de.fun)), mse_train=m_train, mse_valid=m_valid,
                         evals_per_s=evals / (t_de + t_nm), de_calls=cnt_de.calls, pop=pop,
                         neurons=sz.neurons, n_train=n,
                         note=f"DE {de_gens} generations of {pop}; NM maxfev {n_local}"))
        log(f"[3] round {rnd + 1}: jaxfric {fit.timings['run_s']:.1f}s, scipy {t_de + t_nm:.1f}s")
    if not sz.stage_diagnostics:
        return
    # Where identify's time goes: each stage alone on the same cost (one call each; run time =
    # wall - compile spans).
    ds = sz.id_solver or paper_solver(model)
    for label, s, y0 in (
        ("MAPSO stage alone", ds.mapso, None),
        ("MAPSO stage without self-learning (sl_size=1)", dataclasses.replace(ds.mapso, sl_size=1), None),
        ("Nelder-Mead stage alone (from the fitted theta, default first simplex)", ds.nelder_mead, f1.theta),
    ):
        log(f"[3] diagnostic: {label}")
        with Stopwatch() as sw:
            sol = jf.minimise(cost, s, (lo, hi), args=cdata, key=jax.random.key(5), y0=y0, dtype=dtype)
        ev = int(sol.stats["num_evals"])
        rows.append(dict(section="3", case="ENN identification, stages", implementation="(diagnostic) " + label,
                         dtype=str(dtype), evals=ev, seconds=sw.run_s, compile_s=sw.compile_s,
                         evals_per_s=ev / sw.run_s, J=float(sol.f)))


def estimate_numpy_time(rows: list) -> None:
    """scipy + NumPy-objective time, estimated from section 2's float64 NumPy medians
    (64 candidates x 1600 samples of the same 30-neuron network)."""
    vec = {r["dtype"]: r["seconds"] for r in rows if r["section"] == "2" and r["case"].startswith("ENN")
           and r["implementation"] == rollout_speed.NP_VEC}
    loop = {r["dtype"]: r["seconds"] for r in rows if r["section"] == "2" and r["case"].startswith("ENN")
            and r["implementation"] == rollout_speed.NP_LOOP}
    for r in rows:
        if r["section"] == "3" and "de_calls" in r and "float64" in vec and r["neurons"] == rollout_speed.NEURONS:
            per_sample = r["n_train"] / rollout_speed.SAMPLES
            r["est_numpy_s"] = per_sample * (
                r["de_calls"] * vec["float64"] * r["pop"] / rollout_speed.CANDIDATES
                + r["evals_local"] * loop["float64"] / rollout_speed.CANDIDATES)


# -------------------------------------------------------- section 5: scan eff.
def section_scan(sz: Sizes, rows: list, log) -> None:
    log("[5] scan efficiency")
    N, T, P = rollout_speed.NEURONS, sz.scan_samples, sz.scan_candidates
    rng = np.random.default_rng(1)
    elman = Elman(neurons=N)
    lo, hi = elman.bounds()
    th = rng.uniform(lo, hi, (P, elman.num_params))
    u = np.sin(2 * np.pi * 0.2 * np.arange(T) / 128.0)
    s = np.cos(2 * np.pi * 0.37 * np.arange(T) / 128.0)  # stands in for the context
    X = rng.uniform(-1, 1, (T, N, P))
    blocks = ("w", "r", "b", "v", "alpha", "c0")
    # Scan and ceilings compiled alike, with the options jaxfric's own jits use.
    jit = functools.partial(jax.jit, compiler_options=jf.compiler_options("rollout") or None)

    def ceiling_fly(th, u, s):
        # Same per neuron-step work as the recurrence (2 mul, 2 add, tanh, mul + fma, reduce)
        # with the context s_t * c0 computed on the fly: nothing carried from step to step.
        p = elman.to_physical(th)
        w, r, b, v, alpha, c0 = (p[k].T for k in blocks)
        rc0, ac0 = r * c0, alpha * c0
        h = jnp.tanh(w[None] * u[:, None, None] + s[:, None, None] * rc0[None] + b[None])
        return jnp.sum(v[None] * h + s[:, None, None] * ac0[None], axis=1)

    def ceiling_pre(th, u, X):
        # The context replaced by a precomputed (T, N, P) input (streams X from memory).
        p = elman.to_physical(th)
        w, r, b, v, alpha, _ = (p[k].T for k in blocks)
        h = jnp.tanh(w[None] * u[:, None, None] + r[None] * X + b[None])
        return jnp.sum(v[None] * h + alpha[None] * X, axis=1)

    cases = []
    for x64, dname in ((False, "float32"), (True, "float64")):
        with jax.enable_x64(x64):
            dt = jnp.float64 if x64 else jnp.float32
            a_th, a_u, a_s, a_X = (jnp.asarray(z, dt) for z in (th, u, s, X))
            variants = [("scan", "JAX Elman.simulate_batch (library default unroll)", elman, a_th)]
            if sz.scan_diagnostics:
                for k in (1, 2, 4, 8):
                    variants.append(("diag", f"(diagnostic) simulate_batch, unroll={k}", Elman(neurons=N, unroll=k), a_th))
                for n_cand in (8, 9, 4 * P):
                    tn = jnp.asarray(np.random.default_rng(n_cand).uniform(lo, hi, (n_cand, elman.num_params)), dt)
                    variants.append(("diag", f"(diagnostic) simulate_batch, {n_cand} candidates", elman, tn))
            for kind, label, model, tt in variants:
                fn = jit(lambda t, x, m=model: m.simulate_batch(t, x, None))
                fn(tt, a_u).block_until_ready()
                cases.append(Case(label, (lambda r, fn=fn, a=(tt, a_u): fn(*a).block_until_ready()), x64=x64,
                                  per_round=5, meta=dict(kind=kind, dtype=dname, work=tt.shape[0] * N * T)))
            for kind, label, f, third in (("ceil", "ceiling: no recurrence, context computed on the fly", ceiling_fly, a_s),
                                          ("ceil", "ceiling: no recurrence, precomputed (T,N,P) context", ceiling_pre, a_X)):
                fn = jit(f)
                fn(a_th, a_u, third).block_until_ready()
                cases.append(Case(label, (lambda r, fn=fn, a=(a_th, a_u, third): fn(*a).block_until_ready()), x64=x64,
                                  per_round=5, meta=dict(kind=kind, dtype=dname, work=P * N * T)))
    run_round_robin(cases, sz.scan_rounds)
    ceil = {}
    for c in cases:
        if c.meta["kind"] == "ceil":
            d = c.meta["dtype"]
            ceil[d] = max(ceil.get(d, 0.0), c.meta["work"] / c.median)
    for c in cases:
        d = c.meta["dtype"]
        rate = c.meta["work"] / c.median
        rows.append(dict(section="5", case=f"ENN N={N}, T={T}", implementation=c.label, dtype=d,
                         seconds=c.median, neuron_steps_per_s=rate, first_call_s=c.first,
                         calls=len(c.times) * c.per_round,
                         efficiency=rate / ceil[d],
                         kind=c.meta["kind"]))


# ------------------------------------------------------------------ appendix
def section_appendix(rows: list, log) -> list[str]:
    log("[A] speed_optim.py main()")
    with tempfile.TemporaryDirectory() as tmp:
        speed_optim.main(["--out", tmp, "--repeats", "5"])
        with open(Path(tmp) / "speed_optim.csv") as fh:
            table = list(csv.DictReader(fh))
    for r in table:
        rows.append(dict(section="A", case="rosenbrock (speed_optim.py)", implementation=r["implementation"],
                         dtype="float32", evals=int(r["evals"]), seconds=float(r["seconds"]),
                         evals_per_s=float(r["evals_per_s"]), compile_s=float(r["compile_s"]),
                         best_f=float(r["best_f"]), ratio=float(r["ratio_vs_peer"])))
    return table


# ----------------------------------------------------------------- reporting
def targets(rows: list) -> list[dict]:
    """One line per target: what was measured, the target, met or not."""
    out = []

    def add(name, value, target, higher=True, unit="x", where=""):
        if value is None:
            return
        met = value >= target if higher else value <= target
        out.append(dict(target=name, measured=value, goal=target, higher=higher, unit=unit, met=met, where=where))

    for r in rows:
        if r["section"] == "1" and r.get("kind") in ("pso", "mapso", "pso_batch", "mapso_batch"):
            add(f"{r['implementation']} evals/s vs pyswarms ({r['case']})", r["ratio"], TARGETS["pso"], where="§1")
        if r["section"] == "1" and r.get("kind") in ("nm", "nm_batch"):
            add(f"{r['implementation']} evals/s vs scipy ({r['case']})", r["ratio"], TARGETS["nm"], where="§1")
        if r["section"] == "2" and r["case"].startswith("ENN") and r["implementation"] == rollout_speed.JAX_BATCH:
            add(f"batched ENN rollout vs NumPy vectorised, {r['dtype']}", r["ratio_vec"], TARGETS["rollout_vec"], where="§2")
            add(f"batched ENN rollout vs NumPy per-candidate loop, {r['dtype']}", r["ratio_loop"], TARGETS["rollout_loop"], where="§2")
        if r["section"] == "5" and r.get("kind") == "scan":
            add(f"scan efficiency, {r['dtype']}", r["efficiency"], TARGETS["scan"], unit="%", where="§5")
        if r["section"] == "4" and r["case"].startswith("identify"):
            add(f"{r['case']} compile (trace + lower + XLA spans)", r["compile_s"], TARGETS["compile"], higher=False, unit="s", where="§4")
            add(f"{r['case']} first call − second call", r["first_minus_second_s"], TARGETS["compile"], higher=False, unit="s", where="§4")
    return out


def show(value, unit):
    if unit == "%":
        return f"{100 * value:.0f} %"
    if unit == "s":
        return f"{value:.1f} s"
    return f"{value:.1f}x"


def section_head(title: str, prose: str, header: str, align: str) -> list[str]:
    """The opening lines of a report section: its heading, its prose, a table's header rows."""
    return ["", f"## {title}", "", prose, "", header, align]


#: The sections whose report is one table of their rows: number -> (heading, prose
#: block, table header, alignment row, one row's cells).
TABLE_SECTIONS = {
    "2": ("2. Friction-model rollouts: 64 candidates × 1600 samples", "s2",
          "| model | implementation | dtype | first call s | median ms | model evals/s | vs NumPy vectorised | vs hoisted NumPy | vs per-candidate loop |",
          "|---|---|---|---:|---:|---:|---:|---:|---:|",
          lambda r: (f"| {r['case']} | {r['implementation']} | {r['dtype']} | {r['first_call_s']:.3f} | "
                     f"{1e3 * r['seconds']:.2f} | {r['evals_per_s']:,.0f} | {fmt(r.get('ratio_vec'), '.1f')} | "
                     f"{fmt(r.get('ratio_hoisted'), '.1f')} | {fmt(r.get('ratio_loop'), '.0f')} |")),
    "4": ("4. Compile time", "s4",
          "| call | dtype | first call s | second call s | first − second s | compile s | trace s | lower s | XLA s | XLA compiles | recompiles on 2nd call |",
          "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
          lambda r: (f"| {r['case']} | {r['dtype']} | {r['first_call_s']:.1f} | {r['second_call_s']:.1f} | "
                     f"{r['first_minus_second_s']:.1f} | {r['compile_s']:.1f} | {r['trace_s']:.1f} | {r['lower_s']:.1f} | "
                     f"{r['xla_s']:.1f} | {r['xla_compiles']} | {r['recompiles_second']} |")),
    "5": ("5. Scan efficiency of the ENN rollout", "s5",
          "| implementation | dtype | median ms | neuron-steps/s | efficiency |",
          "|---|---|---:|---:|---:|",
          lambda r: (f"| {r['implementation']} ({r['case']}) | {r['dtype']} | {1e3 * r['seconds']:.2f} | "
                     f"{r['neuron_steps_per_s']:.3g} | {100 * r['efficiency']:.0f} % |")),
}


def table_section(rows: list, number: str) -> list[str]:
    """A :data:`TABLE_SECTIONS` section's report lines (none when it has no rows)."""
    title, prose, header, align, cells = TABLE_SECTIONS[number]
    chosen = [r for r in rows if r["section"] == number]
    return section_head(title, PROSE(prose), header, align) + [cells(r) for r in chosen] if chosen else []


def to_markdown(rows, tgts, meta, appendix) -> str:
    L = []
    a = L.append
    a(f"# jaxfric against its peers{' (' + meta['tag'] + ')' if meta['tag'] else ''}")
    a("")
    a(PROSE("intro", quick_flag=" --quick" if meta["quick"] else ""))
    a("")
    a(PROSE("machine", machine=meta["machine"], devices=meta["devices"], jax=jax.__version__,
            numpy=np.__version__, scipy=meta["scipy"], pyswarms=meta["pyswarms"],
            python=platform.python_version(), load_start=f"{meta['load_start']:.1f}",
            load_end=f"{meta['load_end']:.1f}", wall_min=f"{meta['wall'] / 60:.1f}"))
    if meta["quick"]:
        a("")
        a(PROSE("quick"))
    a("")
    a("## Targets")
    a("")
    a("| target | measured | goal | met? | section |")
    a("|---|---:|---:|---|---|")
    for t in tgts:
        goal = ("≥ " if t["higher"] else "≤ ") + show(t["goal"], t["unit"])
        if t["met"]:
            margin = t["measured"] / t["goal"] if t["higher"] else t["goal"] / t["measured"]
            verdict = f"yes ({margin:.2f}x margin)"
        else:
            short = t["goal"] / t["measured"] if t["higher"] else t["measured"] / t["goal"]
            verdict = f"**no** ({short:.2f}x short)" if t["higher"] else f"**no** ({short:.2f}x over)"
        a(f"| {t['target']} | {show(t['measured'], t['unit'])} | {goal} | {verdict} | {t['where']} |")
    a("")
    a(PROSE("targets_note"))

    # -- section 1
    s1 = [r for r in rows if r["section"] == "1"]
    if s1:
        a("")
        a("## 1. Test functions: throughput and best value at equal budgets")
        a("")
        a(PROSE("s1", s1=meta["s1"]))
        for fname in dict.fromkeys(r["case"] for r in s1):
            a("")
            a(f"**{fname}**")
            a("")
            a("| implementation | evals/run | s (median) | evals/s | ratio | first call s | calls | best f (median) | best f (min) |")
            a("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
            for r in s1:
                if r["case"] != fname:
                    continue
                ratio = (f"{r['ratio']:.2f}x vs {r['ratio_to']}" if r.get("ratio") is not None
                         else "(peer)" if r.get("kind") in ("pyswarms", "scipy_nm") else "-")
                a(f"| {r['implementation']} | {r['evals']} | {r['seconds']:.3f} | {r['evals_per_s']:.3g} | {ratio} | "
                  f"{r['first_call_s']:.2f} | {r['calls']} | {fmt(r['best_f'])} | {fmt(r['best_f_min'])} |")
            notes = [r["note"] for r in s1 if r["case"] == fname and r.get("note")]
            if notes:
                a("")
                a("DE: " + "; ".join(notes) + ".")

    L += table_section(rows, "2")

    # -- section 3
    s3 = [r for r in rows if r["section"] == "3"]
    if s3:
        L += section_head("3. End to end: ENN identification at an equal evaluation budget",
                          PROSE("s3", s3=meta["s3"], e2e_rounds=meta["e2e_rounds"]),
                          "| implementation | dtype | evals (global + local) | run s | evals/s | J (train cost) | train MSE % | validation MSE % | est. s with NumPy objective |",
                          "|---|---|---:|---:|---:|---:|---:|---:|---:|")
        diag = [r for r in s3 if r["case"].endswith("stages")]
        s3 = [r for r in s3 if not r["case"].endswith("stages")]
        for r in s3:
            a(f"| {r['implementation']} | {r['dtype']} | {r['evals']} ({r['evals_global']} + {r['evals_local']}) | "
              f"{r['seconds']:.1f} | {r['evals_per_s']:.3g} | {r['J']:.4g} | {r['mse_train']:.3f} | {r['mse_valid']:.3f} | "
              f"{fmt(r.get('est_numpy_s'), '.0f')} |")
        sc = [r for r in s3 if r["implementation"].startswith("scipy")]
        if sc:
            a("")
            a("scipy split: " + "; ".join(f"DE {r['seconds_global']:.1f} s, Nelder–Mead {r['seconds_local']:.1f} s"
                                          for r in sc) + f" ({sc[0]['note']}). " + PROSE("s3_numpy_estimate"))
        if diag:
            a("")
            a(PROSE("s3_stages"))
            a("")
            a("| stage | evals | run s | evals/s | compile s | J |")
            a("|---|---:|---:|---:|---:|---:|")
            for r in diag:
                a(f"| {r['implementation']} | {r['evals']} | {r['seconds']:.1f} | {r['evals_per_s']:.3g} | "
                  f"{r['compile_s']:.1f} | {r['J']:.4g} |")

    L += table_section(rows, "4") + table_section(rows, "5")

    if appendix:
        L += section_head("Appendix: `benchmarks/speed_optim.py`, called from this run", PROSE("appendix"),
                          "| implementation | evals | s (median) | evals/s | × peer | compile s | best f |",
                          "|---|---:|---:|---:|---:|---:|---:|")
        for r in appendix:
            a(f"| {r['implementation']} | {r['evals']} | {float(r['seconds']):.3f} | {float(r['evals_per_s']):.3g} | "
              f"{float(r['ratio_vs_peer']):.1f} | {float(r['compile_s']):.1f} | {float(r['best_f']):.3g} |")

    a("")
    a("## Known limits")
    a("")
    a(render("peers_limits.md.in").rstrip("\n"))
    a("")
    a("## Re-running")
    a("")
    a(PROSE("rerunning"))
    a("")
    return "\n".join(L)


def solver_text(sz: Sizes) -> str:
    model = Elman(neurons=sz.neurons)
    ds = sz.id_solver or paper_solver(model)
    m, nm = ds.mapso, ds.nelder_mead
    return (f"MAPSO {m.lattice_size}×{m.lattice_size}, {m.num_generations} generations, then "
            f"Nelder–Mead capped at {nm.max_evals} evaluations")


def plot(tgts, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not tgts:
        return
    labels, values, colours = [], [], []
    for t in tgts:
        score = t["measured"] / t["goal"] if t["higher"] else t["goal"] / t["measured"]
        labels.append(t["target"])
        values.append(score)
        colours.append("tab:green" if t["met"] else "tab:red")
    fig, ax = plt.subplots(figsize=(10, 0.38 * len(tgts) + 1.4))
    y = np.arange(len(tgts))
    ax.barh(y, values, color=colours)
    ax.axvline(1.0, color="k", lw=1)
    ax.set_yticks(y, labels, fontsize=7)
    ax.invert_yaxis()
    ax.set_xscale("log")
    from matplotlib.ticker import FixedLocator, NullFormatter, NullLocator

    ticks = [t for t in (0.1, 0.2, 0.5, 1, 2, 5, 10) if min(values) / 1.5 <= t <= max(values) * 1.5]
    ax.xaxis.set_major_locator(FixedLocator(ticks))
    ax.set_xticklabels([f"{t:g}" for t in ticks])
    ax.xaxis.set_minor_locator(NullLocator())
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("measured / target (> 1: target met)")
    ax.set_title("jaxfric vs peers: targets (benchmarks/peers.py)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    add_output_arguments(p, "tiny sizes, every section (smoke test; written to results/quick/)")
    p.add_argument("--tag", default="", help="suffix of the output files, e.g. gpu -> peers_gpu.md")
    p.add_argument("--sections", default="1,2,3,4,5,A",
                   help="comma-separated subset of 1,2,3,4,5,A (3 and 4 run together)")
    p.add_argument("--e2e-rounds", type=int, default=None,
                   help="§3: jaxfric and scipy runs each (default 2; 1 on a GPU to save time)")
    p.add_argument("--no-stage-diagnostics", action="store_true",
                   help="§3: skip timing identify's stages one by one")
    a = p.parse_args(argv)
    sz = quick_sizes() if a.quick else Sizes()
    if a.e2e_rounds is not None:
        if a.e2e_rounds < 1:
            p.error("--e2e-rounds must be >= 1")
        sz.e2e_rounds = a.e2e_rounds
    if a.no_stage_diagnostics:
        sz.stage_diagnostics = False
    wanted = set(a.sections.split(","))
    t_start = time.perf_counter()
    load_start = load_now()

    def log(msg):
        print(f"[{time.perf_counter() - t_start:6.1f}s] {msg}", flush=True)

    jnp.ones(3).block_until_ready()  # backend start-up is not compile time
    rows: list[dict] = []
    # Compile times first, on cold caches.
    if ("4" in wanted or "3" in wanted) and sz.hybrid_compile:
        section_compile_hybrid(sz, rows, log)
    if "4" in wanted or "3" in wanted:
        section_identify(sz, rows, a.quick, log)
    if "1" in wanted:
        section_test_functions(sz, rows, log)
    if "2" in wanted:
        section_rollouts(sz, rows, a.quick, log)
        estimate_numpy_time(rows)
    if "5" in wanted:
        section_scan(sz, rows, log)
    appendix = section_appendix(rows, log) if ("A" in wanted and sz.appendix) else []
    order = {"1": 0, "2": 1, "3": 2, "4": 3, "5": 4, "A": 5}
    rows.sort(key=lambda r: order[r["section"]])  # stable within a section

    import pyswarms
    import scipy

    meta = dict(
        tag=a.tag, quick=a.quick, e2e_rounds=sz.e2e_rounds, load_start=load_start, load_end=load_now(),
        wall=time.perf_counter() - t_start, scipy=scipy.__version__, pyswarms=pyswarms.__version__,
        machine=f"{platform.processor() or platform.machine()}, {os.cpu_count()} logical cores",
        devices=", ".join(sorted({f"{d.device_kind} ({d.platform})" for d in jax.devices()})),
        s1=(f"{sz.dim}-D, {sz.agents} agents, {sz.generations} PSO generations, Nelder–Mead cap "
            f"{sz.nm_evals} evaluations, {sz.repeats} timed rounds ({sz.slow_repeats} for the slowest rows), "
            f"batched rows {sz.seeds} seeds"),
        s3=(f"Elman network, {sz.neurons} neurons ({6 * sz.neurons} parameters), "
            + ("the synthetic rig record (`jaxfric.rig.synthetic_friction_data(key(0))`: 2000 samples, "
               f"1600 for training), `identify('elman', data)` with its default solver ({solver_text(sz)})."
               if not a.quick else f"a {sz.id_samples}-sample LuGre-generated record, a tiny MAPSO–NMDS.")),
    )
    tgts = targets(rows)
    a.out = results_dir(a.out, quick=a.quick)
    stem = "peers" + (f"_{a.tag}" if a.tag else "")
    write_csv(rows, a.out / f"{stem}.csv")
    (a.out / f"{stem}.md").write_text(to_markdown(rows, tgts, meta, appendix))
    plot(tgts, a.out / f"{stem}.png")
    log(f"wrote {a.out / stem}.md/.csv/.png")
    for t in tgts:
        print(f"  {'MET ' if t['met'] else 'MISS'} {t['target']}: {show(t['measured'], t['unit'])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
