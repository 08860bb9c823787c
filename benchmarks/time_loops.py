"""The models' time-loop forms on this backend: why jaxfric picks them per platform.

Times, on JAX's default device, the two choices that ``jaxfric/models/_scan.py``
makes per platform:

* the Elman rollout (30 neurons, 1600 samples, float32) at ``unroll`` 1-64 for
  1, 64 and 4096 candidates (the CPU default is 2, other platforms 32);
* the bristle models' recurrence ``z ← d·z + g`` (LuGre, Dahl) as the sequential
  ``lax.scan`` against the associative scan, float32 and float64, with their largest
  relative difference (the CPU default is sequential, other platforms associative).

Medians of 7 calls after a warm-up, compile apart. The committed
``results/time_loops_gpu.txt`` came from this measurement on an H100 (jax 0.11.2);
``results/time_loops.txt`` from the 2-core development CPU.

    python benchmarks/time_loops.py [--out results/time_loops.txt]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxfric.models import Elman
from jaxfric.models._scan import linear_recurrence_parallel, linear_recurrence_sequential
from jaxfric.models.lugre import _phi

T = 1600


def median_ms(f, *args, n=7) -> float:
    jax.block_until_ready(f(*args))
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        jax.block_until_ready(f(*args))
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e3


def elman_lines() -> list[str]:
    u = jnp.asarray(np.sin(np.arange(T) / 50.0), jnp.float32)
    lines = []
    for c in (1, 64, 4096):
        cells = []
        for unroll in (1, 2, 4, 8, 16, 32, 64):
            model = Elman(neurons=30, unroll=unroll)
            lo, hi = model.bounds()
            th = jnp.asarray(np.random.default_rng(0).uniform(lo, hi, (c, model.num_params)), jnp.float32)
            f = jax.jit(lambda th, x, m=model: m.simulate_batch(th, x, None))
            cells.append(f"u{unroll}:{median_ms(f, th, u):.2f}")
        lines.append(f"Elman C={c:5d} ms  " + "  ".join(cells))
    return lines


def bristle_lines() -> list[str]:
    lines = []
    for x64 in (False, True):
        with jax.enable_x64(x64):
            dtype = jnp.float64 if x64 else jnp.float32
            v = jnp.asarray(0.01 * np.sin(2 * np.pi * 0.2 * np.arange(T) / 128), dtype)
            for c in (1, 64, 4096):
                rng = np.random.default_rng(1)
                sigma0 = jnp.asarray(10 ** rng.uniform(3, 8, (c, 1)), dtype)
                g = jnp.asarray(rng.uniform(50, 400, (c, 1)), dtype)
                x = sigma0 * jnp.abs(v[None]) / g / 128.0
                decay, gain = jnp.exp(-x), v[None] / 128.0 * _phi(x)
                z0 = jnp.sign(v[0]) * g[:, 0] / sigma0[:, 0]
                seq, par = jax.jit(linear_recurrence_sequential), jax.jit(linear_recurrence_parallel)
                zs, zp = seq(decay, gain, z0), par(decay, gain, z0)
                rel = float(jnp.max(jnp.abs(zs - zp) / jnp.max(jnp.abs(zs), axis=1, keepdims=True)))
                lines.append(f"LuGre {'f64' if x64 else 'f32'} C={c:5d}  seq {median_ms(seq, decay, gain, z0):7.3f} ms  "
                             f"assoc {median_ms(par, decay, gain, z0):7.3f} ms  max rel diff {rel:.2e}")
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, default=None, help="also write the lines to this file")
    a = p.parse_args(argv)
    lines = [f"backend {jax.default_backend()} ({', '.join(sorted({d.device_kind for d in jax.devices()}))}), "
             f"jax {jax.__version__}"]
    print(lines[0], flush=True)
    for line in elman_lines() + bristle_lines():
        print(line, flush=True)
        lines.append(line)
    if a.out is not None:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
