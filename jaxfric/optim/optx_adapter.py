"""A foreign ``optimistix.AbstractMinimiser`` (BFGS, optimistix's own Nelder–Mead, ...)
seen through jaxfric's solver contract. jaxfric's [`NelderMead`][jaxfric.optim.NelderMead] needs no
adapter: it is a jaxfric solver itself.

The adapter runs the minimiser's own ``init / step / terminate / postprocess`` exactly
as ``optimistix.minimise`` does (the same termination test, on the same iterate, and
the same "max steps reached" rule), so a run under [`jaxfric.minimise`][jaxfric.optim.minimise] equals
``optx.minimise(..., throw=False)`` for the same start. Box bounds reach it as
``options={"lower": ..., "upper": ...}`` (solvers that ignore them search unbounded).
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from ._base import RESULTS, History, Solution, count_dtype, safe_value, uniform_in_box
from .contract import AbstractLocal, AbstractSolver, Capabilities, optx_finished

_TAGS = frozenset()

#: The step cap of a minimiser that gives none, as in ``optimistix.minimise``'s default.
DEFAULT_STEPS = 1000


class OptxState(eqx.Module):
    """The minimiser's iterate ``y`` and state, optimistix's loop flags, the value at
    ``y`` and the evaluations spent on it."""

    y: Any
    inner: Any
    num_steps: Any
    done: Any
    result: RESULTS
    f: Any
    extra_evals: Any


def _with_aux(fn):
    return lambda y, args: (fn(y, args), None)


def _all_finite(y):
    return jnp.all(jnp.isfinite(y))


class OptxMinimiser(AbstractLocal):
    """Adapter: ``minimiser`` (a foreign ``optx.AbstractMinimiser``) as a jaxfric solver.

    Args:
        minimiser: the optimistix minimiser.
        steps: step cap (``None``: 1000, ``optimistix.minimise``'s default).
    """

    minimiser: optx.AbstractMinimiser
    steps: int | None = None

    def check(self):
        if isinstance(self.minimiser, AbstractSolver):
            raise ValueError(
                f"{type(self.minimiser).__name__} is a jaxfric solver: pass it to minimise "
                "or chain directly, not through OptxMinimiser")

    def _step_cap(self) -> int:
        return self.steps if self.steps is not None else DEFAULT_STEPS

    def capabilities(self, n: int) -> Capabilities:
        # batches_runs: its steps branch on the iterate; vmap would compute every branch
        return Capabilities(max_steps=self._step_cap(), batches_runs=False,
                            progress_totals=(None, self.steps),
                            ask_tell_refused=self._refusal())

    def _options(self, lower, upper, extra=None):
        return {"lower": lower, "upper": upper, **(extra or {})}

    def _refusal(self) -> str:
        return (f"ask/tell cannot drive {type(self.minimiser).__name__}: it evaluates its "
                "objective itself (one point at a time, or with gradients); ask/tell drives "
                "solvers that evaluate in batches: PSO, MAPSO, Evosax, NelderMead and chains "
                "of them")

    def _objective(self, objective):
        if objective is None:
            raise ValueError(self._refusal())
        return objective

    def _terminate(self, y, opts, inner, objective):
        fn, args = self._objective(objective)
        done, result = self.minimiser.terminate(_with_aux(fn), y, args, opts, inner, _TAGS)
        return done, RESULTS.where(_all_finite(y), result, RESULTS.nonfinite)

    def _value(self, objective, y):
        fn, args = self._objective(objective)
        return safe_value(fn(y, args))

    def init_rounds(self, lower, upper, key, x0=None, objective=None, options=None):
        """``options``: extra optimistix options."""
        if x0 is None:
            x0 = uniform_in_box(key, lower.shape, lower, upper)
        elif x0.ndim != 1:
            raise ValueError("an optimistix minimiser takes one start y0, not a population")
        fn, args = self._objective(objective)
        opts = self._options(lower, upper, options)
        f_struct = jax.ShapeDtypeStruct((), x0.dtype)
        inner = self.minimiser.init(_with_aux(fn), x0, args, opts, f_struct, None, _TAGS)
        done, result = self._terminate(x0, opts, inner, objective)
        return OptxState(x0, inner, jnp.array(0, jnp.int32), done, result,
                         self._value(objective, x0), jnp.array(1, count_dtype()))
        yield  # a generator with no batches: the minimiser evaluates by itself

    def step_rounds(self, lower, upper, state, stage=0, objective=None):
        fn, args = self._objective(objective)
        opts = self._options(lower, upper)
        y, inner, _ = self.minimiser.step(_with_aux(fn), state.y, args, opts, state.inner,
                                          _TAGS)
        # optimistix tests termination on the iterate the step started from
        done, result = self._terminate(state.y, opts, inner, objective)
        return OptxState(y, inner, state.num_steps + 1, done, result, self._value(objective, y),
                         state.extra_evals + 1)
        yield  # a generator with no batches: the minimiser evaluates by itself

    def finished(self, state):
        return optx_finished(state.done, state.result, state.num_steps >= self._step_cap())

    def solution(self, fn, lower, upper, args, state, result) -> Solution:
        opts = self._options(lower, upper)
        y, _, stats = self.minimiser.postprocess(
            _with_aux(fn), state.y, None, args, opts, state.inner, _TAGS, result)
        stats = {**stats, "num_steps": state.num_steps, "num_evals": self.num_evals(state)}
        return Solution(value=y, f=state.f, result=result, stats=stats,
                        history=History.empty(1, state.f.dtype), state=state)

    def best(self, state):
        return state.y, state.f

    def num_evals(self, state):
        return state.extra_evals


def as_protocol(solver) -> AbstractSolver:
    """The jaxfric solver for ``solver`` (a jaxfric solver, or a foreign optimistix
    minimiser wrapped in [`OptxMinimiser`][jaxfric.optim.OptxMinimiser])."""
    if isinstance(solver, AbstractSolver):
        return solver
    if isinstance(solver, optx.AbstractMinimiser):
        return OptxMinimiser(solver)
    raise ValueError(
        "solver must be a jaxfric solver (PSO, MAPSO, NelderMead, MAPSONMDS, chain(...)) "
        f"or an optimistix minimiser, got {type(solver).__name__}"
    )
