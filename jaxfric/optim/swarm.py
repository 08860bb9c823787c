"""What every swarm shares: the state, personal/global bests, stall-based stopping,
warm starts and ``ask / tell`` (docs/algorithms.md §3, §10).

A swarm writes one generation as evaluation *rounds* ([`jaxfric.optim.rounds`][jaxfric.optim.rounds]): a
Python generator that yields each batch of candidates it needs evaluated and receives
their fitness back (``f = yield X``). The compiled run feeds it the objective,
evaluated on the whole batch at once;
[`ask`][jaxfric.optim.asktell.ask] / ``tell`` feed it values
computed anywhere (a simulator outside JAX), one batch per call. The same code therefore
defines both, and a run driven by ``ask``/``tell`` visits the points
[`jaxfric.minimise`][jaxfric.optim.minimise] visits for the same key.
"""


from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from ._base import (
    check_positive_int,
    check_range,
    count_dtype,
    split_drawn,
    uniform_flat_each,
)
from .contract import AbstractGenerational, AbstractStartDraws, Capabilities
from .rounds import Rounds


class SwarmState(eqx.Module):
    """Explicit state of a swarm: positions, velocities, fitness, personal and global bests.

    ``generation`` counts generations done; ``u`` holds the random numbers of the next
    generation (drawn one generation ahead, so they are stored once instead of
    recomputed in every fused consumer, see [`jaxfric.optim.rng.counter_uniform`][jaxfric.optim.rng.counter_uniform]);
    ``stall`` counts generations without a relative improvement of more than the
    solver's ``function_tolerance`` since ``stall_f``.
    """

    x: Array
    v: Array
    f: Array
    pbest: Array
    pbest_f: Array
    gbest: Array
    gbest_f: Array
    num_evals: Array
    key: Any
    generation: Any = None
    u: Any = None
    stall: Any = None
    stall_f: Any = None


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


def first_draws(key, num, lower):
    """The first population's numbers: ``U(0, 1)`` for the positions and the velocities,
    ``(num, D)`` each, and the run's key after them as raw words. A pure function of
    ``key`` and the shapes (no objective): ``start_draws``."""
    kx, kv, key = jax.random.split(key, 3)
    # positions from kx and velocities from kv, drawn as one generator (uniform_flat_each)
    ux, uv = uniform_flat_each(jnp.stack([kx, kv]), (num, lower.shape[0]), lower.dtype)
    return ux, uv, jax.random.key_data(key)


def first_population(key, num, lower, upper, vmax, x0=None, draws=None):
    """Positions ~ U(box), velocities ~ U(±Vmax); the rows of ``x0`` (one start, or a
    ``(k, D)`` initial population) replace the first agents. Returns ``(x, v, key)``,
    ``key`` as raw words (``jax.random.key_data``). ``draws``: `first_draws` of ``key``,
    made beforehand."""
    ux, uv, key = first_draws(key, num, lower) if draws is None else draws
    x = lower + ux * (upper - lower)
    if x0 is not None:
        x0 = jnp.atleast_2d(jnp.clip(x0, lower, upper))
        x = x.at[: x0.shape[0]].set(x0)
    v = -vmax + uv * (vmax - -vmax)
    # the state keeps the key's raw words (all counter_seed reads), so a Solution holds
    # plain arrays only
    return x, v, key


def swarm_from(x, v, f, key) -> SwarmState:
    """The state of an evaluated first population."""
    i = jnp.argmin(f)
    return SwarmState(x=x, v=v, f=f, pbest=x, pbest_f=f, gbest=x[i], gbest_f=f[i],
                      num_evals=jnp.array(x.shape[0], count_dtype()), key=key)


