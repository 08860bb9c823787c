"""Parallel-in-time (DEER, ``jaxfric.parallel_scan``) against the sequential ``lax.scan``.

Per case: the wall time of both rollouts (jitted, compile excluded, medians of round-robin
rounds), the Newton iterations, whether they converged (else the sequential scan answered,
``fell_back``) and the largest relative difference of the outputs. ``elman``: the diagonal
Elman network, 30 neurons, P candidates, float32, in the default box and a contracting one;
``motion``: friction models inside the mechanics (``simulate_motion``), float64, a multi-sine
force on a 95 kg axis, the whole record at once and in chunks. ``--tag gpu``:
``parallel_scan_gpu.*`` (benchmarks/gpu_check.sh); every row names its device.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import (Case, add_output_arguments, cell, markdown_table, results_dir, run_round_robin,  # noqa: E402
                      tagged, write_report)


def _device() -> str:
    import jax

    d = jax.devices()[0]
    return f"{d.platform}:{getattr(d, 'device_kind', '')}".rstrip(":")


def elman_cases(T: int, P: int, rounds: int):
    import jax
    import jax.numpy as jnp

    from jaxfric.models import Elman
    from jaxfric.parallel_scan import elman_rollout

    rows = []
    for box, model in (("default", Elman(neurons=30, context_weight_bound=1.0)),
                       ("contracting", Elman(neurons=30, context_weight_bound=0.4, alpha_max=0.5))):
        lo, hi = model.bounds()
        th = jax.random.uniform(jax.random.key(0), (P, model.num_params), minval=lo, maxval=hi).astype(jnp.float32)
        t = jnp.linspace(0.0, 1.0, T, dtype=jnp.float32)
        u = 0.9 * jnp.sin(2 * jnp.pi * 40 * t) * jnp.cos(2 * jnp.pi * 3 * t)
        seq = jax.jit(lambda a, b, m=model: m.simulate_batch(a, b))
        par = jax.jit(lambda a, b, m=model: elman_rollout(m, a, b, return_info=True))
        cases = [Case("sequential", lambda r: jax.block_until_ready(seq(th, u))),
                 Case("deer", lambda r: jax.block_until_ready(par(th, u)))]
        run_round_robin(cases, rounds)
        y_seq = np.asarray(cases[0].results[-1])
        y_par, info = cases[1].results[-1]
        rows.append(_row("elman", f"{box} box", T, P, "float32", cases, info,
                         np.max(np.abs(np.asarray(y_par) - y_seq)) / np.max(np.abs(y_seq))))
    return rows


def motion_cases(T: int, rounds: int, chunks=(None,)):
    import jax
    import jax.numpy as jnp

    import jaxfric.models as M
    from jaxfric.motion import friction_step
    from jaxfric.motion._forward import simulate_motion
    from jaxfric.parallel_scan import simulate_motion_parallel

    rows = []
    dt = 1e-3
    t = np.arange(T) * dt
    force = 60.0 * np.sin(2 * np.pi * 0.7 * t) + 15.0 * np.sin(2 * np.pi * 5.3 * t)
    with jax.enable_x64(True):
        for model in (M.Coulomb(), M.Stribeck(), M.LuGre(), M.Dahl()):
            lo, hi = model.bounds(model.search_box(None, 0.1 * np.sin(t), force))
            theta = jnp.asarray(lo + 0.4 * (hi - lo))
            step = friction_step(model)
            f = jnp.asarray(force)
            seq = jax.jit(lambda th, s=step: simulate_motion(s, th, 95.0, f, dt, 0.0, 0.0))
            for chunk in chunks:
                par = jax.jit(lambda th, s=step, c=chunk: simulate_motion_parallel(
                    s, th, 95.0, f, dt, 0.0, 0.0, chunk=c, return_info=True))
                cases = [Case("sequential", lambda r: jax.block_until_ready(seq(theta)), x64=True),
                         Case("deer", lambda r, p=par: jax.block_until_ready(p(theta)), x64=True)]
                run_round_robin(cases, rounds)
                a = cases[0].results[-1]
                b, info = cases[1].results[-1]
                diff = max(float(np.max(np.abs(np.asarray(b[k]) - np.asarray(a[k])))
                                 / np.max(np.abs(np.asarray(a[k])))) for k in ("x", "v"))
                label = type(model).__name__ + ("" if chunk is None else f", chunks of {chunk}")
                rows.append(_row("motion", label, T, 1, "float64", cases, info, diff))
    return rows


def _row(kind, case, T, P, dtype, cases, info, diff):
    seq, par = cases
    return {"kind": kind, "case": case, "T": T, "P": P, "dtype": dtype, "device": _device(),
            "sequential_ms": 1e3 * seq.median, "deer_ms": 1e3 * par.median,
            "speedup": seq.median / par.median, "iterations": int(info.iterations),
            "converged": bool(info.converged), "fell_back": bool(info.fell_back),
            "max_rel_diff": float(diff)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_output_arguments(p, tag=True)
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--elman", default="2000x1,2000x64,24741x1,24741x16", metavar="TxP,...",
                   help="Elman cases: record length x candidates")
    p.add_argument("--motion", default="2000,24741", metavar="T,...", help="motion cases: record lengths")
    p.add_argument("--chunks", default="none,250,1000", metavar="L,...",
                   help="motion cases: DEER chunk lengths ('none': the whole record at once)")
    args = p.parse_args(argv)
    out = results_dir(args.out, quick=args.quick)
    sizes = [(500, 8)] if args.quick else [tuple(int(x) for x in c.split("x")) for c in args.elman.split(",") if c]
    rounds = 2 if args.quick else args.rounds
    chunks = [None if c == "none" else int(c) for c in args.chunks.split(",") if c]
    rows = [r for T, P in sizes for r in elman_cases(T, P, rounds)] + [
        r for T in ([500] if args.quick else [int(x) for x in args.motion.split(",") if x])
        for r in motion_cases(T, rounds, [None, 128] if args.quick else [c for c in chunks if c is None or c < T])]
    text = [f"# Parallel-in-time (DEER) against the sequential scan ({_device()})", "",
            f"`python benchmarks/parallel_scan.py{' --quick' if args.quick else ''}"
            f"{f' --tag {args.tag}' if args.tag else ''}`; jitted, compile excluded, medians of "
            f"{rounds} round-robin rounds. `fell_back`: Newton did not converge in 100 iterations and the "
            f"sequential scan answered (its time is then included). `max_rel_diff`: largest difference of the "
            f"outputs (Elman) or of x and v (motion), relative to their largest magnitude.", "",
            markdown_table(rows, fmt=cell(".3g")), ""]
    write_report(out, tagged("parallel_scan", args.tag), text, rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
