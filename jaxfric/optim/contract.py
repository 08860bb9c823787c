"""The one solver contract (docs/solvers.md): [`AbstractSolver`][jaxfric.optim.AbstractSolver], whose start and
steps are evaluation rounds ([`jaxfric.optim.rounds`][jaxfric.optim.rounds]), with one capabilities record
([`Capabilities`][jaxfric.optim.Capabilities]); and the nominal kinds a capability that is
really a type is written as: [`AbstractGenerational`][jaxfric.optim.AbstractGenerational] (population
solvers that run a number of generations), [`AbstractLocal`][jaxfric.optim.AbstractLocal]
(local solvers from one start), [`AbstractStaged`][jaxfric.optim.AbstractStaged] (solvers of several
stages: the chains) and [`AbstractStartDraws`][jaxfric.optim.AbstractStartDraws] (a start whose
random numbers can be drawn apart from the objective). The driver, the loop and the chains
read the record or test these types, never ``hasattr``.

ask/tell is no part of the contract: it is a driver beside [`jaxfric.minimise`][jaxfric.optim.minimise]
([`jaxfric.optim.asktell`][jaxfric.optim.asktell]) that runs any solver's rounds."""


import abc
import dataclasses
from typing import Any, Callable

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array

from ._base import RESULTS, History, Solution, result_from_f
from .rounds import Rounds


@dataclasses.dataclass(frozen=True)
class Capabilities:
    """What a solver can do and costs on ``n`` parameters
    ([`AbstractSolver.capabilities`][jaxfric.optim.AbstractSolver.capabilities]); every field has the
    default of a plain one-stage solver that takes one start.

    Attributes:
        population_size: agents of a population solver (a start ``y0`` may then be an
            initial population of up to this many rows); ``None``: one start.
        num_stages: stages run one after another (a two-stage chain has 2, and is an
            [`AbstractStaged`][jaxfric.optim.AbstractStaged]); the loop runs each in a ``while_loop`` of its
            own, so batched runs never pay for one stage's step while in another.
        max_steps: the step cap, most steps of a run (``None``: none known); sizes the
            history.
        max_evaluations: most objective evaluations of a run (``None``: unknown), checked
            by the driver against the evaluation counter's range before running.
        batches_runs: whether [`jaxfric.minimise_many`][jaxfric.optim.minimise_many] should, on one CPU, run
            several keys side by side (``vmap``: ``True``, for steps that are batches of one
            size) rather than one after another (``lax.map``: ``False``, for conditional
            batches, whose branches ``vmap`` turns into selects that compute both sides).
        progress_totals: (global generations, local step cap) for a progress display.
        ask_tell_refused: ``None`` where ask/tell ([`jaxfric.optim.asktell`][jaxfric.optim.asktell]) can drive the
            solver, else why not (``ask_init`` raises ``ValueError`` with it).
    """

    population_size: int | None = None
    num_stages: int = 1
    max_steps: int | None = None
    max_evaluations: int | None = None
    batches_runs: bool = True
    progress_totals: tuple[int | None, int | None] = (None, None)
    ask_tell_refused: str | None = None


