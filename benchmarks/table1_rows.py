"""Table 1 rows for evosax's CMA-ES (issue 16 item 3): CMA-ES alone and CMA-ES → Nelder–Mead,
at the evaluation budget of the MAPSO–NMDS rows.

Two entry points:

* :func:`evosax_runs` — what ``benchmarks/table1.py`` calls per function (its own timing
  and summary then treat these rows like MAPSO–NMDS's and PSO's);
* :func:`evosax_rows` / ``python benchmarks/table1_rows.py`` — standalone: the rows with
  mean, std, best, worst, success (f ≤ 1e-8), median evaluations to success and time,
  written to ``table1_evosax.md``/``.csv`` (a quick look at these rows alone; the
  committed table is ``table1.md``, where ``table1.py`` includes them).

Budgets. ``budget`` is the most evaluations a run may use (default: MAPSO–NMDS's own
worst case at G = 1000, ``mapso_nmds(num_generations=1000).max_evaluations(D)``).
CMA-ES (population 4 + ⌊3 ln D⌋, σ₀ = 0.3 box widths, see :class:`jaxfric.Evosax`)
runs ``⌊(budget − 1)/P⌋`` generations; CMA-ES → NM gives ``GLOBAL_SHARE`` of the
budget to CMA-ES and the rest to ``NelderMead(max_evals=...)`` from its best point.
All runs of a row are one vmapped call (:func:`jaxfric.minimise_many`).

    python benchmarks/table1_rows.py --dims 10 --functions griewank,rastrigin --runs 30
"""

from __future__ import annotations

import argparse
import math
import platform
import sys
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/ is not on sys.path under `jaxfric bench`
from _harness import results_dir, write_csv  # noqa: E402

SUCCESS = 1e-8
#: Share of the budget CMA-ES gets in CMA-ES → NM (Nelder–Mead gets the rest).
GLOBAL_SHARE = 0.8


def _jf():
    try:
        import jaxfric
    except ImportError:  # a source checkout without installing
        sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
        import jaxfric
    return jaxfric


def have_evosax() -> bool:
    """Whether evosax is installed (``pip install -e ".[evosax]"``)."""
    import importlib.util

    return importlib.util.find_spec("evosax") is not None


def default_budget(dim: int, generations: int = 1000) -> int:
    """MAPSO–NMDS's most evaluations at ``generations`` (table1.py's default G)."""
    return int(_jf().mapso_nmds(num_generations=generations).max_evaluations(dim))


