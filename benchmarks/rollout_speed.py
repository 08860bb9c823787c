"""Rollout speed: batched JAX Elman (and LuGre) against NumPy baselines.

Workload of the paper's fit (docs/algorithms.md §1, §2.2): an Elman network with 30
neurons (180 parameters), 1600 training samples, 64 candidates per call (one
swarm generation). Measured in one process, compile time apart, medians over
repeats:

- JAX ``Elman.simulate_batch`` (one ``lax.scan`` over time, (N, P) state),
  float32 and float64, compiled with :func:`jaxfric.compiler_options` ``("rollout")``
  as the library's own jits are (and once with XLA's defaults); ``vmap(Elman.simulate)`` (routed to ``simulate_batch``
  by a custom batching rule, what a vmapping optimiser gets); and JAX's default
  batching of a single-candidate scan, for comparison;
- :func:`baselines.elman_rollout_vectorised` (Python time
  loop, NumPy over candidates) and ``elman_rollout_loop`` (Python loops over
  candidates and time), float64;
- LuGre (6 parameters, exact ZOH update), same sizes, float32 and float64.

Targets (issue 4): batched JAX ENN >= 5x the NumPy vectorised rollout and
>= 100x the per-candidate loop.

Usage: ``python benchmarks/rollout_speed.py [--quick] [--out DIR]``. Writes a
Markdown table ``rollout_speed.md`` to ``DIR`` (default ``benchmarks/results/``; ``results/quick/`` with ``--quick``).
"""

from __future__ import annotations

import argparse
import functools
import os
import platform
import statistics
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import jaxfric as jf
from jaxfric.models import Elman, LuGre
from baselines import elman_rollout_loop, elman_rollout_vectorised

NEURONS, SAMPLES, CANDIDATES, FS = 30, 1600, 64, 128.0
NP_VEC = "NumPy vectorised over candidates"
NP_LOOP = "NumPy per-candidate loop"
JAX_BATCH = "JAX simulate_batch (scan, (N,P) state)"
JAX_DEFAULT_OPTIONS = "JAX simulate_batch, XLA's default compiler options"


def _first_call(fn, *args) -> float:
    t0 = time.perf_counter()
    jax.block_until_ready(fn(*args))
    return time.perf_counter() - t0


def _interleaved(cases: list[dict], rounds: int) -> None:
    """Time every case once per round, round-robin, so that load from other
    processes on a shared machine hits all implementations alike. Each case
    gets ``per_round`` calls in each of its first ``max_rounds`` rounds."""
    for case in cases:
        with jax.enable_x64(case.get("x64", False)):
            case["first"] = _first_call(case["fn"], *case["args"])
        case["times"] = []
    for r in range(rounds):
        for case in cases:
            if r >= case.get("max_rounds", rounds):
                continue
            # The x64 state is part of jit's cache key: time each case in its own mode.
            with jax.enable_x64(case.get("x64", False)):
                for _ in range(case.get("per_round", 1)):
                    t0 = time.perf_counter()
                    jax.block_until_ready(case["fn"](*case["args"]))
                    case["times"].append(time.perf_counter() - t0)


def _inputs(rng):
    t = np.arange(SAMPLES) / FS
    v = 0.010 * np.sin(2 * np.pi * 0.2 * t) + 0.004 * np.sin(2 * np.pi * 0.53 * t)  # §7 stand-in, m/s
    u = 2 * (v - v.min()) / (v.max() - v.min()) - 1  # mapminmax-scaled input for the ENN
    elman = Elman(neurons=NEURONS)
    lo, hi = elman.bounds()
    th_e = rng.uniform(lo, hi, (CANDIDATES, elman.num_params))
    lugre = LuGre()
    lo, hi = lugre.bounds()
    th_l = rng.uniform(lo, hi, (CANDIDATES, lugre.num_params))
    return elman, u, th_e, lugre, v, th_l


