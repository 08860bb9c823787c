"""Evaluation rounds: one definition of a solver's evaluations serves the compiled run
and a run driven from Python by ``ask`` / ``tell``.

A solver writes its start and each of its steps as a Python *generator* ("rounds")
that yields every batch of points it needs evaluated and receives their values back,
one NaN-safe value per row (``f = yield X``). A batch may be conditional,
``f = yield Batch(X, needed)`` with a traced boolean ``needed`` (Nelder–Mead's second
trial point or shrink, the switch of a two-stage chain): when it is not needed nothing
is evaluated or counted and the generator receives ``+inf`` values. An inner loop is
``carry = yield Scan(body, carry, xs, length)``, ``body(carry, x)`` being rounds
(MAPSO's self-learning generations).

* :func:`drive` runs rounds inside the compiled program: each batch is one call of the
  objective on the whole batch (a conditional one under ``lax.cond``), a :class:`Scan`
  one ``lax.scan``;
* :meth:`AbstractBatchSolver.ask` / :meth:`~AbstractBatchSolver.tell` drive the same
  compiled run from Python, one needed batch per call (:mod:`jaxfric.optim.asktell`).
"""

from __future__ import annotations

import abc
import dataclasses
from typing import Any, Callable, Generator

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from . import asktell
from ._base import AbstractSolver, History, Solution, batch_objective, result_from_f

Rounds = Generator[Any, Any, Any]


class Batch(eqx.Module):
    """Points to evaluate (the rows of ``x``), only where ``needed`` (a boolean scalar;
    ``True``: always)."""

    x: Array
    needed: Any = True
    # a population may be split over the devices (jaxfric.optim.sharding); Nelder–Mead's
    # few points are evaluated whole, as optimistix's own step evaluates them
    split: bool = eqx.field(static=True, default=True)


@dataclasses.dataclass(frozen=True)
class Scan:
    """``length`` repetitions of the rounds ``body(carry, x)`` (which return the next
    carry) over the leading axis of ``xs``; yielding it gives back the last carry
    (``carry = yield Scan(...)``). Compiled, it is one ``lax.scan``; driven by
    ``ask``/``tell``, each repetition's batches are asked one after another (MAPSO's
    self-learning generations)."""

    body: Callable
    carry: Any
    xs: Any
    length: int


def _request(req):
    return req if isinstance(req, (Batch, Scan)) else Batch(req)


def skipped(x):
    """What a batch that is not needed gives back: ``+inf`` for every row."""
    return jnp.full((x.shape[0],), jnp.inf, x.dtype)


def _run(rounds: Rounds, handle: Callable):
    """Feed ``rounds`` ``handle(batch)`` for every batch it yields; its result."""
    out = None
    while True:
        try:
            req = rounds.send(out)
        except StopIteration as stop:
            return stop.value
        out = handle(_request(req))


def drive(rounds: Rounds, evaluate: Callable, skip: Callable = skipped,
          whole: Callable | None = None):
    """Run ``rounds`` to the end inside a compiled program, evaluating each batch it
    yields with ``evaluate`` (``whole`` for a batch that is not to be split over
    devices; a conditional batch under ``lax.cond``, ``skip`` otherwise); returns the
    generator's result."""
    def handle(b):
        if isinstance(b, Scan):
            def body(carry, x):
                return drive(b.body(carry, x), evaluate, skip, whole), None

            return jax.lax.scan(body, b.carry, b.xs, length=b.length)[0]
        ev = evaluate if b.split or whole is None else whole
        return ev(b.x) if b.needed is True else jax.lax.cond(b.needed, ev, skip, b.x)

    return _run(rounds, handle)


def _objectives(fn, args):
    """``(evaluate, whole)`` for :func:`drive`: the batched objective, and the same
    without the driver's device layout."""
    one = fn if getattr(fn, "layout", None) is None else eqx.tree_at(
        lambda f: f.layout, fn, None, is_leaf=lambda x: x is None)
    return batch_objective(fn, args), batch_objective(one, args)


