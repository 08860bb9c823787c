"""Two-stage solvers: a global search, then a local one from its best point(s)
(docs/algorithms.md §5.1: ``θ_G = global(J, bounds)``, ``θ* = local(J, start=θ_G)``).

[`chain`][jaxfric.optim.chain] builds one from any global solver (PSO, MAPSO, ...) and any local one
([`NelderMead`][jaxfric.optim.NelderMead] or another ``optimistix`` minimiser);
[`MAPSONMDS`][jaxfric.optim.MAPSONMDS] is the paper's instance. The run's key is split once,
``k_global, k_local = jax.random.split(key)``.

The chain is two *stages* of the step protocol: the driver runs stage 0 (global steps)
in one loop and stage 1 (local steps) in the next, so batched runs never compute one
stage's step while in the other. With ``num_starts = k`` the local solver is restarted
from the ``k`` best personal bests of a swarm, one run after another, and the best
refined point wins (multi-start local stage).

Every chain can be driven by ask/tell ([`jaxfric.optim.asktell`][jaxfric.optim.asktell]), for an objective
outside JAX: during the global stage ``ask`` returns the population (and a swarm's further
batches), then Nelder–Mead's first simplex (``n + 1`` points, one per start), then the
trial points of each step, one at a time (a shrink: ``n``) under the sequential rule or
four at once with ``NelderMead(batched_trials=True)``. The switch to the local stage
follows the compiled run's rule, and the evaluation counts are exact::

    solver = chain(PSO(num_generations=50), NelderMead())
    st = jf.ask_init(solver, lower, upper, 0)
    while not jf.ask_done(st):
        X, st = jf.ask(st)
        st = jf.tell(st, X, np.array([simulate(x) for x in np.asarray(X)]))
    solution = jf.ask_result(st)   # minimise(fn, solver, ..., key=0) for a JAX fn
"""

# No ``from __future__ import annotations`` here: equinox recognises ``eqx.AbstractVar``
# only in an evaluated annotation (a string one silently becomes a plain field).
import functools
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from ._base import (
    RESULTS,
    Drawn,
    History,
    Solution,
    check_positive_int,
    put,
    split_drawn,
)
from .contract import (
    AbstractGenerational,
    AbstractLocal,
    AbstractSolver,
    AbstractStaged,
    AbstractStartDraws,
    Capabilities,
    progress_of,
)
from .optx_adapter import OptxMinimiser, as_protocol
from .rounds import drive, only_if, skipped
from .swarm import AbstractSwarm


class ChainState(eqx.Module):
    """``stage`` (0 global, 1 local), the global state, the ``num_starts`` local states
    (stacked; with one start, that run's state itself; placeholders until stage 1) and
    which of them have finished."""

    stage: Any
    first: Any
    second: Any
    second_done: Any
    key: Any  # the local stage's key as raw words (a Solution holds plain arrays only)
    key_impl: Any = eqx.field(static=True, default=None)

    def local_key(self):
        if self.key_impl is None:
            return self.key
        return jax.random.wrap_key_data(self.key, impl=self.key_impl)


def _unfinished_at_start(solver) -> bool:
    """Whether ``solver``'s first state is known, without running it, not to have finished:
    a swarm or evosax strategy starts at generation 0 of at least one, with no stall
    counted (a subclass with its own ``stopped`` rule is not assumed to)."""
    return (isinstance(solver, AbstractGenerational)
            and type(solver).stopped in (AbstractGenerational.stopped, AbstractSwarm.stopped))


def _index(tree, i):
    return jax.tree_util.tree_map(lambda a: a[i], tree)


def _put(tree, i, leaf_tree):
    return jax.tree_util.tree_map(lambda a, b: put(a, i, b), tree, leaf_tree)


