"""The one solver contract (docs/solvers.md): [`AbstractSolver`][jaxfric.optim.AbstractSolver], whose start and
steps are evaluation rounds ([`jaxfric.optim.rounds`][jaxfric.optim.rounds]), and
[`AbstractGenerational`][jaxfric.optim.AbstractGenerational] for population solvers that run a number of generations."""

from __future__ import annotations

import abc
from typing import Any, Callable

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array

from . import asktell
from ._base import History, Solution, result_from_f
from .rounds import Rounds


class AbstractSolver(eqx.Module):
    """The one contract of a jaxfric solver on a box (docs/solvers.md): its evaluations
    come in rounds (see the module docstring). Required:

    * [`init_rounds`][jaxfric.optim.AbstractSolver.init_rounds] and [`step_rounds`][jaxfric.optim.AbstractSolver.step_rounds]: the start and one step, as rounds;
    * [`finished`][jaxfric.optim.AbstractSolver.finished]: ``(done, result)``, a boolean scalar and an ``optimistix.RESULTS``;
    * [`best`][jaxfric.optim.AbstractSolver.best]: ``(x, f)``, the best point so far and its (NaN-safe) value;
    * [`num_evals`][jaxfric.optim.AbstractSolver.num_evals]: the objective evaluations spent so far.

    Everything else is an optional capability with a default: the driver, the loop and
    the chains ask these, never the solver's type. ``ask``/``tell`` (from Python) come
    from the required methods. Every method is pure and traceable; ``lower`` and
    ``upper`` are 1-D arrays of one floating dtype (the driver flattens pytree bounds)
    and the state is a pytree of arrays (what a checkpoint stores). The loop
    ([`jaxfric.optim.loop`][jaxfric.optim.loop]) records ``best(state)[1]`` against ``num_evals(state)``
    after every step and reports [`progress`][jaxfric.optim.AbstractSolver.progress].

    The names differ from optimistix's ``init / step / terminate / postprocess`` on
    purpose: [`NelderMead`][jaxfric.optim.NelderMead] is both a jaxfric solver and an
    ``optx.AbstractMinimiser``, each protocol under its own names.

    ``objective`` is ``(fn, args)`` inside the compiled run: with it inner loops may
    run as ``lax.scan`` (MAPSO's self-learning) and a minimiser that evaluates by
    itself (an optimistix gradient method) can run at all.
    """

    def __check_init__(self):
        # Solvers validate on construction, as the models do: a bad hyperparameter
        # fails where it is written, naming the field.
        self.check()

    # ------------------------------------------------------------------ required
    @abc.abstractmethod
    def init_rounds(self, lower, upper, key, x0=None, objective=None) -> Rounds:
        """Rounds of the start (``x0``: an optional start inside the box); returns the
        first state."""

    @abc.abstractmethod
    def step_rounds(self, lower, upper, state, stage: int = 0, objective=None) -> Rounds:
        """Rounds of one step of ``stage`` (static), which ``state`` is in; returns the
        new state."""

    @abc.abstractmethod
    def finished(self, state) -> tuple[Array, Any]:
        """``(done, result)``: a boolean scalar and an ``optimistix.RESULTS``."""

    @abc.abstractmethod
    def best(self, state) -> tuple[Array, Array]:
        """``(x, f)``: the best point so far and its (NaN-safe) value."""

    @abc.abstractmethod
    def num_evals(self, state) -> Array:
        """Objective evaluations spent so far."""

    # ---------------------------------------------------------- optional capabilities
    def check(self) -> None:
        """Raise ``ValueError`` on invalid hyperparameters. Run on construction
        (``__check_init__``) and again by [`jaxfric.minimise`][jaxfric.optim.minimise] before any tracing."""

    def solution(self, fn: Callable, lower, upper, args, state, result) -> Solution:
        """The [`Solution`][jaxfric.optim.Solution] (flat ``value``; the loop adds the history)."""
        x, f = self.best(state)
        return Solution(value=x, f=f, result=result, stats={"num_evals": self.num_evals(state)},
                        history=History.empty(1, f.dtype), state=state)

    def population_size(self) -> int | None:
        """Agents of a population solver (a start ``y0`` may then be an initial
        population of up to this many rows); ``None``: the solver takes one start."""
        return None

    def personal_bests(self, state) -> tuple[Array, Array] | None:
        """``(X, f)``: each agent's best point and value, for a population solver (a
        chain then starts its local stage from the best of them); ``None`` otherwise."""
        return None

    def start_options(self, spread, lower, upper) -> dict | None:
        """Options for a local run started where a population of per-coordinate
        standard deviation ``spread`` converged, passed to [`init_rounds`][jaxfric.optim.AbstractSolver.init_rounds] as
        ``options=`` (``None``: this solver takes none)."""
        return None

    def steps_for(self, n: int) -> int | None:
        """The step cap: most steps of a run on ``n`` parameters (``None``: none known)."""
        return None

    def max_evaluations(self, n: int) -> int | None:
        """The evaluation cap: most objective evaluations of a run on ``n`` parameters
        (``None`` if unknown), checked by the driver against the evaluation counter's
        range before running."""
        return None

    def num_stages(self) -> int:
        """Stages run one after another (a two-stage [`chain`][jaxfric.optim.chain]
        has 2). The loop runs each in a loop of its own, so batched runs never pay for
        one stage's step while in another."""
        return 1

    def stage(self, state) -> Array:
        """The stage ``state`` is in (``0 .. num_stages() − 1``)."""
        return jnp.array(0, jnp.int32)

    def batches_runs(self) -> bool:
        """Whether [`jaxfric.minimise_many`][jaxfric.optim.minimise_many] should, on one CPU, run several keys side
        by side (``vmap``: ``True``, for solvers whose steps are batches of the same size)
        rather than one after another (``lax.map``: ``False``, for a solver with
        conditional batches, whose branches ``vmap`` turns into selects that compute
        both sides)."""
        return True

    def continued(self, state):
        """``state`` of a finished run, ready to go on under this solver's (larger)
        budget (``minimise(..., warm_start=solution)``)."""
        return state

    def progress(self, state) -> tuple[Array, Array]:
        """``(phase, step)`` for a progress display: phase 0 a global (swarm) stage,
        phase 1 a local (Nelder–Mead) stage; ``step`` counts within the phase."""
        return jnp.array(0, jnp.int32), jnp.array(0, jnp.int32)

    def progress_totals(self) -> tuple[int | None, int | None]:
        """(global generations, local step cap) for a progress display."""
        return None, None

    def check_ask_tell(self) -> None:
        """Raise ``ValueError`` if ``ask``/``tell`` cannot drive this solver."""

    # ------------------------------------------------------------------- ask / tell
    def ask_init(self, lower, upper, key=None, x0=None, *, keys=None) -> asktell.AskTellState:
        """Start a run driven from Python ([`jaxfric.optim.asktell`][jaxfric.optim.asktell]). ``lower`` /
        ``upper``: 1-D bounds (their dtype is the search dtype, as in
        [`jaxfric.minimise`][jaxfric.optim.minimise]); ``key``: a PRNG key or an int seed; ``x0``: an
        optional start (swarms: or an initial population).

        ``keys`` instead of ``key``: a batch of ``S`` PRNG keys, as
        [`jaxfric.minimise_many`][jaxfric.optim.minimise_many] takes them. The seeds then run side by side in one
        run (``minimise_many``'s ``batching="vmap"``): every ask carries every seed's
        batch, so one host call evaluates them all. Exactly one of ``key`` and ``keys``."""
        self.check()
        self.check_ask_tell()
        return asktell.start(self, lower, upper, key, x0, keys=keys)

    def ask(self, st: asktell.AskTellState):
        """``(X, st)``: the points (rows) whose values [`tell`][jaxfric.optim.AbstractSolver.tell] needs next, ``(k, n)``;
        with ``keys``, ``(S, k, n)``, block ``s`` for seed ``s``."""
        return asktell.ask(st)

    def tell(self, st: asktell.AskTellState, X, f) -> asktell.AskTellState:
        """Give the values ``f`` of the rows ``X`` returned by [`ask`][jaxfric.optim.AbstractSolver.ask] (NaN and inf
        count as the worst value), of shape ``(k,)``, or ``(S, k)`` with ``keys``; returns
        the state asking for the next batch."""
        return asktell.tell(st, X, f)

    def ask_done(self, st: asktell.AskTellState) -> bool:
        """Whether the run has finished (by the rule the compiled run stops on)."""
        return asktell.done(st)

    def ask_result(self, st: asktell.AskTellState) -> Solution:
        """The [`Solution`][jaxfric.optim.Solution] (flat ``value``): what [`jaxfric.minimise`][jaxfric.optim.minimise] returns
        for the same key once the run has finished (with ``keys``: what
        ``minimise_many(..., batching="vmap")`` returns); before, the best point told so
        far (per seed, see [`jaxfric.optim.asktell.result`][jaxfric.optim.asktell.result])."""
        return asktell.result(st)


class AbstractGenerational(AbstractSolver):
    """A population solver that runs ``num_generations`` generations (swarms, evosax
    strategies). Its state has ``generation`` and ``num_evals``; [`best`][jaxfric.optim.AbstractSolver.best] gives the
    best point; [`stopped`][jaxfric.optim.AbstractGenerational.stopped] an optional earlier end."""

    num_generations: eqx.AbstractVar[int]

    def stopped(self, state):
        """Whether the run ends before ``num_generations`` (default: never)."""
        return False

    def finished(self, state):
        done = (state.generation >= self.num_generations) | self.stopped(state)
        return done, result_from_f(self.best(state)[1])

    def solution(self, fn, lower, upper, args, state, result) -> Solution:
        x, f = self.best(state)
        return Solution(
            value=x, f=f, result=result,
            stats={"num_steps": state.generation, "num_evals": state.num_evals},
            history=History.empty(1, f.dtype), state=state,
        )

    def num_evals(self, state):
        return state.num_evals

    def steps_for(self, n: int) -> int:
        return self.num_generations

    def progress(self, state):
        return jnp.array(0, jnp.int32), state.generation

    def progress_totals(self):
        return self.num_generations, None
