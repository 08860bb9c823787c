"""Table 1 rows for evosax's CMA-ES (issue 16 item 3): CMA-ES alone and CMA-ES → Nelder–Mead,
at the evaluation budget of the MAPSO–NMDS rows, and the one-call batch timing every row uses.

:func:`evosax_runs` is what ``benchmarks/table1.py`` calls per function (its summary then
treats these rows like MAPSO–NMDS's and PSO's); the table is ``python benchmarks/table1.py``
(its ``--rows cmaes`` runs these rows with the paper row that sets their budget).

Budgets. ``budget`` is the most evaluations a run may use (default: MAPSO–NMDS's own
worst case at G = 1000, ``mapso_nmds(num_generations=1000).max_evaluations(D)``).
CMA-ES (population 4 + ⌊3 ln D⌋, σ₀ = 0.3 box widths, see :class:`jaxfric.Evosax`)
runs ``⌊(budget − 1)/P⌋`` generations; CMA-ES → NM gives ``GLOBAL_SHARE`` of the
budget to CMA-ES and the rest to ``NelderMead(max_evals=...)`` from its best point.
All runs of a row are one vmapped call (:func:`jaxfric.minimise_many`).
"""

from __future__ import annotations

import sys
from pathlib import Path

import jax


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
