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

* [`drive`][jaxfric.optim.rounds.drive] runs rounds inside the compiled program: each batch is one call of the
  objective on the whole batch (a conditional one under ``lax.cond``), a [`Scan`][jaxfric.optim.Scan]
  one ``lax.scan``;
* [`compiled_start`][jaxfric.optim.rounds.compiled_start] / [`compiled_step`][jaxfric.optim.rounds.compiled_step] are a solver's start and step so run;
* [`ask`][jaxfric.optim.asktell.ask] / ``tell`` drive the same compiled
  run from Python, one needed batch per call ([`jaxfric.optim.asktell`][jaxfric.optim.asktell]).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Generator

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from ._base import batch_objective

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
    """``(evaluate, whole)`` for [`drive`][jaxfric.optim.rounds.drive]: the batched objective, and the same
    without the driver's device layout."""
    one = fn if getattr(fn, "layout", None) is None else eqx.tree_at(
        lambda f: f.layout, fn, None, is_leaf=lambda x: x is None)
    return batch_objective(fn, args), batch_objective(one, args)


class relay:
    """``rounds`` seen through ``request`` (applied to each [`Batch`][jaxfric.optim.Batch] it yields) and
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


def compiled_start(solver, fn, lower, upper, args, key, x0=None):
    """``solver``'s first state, its start's batches evaluated by ``fn`` (one call of the
    vectorised objective per batch)."""
    evaluate, whole = _objectives(fn, args)
    return drive(solver.init_rounds(lower, upper, key, x0, (fn, args)), evaluate, whole=whole)


def compiled_step(solver, fn, lower, upper, args, state, stage: int = 0):
    """``solver``'s state after one step of ``stage`` (static), evaluated by ``fn``."""
    evaluate, whole = _objectives(fn, args)
    return drive(solver.step_rounds(lower, upper, state, stage, (fn, args)), evaluate,
                 whole=whole)
