"""Any ``optimistix.AbstractMinimiser`` (jaxfric's :class:`~jaxfric.NelderMead`, or
optimistix's own) seen through jaxfric's step protocol.

The adapter runs the minimiser's own ``init / step / terminate / postprocess`` exactly
as ``optimistix.minimise`` does (the same termination test, on the same iterate, and
the same "max steps reached" rule), so a run under :func:`jaxfric.minimise` equals
``optx.minimise(..., throw=False)`` for the same start. Box bounds reach it as
``options={"lower": ..., "upper": ...}`` (solvers that ignore them search unbounded).
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from ._base import (
    RESULTS,
    AbstractSolver,
    History,
    Solution,
    count_dtype,
    safe_value,
    uniform_in_box,
)
from .nelder_mead import NelderMead, NelderMeadState
from .rounds import AbstractBatchSolver, Batch, relay

_TAGS = frozenset()


class OptxState(eqx.Module):
    """The minimiser's iterate ``y`` and state, optimistix's loop flags, and the best
    value (read from a :class:`NelderMeadState`, else evaluated at ``y``)."""

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


def _no_aux(rounds):
    """Nelder–Mead's rounds (which receive ``(f, aux)``) fed values without aux."""
    return relay(rounds, request=lambda b: Batch(b.x, b.needed, split=False),
                 answer=lambda f: (f, None))


class OptxMinimiser(AbstractBatchSolver):
    """Adapter: ``minimiser`` (an ``optx.AbstractMinimiser``) as a jaxfric solver.

    Args:
        minimiser: the optimistix minimiser.
        steps: step cap; ``None`` takes the minimiser's own (``NelderMead``: 200·n),
            else 1000.
    """

    minimiser: optx.AbstractMinimiser
    steps: int | None = None

    def check(self):
        if isinstance(self.minimiser, AbstractSolver):
            self.minimiser.check()

    def max_steps(self, n: int) -> int:
        if self.steps is not None:
            return self.steps
        if isinstance(self.minimiser, AbstractSolver):
            own = self.minimiser.steps_for(n)
            if own is not None:
                return int(own)
        return 1000

    def max_evaluations(self, n: int) -> int | None:
        if isinstance(self.minimiser, NelderMead):
            worst = (n + 1) + self.max_steps(n) * (n + 2)  # a shrink costs n + 2
            if self.minimiser.max_evals is not None:
                worst = min(worst, self.minimiser.max_evals + n + 2)
            return worst
        return None

    def progress_totals(self):
        return None, self.steps if self.steps is not None else (
            self.minimiser.max_steps if isinstance(self.minimiser, NelderMead) else None)

    def start_options(self, spread, lower, upper):
        if isinstance(self.minimiser, AbstractSolver):
            return self.minimiser.start_options(spread, lower, upper)
        return None

    def _options(self, lower, upper, extra=None):
        return {"lower": lower, "upper": upper, **(extra or {})}

    def check_ask_tell(self):
        if not isinstance(self.minimiser, NelderMead):
            self._objective(None)

    def _objective(self, objective):
        if objective is None:
            raise ValueError(
                f"ask/tell cannot drive {type(self.minimiser).__name__}: it evaluates its "
                "objective itself (one point at a time, or with gradients); ask/tell drives "
                "solvers that evaluate in batches: PSO, MAPSO, Evosax, NelderMead and chains "
                "of them")
        return objective

    def _best_f(self, objective, y, inner):
        if isinstance(inner, NelderMeadState):
            return inner.f_simplex[0], 0
        fn, args = self._objective(objective)
        return safe_value(fn(y, args)), 1

    def _terminate(self, y, opts, inner, objective):
        fn, args = (None, None) if objective is None else objective
        done, result = self.minimiser.terminate(_with_aux(fn), y, args, opts, inner, _TAGS)
        return done, RESULTS.where(_all_finite(y), result, RESULTS.nonfinite)

    def init_rounds(self, lower, upper, key, x0=None, objective=None, options=None):
        """``options``: extra optimistix options (``NelderMead``: ``"initial_step"``)."""
        if x0 is None:
            x0 = uniform_in_box(key, lower.shape, lower, upper)
        elif x0.ndim != 1:
            raise ValueError("an optimistix minimiser takes one start y0, not a population")
        opts = self._options(lower, upper, options)
        if isinstance(self.minimiser, NelderMead):
            inner = yield from _no_aux(self.minimiser.init_rounds(x0, opts))
        else:
            fn, args = self._objective(objective)
            f_struct = jax.ShapeDtypeStruct((), x0.dtype)
            inner = self.minimiser.init(_with_aux(fn), x0, args, opts, f_struct, None, _TAGS)
        done, result = self._terminate(x0, opts, inner, objective)
        f, extra = self._best_f(objective, x0, inner)
        return OptxState(x0, inner, jnp.array(0, jnp.int32), done, result, f,
                         jnp.array(extra, count_dtype()))

    def step_rounds(self, lower, upper, state, stage=0, objective=None):
        opts = self._options(lower, upper)
        if isinstance(self.minimiser, NelderMead):
            y, inner, _ = yield from _no_aux(self.minimiser.step_rounds(state.inner, opts))
        else:
            fn, args = self._objective(objective)
            y, inner, _ = self.minimiser.step(_with_aux(fn), state.y, args, opts, state.inner,
                                              _TAGS)
        # optimistix tests termination on the iterate the step started from
        done, result = self._terminate(state.y, opts, inner, objective)
        f, extra = self._best_f(objective, y, inner)
        return OptxState(y, inner, state.num_steps + 1, done, result, f,
                         state.extra_evals + extra)

    def terminate(self, fn, lower, upper, args, state):
        capped = state.num_steps >= self.max_steps(lower.shape[0])
        stop = state.done | (state.result != RESULTS.successful) | capped
        result = RESULTS.where(
            (state.result == RESULTS.successful) & ~state.done,
            RESULTS.nonlinear_max_steps_reached, state.result,
        )
        return stop, result

    def postprocess(self, fn, lower, upper, args, state, result) -> Solution:
        opts = self._options(lower, upper)
        y, _, stats = self.minimiser.postprocess(
            _with_aux(fn), state.y, None, args, opts, state.inner, _TAGS, result)
        stats = {**stats, "num_steps": state.num_steps, "num_evals": self.num_evals(state)}
        return Solution(value=y, f=state.f, result=result, stats=stats,
                        history=History.empty(1, state.f.dtype), state=state)

    def best(self, state):
        if isinstance(state.inner, NelderMeadState):
            return state.inner.simplex[0], state.inner.f_simplex[0]
        return state.y, state.f

    def num_evals(self, state):
        if isinstance(state.inner, NelderMeadState):
            return state.inner.num_evals.astype(count_dtype()) + state.extra_evals
        return state.extra_evals

    def progress(self, state):
        return jnp.array(1, jnp.int32), state.num_steps


def as_protocol(solver) -> AbstractBatchSolver:
    """The step-protocol view of ``solver`` (a jaxfric solver or an optimistix minimiser)."""
    if isinstance(solver, AbstractBatchSolver):
        return solver
    if isinstance(solver, optx.AbstractMinimiser):
        return OptxMinimiser(solver)
    raise ValueError(
        "solver must be a jaxfric solver (PSO, MAPSO, NelderMead, MAPSONMDS, chain(...)) "
        f"or an optimistix minimiser, got {type(solver).__name__}"
    )
