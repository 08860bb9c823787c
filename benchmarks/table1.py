"""The paper's Table 1: MAPSO–NMDS against PSO and CMA-ES on five test functions (+ Rastrigin).

For each dimension, function and solver, ``--runs`` independent runs in ONE vmapped call
(:func:`jaxfric.minimise_many`): ``MAPSO-NMDS (paper)`` (G = ``--generations``, then Nelder–Mead
with fminsearch's budget); ``MAPSO-NMDS + NM restarts`` (Nelder–Mead restarted from its own
result within ``--budget``); ``MAPSO-NMDS (sR=0.2, MAGA)`` unless ``--no-maga``; ``PSO (equal
evaluations)``, ``CMA-ES (evosax)`` and ``CMA-ES→NM`` at the paper row's largest evaluation count.

    python benchmarks/table1.py                 # the full table (tens of minutes on 2 cores)
    python benchmarks/table1.py --quick         # D = 10, 5 runs, 100 generations
    python benchmarks/table1.py --dims 30 --out a & python benchmarks/table1.py --dims 10 --out b
    python benchmarks/table1.py --merge a,b     # one table from both (median curves: table1_curves.npz)
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # not on sys.path under `jaxfric bench table1`
from _harness import (add_output_arguments, machine, markdown_table, pyplot, read_csv, results_dir,  # noqa: E402
                      write_csv, x64)

x64()
import jax  # noqa: E402
import numpy as np  # noqa: E402

import jaxfric as jf  # noqa: E402
from jaxfric import functions as F  # noqa: E402
from jaxfric._timing import Stopwatch  # noqa: E402

SUCCESS = 1e-8
FLOOR = 1e-30  # exact zeros and 1e-200s would squash the log axis
#: Share of the budget CMA-ES gets in CMA-ES → NM (Nelder–Mead gets the rest).
GLOBAL_SHARE = 0.8


def timed_batch(fn_name, solver, dim, keys):
    """``(solutions, compile s, run s)`` of one ``minimise_many`` batch, run once, its wall
    time split by JAX's compile events (the Stopwatch ``identify`` uses)."""
    with Stopwatch() as sw:
        sol = jax.block_until_ready(jf.minimise_many(F.objective(fn_name), solver, F.get(fn_name).bounds(dim),
                                                     keys=keys))
    return sol, sw.compile_s, sw.run_s


