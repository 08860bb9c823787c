"""Friction-model rollouts: batched JAX against the NumPy code users would otherwise write.

64 candidates × 1600 samples (the §7 rig's length at 128 Hz), float32 and float64, compiled
with the options jaxfric's own jits use. ENN (Elman, 30 neurons): ``simulate_batch``,
``vmap(simulate)`` (its custom batching rule) and JAX's default batching of a one-candidate
scan, against ``baselines.elman_rollout_vectorised`` and ``elman_rollout_loop``. LuGre (exact
zero-order hold): ``simulate_batch`` against ``baselines.py``'s per-step (MATLAB style),
hoisted and scalar-loop references. Every reference is checked against the JAX rollout first;
all cases run round-robin (:func:`_harness.run_round_robin`), the first call apart.

    python benchmarks/peers.py [--quick] [--out DIR] [--tag gpu]    # peers[_TAG].md, .csv
"""

from __future__ import annotations

import argparse
import functools
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # not on sys.path under `jaxfric bench`
from _harness import (Case, add_output_arguments, cell, machine, markdown_table, results_dir,  # noqa: E402
                      run_round_robin, tagged, write_report)
from baselines import (elman_rollout_loop, elman_rollout_vectorised, lugre_numpy_hoisted,  # noqa: E402
                       lugre_numpy_per_step, lugre_python_loop)

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxfric as jf  # noqa: E402
from jaxfric.models import Elman, LuGre  # noqa: E402

NEURONS, SAMPLES, CANDIDATES, FS = 30, 1600, 64, 128.0
TARGETS = {"NumPy vectorised": 5.0, "NumPy loop": 100.0}  # batched ENN rollout ≥ 5× / ≥ 100×


def workload():
    """The velocity record, its [−1, 1]-scaled copy and random candidates in each model's box."""
    rng = np.random.default_rng(0)
    t = np.arange(SAMPLES) / FS
    v = 0.010 * np.sin(2 * np.pi * 0.2 * t) + 0.004 * np.sin(2 * np.pi * 0.53 * t)  # m/s
    u = 2 * (v - v.min()) / (v.max() - v.min()) - 1
    elman, lugre = Elman(neurons=NEURONS), LuGre()
    th_e = rng.uniform(*elman.bounds(), (CANDIDATES, elman.num_params))
    th_l = rng.uniform(*lugre.bounds(), (CANDIDATES, lugre.num_params))
    return elman, u, th_e, lugre, v, th_l


