"""Throughput against batch size: where batching, and a GPU, pay (issue 6).

jaxfric compiles a whole search into one program, so its speed depends on how much
work each compiled step holds. A single run of a 100-agent swarm on a 30-D test
function is a few thousand floating-point operations per step: the cost of starting
each step's kernels dominates, on a CPU and even more on a GPU. This script measures
evaluations per second as the batch grows, on whatever device JAX runs on, with the
NumPy peers measured in the same run on this machine's CPU:

1. **Swarm seeds**: ``minimise_many`` over S independent runs (``--seeds``) of PSO
   (100 particles) and MAPSO (10×10 lattice) on 30-D Rosenbrock, float32.
2. **Swarm population**: one run of PSO with P particles (``--particles``) and of
   MAPSO on an L×L lattice (``--lattices``).
3. **ENN rollouts**: ``Elman(30).simulate_batch`` of C candidates (``--candidates``) over
   1600 samples, float32, compiled as jaxfric's own rollouts are.
4. **Peers** (always on the CPU): pyswarms ``GlobalBestPSO`` (one run, 100 particles,
   the same PSO settings as ``peers.py``) and the NumPy ENN rollout vectorised over
   candidates (``baselines.elman_rollout_vectorised``) at each C up to
   ``--numpy-max``.

Every point: the first call (compile + run) apart, then the median of ``--repeats``
timed calls (other keys). Compare ratios within one file: one run, one machine.

Usage::

    python benchmarks/scaling.py                 # CPU sizes (about 2 min on 2 cores)
    python benchmarks/scaling.py --quick         # smoke test
    python benchmarks/scaling.py --tag gpu --seeds 1,8,64,512,4096 \\
        --particles 100,1000,10000,100000 --lattices 10,32,100 --candidates 64,512,4096,32768

Writes ``scaling[_TAG].md``, ``.csv`` and ``.png`` to ``--out`` (default
``benchmarks/results``).
"""

from __future__ import annotations

import argparse
import logging
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from _harness import results_dir  # noqa: E402
from peers import load_now, write_csv  # noqa: E402

import jaxfric as jf  # noqa: E402
from jaxfric import functions as F  # noqa: E402
from jaxfric.models import Elman  # noqa: E402
from baselines import elman_rollout_vectorised, rosen_batch  # noqa: E402

DIM, NEURONS, SAMPLES, FS = 30, 30, 1600, 128.0


def ints(text: str) -> list[int]:
    vals = [int(t) for t in text.split(",") if t.strip()]
    if not vals or min(vals) < 1:
        raise argparse.ArgumentTypeError(f"expected positive integers separated by commas, got {text!r}")
    return vals


def timed(once, repeats: int) -> tuple[float, float, object]:
    """``once(r)`` for r = -1 (first call) and 0..repeats-1: (first s, median s, last result)."""
    t0 = time.perf_counter()
    out = jax.block_until_ready(once(-1))
    first = time.perf_counter() - t0
    times = []
    for r in range(repeats):
        t0 = time.perf_counter()
        out = jax.block_until_ready(once(r))
        times.append(time.perf_counter() - t0)
    return first, statistics.median(times), out


def row(kind, impl, batch, evals, first, median, **extra) -> dict:
    return dict(kind=kind, implementation=impl, batch=batch, evals=evals, first_call_s=first,
                median_s=median, evals_per_s=evals / median, **extra)