def evosax_runs(fn_name: str, dim: int, keys, budget: int):
    """``[(label, solutions, compile s, run s)]``: CMA-ES and CMA-ES → NM within ``budget``."""
    pop = jf.Evosax("CMA_ES", num_generations=1).population(dim)
    cma = jf.Evosax("CMA_ES", num_generations=max(1, (budget - 1) // pop))
    g = max(1, int(GLOBAL_SHARE * budget - 1) // pop)
    nm_evals = budget - jf.Evosax("CMA_ES", num_generations=g).evaluations(dim) - (dim + 2)
    chain = jf.cmaes_nm(num_generations=g, nm_max_evals=max(dim + 2, nm_evals))
    return [(label, *timed_batch(fn_name, s, dim, keys)) for label, s in
            [("CMA-ES (evosax)", cma), ("CMA-ES→NM", chain)]]


def evals_to_success(sol):
    """Evaluations at the first history entry ≤ SUCCESS, per run (NaN where never)."""
    ev = np.asarray(sol.history.evals, dtype=np.float64)
    f = np.asarray(sol.history.f, dtype=np.float64)
    hit = f <= SUCCESS
    first = np.argmax(hit, axis=1)
    return np.where(hit.any(axis=1), ev[np.arange(ev.shape[0]), first], np.nan)


def summarise(label, fn_name, dim, sol, compile_s, run_s):
    f = np.asarray(sol.f, dtype=np.float64)
    evals = np.asarray(sol.stats["num_evals"])
    e2s = evals_to_success(sol)
    return {"dim": dim, "function": fn_name, "solver": label, "mean": float(np.mean(f)),
            "std": float(np.std(f, ddof=1)) if f.size > 1 else 0.0,
            "variance": float(np.var(f, ddof=1)) if f.size > 1 else 0.0,
            "best": float(np.min(f)), "worst": float(np.max(f)), "success": float(np.mean(f <= SUCCESS)),
            "solved": int(np.sum(f <= SUCCESS)), "runs": int(f.size),
            "evals_to_success": float(np.nanmedian(e2s)) if np.any(np.isfinite(e2s)) else float("nan"),
            "evals": int(np.round(np.mean(evals))), "evals_max": int(np.max(evals)),
            "compile_s": compile_s, "batch_s": run_s, "per_run_s": run_s / f.size}


def median_history(sol):
    """Median (over runs) best-so-far curve on a common evaluation grid."""
    ev = np.asarray(sol.history.evals, dtype=np.float64)
    f = np.asarray(sol.history.f, dtype=np.float64)
    grid = np.linspace(0, ev.max(), 200)
    curves = np.stack([np.interp(grid, e, v) for e, v in zip(ev, f)])
    return grid, np.median(curves, axis=0)


def variants(a, dim):
    """(label, solver) rows besides PSO; see the module docstring."""
    paper = jf.mapso_nmds(num_generations=a.generations)
    g, sl = a.restart_generations, a.restart_sl_generations
    swarm_evals = jf.MAPSO(num_generations=g, sl_generations=sl).evaluations()
    restarted = jf.mapso_nmds(num_generations=g, sl_generations=sl, nm_restarts=a.nm_restarts,
                              nm_max_evals=max(1, a.budget - swarm_evals - (dim + 1)),  # a last step may add n + 1
                              nm_max_steps=10 * a.budget)  # the evaluation budget binds, not the step cap
    rows = [("MAPSO-NMDS (paper)", paper), ("MAPSO-NMDS + NM restarts", restarted)]
    if not a.no_maga:
        rows.append(("MAPSO-NMDS (sR=0.2, MAGA)", jf.mapso_nmds(num_generations=a.generations, sl_radius=0.2)))
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dims", default="30,10")
    p.add_argument("--dim", type=int, default=None, help="one dimension (overrides --dims)")
    p.add_argument("--runs", type=int, default=30)
    p.add_argument("--generations", type=int, default=1000, help="paper row: MAPSO generations G")
    p.add_argument("--restart-generations", type=int, default=1000, help="restart row: MAPSO generations")
    p.add_argument("--restart-sl-generations", type=int, default=5, help="restart row: self-learning generations")
    p.add_argument("--nm-restarts", type=int, default=200, help="restart row: most Nelder-Mead restarts")
    p.add_argument("--budget", type=int, default=200_000, help="restart row: total evaluations per run")
    p.add_argument("--functions", default=",".join(F.PAPER_TABLE1 + ("rastrigin",)))
    p.add_argument("--seed", type=int, default=2017)
    add_output_arguments(p, "D=10, 5 runs, 100 generations")
    p.add_argument("--no-maga", action="store_true", help="skip the sR = 0.2 variant")
    p.add_argument("--rows", choices=("all", "swarm", "cmaes"), default="all",
                   help="swarm: the MAPSO-NMDS rows and PSO; cmaes: the paper row and CMA-ES (then --merge)")
    p.add_argument("--merge", default=None, help="output folders of runs on parts of the table: one table "
                   "from them (no runs; the settings given here must match theirs)")
    p.add_argument("--load", type=float, default=None, help="with --merge: the load average at the runs' start")
    a = p.parse_args(argv)
    dims = [a.dim] if a.dim is not None else [int(d) for d in a.dims.split(",")]
    if a.quick:
        dims, a.runs, a.generations, a.restart_generations, a.budget = [10], 5, 100, 100, 20_000
    for name in a.functions.split(","):
        F.get(name)  # unknown names fail before any computation
    if min(dims) < 2 or a.runs < 1 or a.generations < 1 or a.restart_generations < 1:
        p.error("dimensions must be >= 2, --runs and the generation counts >= 1")
    if jf.MAPSO(num_generations=a.restart_generations, sl_generations=a.restart_sl_generations).evaluations() >= a.budget:
        p.error("--budget must exceed the swarm's evaluations at --restart-generations")
    out = results_dir(a.out, quick=a.quick)
    if a.merge:
        a.load = float("nan") if a.load is None else a.load
        return merge(a, out)
    a.load = os.getloadavg()[0]  # the machine may be shared: say how busy it was at the start
    keys = jax.random.split(jax.random.key(a.seed), a.runs)
    rows, curves = [], {}
    for dim in dims:
        for name in a.functions.split(","):
            results = [(label, *timed_batch(name, solver, dim, keys))  # the paper row sets the others' budget
                       for label, solver in variants(a, dim)[:None if a.rows != "cmaes" else 1]]
            budget = int(np.max(np.asarray(results[0][1].stats["num_evals"])))
            if a.rows != "cmaes":
                pso = jf.PSO(num_particles=25, num_generations=max(1, math.ceil(budget / 25) - 1))
                results.append(("PSO (equal evaluations)", *timed_batch(name, pso, dim, keys)))
            if a.rows != "swarm" and importlib.util.find_spec("evosax"):  # CMA-ES rows at this budget
                results += evosax_runs(name, dim, keys, budget)
            for label, sol, c, r in results:
                rows.append(row := summarise(label, name, dim, sol, c, r))
                curves[(dim, name, label)] = median_history(sol)
                print(f"D={dim:2d} {name:11s} {label:27s} mean={row['mean']:.3e} best={row['best']:.2e} "
                      f"worst={row['worst']:.2e} solved={row['solved']}/{row['runs']} evals={row['evals']} "
                      f"compile={c:.1f}s run={r:.1f}s", flush=True)
            write_all(out, rows, curves, a, dims)
    print(f"wrote {out / 'table1.md'}, table1.csv, table1_convergence.png")


def write_all(out, rows, curves, a, dims):
    write_csv(rows, out / "table1.csv", float_format="")
    np.savez_compressed(out / "table1_curves.npz",
                        **{f"{d}|{fn}|{label}": np.stack(gm) for (d, fn, label), gm in curves.items()})
    write_md(out / "table1.md", rows, a, dims)
    plot(out / "table1_convergence.png", curves, a)


def merge(a, out):
    """One table from the outputs of runs on disjoint dimensions (``--merge a,b``)."""
    rows, curves = [], {}
    for d in a.merge.split(","):
        rows += read_csv(Path(d) / "table1.csv")
        with np.load(Path(d) / "table1_curves.npz") as z:
            for k in z.files:
                dim, fn, label = k.split("|", 2)
                curves[(int(dim), fn, label)] = tuple(z[k])
    dims = list(dict.fromkeys(r["dim"] for r in rows))
    # one row per (D, function, solver), in the order a single run writes them
    fn_order = list(F.PAPER_TABLE1 + tuple(F.REGISTRY))
    labels = ["MAPSO-NMDS (paper)", "MAPSO-NMDS + NM restarts", "MAPSO-NMDS (sR=0.2, MAGA)",
              "PSO (equal evaluations)", "CMA-ES (evosax)", "CMA-ES→NM"]
    unique = {}
    for r in rows:
        unique.setdefault((r["dim"], r["function"], r["solver"]), r)
    rows = sorted(unique.values(), key=lambda r: (dims.index(r["dim"]), fn_order.index(r["function"]),
                                                  labels.index(r["solver"]) if r["solver"] in labels else 99))
    wanted = [lab for lab in labels if not (a.no_maga and "MAGA" in lab)]
    a.missing = [f"D = {d}, {fn}: {', '.join(lab for lab in wanted if (d, fn, lab) not in unique)}"
                 for d in [int(x) for x in a.dims.split(",")] for fn in a.functions.split(",")
                 if any((d, fn, lab) not in unique for lab in wanted)]
    write_all(out, rows, curves, a, dims)
    print(f"merged {a.merge} into {out / 'table1.md'}")


def write_md(path, rows, a, dims):
    lines = [
        "# Table 1: MAPSO–NMDS against PSO and CMA-ES",
        "",
        f"D = {', '.join(map(str, dims))}; {a.runs} independent runs per function and solver (one vmapped call "
        f"each), lattice 5×5, float64. Paper row: MAPSO G = {a.generations}, then Nelder–Mead with fminsearch's "
        f"budget. Restart row: G = {a.restart_generations}, sGen = {a.restart_sl_generations}, then Nelder–Mead "
        f"restarted from its own result (at most {a.nm_restarts} restarts) within {a.budget} evaluations in total. "
        f"PSO (25 particles), CMA-ES (evosax, population 4 + ⌊3 ln D⌋, σ₀ = 0.3 box widths) and CMA-ES→NM (80 % of "
        f"the budget to CMA-ES, the rest to Nelder–Mead) get the largest evaluation count of the paper row. "
        f"Success: f ≤ 1e-8; evaluations to success: median over the successful runs of the first history entry ≤ "
        f"1e-8. Std and variance: sample (n − 1). Time: one call per row (all runs), split into compilation (JAX's "
        f"compile events) and the run of the whole batch; per run = batch / runs.",
        "",
        f"Machine: {machine()} (at the end); jaxfric {jf.__version__}; shared with other jobs, load average "
        f"{a.load:.1f} at the start, so times are noisy. Re-run: `python benchmarks/table1.py"
        f"{' --quick' if a.quick else ''}{' --no-maga' if a.no_maga else ''}`."
        + (f" This table was merged (`--merge`) from {len(a.merge.split(','))} processes that ran "
           "the same settings on parts of it at the same time (`--dims`, `--rows`, `--functions`), "
           "so their times are each other's load too." if a.merge else ""),
        "",
    ]

    def e2s(r, none, fmt="{:.0f}"):  # median evaluations to success
        return none if math.isnan(r["evals_to_success"]) else fmt.format(r["evals_to_success"])

    lines.append(markdown_table([{
        "D": r["dim"], "function": r["function"], "solver": r["solver"], "mean": f"{r['mean']:.3e}",
        "std": f"{r['std']:.2e}", "variance": f"{r['variance']:.3e}", "best": f"{r['best']:.3e}",
        "worst": f"{r['worst']:.3e}", "success": f"{r['solved']}/{r['runs']}",
        "evals to success (median)": e2s(r, "–"), "evals/run (mean, max)": f"{r['evals']}, {r['evals_max']}",
        "compile s": f"{r['compile_s']:.1f}",
        "batch s": f"{r['batch_s']:.1f}", "s/run": f"{r['per_run_s']:.2f}"} for r in rows]))
    lines += ["", "## What each row reached", ""] + [
        f"- D = {dim}, {name}: " + "; ".join(
            f"{r['solver']} {r['solved']}/{r['runs']}{e2s(r, '', ' (median {:.0f} evals)')}"
            for r in rows if r["dim"] == dim and r["function"] == name) + "."
        for dim, name in dict.fromkeys((r["dim"], r["function"]) for r in rows)]
    if getattr(a, "missing", None):
        lines += ["", "## Not run (the processes were stopped at the deadline)", ""]
        lines += [f"- {m}" for m in a.missing]
    Path(path).write_text("\n".join(lines) + "\n")


def plot(path, curves, a):
    plt = pyplot()
    order = list(F.PAPER_TABLE1 + tuple(F.REGISTRY))
    names = sorted({k[1] for k in curves}, key=order.index)
    dims = sorted({k[0] for k in curves}, reverse=True)
    fig, axes = plt.subplots(len(dims), len(names), figsize=(4 * len(names), 3.4 * len(dims)), squeeze=False)
    for row, dim in zip(axes, dims):
        for ax, name in zip(row, names):
            for (grid, med), label in ((g, lab) for (d, fn, lab), g in curves.items() if fn == name and d == dim):
                ax.semilogy(grid, np.maximum(med, FLOOR), label=label)
            ax.set(title=f"{name} (D = {dim})", xlabel="function evaluations",
                   ylabel=f"median best f (floored at {FLOOR:g})")
            ax.ticklabel_format(axis="x", style="sci", scilimits=(0, 0))
            ax.grid(True, which="both", alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.suptitle(f"Convergence, median of {a.runs} runs")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