class AbstractSwarm(AbstractGenerational, AbstractStartDraws):
    """A population solver: a fixed number of generations, optionally stopped early.

    Subclasses give ``num_agents``, ``vmax``, ``draw`` (generation ``i``'s random
    numbers, a pure function of the key and ``i``) and ``generation`` (a generator:
    yields candidate batches, receives their fitness, returns the new state).

    Early stopping (MATLAB ``particleswarm``'s ``MaxStallIterations`` and
    ``FunctionTolerance``; off by default, so the paper's fixed ``G`` holds): with
    ``stall_generations = S`` the run ends once the best value has not improved by more
    than ``function_tolerance · max(1, |f_best|)`` for ``S`` generations in a row.
    """

    num_generations: eqx.AbstractVar[int]
    # The PSO operator (docs/algorithms.md §3.3, §10) and early stopping: the same fields
    # and defaults for every swarm, keyword-only (after each swarm's own fields).
    w_max: float = eqx.field(default=0.9, kw_only=True)
    w_min: float = eqx.field(default=0.4, kw_only=True)
    c1: float = eqx.field(default=2.0, kw_only=True)
    c2: float = eqx.field(default=2.0, kw_only=True)
    vmax_fraction: float = eqx.field(default=0.2, kw_only=True)
    zero_velocity_at_bounds: bool = eqx.field(default=True, kw_only=True)
    stall_generations: int | None = eqx.field(default=None, kw_only=True)
    function_tolerance: float = eqx.field(default=1e-6, kw_only=True)

    # --------------------------------------------------------------- subclass hooks
    @property
    def num_agents(self) -> int:
        raise NotImplementedError

    def capabilities(self, n: int) -> Capabilities:
        G = self.num_generations  # AbstractGenerational's, with the population's two
        return Capabilities(population_size=self.num_agents, max_steps=G,
                            max_evaluations=self.evaluations(), progress_totals=(G, None))

    def personal_bests(self, state: SwarmState):
        """``(X, f)``: each agent's best point and value (a chain starts its local stage
        from the best of them)."""
        return state.pbest, state.pbest_f

    def vmax(self, lower, upper):
        return self.vmax_fraction * (upper - lower)

    def draw(self, key, i, x):
        raise NotImplementedError

    def generation(self, state: SwarmState, lower, upper) -> Rounds:
        """Generation ``state.generation`` with its numbers ``state.u`` (inner loops
        yield a [`Scan`][jaxfric.optim.Scan])."""
        raise NotImplementedError

    def evaluations(self) -> int:
        raise NotImplementedError

    def check_swarm(self) -> None:
        """Checks of what every swarm has: the budget, early stopping and the PSO
        operator's coefficients (docs/algorithms.md §3.3)."""
        check_positive_int("num_generations", self.num_generations)
        if self.stall_generations is not None:
            check_positive_int("stall_generations", self.stall_generations)
        check_range("function_tolerance", self.function_tolerance, 0.0)
        for name in ("w_max", "w_min", "c1", "c2"):
            check_range(name, getattr(self, name), 0.0)
        check_range("vmax_fraction", self.vmax_fraction, 0.0, lo_open=True)

    # ------------------------------------------------------------------ generators
    def start_draws(self, lower, upper, key):
        """What the start draws from ``key``, for a ``Drawn`` key: `first_draws`, and
        generation 0's numbers (``draw``, a pure function of the key words `first_draws`
        leaves), so neither is in a new objective's program (issue 47)."""
        ux, uv, raw = first_draws(key, self.num_agents, lower)
        shape = jax.ShapeDtypeStruct((self.num_agents, lower.shape[0]), lower.dtype)
        return ux, uv, raw, self.draw(raw, jnp.array(0, jnp.int32), shape)

    def first(self, lower, upper, key, x0=None) -> Rounds:
        key, draws = split_drawn(key)
        x, v, key = first_population(key, self.num_agents, lower, upper,
                                     self.vmax(lower, upper), x0,
                                     None if draws is None else draws[:3])
        f = yield x
        return self._started(swarm_from(x, v, f, key), None if draws is None else draws[3])

    def _started(self, s: SwarmState, u=None) -> SwarmState:
        """``s`` at generation 0, with its numbers ``u`` (drawn here when not given)."""
        zero = jnp.array(0, jnp.int32)
        return eqx.tree_at(
            lambda s: (s.generation, s.u, s.stall, s.stall_f), s,
            (zero, self.draw(s.key, zero, s.x) if u is None else u, zero, s.gbest_f),
            is_leaf=lambda x: x is None,
        )

    def _advanced(self, s: SwarmState) -> SwarmState:
        i = s.generation + 1
        scale = jnp.maximum(1.0, jnp.abs(s.gbest_f))
        improved = ~(s.gbest_f >= s.stall_f - self.function_tolerance * scale)
        improved = improved & jnp.isfinite(s.gbest_f)
        return eqx.tree_at(
            lambda s: (s.generation, s.u, s.stall, s.stall_f), s,
            (i, self.draw(s.key, i, s.x), jnp.where(improved, 0, s.stall + 1),
             jnp.where(improved, s.gbest_f, s.stall_f)),
        )

    def _next(self, state: SwarmState, lower, upper) -> Rounds:
        s = yield from self.generation(state, lower, upper)
        return self._advanced(s)

    # ------------------------------------------------------------ rounds protocol
    def init_rounds(self, lower, upper, key, x0=None, objective=None) -> Rounds:
        return self.first(lower, upper, key, x0)

    def step_rounds(self, lower, upper, state, stage=0, objective=None) -> Rounds:
        return self._next(state, lower, upper)

    def stopped(self, state):
        if self.stall_generations is None:
            return False
        return state.stall >= self.stall_generations

    def best(self, state):
        return state.gbest, state.gbest_f

    def continued(self, state: SwarmState) -> SwarmState:
        """A finished run's state, ready to run on under this solver's budget (warm
        start): the stall count restarts, generation ``i`` keeps its random numbers."""
        zero = jnp.zeros_like(state.stall)
        return eqx.tree_at(lambda s: (s.stall, s.stall_f), state, (zero, state.gbest_f))