def evosax_solvers(dim: int, budget: int) -> list[tuple[str, object]]:
    """``[(label, solver)]``: CMA-ES and CMA-ES → NM within ``budget`` evaluations."""
    jf = _jf()
    pop = jf.Evosax("CMA_ES", num_generations=1).population(dim)
    cma = jf.Evosax("CMA_ES", num_generations=max(1, (budget - 1) // pop))
    g = max(1, int(GLOBAL_SHARE * budget - 1) // pop)
    nm_evals = budget - jf.Evosax("CMA_ES", num_generations=g).evaluations(dim) - (dim + 2)
    chain = jf.cmaes_nm(num_generations=g, nm_max_evals=max(dim + 2, nm_evals))
    return [("CMA-ES (evosax)", cma), ("CMA-ES→NM", chain)]


def timed_batch(fn_name, solver, dim, keys):
    """``(solutions, compile s, run s)`` of one ``minimise_many`` batch, run once: the
    wall time is split into compilation (JAX's compile events, the Stopwatch that
    ``identify`` uses) and run time, so long rows are not paid twice."""
    from jaxfric.identification._timing import Stopwatch

    jf = _jf()
    t = jf.functions.get(fn_name)
    obj, bounds = jf.functions.objective(fn_name), t.bounds(dim)
    with Stopwatch() as sw:
        sol = jax.block_until_ready(jf.minimise_many(obj, solver, bounds, keys=keys))
    return sol, sw.compile_s, sw.run_s


def evosax_runs(fn_name: str, dim: int, keys, budget: int):
    """``[(label, solution batch, compile s, run s)]`` of the evosax rows for one
    function, timed with :func:`timed_batch` as table1.py times its own rows."""
    return [(label, *timed_batch(fn_name, s, dim, keys)) for label, s in evosax_solvers(dim, budget)]


def evals_to_success(sol, threshold=SUCCESS):
    """Per run: evaluations when the best value first reached ``threshold`` (from the
    history, so within one history stride), NaN for runs that never did."""
    ev = np.asarray(sol.history.evals, np.float64)
    f = np.asarray(sol.history.f, np.float64)
    hit = f <= threshold
    first = np.argmax(hit, axis=1)
    return np.where(hit.any(axis=1), ev[np.arange(len(ev)), first], np.nan)


def summary(label, fn_name, dim, sol, compile_s, run_s) -> dict:
    f = np.asarray(sol.f, np.float64)
    hits = evals_to_success(sol)
    return {
        "function": fn_name, "dim": dim, "solver": label, "runs": f.size,
        "mean": float(np.mean(f)), "std": float(np.std(f, ddof=1)) if f.size > 1 else 0.0,
        "best": float(np.min(f)), "worst": float(np.max(f)),
        "success": float(np.mean(f <= SUCCESS)),
        "median_evals_to_success": float(np.nanmedian(hits)) if np.isfinite(hits).any() else None,
        "evals": int(np.max(np.asarray(sol.stats["num_evals"]))),
        "compile_s": compile_s, "batch_s": run_s, "per_run_s": run_s / f.size,
    }


def evosax_rows(functions, dims, runs: int, budget: int | None = None, *, seed: int = 2017,
                with_paper_rows: bool = False, echo=print) -> list[dict]:
    """Rows (dicts, see :func:`summary`) for every function and dimension; with
    ``with_paper_rows`` also MAPSO–NMDS (G = 1000) and PSO at the same budget."""
    jf = _jf()
    keys = jax.random.split(jax.random.key(seed), runs)
    rows = []
    for dim in dims:
        b = budget or default_budget(dim)
        extra = []
        if with_paper_rows:
            extra = [("MAPSO-NMDS", jf.mapso_nmds(num_generations=1000)),
                     ("PSO (equal evaluations)",
                      jf.PSO(num_particles=25, num_generations=max(1, math.ceil(b / 25) - 1)))]
        for name in functions:
            batches = [(label, *timed_batch(name, s, dim, keys)) for label, s in extra]
            batches += evosax_runs(name, dim, keys, b)
            for label, sol, c, r in batches:
                row = summary(label, name, dim, sol, c, r)
                rows.append(row)
                echo(f"D={dim:3d} {name:11s} {label:24s} mean={row['mean']:.3e} std={row['std']:.2e} "
                     f"best={row['best']:.2e} worst={row['worst']:.2e} succ={row['success']:.2f} "
                     f"med_evals_succ={row['median_evals_to_success']} evals<={row['evals']} "
                     f"compile={c:.1f}s run={r:.1f}s")
    return rows


def write(out: Path, rows, argv_line: str):
    out.mkdir(parents=True, exist_ok=True)
    write_csv(rows, out / "table1_evosax.csv", float_format="")
    jf = _jf()
    lines = [
        "# Table 1 rows: evosax CMA-ES and CMA-ES → Nelder–Mead",
        "",
        f"`{argv_line}`. float64; each row is one vmapped call of all its runs. Budget: "
        "MAPSO–NMDS's most evaluations at G = 1000 unless `--budget`; CMA-ES → NM gives "
        f"{GLOBAL_SHARE:.0%} of it to CMA-ES. Success: f ≤ 1e-8; evaluations to success from "
        "the history (median over successful runs). Time: compile apart, then the whole batch.",
        "",
        f"Machine: {platform.machine()}, CPU shared with other jobs (timings noisy), "
        f"jax {jax.__version__}, jaxfric {jf.__version__}.",
        "",
        "| D | function | solver | mean | std | best | worst | success | median evals to success "
        "| evals/run ≤ | compile s | batch s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        med = r["median_evals_to_success"]
        lines.append(
            f"| {r['dim']} | {r['function']} | {r['solver']} | {r['mean']:.3e} | {r['std']:.2e} | "
            f"{r['best']:.2e} | {r['worst']:.2e} | {r['success']:.0%} | "
            f"{'—' if med is None else f'{med:.0f}'} | {r['evals']} | {r['compile_s']:.1f} | "
            f"{r['batch_s']:.1f} |")
    (out / "table1_evosax.md").write_text("\n".join(lines) + "\n")


def main(argv=None):
    jax.config.update("jax_enable_x64", True)  # benchmarks choose x64 at start-up
    jf = _jf()
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dims", default="10,30")
    p.add_argument("--functions", default=",".join(jf.functions.PAPER_TABLE1 + ("rastrigin",)))
    p.add_argument("--runs", type=int, default=30)
    p.add_argument("--budget", type=int, default=None)
    p.add_argument("--with-paper-rows", action="store_true",
                   help="also run MAPSO-NMDS (G = 1000) and PSO")
    p.add_argument("--out", default=None)
    a = p.parse_args(argv)
    a.out = results_dir(a.out, quick=getattr(a, "quick", False))
    functions = a.functions.split(",")
    for name in functions:
        jf.functions.get(name)
    rows = []

    def echo(line):
        print(line, flush=True)

    for dim in (int(d) for d in a.dims.split(",")):
        for name in functions:  # written after every function: a timeout keeps what ran
            rows += evosax_rows([name], [dim], a.runs, a.budget,
                                with_paper_rows=a.with_paper_rows, echo=echo)
            write(Path(a.out), rows,
                  "python benchmarks/table1_rows.py " + " ".join(argv or sys.argv[1:]))
    print(f"wrote {Path(a.out) / 'table1_evosax.md'}")


if __name__ == "__main__":
    main()
