"""Multi-agent particle swarm optimisation (MAPSO, docs/algorithms.md §3; Zhao et al. 2005).

Agents sit on an ``L×L`` torus held as one ``(L·L, D)`` array. Each generation:

1. neighbourhood competition (§3.2): an agent that is not strictly better than the
   best of its four von Neumann neighbours is replaced by an agent built from that
   neighbour, by strategy 1 (probability ``Po``) or strategy 2;
2. the PSO operator (§3.3) with the linearly decreasing inertia;
3. self-learning (§3.4): a small ``sL×sL`` MAPSO (competition + PSO) run for
   ``sGen`` generations around the global best, which replaces it when beaten.

Everything is vectorised: neighbours come from ``jnp.roll`` on the lattice, never
from a Python loop over agents, and the generations run in ``lax.scan``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from ._base import check_positive_int, check_range, clip, count_dtype, linear_inertia
from .pso import pso_move
from .rng import counter_seed, counter_uniform, extend_seed
from .rounds import Scan
from .swarm import AbstractSwarm, SwarmState, update_bests


def lattice_neighbours(values, side: int):
    """Von Neumann neighbours on a torus (§3.1).

    ``values`` has leading axis ``side²`` (row-major lattice). Returns an array with
    a new leading axis of 4: up, down, left, right (wrapping around the edges).
    """
    grid = values.reshape((side, side) + values.shape[1:])
    nb = jnp.stack(
        [
            jnp.roll(grid, 1, axis=0),
            jnp.roll(grid, -1, axis=0),
            jnp.roll(grid, 1, axis=1),
            jnp.roll(grid, -1, axis=1),
        ]
    )
    return nb.reshape((4, side * side) + values.shape[1:])


def best_neighbour(x, f, side: int):
    """Position and fitness of each agent's best von Neumann neighbour (``M_ij``), from
    four rolled copies (a gather through an index table ran slower: docs/solvers.md)."""
    nx = lattice_neighbours(x, side)  # (4, P, D)
    nf = lattice_neighbours(f, side)  # (4, P)
    j = jnp.argmin(nf, axis=0)
    m = jnp.take_along_axis(nx, j[None, :, None], axis=0)[0]
    fm = jnp.take_along_axis(nf, j[None, :], axis=0)[0]
    return m, fm


def reverse_segment_index(u_a, u_b, dim: int, strict: bool):
    """Gather indices that reverse a random segment ``[i1, i2]`` of each row.

    ``u_a, u_b ~ U(0, 1)`` (one pair per row) pick ``i1 < i2`` uniformly over
    ``0..D-1`` [D]; with ``strict`` (MAGA's ``1 < i1 < i2 < D``, 1-based) the first and
    last coordinate stay put, which needs ``D >= 4``; for smaller ``D`` the strict rule
    has no valid pair and the unrestricted rule is used. (Integers come from
    ``floor(u·span)`` rather than ``jax.random.randint``, whose lowering is ~1,700 HLO
    lines and made the vmapped solver compile several times slower.)
    """
    num = u_a.shape[0]
    lo, hi = (1, dim - 1) if (strict and dim >= 4) else (0, dim)
    span = hi - lo
    if span < 2:
        return jnp.broadcast_to(jnp.arange(dim), (num, dim))
    a = jnp.minimum(jnp.floor(u_a * span).astype(jnp.int32), span - 1)
    b = jnp.minimum(jnp.floor(u_b * (span - 1)).astype(jnp.int32), span - 2)
    b = b + (b >= a)
    i1 = lo + jnp.minimum(a, b)
    i2 = lo + jnp.maximum(a, b)
    k = jnp.arange(dim)[None, :]
    inside = (k >= i1[:, None]) & (k <= i2[:, None])
    return jnp.where(inside, i1[:, None] + i2[:, None] - k, k)


def competition(u, x, f, side, lower, upper, po, strict_segment=False):
    """Neighbourhood competition and cooperation (§3.2, paper eq. (12)), synchronous.

    Returns the new positions and a boolean mask of the agents that lost (were replaced).
    Strategy 1 (``U < Po``): ``e = clip(m + U(−1, 1)⊙(m − l))``. Strategy 2: map the
    winner ``m`` to the unit cube, reverse a random segment, map back. ``u`` holds
    ``U(0, 1)`` draws of shape ``(num, D + 3)``: strategy choice, the two segment ends,
    and the crossover weights.
    """
    num, dim = x.shape
    m, fm = best_neighbour(x, f, side)
    lose = ~(f < fm)
    use_first = u[:, 0] < po
    e1 = clip(m + (2.0 * u[:, 3:] - 1.0) * (m - x), lower, upper)
    width = upper - lower
    unit = (m - lower) / width
    idx = reverse_segment_index(u[:, 1], u[:, 2], dim, strict_segment)
    e2 = lower + jnp.take_along_axis(unit, idx, axis=1) * width
    e = jnp.where(use_first[:, None], e1, e2)
    return jnp.where(lose[:, None], e, x), lose


class MAPSO(AbstractSwarm):
    """Multi-agent PSO on an ``L×L`` torus (docs/algorithms.md §3.5 defaults).

    Args:
        lattice_size: lattice side ``Lsize``; population ``Lsize²`` (5 → 25 agents).
        num_generations: generations ``G``.
        po: probability of competition strategy 1 (``Po`` = 0.2, MAGA).
        sl_size: self-learning lattice side ``sLsize`` (3).
        sl_radius: self-learning search radius ``sR ∈ [0, 1]``. Default 1.0, not MAGA's
            0.2 [R]; the paper's value is unknown [?]. The multiplicative factor
            ``U(1 − sR, 1 + sR)`` can then take a coordinate anywhere between 0 and twice
            its value, which is what frees a coordinate caught in a Griewank side basin.
            On 30-D Griewank (30 runs, G = 1000) sR = 1.0 solved 30/30, sR = 0.8 28/30
            and sR = 0.2 about half; Ackley, Sphere, Schwefel and Rosenbrock did not get
            worse (``benchmarks/table1.py`` shows sR = 0.2 beside the default).
        sl_generations: self-learning generations ``sGen`` (10).
        sl_mode: ``"multiplicative"`` (the paper's ``g_k·U(1−sR, 1+sR)``) or
            ``"additive"`` (``g_k + U(−sR, sR)·(upper_k − lower_k)``, which can move a
            coordinate that is exactly zero).
        w_max, w_min, c1, c2, vmax_fraction: PSO operator, as in [`PSO`][jaxfric.optim.PSO].
        social: ``"gbest"`` (Zhao et al.) or ``"lbest"`` (best personal best of the
            agent's von Neumann neighbourhood and itself).
        strict_maga_segment: MAGA's rule leaving the first and last coordinate out of
            strategy 2's reversed segment.
        reset_velocity_on_replace: zero the velocity of a replaced agent (default keeps it).
        evaluate_replaced: evaluate a replaced agent before its PSO move so its
            personal best can improve (costs up to ``Lsize²`` more evaluations per
            generation; by default the PSO move follows at once and is evaluated).
        stall_generations, function_tolerance: optional early stop, as in [`PSO`][jaxfric.optim.PSO].

    Evaluations per generation: ``Lsize² + (sLsize² − 1) + sLsize²·sGen`` (123 with
    the defaults), plus ``Lsize²`` if ``evaluate_replaced``; see [`evaluations`][jaxfric.optim.MAPSO.evaluations].
    """

    lattice_size: int = 5
    num_generations: int = 500
    po: float = 0.2
    sl_size: int = 3
    sl_radius: float = 1.0
    sl_generations: int = 10
    sl_mode: str = "multiplicative"
    social: str = "gbest"
    strict_maga_segment: bool = False
    reset_velocity_on_replace: bool = False
    evaluate_replaced: bool = False

    def check(self):
        check_positive_int("lattice_size", self.lattice_size)
        self.check_swarm()
        check_positive_int("sl_size", self.sl_size)
        check_positive_int("sl_generations", self.sl_generations, minimum=0)
        check_range("po", self.po, 0.0, 1.0)
        check_range("sl_radius", self.sl_radius, 0.0, 1.0)
        if self.sl_mode not in ("multiplicative", "additive"):
            raise ValueError(
                f"sl_mode must be 'multiplicative' or 'additive', got {self.sl_mode!r}"
            )
        if self.social not in ("gbest", "lbest"):
            raise ValueError(f"social must be 'gbest' or 'lbest', got {self.social!r}")

    @property
    def num_agents(self) -> int:
        return self.lattice_size**2

    def evaluations(self) -> int:
        """Exact number of objective evaluations of one run."""
        p, s = self.num_agents, self.sl_size**2
        per_gen = p * (2 if self.evaluate_replaced else 1)
        if s > 1:  # a 1×1 self-learning lattice is no self-learning (see step)
            per_gen += (s - 1) + s * self.sl_generations
        return p + self.num_generations * per_gen

    # ------------------------------------------------------------------ operators
    def random_width(self, dim: int) -> int:
        """U(0, 1) numbers one agent needs per lattice generation (competition + PSO)."""
        return 3 * dim + 3

    def _lattice_generation(self, state: SwarmState, u, side, lower, upper, w, social_mode):
        """Competition then PSO move on one lattice (main lattice or self-learning), as
        a generator of evaluation batches (see [`jaxfric.optim.swarm`][jaxfric.optim.swarm]).

        ``u`` (agents × [`random_width`][jaxfric.optim.MAPSO.random_width]) holds all of this generation's random
        numbers, drawn by the caller in one call.
        """
        dim = state.x.shape[1]
        vmax = self.vmax_fraction * (upper - lower)
        x, lost = competition(
            u[:, : dim + 3], state.x, state.f, side, lower, upper, self.po,
            self.strict_maga_segment,
        )
        r = jnp.stack([u[:, dim + 3 : 2 * dim + 3], u[:, 2 * dim + 3 :]])
        v = state.v
        if self.reset_velocity_on_replace:
            v = jnp.where(lost[:, None], jnp.zeros_like(v), v)
        num = x.shape[0]
        evals = state.num_evals
        state = eqx.tree_at(lambda s: s.v, state, v)
        if self.evaluate_replaced:
            f_x = yield x
            f_rep = jnp.where(lost, f_x, state.f)
            state = update_bests(state, x, f_rep)
            evals = evals + num
        if social_mode == "lbest":
            nb_f = lattice_neighbours(state.pbest_f, side)
            nb_x = lattice_neighbours(state.pbest, side)
            all_f = jnp.concatenate([state.pbest_f[None], nb_f])
            all_x = jnp.concatenate([state.pbest[None], nb_x])
            j = jnp.argmin(all_f, axis=0)
            social = jnp.take_along_axis(all_x, j[None, :, None], axis=0)[0]
        else:
            social = state.gbest[None, :]
        x, v = pso_move(
            r, x, state.v, state.pbest, social, w, self.c1, self.c2, vmax,
            lower, upper, self.zero_velocity_at_bounds, clip=clip,
        )
        f = yield x
        state = eqx.tree_at(lambda s: (s.v, s.num_evals), state, (v, evals + num))
        return update_bests(state, x, f)

    def _self_learning(self, u0, u_inner, g, g_f, lower, upper):
        """Self-learning around gBest (§3.4), a generator: returns (best position,
        fitness, evaluations). The ``sGen`` inner generations are one
        [`Scan`][jaxfric.optim.Scan] (a ``lax.scan`` in a compiled run)."""
        side = self.sl_size
        s = side * side
        if self.sl_mode == "multiplicative":
            cand = g * (1.0 - self.sl_radius + 2.0 * self.sl_radius * u0)
        else:
            cand = g + (2.0 * u0 - 1.0) * self.sl_radius * (upper - lower)
        # sL_11 = g; the others perturbed and clipped
        cand = jnp.concatenate([g[None], clip(cand[1:], lower, upper)])
        f_rest = yield cand[1:]
        f = jnp.concatenate([g_f[None], f_rest])
        i = jnp.argmin(f)
        inner = SwarmState(
            x=cand, v=jnp.zeros_like(cand), f=f, pbest=cand, pbest_f=f,
            gbest=cand[i], gbest_f=f[i], num_evals=jnp.array(s - 1, count_dtype()), key=None,
        )

        def generation(st, xs):
            j, uj = xs
            w = linear_inertia(j, self.sl_generations - 1, self.w_max, self.w_min)
            return self._lattice_generation(st, uj, side, lower, upper, w, "gbest")

        inner = yield Scan(generation, inner, (jnp.arange(self.sl_generations), u_inner),
                           self.sl_generations)
        return inner.gbest, inner.gbest_f, inner.num_evals

    # ------------------------------------------------------------- solver protocol
    def draw(self, key, i, x):
        """Generation ``i``'s numbers: the main lattice's (agents × [`random_width`][jaxfric.optim.MAPSO.random_width]),
        self-learning's perturbation ``u0`` (sLsize² × D) and its inner lattice's
        (sGen × sLsize² × width)."""
        dim, dt = x.shape[1], x.dtype
        width = self.random_width(dim)
        s = self.sl_size**2
        seed = counter_seed(key, i)  # counter_seed(key, i, stream), the streams' work shared
        main = counter_uniform(extend_seed(seed, 0), (self.num_agents, width), dt)
        if s <= 1:
            return main, None, None
        u0 = counter_uniform(extend_seed(seed, 1), (s, dim), dt)
        inner = counter_uniform(extend_seed(seed, 2), (self.sl_generations, s, width), dt)
        return main, u0, inner

    def generation(self, state, lower, upper):
        u, u0, u_inner = state.u
        w = linear_inertia(state.generation, self.num_generations - 1, self.w_max, self.w_min)
        state = yield from self._lattice_generation(
            state, u, self.lattice_size, lower, upper, w, self.social
        )
        if self.sl_size * self.sl_size <= 1:
            return state
        g, g_f, evals = yield from self._self_learning(
            u0, u_inner, state.gbest, state.gbest_f, lower, upper
        )
        better = g_f < state.gbest_f
        # The agent whose memory is gBest takes the self-learned agent's place.
        a = jnp.argmin(state.pbest_f)

        def put(arr, val):
            # arr[a] = val if better, as an in-place dynamic_update_slice (a select of
            # two arrays would copy one)
            keep = jax.lax.dynamic_index_in_dim(arr, a, 0, keepdims=False)
            return jax.lax.dynamic_update_index_in_dim(arr, jnp.where(better, val, keep), a, 0)

        return eqx.tree_at(
            lambda s: (s.x, s.f, s.pbest, s.pbest_f, s.gbest, s.gbest_f, s.num_evals),
            state,
            (
                put(state.x, g),
                put(state.f, g_f),
                put(state.pbest, g),
                put(state.pbest_f, g_f),
                jnp.where(better, g, state.gbest),
                jnp.where(better, g_f, state.gbest_f),
                state.num_evals + evals,
            ),
        )

