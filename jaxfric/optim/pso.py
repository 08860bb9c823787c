"""Global-best particle swarm optimisation (docs/algorithms.md §10), the paper's baseline.

Shi & Eberhart's linearly decreasing inertia PSO: per-dimension random coefficients,
velocity clamp as a fraction of the box, bounds by clipping. One generation is one
batch of evaluations; state, stopping, warm start and ``ask``/``tell`` come from
[`AbstractSwarm`][jaxfric.optim.AbstractSwarm].
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp

from ._base import check_positive_int, linear_inertia
from .rng import counter_seed, counter_uniform
from .swarm import AbstractSwarm, update_bests


def pso_move(r, x, v, pbest, social, w, c1, c2, vmax, lower, upper, zero_at_bounds=True,
             clip=jnp.clip):
    """One PSO operator step (docs/algorithms.md §3.3 / §10):

    ``v ← w v + c1 r1 ⊙ (pbest − x) + c2 r2 ⊙ (social − x)``, ``v ← clip(v, ±Vmax)``,
    ``x ← clip(x + v, lower, upper)``; ``r1, r2 ~ U(0, 1)`` drawn per particle *and*
    per dimension (per-particle coefficients measurably hurt, docs/algorithms.md §3.3) and passed in
    as ``r`` of shape ``(2,) + x.shape``. With ``zero_at_bounds`` the velocity of a
    clipped coordinate is set to zero so a particle does not keep pushing against the wall.

    ``clip(x, lo, hi)`` bounds both; it gives the same numbers either way. [`PSO`][jaxfric.optim.PSO]
    keeps ``jnp.clip``; [`MAPSO`][jaxfric.optim.MAPSO] passes the select form
    (`jaxfric.optim._base.clip`), faster for MAPSO and slower for PSO (measured:
    docs/solvers.md, "What measurements decided").
    """
    v = w * v + c1 * r[0] * (pbest - x) + c2 * r[1] * (social - x)
    v = clip(v, -vmax, vmax)
    x_new = x + v
    x_clip = clip(x_new, lower, upper)
    if zero_at_bounds:
        v = jnp.where(x_clip != x_new, jnp.zeros_like(v), v)
    return x_clip, v


class PSO(AbstractSwarm):
    """Global-best PSO with linearly decreasing inertia (the paper's baseline, §10).

    Args:
        num_particles: swarm size (default 25, matching MAPSO's 5×5 lattice).
        num_generations: generations ``G``; evaluations = ``P·(G + 1)``.
        w_max, w_min: inertia falls linearly from ``w_max`` to ``w_min`` over ``G``.
        c1, c2: cognitive and social acceleration (2, 2).
        vmax_fraction: velocity clamp ``Vmax = vmax_fraction·(upper − lower)`` [D: 0.2].
        zero_velocity_at_bounds: zero the velocity of a coordinate clipped to a bound.
        stall_generations, function_tolerance: optional early stop (MATLAB's
            ``MaxStallIterations``/``FunctionTolerance``; ``None`` = run all ``G``).
    """

    num_particles: int = 25
    num_generations: int = 500

    def check(self):
        check_positive_int("num_particles", self.num_particles)
        self.check_swarm()

    @property
    def num_agents(self) -> int:
        return self.num_particles

    def evaluations(self) -> int:
        """Most objective evaluations of one run (exact without early stopping)."""
        return self.num_particles * (self.num_generations + 1)

    def draw(self, key, i, x):
        """``r1, r2`` for every particle and dimension, shape ``(2, P, D)``."""
        return counter_uniform(counter_seed(key, i), (2,) + x.shape, x.dtype)

    def generation(self, state, lower, upper):
        w = linear_inertia(state.generation, self.num_generations - 1, self.w_max, self.w_min)
        x, v = pso_move(
            state.u, state.x, state.v, state.pbest, state.gbest[None, :], w,
            self.c1, self.c2, self.vmax(lower, upper), lower, upper,
            self.zero_velocity_at_bounds,
        )
        f = yield x
        state = eqx.tree_at(
            lambda s: (s.v, s.num_evals), state, (v, state.num_evals + self.num_particles)
        )
        return update_bests(state, x, f)
