"""Rollout speed: batched JAX Elman (and LuGre) against NumPy baselines.

Workload of the paper's fit (ALGORITHMS.md §1, §2.2): an Elman network with 30
neurons (180 parameters), 1600 training samples, 64 candidates per call (one
swarm generation). Measured in one process, compile time apart, medians over
repeats:

- JAX ``Elman.simulate_batch`` (one ``lax.scan`` over time, (N, P) state),
  float32 and float64, plus ``vmap`` of the single-candidate rollout for
  comparison;
- :func:`jaxfric.models.reference_numpy.elman_rollout_vectorised` (Python time
  loop, NumPy over candidates) and ``elman_rollout_loop`` (Python loops over
  candidates and time), float64;
- LuGre (6 parameters, exact ZOH update), same sizes, float32 and float64.

Targets (issue 4): batched JAX ENN >= 5x the NumPy vectorised rollout and
>= 100x the per-candidate loop.

Usage: ``python benchmarks/rollout_speed.py [--quick] [--out PATH]``. Writes a
Markdown table (default ``benchmarks/results/rollout_speed.md``).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxfric.models import Elman, LuGre
from jaxfric.models.reference_numpy import elman_rollout_loop, elman_rollout_vectorised

NEURONS, SAMPLES, CANDIDATES, FS = 30, 1600, 64, 128.0


def _timed(fn, *args, repeats: int) -> tuple[float, float]:
    """(first-call seconds, median seconds of the following ``repeats`` calls)."""
    t0 = time.perf_counter()
    jax.block_until_ready(fn(*args))
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - t0)
    return first, statistics.median(times)


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
    rep_jax = 10 if quick else 50
    rows: list[dict] = []

    for x64 in (False, True):
        dname = "float64" if x64 else "float32"
        with jax.enable_x64(x64):
            dtype = jnp.float64 if x64 else jnp.float32
            uj, thj = jnp.asarray(u, dtype), jnp.asarray(th_e, dtype)
            batched = jax.jit(lambda th, x: elman.simulate_batch(th, x, None))
            first, med = _timed(batched, thj, uj, repeats=rep_jax)
            rows.append(dict(model="Elman", impl="JAX simulate_batch (scan, (N,P) state)", dtype=dname, first=first, median=med))
            vm = jax.jit(jax.vmap(lambda th, x: elman.simulate(th, x, None), in_axes=(0, None)))
            first, med = _timed(vm, thj, uj, repeats=rep_jax)
            rows.append(dict(model="Elman", impl="JAX vmap(simulate)", dtype=dname, first=first, median=med))

            vj, tlj = jnp.asarray(v, dtype), jnp.asarray(th_l, dtype)
            lug = jax.jit(lambda th, x, dt: lugre.simulate_batch(th, x, dt))
            first, med = _timed(lug, tlj, vj, 1.0 / FS, repeats=rep_jax)
            rows.append(dict(model="LuGre", impl="JAX simulate_batch (exact ZOH, scan)", dtype=dname, first=first, median=med))

    first, med = _timed(elman_rollout_vectorised, th_e, u, NEURONS, repeats=3 if quick else 7)
    rows.append(dict(model="Elman", impl="NumPy vectorised over candidates", dtype="float64", first=first, median=med))
    loop_th = th_e[:8] if quick else th_e
    first, med = _timed(elman_rollout_loop, loop_th, u, NEURONS, repeats=1 if quick else 3)
    scale = CANDIDATES / loop_th.shape[0]  # quick mode times 8 candidates and scales linearly
    rows.append(dict(model="Elman", impl="NumPy per-candidate loop", dtype="float64", first=first * scale, median=med * scale))

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
    np_vec = by[("Elman", "NumPy vectorised over candidates", "float64")]
    np_loop = by[("Elman", "NumPy per-candidate loop", "float64")]
    lines = [
        "# Rollout speed: batched JAX vs NumPy",
        "",
        f"Workload: {CANDIDATES} candidates x {SAMPLES} samples; Elman N = {NEURONS} "
        f"({6 * NEURONS} parameters), LuGre 6 parameters. Median of repeated calls, compile "
        "time (first call) reported apart. Generated by `benchmarks/rollout_speed.py`"
        + (" (--quick: fewer repeats, loop timed on 8 candidates and scaled)." if quick else "."),
        "",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"load average at the end {os.getloadavg()[0]:.1f}; jax {jax.__version__}, numpy {np.__version__}.",
        "",
        "| model | implementation | dtype | first call (s) | median (ms) | model evals/s | vs NumPy vectorised | vs NumPy loop |",
        "|---|---|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        ratio_vec = f"{np_vec / r['median']:.1f}x" if r["model"] == "Elman" else "-"
        ratio_loop = f"{np_loop / r['median']:.0f}x" if r["model"] == "Elman" else "-"
        lines.append(
            f"| {r['model']} | {r['impl']} | {r['dtype']} | {r['first']:.3f} | {1e3 * r['median']:.2f} | "
            f"{CANDIDATES / r['median']:,.0f} | {ratio_vec} | {ratio_loop} |"
        )
    jax32 = by[("Elman", "JAX simulate_batch (scan, (N,P) state)", "float32")]
    jax64 = by[("Elman", "JAX simulate_batch (scan, (N,P) state)", "float64")]
    lines += [
        "",
        "Targets: batched JAX ENN >= 5x NumPy vectorised and >= 100x the per-candidate loop.",
        f"Measured: float32 {np_vec / jax32:.1f}x / {np_loop / jax32:.0f}x; "
        f"float64 {np_vec / jax64:.1f}x / {np_loop / jax64:.0f}x.",
        "",
        "Notes: the NumPy baselines are float64 (NumPy's natural precision; float32 NumPy is "
        "not faster here because the per-step Python overhead dominates). The JAX "
        "\"first call\" includes tracing and XLA compilation. Timings on a shared 2-core "
        "machine vary by tens of percent between runs; compare ratios measured in one run.",
        "",
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats (smoke test)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "rollout_speed.md")
    args = parser.parse_args()
    rows = run(quick=args.quick)
    text = to_markdown(rows, args.quick)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
