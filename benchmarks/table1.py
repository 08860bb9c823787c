"""The paper's Table 1: MAPSO–NMDS against PSO on five test functions.

For each function (default D = 30) and each solver, ``--runs`` independent runs
(default 30) go through ONE vmapped call (:func:`jaxfric.minimise_many`). PSO gets
the same number of function evaluations as MAPSO–NMDS used (the largest count over
its runs), so the comparison is at an equal budget. Also shown: MAPSO–NMDS with
MAGA's self-learning radius sR = 0.2 (the paper's value is unknown; jaxfric's
default is 0.8, see ``jaxfric.MAPSO``).

Writes ``table1.md``, ``table1.csv`` and ``table1_convergence.png`` to ``--out``
(default ``benchmarks/results``). Columns: mean, sample variance (n − 1, MATLAB's
``var``), best, worst, success rate (f < 1e-8), evaluations per run, and time:
compile time apart from the run time of the whole batch and per run.

    python benchmarks/table1.py                 # the full table (several minutes)
    python benchmarks/table1.py --quick         # D = 10, 5 runs, 100 generations
"""

from __future__ import annotations

import argparse
import csv
import math
import platform
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)  # benchmarks choose x64 at start-up

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxfric as jf  # noqa: E402
from jaxfric import functions as F  # noqa: E402

# the evosax rows (issue 16 item 3); this folder is not on sys.path when the CLI
# (`jaxfric bench table1`) loads the script by path
sys.path.insert(0, str(Path(__file__).resolve().parent))
import table1_rows  # noqa: E402

SUCCESS = 1e-8
FLOOR = 1e-30  # exact zeros and 1e-200s would squash the log axis


def timed_batch(fn_name, solver, dim, keys):
    """Run the batch twice: the first call includes compilation, the second does not."""
    t = F.get(fn_name)
    bounds = t.bounds(dim)
    obj = F.objective(fn_name)
    t0 = time.perf_counter()
    sol = jf.minimise_many(obj, solver, bounds, keys=keys)
    jax.block_until_ready(sol)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    sol = jf.minimise_many(obj, solver, bounds, keys=keys)
    jax.block_until_ready(sol)
    run = time.perf_counter() - t0
    return sol, max(first - run, 0.0), run


def summarise(label, fn_name, sol, compile_s, run_s):
    f = np.asarray(sol.f, dtype=np.float64)
    evals = np.asarray(sol.stats["num_evals"])
    return {
        "function": fn_name,
        "solver": label,
        "mean": float(np.mean(f)),
        "variance": float(np.var(f, ddof=1)) if f.size > 1 else 0.0,
        "best": float(np.min(f)),
        "worst": float(np.max(f)),
        "success": float(np.mean(f < SUCCESS)),
        "evals": int(np.round(np.mean(evals))),
        "compile_s": compile_s,
        "batch_s": run_s,
        "per_run_s": run_s / f.size,
    }