# ------------------------------------------------------------------- swarms
def swarm_rows(a, log) -> list[dict]:
    lo, hi = F.get("rosenbrock").bounds(DIM, np.float32)
    obj = F.objective("rosenbrock")
    rows = []

    def minimise_row(kind, label, batch, solver, seeds):
        def once(r):
            keys = jax.random.split(jax.random.key(1000 + r), seeds)
            if seeds == 1:
                return jf.minimise(obj, solver, (lo, hi), key=keys[0])
            return jf.minimise_many(obj, solver, (lo, hi), keys=keys)

        first, med, sol = timed(once, a.repeats)
        evals = int(np.sum(np.asarray(sol.stats["num_evals"])))
        best = float(np.median(np.asarray(sol.f)))
        log(f"  {label:38s} batch {batch:7d}: {evals / med:10.3g} evals/s (first call {first:.1f} s)")
        rows.append(row(kind, label, batch, evals, first, med, best_f=best))

    pso = jf.PSO(num_particles=100, num_generations=a.pso_generations)
    mapso = jf.MAPSO(lattice_size=10, num_generations=a.mapso_generations)
    log("[1] swarm seeds (minimise_many)")
    for s in a.seeds:
        minimise_row("seeds", "jaxfric PSO, 100 particles", s, pso, s)
        minimise_row("seeds", "jaxfric MAPSO, 10x10 lattice", s, mapso, s)
    log("[2] swarm population (one run)")
    for p in a.particles:
        minimise_row("population", "jaxfric PSO", p, jf.PSO(num_particles=p, num_generations=a.pso_generations), 1)
    for side in a.lattices:
        minimise_row("population", "jaxfric MAPSO", side * side,
                     jf.MAPSO(lattice_size=side, num_generations=a.mapso_generations), 1)
    return rows


def pyswarms_row(a, log) -> dict:
    import pyswarms as ps

    logging.getLogger("pyswarms").setLevel(logging.ERROR)
    lo, hi = F.get("rosenbrock").bounds(DIM, np.float64)
    iters = a.pso_generations + 1  # the same number of evaluations as jaxfric's PSO

    vmax = 0.2 * (hi - lo)

    def once(r):
        np.random.seed(max(r, 0))  # pyswarms draws from the global NumPy state
        opt = ps.single.GlobalBestPSO(  # configured as peers.py §1: jaxfric's PSO settings
            100, DIM, options={"c1": 2.0, "c2": 2.0, "w": 0.9}, bounds=(lo, hi),
            oh_strategy={"w": "lin_variation"}, bh_strategy="nearest",
            velocity_clamp=(-vmax, vmax), vh_strategy="zero")
        cost, _ = opt.optimize(rosen_batch, iters=iters, verbose=False)
        return cost

    first, med, cost = timed(once, a.repeats)
    log(f"  pyswarms GlobalBestPSO, 100 particles: {100 * iters / med:10.3g} evals/s")
    return row("peer", "pyswarms GlobalBestPSO (NumPy, CPU), 100 particles", 1, 100 * iters, first, med,
               best_f=float(cost))


# ----------------------------------------------------------------- rollouts
def rollout_rows(a, log) -> list[dict]:
    rng = np.random.default_rng(0)
    t = np.arange(SAMPLES) / FS
    v = 0.010 * np.sin(2 * np.pi * 0.2 * t) + 0.004 * np.sin(2 * np.pi * 0.53 * t)
    u = 2 * (v - v.min()) / (v.max() - v.min()) - 1
    elman = Elman(neurons=NEURONS)
    lo, hi = elman.bounds()
    uj = jnp.asarray(u, jnp.float32)
    sim = jax.jit(lambda th, x: elman.simulate_batch(th, x, None),
                  compiler_options=jf.compiler_options("rollout") or None)
    rows = []
    log("[3] ENN rollouts (simulate_batch)")
    for c in a.candidates:
        th = rng.uniform(lo, hi, (c, elman.num_params)).astype(np.float32)
        thj = jnp.asarray(th)
        first, med, out = timed(lambda r, thj=thj: sim(thj, uj), a.repeats)
        log(f"  jaxfric Elman.simulate_batch  C {c:7d}: {c / med:10.3g} rollouts/s")
        rows.append(row("rollout", "jaxfric Elman.simulate_batch (lax.scan)", c, c, first, med,
                        neuron_steps_per_s=c * NEURONS * SAMPLES / med))
        if c <= a.numpy_max:
            th64 = th.astype(np.float64)
            first, med, ref = timed(lambda r, th64=th64: elman_rollout_vectorised(th64, u, NEURONS, dtype=np.float32),
                                    max(1, min(a.repeats, 5)))
            # Same model: the first samples agree before chaotic networks separate.
            np.testing.assert_allclose(np.asarray(out)[:8, :20], ref[:8, :20], rtol=1e-3, atol=1e-3)
            log(f"  NumPy vectorised (CPU)        C {c:7d}: {c / med:10.3g} rollouts/s")
            rows.append(row("rollout", "NumPy vectorised over candidates (CPU)", c, c, first, med,
                            neuron_steps_per_s=c * NEURONS * SAMPLES / med))
    return rows


