"""Evaluation rounds: one definition of a solver's evaluations serves the compiled run
and a run driven from Python by ``ask`` / ``tell`` (issue 15 item 1).

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
* :meth:`AbstractAskTellSolver.ask` / :meth:`~AbstractAskTellSolver.tell` run the same
  rounds from Python with values computed anywhere (an external simulator, NumPy), one
  needed batch per call. The run visits the points :func:`jaxfric.minimise` visits for
  the same key, with the same evaluation count, and switches stages by the same rule.
  Each kind of round (the start, a step of each stage) is one compiled program that
  takes a value for every batch of the round (:func:`feed`; a :class:`Scan` is a
  ``lax.scan`` there too), so ask/tell compiles about as much as :func:`jaxfric.minimise`.

Every solver built on :class:`AbstractAskTellSolver` has ``ask``/``tell``: PSO, MAPSO,
:class:`~jaxfric.optim.Evosax`, Nelder–Mead (``OptxMinimiser(NelderMead())``, the view
:func:`jaxfric.minimise` runs it through) and the two-stage chains (MAPSO–NMDS, ``chain(PSO(), NelderMead())``, ``cmaes_nm()``). During a
chain's global stage ``ask`` returns the population (MAPSO: then its self-learning
batches); during the Nelder–Mead stage the first simplex (``n + 1`` points), then each
step's trial points: the reflection, then at most one more point or a shrink's ``n``
points under the sequential rule, or the four trial points at once with
``NelderMead(batched_trials=True)``. Example, with an objective JAX cannot trace::

    solver = jaxfric.mapso_nmds(num_generations=50)
    st = solver.ask_init(lower, upper, jax.random.key(0))
    while not solver.ask_done(st):
        X, st = solver.ask(st)                        # (k, n) points
        st = solver.tell(st, X, [simulate(x) for x in np.asarray(X)])
    solution = solver.ask_result(st)                  # as minimise's, flat value

``tell`` needs one value per row of the batch ``ask`` gave (else ``ValueError``); NaN
and inf count as the worst value and never become the best.
"""

from __future__ import annotations

import abc
import dataclasses
from typing import Any, Callable, Generator

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from ._base import (
    AbstractIterativeSolver,
    History,
    Solution,
    batch_objective,
    result_from_f,
    safe_value,
)
from .problem import check_key

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


def _slice(xs, j):
    return jax.tree_util.tree_map(lambda a: a[j], xs)


def _unrolled(handle: Callable) -> Callable:
    """``handle`` for batches, with every :class:`Scan` run as a Python loop."""
    def h(req):
        if not isinstance(req, Scan):
            return handle(req)
        carry = req.carry
        for j in range(req.length):
            carry = _run(req.body(carry, _slice(req.xs, j)), h)
        return carry

    return h


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


def feed(rounds: Rounds, told: tuple):
    """Run ``rounds`` to the end feeding batch ``k`` the values ``told[k]`` (what a
    batch that was not needed gets: ``+inf``), a :class:`Scan`'s batches as one
    ``lax.scan`` over their values. Returns every batch it asked for, in order, and the
    generator's result. Batch ``k`` depends only on ``told[:k]``, so the batches up to
    the first value not yet known are exact whatever stands in for the later ones."""
    take = _taker(told)
    asked: list = []
    result = _feed(rounds, take, asked)
    if take.left():
        raise _LayoutChanged
    return asked, result


def _taker(values):
    """The values one by one (``_LayoutChanged`` past the end); at the end, ``.left()``
    tells whether any were not taken."""
    it = iter(values)

    def take():
        f = next(it, None)
        if f is None:
            raise _LayoutChanged
        return f

    take.left = lambda: next(it, None) is not None
    return take


def _feed(rounds: Rounds, take: Callable, asked: list):
    def handle(b):
        if isinstance(b, Scan):
            return _feed_scan(b, take, asked)
        f = take()
        if f.shape != (b.x.shape[0],):
            raise _LayoutChanged
        asked.append(b)
        return f

    return _run(rounds, handle)


def _feed_scan(scan: Scan, take: Callable, asked: list):
    """A :class:`Scan` fed its values: ``m`` batches a repetition, the ``j``-th value of
    every repetition stacked into one array the scan runs over."""
    if scan.length == 0:
        return scan.carry  # what lax.scan gives
    m = _batches_per_repetition(scan)
    columns = list(zip(*[[take() for _ in range(m)] for _ in range(scan.length)])) if m else []
    if any(len({f.shape for f in col}) != 1 for col in columns):
        raise _LayoutChanged
    stacked = tuple(jnp.stack(col) for col in columns)

    def body(carry, xf):
        x, fs = xf
        inner: list = []
        take_rep = _taker(fs)
        carry = _feed(scan.body(carry, x), take_rep, inner)
        if len(inner) != m or take_rep.left():
            raise _LayoutChanged
        return carry, (tuple(b.x for b in inner), tuple(jnp.asarray(b.needed) for b in inner))

    carry, (xs, needed) = jax.lax.scan(body, scan.carry, (scan.xs, stacked), length=scan.length)
    for j in range(scan.length):
        asked.extend(Batch(x[j], n[j]) for x, n in zip(xs, needed))
    return carry