def run(quick: bool = False) -> list[dict]:
    rng = np.random.default_rng(0)
    elman, u, th_e, lugre, v, th_l = _inputs(rng)
    cases: list[dict] = []
    for x64 in (False, True):
        dname = "float64" if x64 else "float32"
        with jax.enable_x64(x64):
            dtype = jnp.float64 if x64 else jnp.float32
            uj, thj = jnp.asarray(u, dtype), jnp.asarray(th_e, dtype)
            vj, tlj = jnp.asarray(v, dtype), jnp.asarray(th_l, dtype)
            # x64 must be on while these are traced and compiled: compile them here, with
            # the options jaxfric's own jits use (jaxfric.compiler_options, jaxfric/_xla.py).
            jit = functools.partial(jax.jit, compiler_options=jf.compiler_options("rollout") or None)
            batched = jit(lambda th, x: elman.simulate_batch(th, x, None))
            # The same rollout with XLA's default options (256-bit vectors), for comparison.
            default = jax.jit(lambda th, x: elman.simulate_batch(th, x, None))
            # What an optimiser that vmaps a per-candidate objective gets: simulate's
            # custom batching rule forwards to simulate_batch.
            vm = jit(jax.vmap(lambda th, x: elman.simulate(th, x, None), in_axes=(0, None)))
            # JAX's default batching of a single-candidate scan, for comparison.
            plain = jit(jax.vmap(lambda th, x: elman.simulate_batch(th[None], x, None)[0], in_axes=(0, None)))
            lug = jit(lambda th, x: lugre.simulate_batch(th, x, 1.0 / FS))
            for model, impl, fn, args in [
                ("Elman", JAX_BATCH, batched, (thj, uj)),
                ("Elman", JAX_DEFAULT_OPTIONS, default, (thj, uj)),
                ("Elman", "JAX vmap(simulate) (custom batching rule)", vm, (thj, uj)),
                ("Elman", "JAX default vmap of a 1-candidate scan", plain, (thj, uj)),
                ("LuGre", "JAX simulate_batch (exact ZOH, scan)", lug, (tlj, vj)),
            ]:
                first = _first_call(fn, *args)
                cases.append(
                    dict(model=model, impl=impl, dtype=dname, fn=fn, args=args, per_round=5, first_compile=first, x64=x64)
                )
    loop_th = th_e[:8] if quick else th_e
    for dname, dtype in (("float32", np.float32), ("float64", np.float64)):
        vec = functools.partial(elman_rollout_vectorised, dtype=dtype)
        loop = functools.partial(elman_rollout_loop, dtype=dtype)
        cases.append(dict(model="Elman", impl=NP_VEC, dtype=dname, fn=vec, args=(th_e, u, NEURONS), per_round=1))
        cases.append(dict(model="Elman", impl=NP_LOOP, dtype=dname, fn=loop, args=(loop_th, u, NEURONS),
                          per_round=1, max_rounds=2 if quick else 5,
                          scale=CANDIDATES / loop_th.shape[0]))  # quick mode: 8 candidates, scaled
    _interleaved(cases, rounds=3 if quick else 15)

    rows = []
    for c in cases:
        scale = c.get("scale", 1.0)
        rows.append(dict(model=c["model"], impl=c["impl"], dtype=c["dtype"],
                         first=c.get("first_compile", c["first"]) * scale,
                         median=statistics.median(c["times"]) * scale, best=min(c["times"]) * scale,
                         n=len(c["times"])))

    # Correctness guard. Random networks in the §2.4 box are mostly chaotic (r up to 5),
    # so XLA's and libm's tanh (1-ulp apart) separate after ~100 samples; compare the
    # first 100 against JAX and the full record between the two NumPy versions.
    with jax.enable_x64(True):
        ref = np.asarray(elman.simulate_batch(th_e[:4], u[:100], None))
    assert np.allclose(elman_rollout_vectorised(th_e[:4], u[:100], NEURONS), ref, rtol=1e-9, atol=1e-9)
    assert np.allclose(elman_rollout_vectorised(th_e[:2], u, NEURONS), elman_rollout_loop(th_e[:2], u, NEURONS), atol=1e-12)
    return rows


def to_markdown(rows: list[dict], quick: bool) -> str:
    by = {(r["model"], r["impl"], r["dtype"]): r["median"] for r in rows}
    lines = [
        "# Rollout speed: batched JAX vs NumPy",
        "",
        f"Workload: {CANDIDATES} candidates x {SAMPLES} samples; Elman N = {NEURONS} "
        f"({6 * NEURONS} parameters), LuGre 6 parameters. Median (and best) of repeated calls, "
        "implementations timed round-robin so that load from other processes hits all alike; "
        "compile time (first call) reported apart. Ratios use medians and compare with the "
        "NumPy baseline of the *same dtype*. Generated by `benchmarks/rollout_speed.py`"
        + (" (--quick: fewer repeats, loop timed on 8 candidates and scaled)." if quick else "."),
        "",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"load average at the end {os.getloadavg()[0]:.1f}; jax {jax.__version__}, numpy {np.__version__}.",
        "",
        "| model | implementation | dtype | first call (s) | median (ms) | best (ms) | calls | model evals/s (median) | vs NumPy vectorised | vs NumPy loop |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        if r["model"] == "Elman":
            np_vec, np_loop = by[("Elman", NP_VEC, r["dtype"])], by[("Elman", NP_LOOP, r["dtype"])]
            ratio_vec, ratio_loop = f"{np_vec / r['median']:.1f}x", f"{np_loop / r['median']:.0f}x"
        else:
            ratio_vec = ratio_loop = "-"
        lines.append(
            f"| {r['model']} | {r['impl']} | {r['dtype']} | {r['first']:.3f} | {1e3 * r['median']:.2f} | "
            f"{1e3 * r['best']:.2f} | {r['n']} | "
            f"{CANDIDATES / r['median']:,.0f} | {ratio_vec} | {ratio_loop} |"
        )
    summary = []
    for d in ("float32", "float64"):
        j = by[("Elman", JAX_BATCH, d)]
        summary.append(f"{d} {by[('Elman', NP_VEC, d)] / j:.1f}x / {by[('Elman', NP_LOOP, d)] / j:.0f}x")
    lines += [
        "",
        "Targets: batched JAX ENN >= 5x NumPy vectorised and >= 100x the per-candidate loop.",
        "Measured (JAX simulate_batch vs NumPy of the same dtype, vectorised / loop): " + "; ".join(summary) + ".",
        "",
        "Notes: the JAX \"first call\" includes tracing and XLA compilation. A float64 scan step "
        "costs XLA about twice a float32 one (not `tanh` alone: see peers.md, Known limits), while "
        "NumPy's time is mostly per-step Python overhead that does not depend on dtype, so the "
        "float64 ratios are the smaller ones. Timings on a shared 2-core machine vary by tens of percent between runs; "
        "compare ratios measured in one run.",
        "",
    ]
    return "\n".join(lines)


def main(argv=None) -> None:
    from _harness import add_output_arguments, results_dir

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_output_arguments(parser, "fewer repeats (smoke test; written to results/quick/)")
    args = parser.parse_args(argv)
    rows = run(quick=args.quick)
    text = to_markdown(rows, args.quick)
    out = results_dir(args.out, quick=args.quick) / "rollout_speed.md"
    out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