class AbstractChain(AbstractStaged, AbstractStartDraws):
    """A global solver followed by a local one (see the module docstring)."""

    # fields of Chain; MAPSONMDS names the first two mapso and nelder_mead (properties)
    global_solver: eqx.AbstractVar[Any]
    local_solver: eqx.AbstractVar[Any]
    num_starts: eqx.AbstractVar[int]
    simplex_from_swarm: eqx.AbstractVar[bool]

    @property
    def _global(self) -> AbstractSolver:
        return as_protocol(self.global_solver)

    @property
    def _local(self) -> AbstractSolver:
        return as_protocol(self.local_solver)

    def check(self):
        for name in ("global_solver", "local_solver"):
            try:
                as_protocol(getattr(self, name))
            except ValueError:
                raise ValueError(
                    f"{name} must be a jaxfric solver that evaluates in batches (PSO, MAPSO, "
                    "Evosax, NelderMead) or an optimistix minimiser, got "
                    f"{type(getattr(self, name)).__name__}") from None
        self._global.check()
        self._local.check()
        check_positive_int("num_starts", self.num_starts)
        if self.num_starts > 1:
            if not isinstance(self._global, AbstractSwarm):  # starts from personal bests
                raise ValueError("num_starts > 1 needs a swarm (PSO, MAPSO) as the global solver")
            agents = self._global.num_agents
            if self.num_starts > agents:
                raise ValueError(
                    f"num_starts ({self.num_starts}) exceeds the number of agents ({agents})")

    def capabilities(self, n: int) -> Capabilities:
        g, loc = self._global.capabilities(n), self._local.capabilities(n)

        def total(a, b):
            return None if a is None or b is None else a + self.num_starts * b

        return Capabilities(
            population_size=g.population_size, num_stages=2,
            max_steps=total(g.max_steps, loc.max_steps),
            max_evaluations=total(g.max_evaluations, loc.max_evaluations),
            progress_totals=(g.progress_totals[0], loc.progress_totals[1]),
            ask_tell_refused=g.ask_tell_refused or loc.ask_tell_refused)

    def expected_evaluations(self, n, of):
        g, loc = of(self._global, n), of(self._local, n)
        return None if g is None or loc is None else g + self.num_starts * loc

    # ------------------------------------------------------------------ stages
    def stage(self, state):
        return state.stage

    def _local_options(self, lower, upper, g):
        """The local stage's first step sized from the spread of the global stage's
        personal bests (``simplex_from_swarm``, a swarm then a local solver; see the local
        solver's [`start_options`][jaxfric.optim.AbstractLocal.start_options])."""
        if not (self.simplex_from_swarm and isinstance(self._global, AbstractSwarm)
                and isinstance(self._local, AbstractLocal)):
            return None
        bests = self._global.personal_bests(g)
        return self._local.start_options(jnp.std(bests[0], axis=0), lower, upper)

    def _starts(self, g):
        if self.num_starts == 1:
            return self._global.best(g)[0][None]
        x, f = self._global.personal_bests(g)
        return x[jnp.argsort(f)[: self.num_starts]]

    def _switch(self, lower, upper, state: ChainState, objective) -> ChainState:
        """Rounds that start the local stage from the global stage's best point(s), one
        start after another, where the global stage has finished (else ``state`` as it is)."""
        g = state.first
        done, _ = self._global.finished(g)
        opts = self._local_options(lower, upper, g)
        local = self._local
        extra = {} if opts is None else {"options": opts}
        starts = self._starts(g)
        runs = []
        for x0 in starts:
            runs.append((yield from only_if(done, local.init_rounds(
                lower, upper, state.local_key(), x0, objective, **extra))))
        # one start: its state itself, no batch of one to index (the rule `_each` reads)
        second = runs[0] if self.num_starts == 1 else jax.tree_util.tree_map(lambda *a: jnp.stack(a), *runs)
        second_done = self._each(lambda s: local.finished(s)[0], second)
        if state.second is None:  # the placeholders' shapes (see init_rounds)
            return ChainState(jnp.array(1, jnp.int32), g, second, second_done, state.key,
                              state.key_impl)
        # select only what the switch sets (the global state is the same either way)
        pick = lambda a, b: jnp.where(done, a, b)  # noqa: E731
        return ChainState(pick(1, state.stage).astype(jnp.int32), g,
                          jax.tree_util.tree_map(pick, second, state.second),
                          pick(second_done, state.second_done), state.key, state.key_impl)

    # ------------------------------------------------------------ rounds protocol
    def start_draws(self, lower, upper, key):
        """What the start draws from ``key``: the stages' keys and the global solver's own
        ``start_draws`` of its key (for a ``Drawn`` key)."""
        k_global, k_local = jax.random.split(key)
        inner = (self._global.start_draws(lower, upper, k_global)
                 if isinstance(self._global, AbstractStartDraws) else None)
        return k_global, k_local, inner

    def init_rounds(self, lower, upper, key, x0=None, objective=None):
        key, draws = split_drawn(key)
        if draws is None:
            k_global, k_local = jax.random.split(key)
        else:
            k_global, k_local, inner = draws
            if inner is not None:
                k_global = Drawn(k_global, inner)
        g = yield from self._global.init_rounds(lower, upper, k_global, x0, objective)
        typed = jnp.issubdtype(k_local.dtype, jax.dtypes.prng_key)
        impl = str(jax.random.key_impl(k_local)) if typed else None
        raw = jax.random.key_data(k_local)
        # The local states exist from the start (a loop carries fixed shapes): zeros
        # until the switch fills them.
        zeros = jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype),
                                       self._local_shapes(lower, upper, g, raw, impl, objective))
        state = ChainState(jnp.array(0, jnp.int32), g, zeros[0], zeros[1], raw, impl)
        if _unfinished_at_start(self._global):
            # the switch would change nothing (its batches are not needed): leaving it
            # out keeps a second copy of the local start, and its objective call, out of
            # the compiled program (issue 47)
            return state
        return (yield from self._switch(lower, upper, state, objective))

    def _local_shapes(self, lower, upper, g, raw, impl, objective):
        """``(second, second_done)`` of the switch's state, as shapes: traced once per
        chain and shapes where the local solver is a jaxfric one (which never calls the
        objective to start), not again for every new objective (issue 47)."""
        like = jax.tree_util.tree_map(lambda a: jax.ShapeDtypeStruct(a.shape, a.dtype),
                                      (lower, upper, g, raw))
        if isinstance(self.local_solver, eqx.Module) and not isinstance(
                self._local, OptxMinimiser):
            try:
                return _switch_shapes(self, *like, impl, None)
            except TypeError:  # an unhashable field: traced below
                pass
        return _switch_shapes.__wrapped__(self, *like, impl, objective)

    def step_rounds(self, lower, upper, state, stage=0, objective=None):
        """One step of stage ``stage`` (static), which ``state`` is known to be in."""
        if stage == 0:
            g = yield from self._global.step_rounds(lower, upper, state.first, 0, objective)
            state = eqx.tree_at(lambda s: s.first, state, g)
            return (yield from self._switch(lower, upper, state, objective))
        local = self._local
        i = self._current(state)
        s_i = yield from local.step_rounds(lower, upper, self._run(state, i), 0, objective)
        done_i, _ = local.finished(s_i)
        if self.num_starts == 1:  # the run itself: no update in place to write
            second = jax.tree_util.tree_map(lambda a, b: jnp.asarray(b).astype(a.dtype),
                                            state.second, s_i)
            return eqx.tree_at(lambda s: (s.second, s.second_done), state,
                               (second, jnp.asarray(done_i).astype(state.second_done.dtype)))
        return eqx.tree_at(
            lambda s: (s.second, s.second_done), state,
            (_put(state.second, i, s_i), put(state.second_done, i, done_i)),
        )

    def _current(self, state):
        """The local run being stepped: the first not yet finished (a static 0 for one
        start, so XLA updates its state in place)."""
        return 0 if self.num_starts == 1 else jnp.argmin(state.second_done)

    def _run(self, state, i):
        """Local run ``i``'s state: with one start ``state.second`` holds that run itself
        (no batch of one, whose reads would each be a slice in the program)."""
        return state.second if self.num_starts == 1 else _index(state.second, i)

    def done(self, state):
        return (state.stage == 1) & jnp.all(state.second_done)

    def finished(self, state):
        return self.done(state), self._result(state)

    def _each(self, fn, second):
        """``fn`` of each local run's state in ``second``: of that run itself for one
        start, vmapped over the stacked runs otherwise."""
        return fn(second) if self.num_starts == 1 else jax.vmap(fn)(second)

    def _local_best(self, state):
        """``(i, x, f)``: the best of the local runs (``i`` a static 0 for one start: that
        run itself, no argmin and gather in the program)."""
        xs, fs = self._each(self._local.best, state.second)
        if self.num_starts == 1:
            return 0, xs, fs
        i = jnp.argmin(fs)
        return i, xs[i], fs[i]

    def _result(self, state):
        i, _, _ = self._local_best(state)
        _, results = self._each(self._local.finished, state.second)
        local = results if self.num_starts == 1 else _index(results, i)
        _, gf = self._global.best(state.first)
        return RESULTS.where(state.stage == 1, local,
                             RESULTS.where(jnp.isfinite(gf), RESULTS.successful, RESULTS.nonfinite))

    def best(self, state):
        gx, gf = self._global.best(state.first)
        _, lx, lf = self._local_best(state)
        use_local = (state.stage == 1) & (lf <= gf)
        return jnp.where(use_local, lx, gx), jnp.where(use_local, lf, gf)

    def num_evals(self, state):
        local = self._each(self._local.num_evals, state.second)
        if self.num_starts > 1:
            local = jnp.sum(local)
        g = self._global.num_evals(state.first)
        return g + jnp.where(state.stage == 1, local, 0).astype(g.dtype)

    def solution(self, fn, lower, upper, args, state, result) -> Solution:
        x, f = self.best(state)
        g_sol = self._global.solution(fn, lower, upper, args, state.first,
                                      self._global.finished(state.first)[1])
        i, _, _ = self._local_best(state)
        best_local = self._run(state, i)
        local_steps = jnp.where(state.stage == 1, progress_of(self._local, best_local)[1], 0)
        return Solution(
            value=x, f=f, result=result,
            stats={
                "num_steps": g_sol.stats["num_steps"] + local_steps.astype(jnp.int32),
                "num_evals": self.num_evals(state),
                "num_evals_global": g_sol.stats["num_evals"],
                "f_global": g_sol.f,
            },
            history=History.empty(1, f.dtype), state=state,
        )

    def progress(self, state):
        _, g_step = progress_of(self._global, state.first)
        i = self._current(state)
        _, l_step = progress_of(self._local, self._run(state, i))
        # the step that switched stages is the global stage's last generation
        local = (state.stage == 1) & ((l_step > 0) | jnp.all(state.second_done))
        return local.astype(jnp.int32), jnp.where(local, l_step, g_step)

    def continued(self, state):
        raise ValueError("a finished two-stage run cannot be continued; warm-start its "
                         "global solver with the solution's first stage instead")