def _batches_per_repetition(scan: Scan) -> int:
    """How many batches one repetition of ``scan`` asks for (traced, not compiled)."""
    x = jax.tree_util.tree_map(lambda a: jax.ShapeDtypeStruct(a.shape[1:], a.dtype), scan.xs)
    return len(jax.eval_shape(_asked(scan.body), scan.carry, x))


def _asked(make_rounds: Callable) -> Callable:
    """A function of ``make_rounds``' arguments that gives the points of every batch its
    rounds ask for (each told ``+inf``, a :class:`Scan` unrolled): trace it with
    ``eval_shape`` to learn a round's batches without compiling it."""
    def batches(*args):
        asked = []

        def handle(b):
            asked.append(b.x)
            return skipped(b.x)

        _run(make_rounds(*args), _unrolled(handle))
        return asked

    return batches


class _LayoutChanged(Exception):
    """The round asked for other batches than the layout it was given."""


class _Pending(Exception):
    def __init__(self, batch):
        self.batch = batch


def replay(rounds: Rounds, told: tuple, skip: Callable = skipped):
    """Feed ``rounds`` the values ``told`` (``None``: a batch that was not needed).
    Returns ``(batch, None)`` for the next :class:`Batch` it asks for, or
    ``(None, result)`` once it has finished. (0.7's ask/tell helper, kept for its
    import path; ask/tell now runs whole rounds with :func:`feed`.)"""
    values = iter(told)

    def handle(b):
        f = next(values, _Pending)
        if f is _Pending:
            raise _Pending(b)
        return skip(b.x) if f is None else f

    try:
        return None, _run(rounds, _unrolled(handle))
    except _Pending as pending:
        return pending.batch, None


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


class AskTellState(eqx.Module):
    """A run driven by :meth:`AbstractAskTellSolver.ask` / ``tell``: the solver's state
    (``None`` until the start has been told), the box, the key, the optional start,
    the values told so far within the current round, the batch waiting for values
    (``None`` once the run has finished), the stage the state is in and the batches of
    each kind of round met so far."""

    state: Any
    lower: Array
    upper: Array
    key: Any
    x0: Any = None
    told: tuple = ()
    pending: Any = None
    stage: int | None = eqx.field(static=True, default=None)
    # (kind, ((rows, dtype), ...)): the batches of each kind of round met so far
    layouts: tuple = eqx.field(static=True, default=())

    @property
    def swarm(self):
        """The solver's state (the name of 0.7's swarm-only ask/tell)."""
        return self.state