def check_references(elman, u, th_e, lugre, v, th_l, phys) -> None:
    """The NumPy references equal the JAX rollouts (float64). Random networks in the §2.4
    box are mostly chaotic, so XLA's and libm's tanh (1 ulp apart) separate after ~100
    samples: the ENN is compared on its first 100."""
    dt = 1.0 / FS
    with jax.enable_x64(True):
        enn = np.asarray(elman.simulate_batch(jnp.asarray(th_e[:4]), jnp.asarray(u[:100]), None))
        ref = np.asarray(lugre.simulate_batch(jnp.asarray(th_l), jnp.asarray(v), dt))
    np.testing.assert_allclose(elman_rollout_vectorised(th_e[:4], u[:100], NEURONS), enn, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(elman_rollout_loop(th_e[:2], u, NEURONS),
                               elman_rollout_vectorised(th_e[:2], u, NEURONS), atol=1e-12)
    tol = dict(rtol=1e-9, atol=1e-9 * np.abs(ref).max())
    np.testing.assert_allclose(lugre_numpy_per_step(phys, v, dt), ref, **tol)
    np.testing.assert_allclose(lugre_numpy_hoisted(phys, v, dt), ref, **tol)
    np.testing.assert_allclose(lugre_python_loop({k: x[:2] for k, x in phys.items()}, v, dt), ref[:2], **tol)


def cases(quick: bool) -> list[Case]:
    elman, u, th_e, lugre, v, th_l = workload()
    dt = 1.0 / FS
    with jax.enable_x64(True):
        phys = {k: np.asarray(x, np.float64) for k, x in lugre.to_physical(jnp.asarray(th_l)).items()}
    check_references(elman, u, th_e, lugre, v, th_l, phys)
    out = []
    for x64, dname in ((False, "float32"), (True, "float64")):
        with jax.enable_x64(x64):
            dtype = jnp.float64 if x64 else jnp.float32
            ue, te, vl, tl = (jnp.asarray(a, dtype) for a in (u, th_e, v, th_l))
            jit = functools.partial(jax.jit, compiler_options=jf.compiler_options("rollout") or None)
            jax_rows = [
                ("ENN", "JAX simulate_batch (scan, (N, P) state)", jit(lambda t, x: elman.simulate_batch(t, x, None)), (te, ue)),
                ("ENN", "JAX vmap(simulate) (custom batching rule)",
                 jit(jax.vmap(lambda t, x: elman.simulate(t, x, None), in_axes=(0, None))), (te, ue)),
                ("ENN", "JAX default vmap of a 1-candidate scan",
                 jit(jax.vmap(lambda t, x: elman.simulate_batch(t[None], x, None)[0], in_axes=(0, None))), (te, ue)),
                ("LuGre", "JAX simulate_batch (exact ZOH, scan)", jit(lambda t, x: lugre.simulate_batch(t, x, dt)), (tl, vl)),
            ]
        for model, label, fn, args in jax_rows:
            out.append(Case(label, lambda r, fn=fn, a=args: jax.block_until_ready(fn(*a)), x64=x64, per_round=5,
                            meta=dict(model=model, dtype=dname, kind="jax")))
        d = np.float64 if x64 else np.float32
        nloop = 8 if quick else CANDIDATES  # quick: the loops run 8 candidates, scaled to 64
        out += [
            Case("NumPy vectorised over candidates", lambda r, d=d: elman_rollout_vectorised(th_e, u, NEURONS, dtype=d),
                 meta=dict(model="ENN", dtype=dname, kind="NumPy vectorised")),
            Case("NumPy per-candidate loop", lambda r, d=d, n=nloop: elman_rollout_loop(th_e[:n], u, NEURONS, dtype=d),
                 max_rounds=2 if quick else 5, meta=dict(model="ENN", dtype=dname, kind="NumPy loop",
                                                        scale=CANDIDATES / nloop)),
            Case("NumPy, per step (MATLAB style), vectorised over candidates",
                 lambda r, d=d: lugre_numpy_per_step(phys, v, dt, d), meta=dict(model="LuGre", dtype=dname,
                                                                                kind="NumPy vectorised")),
            Case("NumPy, coefficients hoisted, vectorised over candidates",
                 lambda r, d=d: lugre_numpy_hoisted(phys, v, dt, d), per_round=3,
                 meta=dict(model="LuGre", dtype=dname, kind="NumPy hoisted")),
        ]
    nloop = 4 if quick else CANDIDATES
    loop_p = {k: x[:nloop] for k, x in phys.items()}
    out.append(Case("Python scalar loop per candidate (math, float64)", lambda r: lugre_python_loop(loop_p, v, dt),
                    max_rounds=1 if quick else 5,
                    meta=dict(model="LuGre", dtype="float64", kind="NumPy loop", scale=CANDIDATES / nloop)))
    return out


def rows_of(measured: list[Case]) -> list[dict]:
    t = {(c.meta["model"], c.meta["dtype"], c.meta["kind"]): c.median * c.meta.get("scale", 1.0) for c in measured}
    rows = []
    for c in measured:
        (m, d), sec = (c.meta["model"], c.meta["dtype"]), c.median * c.meta.get("scale", 1.0)
        row = dict(model=m, implementation=c.label, dtype=d, first_call_s=c.first, median_ms=1e3 * sec,
                   calls=len(c.times), rollouts_per_s=CANDIDATES / sec)
        if c.meta["kind"] == "jax":
            for kind in ("NumPy vectorised", "NumPy hoisted", "NumPy loop"):
                ref = t.get((m, d, kind), t.get((m, "float64", kind)) if kind == "NumPy loop" else None)
                row[f"x {kind}"] = ref / sec if ref else None
        rows.append(row)
    return rows


def report(rows: list[dict], quick: bool, wall: float) -> str:
    enn = [r for r in rows if r["model"] == "ENN" and r["implementation"].startswith("JAX simulate_batch")]
    met = [f"{r['dtype']}: {r['x NumPy vectorised']:.1f}× NumPy vectorised (target {TARGETS['NumPy vectorised']:g}×), "
           f"{r['x NumPy loop']:.0f}× the per-candidate loop (target {TARGETS['NumPy loop']:g}×)" for r in enn]
    return "\n".join([
        "# Friction-model rollouts against NumPy", "",
        f"Generated by `python benchmarks/peers.py{' --quick' if quick else ''}` in {wall:.0f} s. "
        f"{CANDIDATES} candidates × {SAMPLES} samples; ENN N = {NEURONS} ({6 * NEURONS} parameters), LuGre "
        "6 parameters. Medians over rounds, implementations timed round-robin so load from other processes "
        "hits all alike; the first call (compile + run) apart; × = the NumPy reference's median time over "
        "this row's, same dtype (the Python loop: float64)."
        + (" --quick: fewer rounds, the loops on 8 (ENN) and 4 (LuGre) candidates, scaled." if quick else ""), "",
        f"Machine: {machine()}.", "",
        "Batched ENN rollout: " + "; ".join(met) + ".", "", markdown_table(rows, fmt=cell(".3g", "-")), ""])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_output_arguments(p, "fewer rounds, short loops (smoke test)", tag=True)
    a = p.parse_args(argv)
    t0 = time.perf_counter()
    measured = cases(a.quick)
    run_round_robin(measured, 3 if a.quick else 15)
    rows = rows_of(measured)
    out = results_dir(a.out, quick=a.quick)
    write_report(out, tagged("peers", a.tag), report(rows, a.quick, time.perf_counter() - t0), rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
