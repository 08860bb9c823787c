"""MAPSO–NMDS (docs/algorithms.md §5.1): MAPSO's global search, then Nelder–Mead from
gBest, the paper's instance of [`chain`][jaxfric.optim.chain].

``θ_MAPSO = MAPSO(J, bounds, G)`` and ``θ* = NM(J, start=θ_MAPSO)``. Optionally the
``num_starts`` best agents (by personal best) seed Nelder–Mead runs and the best
refined point wins.

One object, two spellings with different jobs: [`MAPSONMDS`][jaxfric.optim.MAPSONMDS] is
the solver, a chain whose stages are named ``mapso`` and ``nelder_mead`` and checked to
be a [`MAPSO`][jaxfric.optim.MAPSO] and a [`NelderMead`][jaxfric.optim.NelderMead]; [`mapso_nmds`][jaxfric.optim.mapso_nmds] is its flat-keyword
factory (``nm_*`` keywords go to Nelder–Mead, the rest to MAPSO), for settings that
arrive as one flat set of keywords (the CLI, ``identify``'s budgets), as
[`cmaes_nm`][jaxfric.optim.cmaes_nm] is for CMA-ES → Nelder–Mead. It returns a
[`MAPSONMDS`][jaxfric.optim.MAPSONMDS], never another type, so neither is deprecated.

Like every chain it can be driven from Python by ask/tell (an objective outside JAX,
[`jaxfric.optim.asktell`][jaxfric.optim.asktell]; the recipe in [`chain`][jaxfric.optim.chain]'s
module): ``ask`` returns the lattice, self-learning's points, then simplex points, and
``ask_result`` equals ``minimise(...)`` for the same key.
"""

from __future__ import annotations

from .chained import AbstractChain
from .mapso import MAPSO
from .nelder_mead import NelderMead


class MAPSONMDS(AbstractChain):
    """The paper's two-phase optimiser: [`MAPSO`][jaxfric.optim.MAPSO] then [`NelderMead`][jaxfric.optim.NelderMead].

    Same results as ``chain(mapso, nelder_mead, ...)`` for the same key.

    Args:
        mapso: the global phase.
        nelder_mead: the local phase (its ``max_steps``/``max_evals`` bound the refinement).
        num_starts: Nelder–Mead runs, from the ``num_starts`` best personal bests of the
            lattice (1 = from gBest only, as in the paper), one after another.
        simplex_from_swarm: size the first simplex from the spread of the lattice's
            personal bests (per-coordinate standard deviation, at least
            ``nelder_mead.initial_step`` × 1e-3 of the box) instead of a fixed fraction of
            the box.
    """

    mapso: MAPSO = MAPSO()
    nelder_mead: NelderMead = NelderMead()
    num_starts: int = 1
    simplex_from_swarm: bool = True

    @property
    def global_solver(self):
        return self.mapso

    @property
    def local_solver(self):
        return self.nelder_mead

    def check(self):
        if not isinstance(self.mapso, MAPSO):
            raise ValueError("mapso must be a jaxfric.MAPSO")
        if not isinstance(self.nelder_mead, NelderMead):
            raise ValueError("nelder_mead must be a jaxfric.NelderMead")
        super().check()


def mapso_nmds(**kwargs) -> MAPSONMDS:
    """[`MAPSONMDS`][jaxfric.optim.MAPSONMDS] from flat keywords: ``mapso_nmds(num_generations=300,
    nm_max_steps=5000)`` (see the module docstring for why both spellings exist).

    Keywords prefixed ``nm_`` go to [`NelderMead`][jaxfric.optim.NelderMead]; ``num_starts`` and
    ``simplex_from_swarm`` to [`MAPSONMDS`][jaxfric.optim.MAPSONMDS]; the rest to [`MAPSO`][jaxfric.optim.MAPSO].
    """
    nm = {k[3:]: kwargs.pop(k) for k in list(kwargs) if k.startswith("nm_")}
    top = {k: kwargs.pop(k) for k in ("num_starts", "simplex_from_swarm") if k in kwargs}
    return MAPSONMDS(mapso=MAPSO(**kwargs), nelder_mead=NelderMead(**nm), **top)