# ------------------------------------------------------------------ output
def to_markdown(rows, meta) -> str:
    L = ["# Throughput against batch size", "",
         "Generated by `benchmarks/scaling.py`. Every row was measured in this one run: first call "
         "(compile + run) apart, then the median of the timed calls. jaxfric runs on JAX's default "
         "device; pyswarms and NumPy run on this machine's CPU. Compare ratios within this file only.",
         "",
         f"Machine: {meta['machine']}; JAX devices: {meta['devices']}; jax {jax.__version__}, numpy "
         f"{np.__version__}, Python {platform.python_version()}. Load average (1 min) at start "
         f"{meta['load_start']:.1f}, at end {meta['load_end']:.1f}; wall time {meta['wall'] / 60:.1f} min.",
         ""]
    peer = next((r for r in rows if r["kind"] == "peer"), None)

    def swarm_table(kind, title, unit):
        L.extend([f"## {title}", "",
                  f"30-D Rosenbrock, float32; PSO {meta['pso_generations']} generations, MAPSO "
                  f"{meta['mapso_generations']} generations (its self-learning included). Evaluations "
                  "per second count every run of the call. Ratio: over pyswarms' single run of 100 "
                  "particles for the same number of PSO generations.", "",
                  f"| implementation | {unit} | evals/call | first call s | median s | evals/s | vs pyswarms | best f (median) |",
                  "|---|---:|---:|---:|---:|---:|---:|---:|"])
        for r in [r for r in rows if r["kind"] == kind] + ([peer] if peer else []):
            ratio = f"{r['evals_per_s'] / peer['evals_per_s']:.1f}x" if peer else "-"
            L.append(f"| {r['implementation']} | {r['batch']} | {r['evals']} | {r['first_call_s']:.2f} | "
                     f"{r['median_s']:.4f} | {r['evals_per_s']:.3g} | {ratio} | {r['best_f']:.3g} |")
        L.append("")

    swarm_table("seeds", "1. Independent runs in one call (`minimise_many`)", "seeds")
    swarm_table("population", "2. One run, larger populations", "agents")
    rr = [r for r in rows if r["kind"] == "rollout"]
    if rr:
        L.extend(["## 3. ENN rollouts (30 neurons, 1600 samples, float32)", "",
                  "| implementation | candidates | first call s | median s | rollouts/s | neuron-steps/s | vs NumPy (same C) |",
                  "|---|---:|---:|---:|---:|---:|---:|"])
        numpy = {r["batch"]: r for r in rr if r["implementation"].startswith("NumPy")}
        for r in rr:
            ref = numpy.get(r["batch"])
            ratio = f"{r['evals_per_s'] / ref['evals_per_s']:.1f}x" if ref and ref is not r else "-"
            L.append(f"| {r['implementation']} | {r['batch']} | {r['first_call_s']:.2f} | {r['median_s']:.4f} | "
                     f"{r['evals_per_s']:.3g} | {r['neuron_steps_per_s']:.3g} | {ratio} |")
        L.append("")
    L.extend(["## Re-running", "",
              "    python benchmarks/scaling.py                # CPU sizes",
              "    python benchmarks/scaling.py --tag gpu --seeds 1,8,64,512,4096 \\",
              "        --particles 100,1000,10000,100000 --lattices 10,32,100 --candidates 64,512,4096,32768",
              ""])
    return "\n".join(L)