@functools.lru_cache(maxsize=64)
def _switch_shapes(chain, lower, upper, g, raw, impl, objective):
    """`AbstractChain._local_shapes` of shapes ``lower``, ``upper``, ``g``, ``raw``."""
    def switch(lower, upper, g, raw):
        bare = ChainState(jnp.array(0, jnp.int32), g, None, None, raw, impl)
        out = drive(chain._switch(lower, upper, bare, objective), skipped)
        return out.second, out.second_done

    return jax.eval_shape(switch, lower, upper, g, raw)


class Chain(AbstractChain):
    """``chain(global_solver, local_solver)``: see the module docstring.

    Args:
        global_solver: e.g. [`MAPSO`][jaxfric.optim.MAPSO] or [`PSO`][jaxfric.optim.PSO].
        local_solver: e.g. [`NelderMead`][jaxfric.optim.NelderMead] (any ``optx.AbstractMinimiser``
            or jaxfric solver).
        num_starts: local runs from the ``num_starts`` best personal bests (swarms).
        simplex_from_swarm: size Nelder–Mead's first simplex from the swarm's spread.
    """

    global_solver: Any
    local_solver: Any
    num_starts: int = 1
    simplex_from_swarm: bool = True


def chain(global_solver, local_solver, *, num_starts: int = 1,
          simplex_from_swarm: bool = True) -> Chain:
    """A two-stage solver: ``global_solver``, then ``local_solver`` from its best point."""
    return Chain(global_solver, local_solver, num_starts, simplex_from_swarm)