def median_history(sol):
    """Median (over runs) best-so-far curve on a common evaluation grid."""
    ev = np.asarray(sol.history.evals, dtype=np.float64)
    f = np.asarray(sol.history.f, dtype=np.float64)
    grid = np.linspace(0, ev.max(), 200)
    curves = np.stack([np.interp(grid, e, v) for e, v in zip(ev, f)])
    return grid, np.median(curves, axis=0)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dim", type=int, default=30)
    p.add_argument("--runs", type=int, default=30)
    p.add_argument("--generations", type=int, default=1000,
                   help="MAPSO generations G (1000: the fewest that solved 30/30 Griewank runs)")
    p.add_argument("--functions", default=",".join(F.PAPER_TABLE1))
    p.add_argument("--seed", type=int, default=2017)
    p.add_argument("--quick", action="store_true", help="D=10, 5 runs, 100 generations")
    p.add_argument("--no-maga", action="store_true", help="skip the sR = 0.2 variant")
    p.add_argument("--out", default=str(Path(__file__).parent / "results"))
    a = p.parse_args(argv)
    if a.quick:
        a.dim, a.runs, a.generations = 10, 5, 100
    for name in a.functions.split(","):
        F.get(name)  # unknown names fail before any computation
    if a.dim < 2 or a.runs < 1 or a.generations < 1:
        p.error("--dim must be >= 2, --runs and --generations >= 1")
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)

    keys = jax.random.split(jax.random.key(a.seed), a.runs)
    hybrid = jf.mapso_nmds(num_generations=a.generations)
    variants = [("MAPSO-NMDS", hybrid)]
    if not a.no_maga:
        variants.append(("MAPSO-NMDS (sR=0.2, MAGA)", jf.mapso_nmds(num_generations=a.generations, sl_radius=0.2)))

    rows, curves = [], {}
    for name in a.functions.split(","):
        results = []
        for label, solver in variants:
            sol, c, r = timed_batch(name, solver, a.dim, keys)
            results.append((label, sol, c, r))
        budget = int(np.max(np.asarray(results[0][1].stats["num_evals"])))
        pso = jf.PSO(num_particles=25, num_generations=max(1, math.ceil(budget / 25) - 1))
        sol, c, r = timed_batch(name, pso, a.dim, keys)
        results.append(("PSO (equal evaluations)", sol, c, r))
        if table1_rows.have_evosax():  # issue 16 item 3: CMA-ES, CMA-ES→NM at this budget
            results += table1_rows.evosax_runs(name, a.dim, keys, budget, timed_batch)
        for label, sol, c, r in results:
            row = summarise(label, name, sol, c, r)
            rows.append(row)
            curves[(name, label)] = median_history(sol)
            print(
                f"{name:11s} {label:27s} mean={row['mean']:.3e} var={row['variance']:.2e} "
                f"best={row['best']:.2e} worst={row['worst']:.2e} succ={row['success']:.2f} "
                f"evals={row['evals']} compile={c:.1f}s run={r:.1f}s",
                flush=True,
            )

    write_csv(out / "table1.csv", rows)
    write_md(out / "table1.md", rows, a)
    plot(out / "table1_convergence.png", curves, a)
    print(f"wrote {out / 'table1.md'}, table1.csv, table1_convergence.png")


def write_csv(path, rows):
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def write_md(path, rows, a):
    lines = [
        "# Table 1: MAPSO–NMDS against PSO",
        "",
        f"D = {a.dim}, {a.runs} independent runs per function and solver (one vmapped call each), "
        f"MAPSO G = {a.generations}, lattice 5×5, float64. PSO (25 particles) gets the largest "
        "evaluation count of the MAPSO–NMDS runs. Success: f < 1e-8. Variance: sample (n − 1). "
        "Time: compile once, then the whole batch of runs; per run = batch / runs.",
        "",
        f"Machine: {platform.processor() or platform.machine()}, {jax.device_count()} "
        f"{jax.default_backend()} device(s), jax {jax.__version__}, jaxfric {jf.__version__}, "
        f"Python {sys.version.split()[0]}. Re-run: `python benchmarks/table1.py`"
        + (" --quick" if a.quick else "")
        + ".",
        "",
        "| function | solver | mean | variance | best | worst | success | evals/run | compile s | batch s | s/run |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['function']} | {r['solver']} | {r['mean']:.3e} | {r['variance']:.3e} | "
            f"{r['best']:.3e} | {r['worst']:.3e} | {r['success']:.0%} | {r['evals']} | "
            f"{r['compile_s']:.1f} | {r['batch_s']:.1f} | {r['per_run_s']:.2f} |"
        )
    Path(path).write_text("\n".join(lines) + "\n")


def plot(path, curves, a):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = sorted({k[0] for k in curves}, key=lambda n: list(F.PAPER_TABLE1 + tuple(F.REGISTRY)).index(n))
    fig, axes = plt.subplots(1, len(names), figsize=(4 * len(names), 3.4), squeeze=False)
    for ax, name in zip(axes[0], names):
        for (fn_name, label), (grid, med) in curves.items():
            if fn_name == name:
                ax.semilogy(grid, np.maximum(med, FLOOR), label=label)
        ax.set_title(f"{name} (D = {a.dim})")
        ax.set_xlabel("function evaluations")
        ax.ticklabel_format(axis="x", style="sci", scilimits=(0, 0))
        ax.set_ylabel(f"median best f (floored at {FLOOR:g})")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.suptitle(f"Convergence, median of {a.runs} runs")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
