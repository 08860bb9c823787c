"""MAPSO–NMDS (ALGORITHMS.md §5.1): MAPSO's global search, then Nelder–Mead from gBest.

``θ_MAPSO = MAPSO(J, bounds, G)`` and ``θ* = NM(J, start=θ_MAPSO)``. Optionally the
``num_starts`` best agents (by personal best) seed Nelder–Mead runs
and the best refined point wins. One jitted computation end to end.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ._base import AbstractSolver, Solution, check_positive_int, concat_histories
from .mapso import MAPSO
from .nelder_mead import NelderMead


class MAPSONMDS(AbstractSolver):
    """The paper's two-phase optimiser: :class:`MAPSO` then :class:`NelderMead`.

    Args:
        mapso: the global phase.
        nelder_mead: the local phase (its ``max_steps``/``max_evals`` bound the refinement).
        num_starts: Nelder–Mead runs, from the ``num_starts`` best personal bests of the
            lattice (1 = from gBest only, as in the paper).
        simplex_from_swarm: size the first simplex from the spread of the lattice's
            personal bests (per-coordinate standard deviation, at least
            ``nelder_mead.initial_step`` × 1e-3 of the box) instead of a fixed fraction of
            the box. After a converged global phase the basin is much smaller than the
            box, so a box-sized simplex first spends many evaluations shrinking.
    """

    mapso: MAPSO = MAPSO()
    nelder_mead: NelderMead = NelderMead()
    num_starts: int = 1
    simplex_from_swarm: bool = True

    def check(self):
        if not isinstance(self.mapso, MAPSO):
            raise ValueError("mapso must be a jaxfric.MAPSO")
        if not isinstance(self.nelder_mead, NelderMead):
            raise ValueError("nelder_mead must be a jaxfric.NelderMead")
        self.mapso.check()
        self.nelder_mead.check()
        check_positive_int("num_starts", self.num_starts)
        if self.num_starts > self.mapso.num_agents:
            raise ValueError(
                f"num_starts ({self.num_starts}) exceeds the number of agents "
                f"({self.mapso.num_agents})"
            )

    def progress_totals(self):
        return self.mapso.num_generations, self.nelder_mead.max_steps

    def run(self, fn, lower, upper, args, key, x0=None, progress=None) -> Solution:
        k_global, k_local = jax.random.split(key)
        global_sol, swarm = self.mapso.run_state(
            fn, lower, upper, args, k_global, x0, progress
        )
        return self.local_phase(fn, lower, upper, args, k_local, global_sol, swarm, progress)

    def local_phase(self, fn, lower, upper, args, key, global_sol, swarm, progress=None):
        """Nelder–Mead from the global phase's result (``key``: the local half of the
        run's key, ``jax.random.split(key)[1]``)."""
        step = None
        if self.simplex_from_swarm:
            spread = jnp.std(swarm.pbest, axis=0)
            floor = 1e-3 * self.nelder_mead.initial_step * (upper - lower)
            step = jnp.maximum(spread, floor)

        def refine(start):
            return self.nelder_mead.run(
                fn, lower, upper, args, key, start, progress, initial_step=step
            )

        if self.num_starts == 1:
            best = refine(global_sol.value)
            local_evals = best.stats["num_evals"]
        else:
            # lax.map, not vmap: under vmap Nelder-Mead's conditionals become selects
            # and every step would pay for the shrink branch (PEERS.md 1.6).
            starts = swarm.pbest[jnp.argsort(swarm.pbest_f)[: self.num_starts]]
            local = jax.lax.map(refine, starts)
            i = jnp.argmin(local.f)
            best = jax.tree_util.tree_map(lambda a: a[i], local)
            local_evals = jnp.sum(local.stats["num_evals"])
        # Nelder–Mead starts at gBest, so it can only improve on the global phase.
        use_local = best.f <= global_sol.f
        value = jnp.where(use_local, best.value, global_sol.value)
        f = jnp.where(use_local, best.f, global_sol.f)
        num_evals = global_sol.stats["num_evals"] + local_evals
        history = concat_histories(
            global_sol.history, best.history.offset(global_sol.stats["num_evals"])
        )
        return Solution(
            value=value,
            f=f,
            result=best.result,
            stats={
                "num_steps": global_sol.stats["num_steps"] + best.stats["num_steps"],
                "num_evals": num_evals,
                "num_evals_global": global_sol.stats["num_evals"],
                "f_global": global_sol.f,
            },
            history=history,
        )


def mapso_nmds(**kwargs) -> MAPSONMDS:
    """Convenience constructor: ``mapso_nmds(num_generations=300, nm_max_steps=5000)``.

    Keywords prefixed ``nm_`` go to :class:`NelderMead`; ``num_starts`` and
    ``simplex_from_swarm`` to :class:`MAPSONMDS`; the rest to :class:`MAPSO`.
    """
    nm = {k[3:]: kwargs.pop(k) for k in list(kwargs) if k.startswith("nm_")}
    top = {k: kwargs.pop(k) for k in ("num_starts", "simplex_from_swarm") if k in kwargs}
    return MAPSONMDS(mapso=MAPSO(**kwargs), nelder_mead=NelderMead(**nm), **top)


