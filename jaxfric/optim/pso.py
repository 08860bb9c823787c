"""Global-best particle swarm optimisation (ALGORITHMS.md §10), the paper's baseline.

Shi & Eberhart's linearly decreasing inertia PSO: per-dimension random
coefficients, velocity clamp as a fraction of the box, bounds by clipping. The
whole run is one ``lax.scan`` over generations.
"""

from __future__ import annotations

from typing import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from .. import _xla
from ._base import (
    AbstractSolver,
    History,
    Solution,
    batch_objective,
    check_positive_int,
    check_range,
    counter_seed,
    counter_uniform,
    linear_inertia,
    result_from_f,
    uniform_in_box,
)


def pso_move(r, x, v, pbest, social, w, c1, c2, vmax, lower, upper, zero_at_bounds=True):
    """One PSO operator step (ALGORITHMS.md §3.3 / §10):

    ``v ← w v + c1 r1 ⊙ (pbest − x) + c2 r2 ⊙ (social − x)``, ``v ← clip(v, ±Vmax)``,
    ``x ← clip(x + v, lower, upper)``; ``r1, r2 ~ U(0, 1)`` drawn per particle *and*
    per dimension (per-particle coefficients measurably hurt, PEERS.md §3) and passed in
    as ``r`` of shape ``(2,) + x.shape`` — callers draw all of a generation's random
    numbers in one call, which keeps the compiled loop small. With
    ``zero_at_bounds`` the velocity of a clipped coordinate is set to zero so a
    particle does not keep pushing against the wall.
    """
    v = w * v + c1 * r[0] * (pbest - x) + c2 * r[1] * (social - x)
    v = jnp.clip(v, -vmax, vmax)
    x_new = x + v
    x_clip = jnp.clip(x_new, lower, upper)
    if zero_at_bounds:
        v = jnp.where(x_clip != x_new, jnp.zeros_like(v), v)
    return x_clip, v


class SwarmState(eqx.Module):
    """Explicit state of a swarm: positions, velocities, fitness, personal and global bests."""

    x: Array
    v: Array
    f: Array
    pbest: Array
    pbest_f: Array
    gbest: Array
    gbest_f: Array
    num_evals: Array
    key: Array


def update_bests(state: SwarmState, x, f) -> SwarmState:
    """Personal bests improve only on strictly lower (finite) fitness; gbest likewise."""
    better = f < state.pbest_f
    pbest = jnp.where(better[:, None], x, state.pbest)
    pbest_f = jnp.where(better, f, state.pbest_f)
    i = jnp.argmin(pbest_f)
    improved = pbest_f[i] < state.gbest_f
    gbest = jnp.where(improved, pbest[i], state.gbest)
    gbest_f = jnp.where(improved, pbest_f[i], state.gbest_f)
    return eqx.tree_at(
        lambda s: (s.x, s.f, s.pbest, s.pbest_f, s.gbest, s.gbest_f),
        state,
        (x, f, pbest, pbest_f, gbest, gbest_f),
    )


def init_swarm(key, f_batch, num, lower, upper, vmax, x0=None) -> SwarmState:
    """Positions ~ U(box), velocities ~ U(±Vmax); ``x0`` (if given) becomes agent 0."""
    kx, kv, key = jax.random.split(key, 3)
    x = uniform_in_box(kx, (num, lower.shape[0]), lower, upper)
    if x0 is not None:
        x = x.at[0].set(jnp.clip(x0, lower, upper))
    v = uniform_in_box(kv, x.shape, -vmax, vmax)
    f = f_batch(x)
    i = jnp.argmin(f)
    return SwarmState(
        x=x,
        v=v,
        f=f,
        pbest=x,
        pbest_f=f,
        gbest=x[i],
        gbest_f=f[i],
        num_evals=jnp.array(num, jnp.int32),
        key=key,
    )


