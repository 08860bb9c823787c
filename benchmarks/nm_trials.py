"""Nelder–Mead: trial points of a step one after the other, or as one batch?

Both rules move the simplex identically (same steps, same points, same result at a
fixed number of steps); they differ in evaluations per step (sequential: 1–2, plus n
per shrink; batched: 4, plus n per shrink) and in calls of the objective per step
(sequential: 2 at most, batched: 1). This script times a fixed number of steps of each,
side by side in one process, alternating, median of ``--repeats``, float64, CPU:

* cheap objective: 10-D and 30-D Rosenbrock;
* expensive objective: the MSE of an Elman network (N = 30, 180 parameters) rollout of
  T = 1600 and T = 25 000 samples against a target signal (``jaxfric.models.Elman``).

Writes ``nm_trials.md`` and ``nm_trials.csv`` to ``--out`` (default ``benchmarks/results``).

    python benchmarks/nm_trials.py              # a few minutes
    python benchmarks/nm_trials.py --quick      # fewer steps and repeats
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time
import sys
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)  # benchmarks choose x64 at start-up

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optimistix as optx  # noqa: E402

import jaxfric as jf  # noqa: E402
from jaxfric import functions as F  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/ is not on sys.path under `jaxfric bench`
from _harness import results_dir, write_csv  # noqa: E402


def rosenbrock(y, args):
    return F.rosenbrock(y)


def enn_problem(T):
    model = jf.models.Elman(neurons=30)
    lo, hi = (jnp.asarray(b) for b in model.bounds())
    t = jnp.arange(T) / 128.0
    velocity = jnp.sin(2 * jnp.pi * 0.5 * t) + 0.3 * jnp.sin(2 * jnp.pi * 1.7 * t)
    theta_true = lo + (hi - lo) * jax.random.uniform(jax.random.key(1), lo.shape, jnp.float64)
    target = model.simulate(theta_true, velocity)

    def mse(theta, args):
        v, f = args
        return jnp.mean((model.simulate(theta, v) - f) ** 2)

    y0 = lo + (hi - lo) * jax.random.uniform(jax.random.key(2), lo.shape, jnp.float64)
    return mse, y0, (velocity, target), {"lower": lo, "upper": hi}


def cheap_problem(n):
    y0 = jnp.asarray(np.random.default_rng(0).uniform(-2, 2, n))
    return rosenbrock, y0, None, {"lower": -5.0 * jnp.ones(n), "upper": 5.0 * jnp.ones(n)}


def make_runner(fn, y0, args, options, steps, batched):
    # rtol = atol = 0: never converges, so both run exactly ``steps`` steps.
    solver = jf.NelderMead(rtol=0.0, atol=0.0, batched_trials=batched)

    @jax.jit
    def run(y0, args):
        sol = optx.minimise(fn, solver, y0, args, options=options, max_steps=steps, throw=False)
        return sol.state.f_simplex[0], sol.state.num_evals, sol.stats["num_steps"]

    return run


def measure(label, fn, y0, args, options, steps, repeats):
    runners = {b: make_runner(fn, y0, args, options, steps, b) for b in (False, True)}
    out = {}
    for b, run in runners.items():
        jax.block_until_ready(run(y0, args))  # compile
    times = {False: [], True: []}
    for _ in range(repeats):
        for b, run in runners.items():
            t0 = time.perf_counter()
            f, ev, st = jax.block_until_ready(run(y0, args))
            times[b].append(time.perf_counter() - t0)
            out[b] = (float(f), int(ev), int(st))
    rows = []
    for b in (False, True):
        f, ev, st = out[b]
        med = statistics.median(times[b])
        rows.append({
            "objective": label, "rule": "batched" if b else "sequential", "steps": st,
            "evals": ev, "f": f, "median_s": med, "ms_per_step": 1e3 * med / st,
            "us_per_eval": 1e6 * med / ev,
        })
    # Same path: equal up to the last bits where the batched objective rounds differently
    # (vmap routes the Elman rollout to its batched form).
    assert out[False][2] == out[True][2] and np.isclose(out[False][0], out[True][0], rtol=1e-9), out
    ratio = rows[0]["median_s"] / rows[1]["median_s"]
    for r in rows:
        r["speedup_batched"] = ratio
    print(f"{label:28s} seq {rows[0]['ms_per_step']:.3f} ms/step ({rows[0]['evals']} evals)  "
          f"batched {rows[1]['ms_per_step']:.3f} ms/step ({rows[1]['evals']} evals)  "
          f"batched/seq speed {ratio:.2f}x", flush=True)
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--quick", action="store_true")
    p.add_argument("--out", default=None)
    a = p.parse_args(argv)
    scale = 0.2 if a.quick else 1.0
    reps = 3 if a.quick else a.repeats
    cases = [
        ("rosenbrock n=10", *cheap_problem(10), int(20000 * scale)),
        ("rosenbrock n=30", *cheap_problem(30), int(20000 * scale)),
        ("ENN N=30 T=1600", *enn_problem(1600), int(300 * scale)),
        ("ENN N=30 T=25000", *enn_problem(25000), int(40 * scale)),
    ]
    rows = []
    for label, fn, y0, args, options, steps in cases:
        rows += measure(label, fn, y0, args, options, steps, reps)
    out = results_dir(a.out, quick=a.quick)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(rows, out / "nm_trials.csv", float_format="")
    lines = [
        "# Nelder–Mead trial points: sequential rule vs one batch per step",
        "",
        f"float64, CPU ({platform.processor() or platform.machine()}, {jax.device_count()} device(s)), "
        f"jax {jax.__version__}, jaxfric {jf.__version__}; fixed number of steps (tolerances 0), "
        f"median of {reps} alternating repeats in one process. Same steps and same final simplex "
        "for both rules (checked: equal step counts, final best value equal to 1e-9 relative). Re-run: `python benchmarks/nm_trials.py`"
        + (" --quick" if a.quick else "") + ".",
        "",
        "| objective | rule | steps | evaluations | ms/step | µs/evaluation | batched speed-up per step |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['objective']} | {r['rule']} | {r['steps']} | {r['evals']} | {r['ms_per_step']:.3f} | "
            f"{r['us_per_eval']:.1f} | {r['speedup_batched']:.2f}x |"
        )
    (out / "nm_trials.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out / 'nm_trials.md'}")


if __name__ == "__main__":
    main()