class relay:
    """``rounds`` seen through ``request`` (applied to each :class:`Batch` it yields) and
    ``answer`` (applied to each value sent back); use as ``yield from relay(...)``."""

    def __init__(self, rounds: Rounds, request: Callable | None = None,
                 answer: Callable | None = None):
        self.rounds, self.request, self.answer, self.started = rounds, request, answer, False
        self.scanned = False

    def __iter__(self):
        return self

    def __next__(self):
        return self.send(None)

    def send(self, value):
        if self.started and self.answer is not None and not self.scanned:
            value = self.answer(value)  # a Scan gives back its carry, not values
        self.started = True
        b = _request(self.rounds.send(value))  # its StopIteration carries the result
        self.scanned = isinstance(b, Scan)
        if self.scanned:
            body, request, answer = b.body, self.request, self.answer
            return dataclasses.replace(b, body=lambda c, x: relay(body(c, x), request, answer))
        return b if self.request is None else self.request(b)


def only_if(need, rounds: Rounds) -> Rounds:
    """``rounds`` with every batch needed only where ``need`` (its result is then
    meaningless unless ``need``: the caller selects)."""
    return relay(rounds, request=lambda b: Batch(b.x, need if b.needed is True
                                                 else need & b.needed, b.split))


class AbstractBatchSolver(AbstractSolver):
    """The contract of a jaxfric solver on a box (docs/solvers.md): its evaluations come
    in rounds (see the module docstring). It gives

    * :meth:`init_rounds` and :meth:`step_rounds`: the start and one step, as rounds;
    * :meth:`terminate`: ``(done, result)``, a boolean scalar and an ``optimistix.RESULTS``;
    * :meth:`best`: ``(x, f)``, the best point so far and its (NaN-safe) value;
    * :meth:`num_evals`: the objective evaluations spent so far;

    and gets ``init``/``step`` (compiled, each batch one call of the objective) and
    ``ask``/``tell`` (from Python) from them. Every method is pure and traceable;
    ``lower`` and ``upper`` are 1-D arrays of one floating dtype (the driver flattens
    pytree bounds) and the state is a pytree of arrays (what a checkpoint stores). The
    driver (:mod:`jaxfric.optim.loop`) records ``best(state)[1]`` against
    ``num_evals(state)`` after every step and reports :meth:`progress`. The other
    methods are optional capabilities with defaults (and :class:`AbstractSolver`'s).

    ``objective`` is ``(fn, args)`` in a compiled run, ``None`` under ask/tell: with it
    inner loops may run as ``lax.scan`` (MAPSO's self-learning) and a minimiser that
    evaluates by itself (an optimistix gradient method) can run at all.
    """

    @abc.abstractmethod
    def init_rounds(self, lower, upper, key, x0=None, objective=None) -> Rounds:
        """Rounds of the start (``x0``: an optional start inside the box); returns the
        first state."""

    @abc.abstractmethod
    def step_rounds(self, lower, upper, state, stage: int = 0, objective=None) -> Rounds:
        """Rounds of one step of ``stage`` (static), which ``state`` is in; returns the
        new state."""

    @abc.abstractmethod
    def terminate(self, fn: Callable, lower, upper, args, state):
        """``(done, result)``: a boolean scalar and an ``optimistix.RESULTS``."""

    @abc.abstractmethod
    def best(self, state) -> tuple[Array, Array]:
        """``(x, f)``: the best point so far and its (NaN-safe) value."""

    @abc.abstractmethod
    def num_evals(self, state) -> Array:
        """Objective evaluations spent so far."""

    def postprocess(self, fn: Callable, lower, upper, args, state, result) -> Solution:
        """The :class:`Solution` (flat ``value``; the driver adds the history)."""
        x, f = self.best(state)
        return Solution(value=x, f=f, result=result, stats={"num_evals": self.num_evals(state)},
                        history=History.empty(1, f.dtype), state=state)

    def max_steps(self, n: int) -> int:
        """Most steps a run on ``n`` parameters can take (the driver's cap)."""
        steps = self.steps_for(n)
        return int(steps) if steps is not None else 2**31 - 1

    def max_evaluations(self, n: int) -> int | None:
        """Most objective evaluations of a run (``None`` if unknown): checked by the
        driver against the evaluation counter's range before running."""
        return None

    def num_stages(self) -> int:
        """Stages run one after another (a two-stage :func:`~jaxfric.optim.chained.chain`
        has 2). The driver runs each in a loop of its own, so batched runs never pay
        for one stage's step while in another."""
        return 1

    def stage(self, state) -> Array:
        """The stage ``state`` is in (``0 .. num_stages() − 1``)."""
        return jnp.array(0, jnp.int32)

    def continued(self, state):
        """``state`` of a finished run, ready to go on under this solver's (larger)
        budget (``minimise(..., warm_start=solution)``)."""
        return state

    def progress(self, state) -> tuple[Array, Array]:
        """``(phase, step)`` for a progress display: phase 0 a global (swarm) stage,
        phase 1 a local (Nelder–Mead) stage; ``step`` counts within the phase."""
        return jnp.array(0, jnp.int32), jnp.array(0, jnp.int32)

    def check_ask_tell(self) -> None:
        """Raise ``ValueError`` if ``ask``/``tell`` cannot drive this solver."""

    # ------------------------------------------------------------ compiled protocol
    def init(self, fn, lower, upper, args, key, x0=None):
        evaluate, whole = _objectives(fn, args)
        return drive(self.init_rounds(lower, upper, key, x0, (fn, args)), evaluate,
                     whole=whole)

    def step(self, fn, lower, upper, args, state):
        return self.step_stage(fn, lower, upper, args, state, 0)

    def step_stage(self, fn, lower, upper, args, state, stage: int):
        evaluate, whole = _objectives(fn, args)
        return drive(self.step_rounds(lower, upper, state, stage, (fn, args)), evaluate,
                     whole=whole)

    # ------------------------------------------------------------------- ask / tell
    def ask_init(self, lower, upper, key, x0=None) -> asktell.AskTellState:
        """Start a run driven from Python (:mod:`jaxfric.optim.asktell`). ``lower`` /
        ``upper``: 1-D bounds (their dtype is the search dtype, as in
        :func:`jaxfric.minimise`); ``key``: a PRNG key or an int seed; ``x0``: an
        optional start (swarms: or an initial population)."""
        self.check()
        self.check_ask_tell()
        return asktell.start(self, lower, upper, key, x0)

    def ask(self, st: asktell.AskTellState):
        """``(X, st)``: the points (rows) whose values :meth:`tell` needs next."""
        return asktell.ask(st)

    def tell(self, st: asktell.AskTellState, X, f) -> asktell.AskTellState:
        """Give the values ``f`` of the rows ``X`` returned by :meth:`ask` (NaN and inf
        count as the worst value); returns the state asking for the next batch."""
        return asktell.tell(st, X, f)

    def ask_done(self, st: asktell.AskTellState) -> bool:
        """Whether the run has finished (by the rule the compiled run stops on)."""
        return asktell.done(st)

    def ask_result(self, st: asktell.AskTellState) -> Solution:
        """The :class:`Solution` (flat ``value``): what :func:`jaxfric.minimise` returns
        for the same key once the run has finished; before, the best point told so far."""
        return asktell.result(st)


class AbstractGenerational(AbstractBatchSolver):
    """A population solver that runs ``num_generations`` generations (swarms, evosax
    strategies). Its state has ``generation`` and ``num_evals``; :meth:`best` gives the
    best point; :meth:`stopped` an optional earlier end."""

    num_generations: eqx.AbstractVar[int]

    def stopped(self, state):
        """Whether the run ends before ``num_generations`` (default: never)."""
        return False

    def terminate(self, fn, lower, upper, args, state):
        done = (state.generation >= self.num_generations) | self.stopped(state)
        return done, result_from_f(self.best(state)[1])

    def postprocess(self, fn, lower, upper, args, state, result) -> Solution:
        x, f = self.best(state)
        return Solution(
            value=x, f=f, result=result,
            stats={"num_steps": state.generation, "num_evals": state.num_evals},
            history=History.empty(1, f.dtype), state=state,
        )

    def num_evals(self, state):
        return state.num_evals

    def max_steps(self, n: int) -> int:
        return self.num_generations

    def progress(self, state):
        return jnp.array(0, jnp.int32), state.generation

    def progress_totals(self):
        return self.num_generations, None