class AbstractAskTellSolver(AbstractIterativeSolver):
    """A solver whose evaluations come in rounds (see the module docstring): it gives
    :meth:`init_rounds` and :meth:`step_rounds`, and gets ``init``/``step`` (compiled,
    each batch one call of the objective) and ``ask``/``tell`` (from Python) from them.

    ``objective`` is ``(fn, args)`` in a compiled run, ``None`` under ask/tell: with it
    inner loops may run as ``lax.scan`` (MAPSO's self-learning) and a minimiser that
    evaluates by itself (an optimistix gradient method) can run at all.
    """

    @abc.abstractmethod
    def init_rounds(self, lower, upper, key, x0=None, objective=None) -> Rounds:
        """Rounds of the start; returns the first state."""

    @abc.abstractmethod
    def step_rounds(self, lower, upper, state, stage: int = 0, objective=None) -> Rounds:
        """Rounds of one step of ``stage`` (static), which ``state`` is in; returns the
        new state."""

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
    def ask_init(self, lower, upper, key, x0=None) -> AskTellState:
        """Start a run driven from Python. ``lower``/``upper``: 1-D bounds (their dtype
        is the search dtype, as in :func:`jaxfric.minimise`); ``key``: a PRNG key or an
        int seed; ``x0``: an optional start (swarms: or an initial population)."""
        self.check()
        self.check_ask_tell()
        lower, upper = jnp.asarray(lower), jnp.asarray(upper)
        if lower.ndim != 1 or lower.shape != upper.shape or lower.shape[0] == 0:
            raise ValueError(f"ask_init needs 1-D lower and upper bounds of one length, got "
                             f"shapes {lower.shape} and {upper.shape}")
        if not bool(jnp.all(lower < upper)):
            raise ValueError("every lower bound must be < its upper bound")
        if not jnp.issubdtype(lower.dtype, jnp.floating):
            lower, upper = lower.astype(float), upper.astype(float)
        upper = upper.astype(lower.dtype)
        key = check_key(key)
        x0 = None if x0 is None else jnp.asarray(x0, lower.dtype)
        return self._advance(AskTellState(None, lower, upper, key, x0))

    def ask(self, st: AskTellState):
        """``(X, st)``: the points (rows) whose values :meth:`tell` needs next."""
        if st.pending is None:
            raise ValueError("the run has finished (ask_done is True): read ask_result")
        return st.pending, st

    def tell(self, st: AskTellState, X, f) -> AskTellState:
        """Give the values ``f`` of the rows ``X`` returned by :meth:`ask` (NaN and inf
        count as the worst value); returns the state asking for the next batch."""
        if st.pending is None:
            raise ValueError("the run has finished (ask_done is True): nothing to tell")
        if tuple(jnp.shape(X)) != tuple(st.pending.shape):
            raise ValueError(f"tell needs the batch ask returned, of shape {st.pending.shape}, "
                             f"got shape {tuple(jnp.shape(X))}")
        f = safe_value(jnp.asarray(f, st.lower.dtype))
        if f.shape != (st.pending.shape[0],):
            raise ValueError(f"tell needs one fitness value per candidate: got shape "
                             f"{f.shape} for {st.pending.shape[0]} candidates")
        return self._advance(dataclasses.replace(st, told=st.told + (f,), pending=None))

    def ask_done(self, st: AskTellState) -> bool:
        """Whether the run has finished (by the rule the compiled run stops on)."""
        return st.pending is None

    def ask_result(self, st: AskTellState) -> Solution:
        """The :class:`Solution` so far (flat ``value``; the history holds its last entry)."""
        if st.state is None:
            raise ValueError("no result before the first batch has been told")
        return _result_jit(self, st.state, st.lower, st.upper)

    def _advance(self, st: AskTellState) -> AskTellState:
        """Bring the run to the next batch that is needed (a batch that is not needed is
        told ``+inf``, what the compiled run's ``lax.cond`` gives, and passed over),
        starting the next round whenever one finishes and the run goes on.

        A round is one compiled program per kind (the start, or a step of a stage): it
        takes a value for every batch of the round, the ones told so far and ``+inf``
        for the rest, and gives every batch. Batch ``k`` depends only on the values of
        the batches before it, so the first batch not yet told is exact, and once every
        batch is told so is the new state. (Until 0.8.1 each position in a round was its
        own program replaying the batches before it: a dozen compilations per MAPSO
        step, each larger than the last.)"""
        while True:
            kind = _kind(st)
            layout = dict(st.layouts).get(kind)
            fresh = layout is None
            if fresh:
                layout = _layout(self, st)
                st = dataclasses.replace(st, layouts=st.layouts + ((kind, layout),))
            k = k0 = len(st.told)
            rest = tuple(jnp.asarray(np.full((rows,), np.inf, dtype)) for rows, dtype in layout[k:])
            try:
                xs, needed, state, done, stage = _round_jit(
                    self, st.state, st.lower, st.upper, st.key, st.x0, st.stage,
                    st.told + rest)
            except _LayoutChanged:  # the round's batches differ from last time: look again
                if fresh:
                    raise RuntimeError(f"ask/tell: the batches of {type(self).__name__}'s "
                                       f"round {kind!r} change as it runs") from None
                st = dataclasses.replace(st, layouts=tuple(
                    (kd, lay) for kd, lay in st.layouts if kd != kind))
                continue
            needed = np.asarray(needed)
            while k < len(layout) and not needed[k]:
                st = dataclasses.replace(st, told=st.told + (rest[k - k0],))
                k += 1
            if k < len(layout):
                return dataclasses.replace(st, pending=xs[k])
            st = AskTellState(state, st.lower, st.upper, st.key, st.x0, stage=int(stage),
                              layouts=st.layouts)
            if bool(done):
                return st


def _kind(st: AskTellState):
    return "init" if st.state is None else ("step", st.stage)


def _rounds(solver: AbstractAskTellSolver, state, lower, upper, key, x0, stage) -> Rounds:
    if state is None:
        return solver.init_rounds(lower, upper, key, x0)
    return solver.step_rounds(lower, upper, state, stage)


def _layout(solver: AbstractAskTellSolver, st: AskTellState) -> tuple:
    """``(rows, dtype)`` of every batch of the round ``st`` is in (traced, not compiled)."""
    rounds = _asked(lambda *args: _rounds(solver, *args, st.stage))
    shapes = eqx.filter_eval_shape(rounds, st.state, st.lower, st.upper, st.key, st.x0)
    return tuple((x.shape[0], x.dtype) for x in shapes)


@eqx.filter_jit
def _round_jit(solver: AbstractAskTellSolver, state, lower, upper, key, x0, stage, told):
    asked, new = feed(_rounds(solver, state, lower, upper, key, x0, stage), told)
    needed = jnp.stack([jnp.asarray(b.needed) for b in asked]) if asked else jnp.zeros(0, bool)
    done = solver.terminate(None, lower, upper, None, new)[0]
    return tuple(b.x for b in asked), needed, new, done, solver.stage(new)


@eqx.filter_jit
def _result_jit(solver: AbstractAskTellSolver, state, lower, upper) -> Solution:
    _, result = solver.terminate(None, lower, upper, None, state)
    sol = solver.postprocess(None, lower, upper, None, state, result)
    _, f = solver.best(state)
    hist = History.from_arrays(jnp.asarray(solver.num_evals(state))[None], f[None])
    return eqx.tree_at(lambda t: t.history, sol, hist)


class AbstractGenerational(AbstractAskTellSolver):
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