class AbstractSolver(eqx.Module):
    """The one contract of a jaxfric solver on a box (docs/solvers.md): its evaluations
    come in rounds (see the module docstring). Required:

    * [`init_rounds`][jaxfric.optim.AbstractSolver.init_rounds] and [`step_rounds`][jaxfric.optim.AbstractSolver.step_rounds]: the start and one step, as rounds;
    * [`finished`][jaxfric.optim.AbstractSolver.finished]: ``(done, result)``, a boolean scalar and an ``optimistix.RESULTS``;
    * [`best`][jaxfric.optim.AbstractSolver.best]: ``(x, f)``, the best point so far and its (NaN-safe) value;
    * [`num_evals`][jaxfric.optim.AbstractSolver.num_evals]: the objective evaluations spent so far.

    With defaults: [`check`][jaxfric.optim.AbstractSolver.check] (the hyperparameters),
    [`solution`][jaxfric.optim.AbstractSolver.solution] (the run's end) and
    [`capabilities`][jaxfric.optim.AbstractSolver.capabilities], one record of every number and
    flag the driver, the loop and the chains read. Those are all of the contract's eight
    methods; what a solver of one kind has beyond them (personal bests, a stage, a
    warm start, progress) comes with that kind's base class (module docstring). Every
    method is pure and traceable; ``lower`` and ``upper`` are 1-D arrays of one floating
    dtype (the driver flattens pytree bounds) and the state is a pytree of arrays (what a
    checkpoint stores). The loop ([`jaxfric.optim.loop`][jaxfric.optim.loop]) records ``best(state)[1]``
    against ``num_evals(state)`` after every step.

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

    # ------------------------------------------------------------- with defaults
    def check(self) -> None:
        """Raise ``ValueError`` on invalid hyperparameters. Run on construction
        (``__check_init__``) and again by [`jaxfric.minimise`][jaxfric.optim.minimise] before any tracing."""

    def solution(self, fn: Callable, lower, upper, args, state, result) -> Solution:
        """The [`Solution`][jaxfric.optim.Solution] (flat ``value``; the loop adds the history)."""
        x, f = self.best(state)
        return Solution(value=x, f=f, result=result, stats={"num_evals": self.num_evals(state)},
                        history=History.empty(1, f.dtype), state=state)

    def capabilities(self, n: int) -> Capabilities:
        """The [`Capabilities`][jaxfric.optim.Capabilities] of a run on ``n`` parameters (plain Python
        values, known before tracing)."""
        return Capabilities()


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

    def capabilities(self, n: int) -> Capabilities:
        return Capabilities(max_steps=self.num_generations,
                            progress_totals=(self.num_generations, None))

    def progress(self, state) -> tuple[Array, Array]:
        """``(phase, step)`` for a progress display: phase 0 (a global stage), the generation."""
        return jnp.array(0, jnp.int32), state.generation

    def continued(self, state):
        """``state`` of a finished run, ready to go on under this solver's (larger)
        budget (``minimise(..., warm_start=solution)``)."""
        return state


class AbstractLocal(AbstractSolver):
    """A local solver run from one start (Nelder–Mead, an optimistix minimiser through
    [`OptxMinimiser`][jaxfric.optim.OptxMinimiser]): its state counts ``num_steps``, and a chain may size its
    first step from where a population converged."""

    def start_options(self, spread, lower, upper) -> dict | None:
        """Options for a run started where a population of per-coordinate standard
        deviation ``spread`` converged, passed to [`init_rounds`][jaxfric.optim.AbstractSolver.init_rounds] as
        ``options=`` (``None``: none)."""
        return None

    def progress(self, state) -> tuple[Array, Array]:
        """``(phase, step)`` for a progress display: phase 1 (a local stage), the step."""
        return jnp.array(1, jnp.int32), state.num_steps


class AbstractStaged(AbstractSolver):
    """A solver of several stages run one after another (a chain: global, then local;
    [`Capabilities.num_stages`][jaxfric.optim.Capabilities] of them). The loop runs stage ``s`` while
    [`stage`][jaxfric.optim.AbstractStaged.stage] says the state is in it."""

    @abc.abstractmethod
    def stage(self, state) -> Array:
        """The stage ``state`` is in (``0 .. num_stages − 1``)."""

    @abc.abstractmethod
    def progress(self, state) -> tuple[Array, Array]:
        """``(phase, step)`` for a progress display (phase 0 global, 1 local)."""

    @abc.abstractmethod
    def expected_evaluations(self, n: int, of: Callable) -> int | None:
        """Evaluations a run on ``n`` parameters is expected to take, its stages'
        ``of(stage_solver, n)`` combined (``None``: unknown); ``compiler_options="auto"``
        sizes a run's work with it."""

    def done(self, state) -> Array:
        """``finished(state)[0]`` alone, for the loop's test (a chain's result, traced
        and dropped there, is most of its ``finished``)."""
        return self.finished(state)[0]

    def continued(self, state):
        """A finished run of several stages is not continued (each stage has its own budget)."""
        raise ValueError("a finished run of several stages cannot be continued")


class AbstractStartDraws(AbstractSolver):
    """A solver whose start draws its random numbers from the key alone: ``start_draws``
    makes them by a program of their own, and [`jaxfric.minimise`][jaxfric.optim.minimise] passes them in
    with the key (``Drawn``), so a new objective's program leaves them out (issue 47)."""

    @abc.abstractmethod
    def start_draws(self, lower, upper, key):
        """What the start draws from ``key`` (a pure function of it and the shapes)."""


# ------------------------------------------- for the driver, the loop and the chains
#: The last record asked for: ``(solver, n, capabilities)``. A call of ``minimise`` asks
#: two or three times for the same solver, and a script often calls it again and again
#: with one solver object; a solver is immutable, so the record of the same object and
#: ``n`` is the same record. (Every ``capabilities`` call creates equinox's bound-method
#: modules, about 500 Python calls for a PSO and 1,500 for a chain.)
_LAST: list = [None]


def capabilities_of(solver: AbstractSolver, n: int) -> Capabilities:
    """``solver.capabilities(n)``, remembered for the last solver object asked."""
    last = _LAST[0]
    if last is not None and last[0] is solver and last[1] == n:
        return last[2]
    caps = solver.capabilities(n)
    _LAST[0] = (solver, n, caps)
    return caps


def stage_of(solver: AbstractSolver, state):
    """The stage ``state`` is in: [`AbstractStaged.stage`][jaxfric.optim.AbstractStaged.stage], else 0."""
    return solver.stage(state) if isinstance(solver, AbstractStaged) else 0


def progress_of(solver: AbstractSolver, state) -> tuple[Array, Array]:
    """``(phase, step)`` for a progress display (phase 0 a global stage, 1 a local one):
    the solver kind's own ``progress``, zeros for a solver of none of those kinds."""
    if isinstance(solver, (AbstractGenerational, AbstractLocal, AbstractStaged)):
        return solver.progress(state)
    return jnp.array(0, jnp.int32), jnp.array(0, jnp.int32)


def continued(solver: AbstractSolver, state):
    """``state`` of a finished run, ready to go on under ``solver``'s budget (a warm
    start): the kind's own ``continued``, else ``state`` as it is."""
    if isinstance(solver, (AbstractGenerational, AbstractStaged)):
        return solver.continued(state)
    return state


def optx_finished(done, result, capped):
    """optimistix's stopping rule for ``finished``: ``(stop, result)`` after a step whose
    ``terminate`` gave ``(done, result)``, the step cap reached where ``capped``
    (``nonlinear_max_steps_reached`` if the run stops there unconverged)."""
    stop = done | (result != RESULTS.successful) | capped
    return stop, RESULTS.where((result == RESULTS.successful) & ~done,
                               RESULTS.nonlinear_max_steps_reached, result)