def plot(rows, path: Path, meta) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    peer = next((r for r in rows if r["kind"] == "peer"), None)
    ax = axes[0]
    for kind, style in (("seeds", "-o"), ("population", "--s")):
        for impl in sorted({r["implementation"] for r in rows if r["kind"] == kind}):
            rs = [r for r in rows if r["kind"] == kind and r["implementation"] == impl]
            label = f"{impl} ({'seeds' if kind == 'seeds' else 'agents'})"
            ax.loglog([r["batch"] for r in rs], [r["evals_per_s"] for r in rs], style, label=label)
    if peer:
        ax.axhline(peer["evals_per_s"], color="k", lw=1, ls=":", label="pyswarms, 100 particles (CPU)")
    ax.set_xlabel("seeds per call, or agents per run")
    ax.set_ylabel("function evaluations / s")
    ax.set_title("30-D Rosenbrock")
    ax.legend(fontsize=7)
    ax = axes[1]
    for impl in sorted({r["implementation"] for r in rows if r["kind"] == "rollout"}):
        rs = [r for r in rows if r["kind"] == "rollout" and r["implementation"] == impl]
        ax.loglog([r["batch"] for r in rs], [r["evals_per_s"] for r in rs], "-o", label=impl)
    ax.set_xlabel("candidates per call")
    ax.set_ylabel("rollouts / s (1600 samples)")
    ax.set_title("Elman network, 30 neurons")
    ax.legend(fontsize=7)
    fig.suptitle(f"jaxfric on {meta['devices']}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seeds", type=ints, default=ints("1,8,64,512"))
    p.add_argument("--particles", type=ints, default=ints("100,1000,10000"))
    p.add_argument("--lattices", type=ints, default=ints("10,32"), help="MAPSO lattice sides")
    p.add_argument("--candidates", type=ints, default=ints("64,512,4096"))
    p.add_argument("--numpy-max", type=int, default=4096, help="largest C for the NumPy rollout")
    p.add_argument("--pso-generations", type=int, default=200)
    p.add_argument("--mapso-generations", type=int, default=50)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--quick", action="store_true", help="tiny sizes (smoke test)")
    p.add_argument("--tag", default="", help="suffix of the output files, e.g. gpu -> scaling_gpu.md")
    p.add_argument("--out", type=Path, default=None)
    a = p.parse_args(argv)
    a.out = results_dir(a.out, quick=a.quick)
    if a.quick:
        a.seeds, a.particles, a.lattices, a.candidates = [1, 4], [16, 64], [3], [8, 32]
        a.pso_generations, a.mapso_generations, a.repeats = 10, 3, 2
    t_start = time.perf_counter()

    def log(msg):
        print(f"[{time.perf_counter() - t_start:6.1f}s] {msg}", flush=True)

    meta = dict(load_start=load_now(), pso_generations=a.pso_generations,
                mapso_generations=a.mapso_generations,
                machine=f"{platform.processor() or platform.machine()}, {os.cpu_count()} logical cores",
                devices=", ".join(sorted({f"{d.device_kind} ({d.platform})" for d in jax.devices()})))
    jnp.ones(3).block_until_ready()
    rows = [pyswarms_row(a, log)] + swarm_rows(a, log) + rollout_rows(a, log)
    meta.update(load_end=load_now(), wall=time.perf_counter() - t_start)
    a.out.mkdir(parents=True, exist_ok=True)
    stem = "scaling" + (f"_{a.tag}" if a.tag else "")
    write_csv(rows, a.out / f"{stem}.csv")
    (a.out / f"{stem}.md").write_text(to_markdown(rows, meta))
    plot(rows, a.out / f"{stem}.png", meta)
    log(f"wrote {a.out / stem}.md/.csv/.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