class AbstractSwarm(AbstractSolver):
    """A population solver that runs a fixed number of generations in ``lax.scan``.

    Subclasses implement ``init``, ``draw`` and ``step``; ``run`` records one history
    entry per generation (plus the initial population).
    """

    num_generations: eqx.AbstractVar[int]

    def init(self, f_batch, lower, upper, key, x0=None) -> SwarmState:
        raise NotImplementedError

    def draw(self, key, i, x):
        """The random numbers generation ``i`` uses (a pytree of arrays), a pure
        function of the run's key and ``i`` (:func:`counter_uniform`)."""
        raise NotImplementedError

    def step(self, state, f_batch, lower, upper, i, u) -> SwarmState:
        """Generation ``i``, given its random numbers ``u = draw(state.key, i, state.x)``."""
        raise NotImplementedError

    def progress_totals(self):
        return self.num_generations, None

    def init_state(self, fn: Callable, lower, upper, args, key, x0=None) -> SwarmState:
        """The evaluated first population."""
        return self.init(batch_objective(fn, args), lower, upper, key, x0)

    def advance(self, state, fn: Callable, lower, upper, args, start, length: int, progress=None):
        """Generations ``start .. start + length − 1`` in one ``lax.scan``.

        Returns ``(state, (evals, f_best))`` with one entry per generation. A run split
        into several ``advance`` calls performs exactly the operations of one call, so
        checkpointed runs reproduce uninterrupted ones.
        """
        f_batch = batch_objective(fn, args)

        def body(carry, i):
            s, u = carry
            # Next generation's numbers now, so they are stored once in the carry
            # rather than recomputed in every fused consumer (see counter_uniform).
            u_next = self.draw(s.key, i + 1, s.x)
            s = self.step(s, f_batch, lower, upper, i, u)
            if progress is not None:
                progress.emit(0, i + 1, s.num_evals, s.gbest_f)
            return (s, u_next), (s.num_evals, s.gbest_f)

        def loop(state, start):
            gens = start + jnp.arange(length, dtype=jnp.int32)
            init = (state, self.draw(state.key, start, state.x))
            (state, _), out = jax.lax.scan(body, init, gens)
            return state, out

        # On CPU the whole loop as one kernel, where the objective allows (see _xla).
        return _xla.single_kernel_loop(loop, state, jnp.asarray(start, jnp.int32),
                                       elements=state.x.size)

    def finish(self, state: SwarmState, evals, f_best) -> Solution:
        """The :class:`Solution` of a finished run; ``evals``/``f_best`` hold the
        initial population's entry followed by one per generation."""
        return Solution(
            value=state.gbest,
            f=state.gbest_f,
            result=result_from_f(state.gbest_f),
            stats={
                "num_steps": jnp.array(self.num_generations, jnp.int32),
                "num_evals": state.num_evals,
            },
            history=History.from_arrays(evals, f_best),
        )

    def run_state(self, fn: Callable, lower, upper, args, key, x0=None, progress=None):
        """Run and return ``(Solution, final SwarmState)``."""
        state = self.init_state(fn, lower, upper, args, key, x0)
        first = (state.num_evals[None], state.gbest_f[None])
        state, (evals, fs) = self.advance(
            state, fn, lower, upper, args, 0, self.num_generations, progress
        )
        sol = self.finish(
            state, jnp.concatenate([first[0], evals]), jnp.concatenate([first[1], fs])
        )
        return sol, state

    def run(self, fn, lower, upper, args, key, x0=None, progress=None) -> Solution:
        return self.run_state(fn, lower, upper, args, key, x0, progress)[0]


class PSO(AbstractSwarm):
    """Global-best PSO with linearly decreasing inertia (the paper's baseline, §10).

    Args:
        num_particles: swarm size (default 25, matching MAPSO's 5×5 lattice).
        num_generations: generations ``G``; evaluations = ``P·(G + 1)``.
        w_max, w_min: inertia falls linearly from ``w_max`` to ``w_min`` over ``G``.
        c1, c2: cognitive and social acceleration (2, 2).
        vmax_fraction: velocity clamp ``Vmax = vmax_fraction·(upper − lower)`` [D: 0.2].
        zero_velocity_at_bounds: zero the velocity of a coordinate clipped to a bound.
    """

    num_particles: int = 25
    num_generations: int = 500
    w_max: float = 0.9
    w_min: float = 0.4
    c1: float = 2.0
    c2: float = 2.0
    vmax_fraction: float = 0.2
    zero_velocity_at_bounds: bool = True

    def check(self):
        check_positive_int("num_particles", self.num_particles)
        check_positive_int("num_generations", self.num_generations)
        for name in ("w_max", "w_min", "c1", "c2"):
            check_range(name, getattr(self, name), 0.0)
        check_range("vmax_fraction", self.vmax_fraction, 0.0, lo_open=True)

    def evaluations(self) -> int:
        """Exact number of objective evaluations of one run."""
        return self.num_particles * (self.num_generations + 1)

    def init(self, f_batch, lower, upper, key, x0=None):
        vmax = self.vmax_fraction * (upper - lower)
        return init_swarm(key, f_batch, self.num_particles, lower, upper, vmax, x0)

    def draw(self, key, i, x):
        """``r1, r2`` for every particle and dimension, shape ``(2, P, D)``."""
        return counter_uniform(counter_seed(key, i), (2,) + x.shape, x.dtype)

    def step(self, state, f_batch, lower, upper, i, u):
        vmax = self.vmax_fraction * (upper - lower)
        w = linear_inertia(i, self.num_generations - 1, self.w_max, self.w_min)
        x, v = pso_move(
            u, state.x, state.v, state.pbest, state.gbest[None, :], w,
            self.c1, self.c2, vmax, lower, upper, self.zero_velocity_at_bounds,
        )
        f = f_batch(x)
        state = eqx.tree_at(
            lambda s: (s.v, s.num_evals), state, (v, state.num_evals + self.num_particles)
        )
        return update_bests(state, x, f)
