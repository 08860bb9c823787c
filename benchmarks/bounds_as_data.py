"""The search box as data (jaxfric's default) against the box compiled in as constants.

:func:`jaxfric.minimise` passes the bounds to its compiled run as arguments, so a new
box of the same size reuses the program. A run written by hand (evosax's PSO in
``speed_optim.py``) closes over its box instead: XLA then folds it into the arithmetic.
This script times the same run both ways, side by side, through the public API::

    minimise(fn, solver, (lo, hi), key=k)                                   # box as data
    jax.jit(lambda k: minimise(fn, solver, (lo, hi), key=k),
            compiler_options=jaxfric.compiler_options("solver"))(k)         # box as constants

float64, 30-D Rosenbrock and Ackley, 100 agents, for the test functions' own box (the
same interval in every coordinate) and for a box whose bounds differ per coordinate
(each end moved by up to 0.1 at random). Results are checked bit for bit; ratios are
taken round by round (``--repeats`` rounds, each case once per round, in turn) and their
median reported. Writes ``bounds_as_data.md`` and ``.csv`` to ``--out``.

    python benchmarks/bounds_as_data.py
    python benchmarks/bounds_as_data.py --quick      # smoke run, to results/quick/
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import Case, add_output_arguments, markdown_table, results_dir, run_round_robin, write_csv  # noqa: E402


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dim", type=int, default=30)
    p.add_argument("--generations", type=int, default=500)
    p.add_argument("--repeats", type=int, default=9)
    add_output_arguments(p)
    a = p.parse_args(argv)
    if a.quick:
        a.generations, a.repeats = 20, 2
    out = results_dir(a.out, quick=a.quick)
    import jax.numpy as jnp

    import jaxfric as jf
    from jaxfric import functions as F

    solvers = {"PSO": jf.PSO(num_particles=100, num_generations=a.generations),
               "MAPSO": jf.MAPSO(lattice_size=10, num_generations=a.generations)}
    rows = []
    with jax.enable_x64(True):
        for function in ("rosenbrock", "ackley"):
            obj = F.objective(function)
            lo, hi = F.get(function).bounds(a.dim, np.float64)
            shift = np.random.default_rng(0).uniform(0.0, 0.1, (2, a.dim))
            for box_name, (blo, bhi) in {"same in every coordinate": (lo, hi),
                                         "per coordinate": (lo - shift[0], hi + shift[1])}.items():
                for name, solver in solvers.items():
                    constants = jax.jit(lambda k, s=solver, b=(blo, bhi): jf.minimise(obj, s, b, key=k),
                                        compiler_options=jf.compiler_options("solver"))
                    cases = [
                        Case("data", lambda r, s=solver, b=(blo, bhi): jax.block_until_ready(
                            jf.minimise(obj, s, b, key=jax.random.key(max(r, 0)))), x64=True),
                        Case("constants", lambda r, c=constants: jax.block_until_ready(
                            c(jax.random.key(max(r, 0)))), x64=True),
                    ]
                    run_round_robin(cases, a.repeats)
                    data, const = cases
                    same = all(bool(jnp.array_equal(x.value, y.value)) and float(x.f) == float(y.f)
                               for x, y in zip(data.results, const.results))
                    ratios = [d / c for d, c in zip(data.times, const.times)]
                    rows.append({"function": function, "box": box_name, "solver": name,
                                 "data_ms": 1e3 * data.median, "constants_ms": 1e3 * const.median,
                                 "speed-up_median": statistics.median(ratios),
                                 "speed-up_min": min(ratios), "speed-up_max": max(ratios),
                                 "bit_identical": same})
                    print(rows[-1], flush=True)
    write_csv(rows, out / "bounds_as_data.csv")
    table = markdown_table(rows, fmt=lambda v: f"{v:.3g}" if isinstance(v, float) else str(v))
    (out / "bounds_as_data.md").write_text(
        "# The search box as data or as constants\n\n"
        f"`python benchmarks/bounds_as_data.py{' --quick' if a.quick else ''}` on {platform.processor() or platform.machine()}, "
        f"jax {jax.__version__}: float64, {a.dim}-D, 100 agents, {a.generations} generations, "
        f"{a.repeats} rounds. `data_ms`: `minimise(...)` (the box passed to the compiled run); "
        "`constants_ms`: the same call inside the caller's `jax.jit` with the box closed over and "
        "`compiler_options=jaxfric.compiler_options(\"solver\")`; speed-up = data / constants, "
        "round by round.\n\n" + table + "\n\n"
        f"Medians of the speed-ups: {min(r['speed-up_median'] for r in rows):.2f}-"
        f"{max(r['speed-up_median'] for r in rows):.2f}x. The `constants` call also skips "
        "`minimise`'s checks on the host (bounds, key, a trial evaluation of the objective: a few "
        "milliseconds per call, which counts most in the short PSO runs), so this is an upper "
        "bound on what compiling the box into the program gains. jaxfric keeps the box as data: "
        "a new box of the same size reuses the compiled run.\n")
    print(f"wrote {out / 'bounds_as_data.md'}")


if __name__ == "__main__":
    main()
