"""Shared pieces of every jaxfric optimiser: the result pytree, the fixed-size
history buffer, bounds validation and the NaN-safe objective wrapper.

Conventions (docs/design.md, "Conventions"): objectives are ``fn(y, args) -> scalar``; solvers see a
flat 1-D parameter vector ``x`` inside a box ``[lower, upper]``; NaN and inf
fitness are mapped to ``+inf`` so they can never be reported as the best.
"""

from __future__ import annotations

import math
from typing import Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float, Int

RESULTS = optx.RESULTS
"""Result codes, shared with optimistix (``RESULTS.successful``,
``RESULTS.nonlinear_max_steps_reached``, ``RESULTS.nonfinite``, ...)."""


def put(a, i, value):
    """``a.at[i].set(value)`` along the first axis for an index ``i`` known to be in range
    (a negative one is not wrapped), as a ``dynamic_update_slice``: the same array, where
    XLA:CPU expands a scatter into a loop of its own (issue 47: 20 scatters of a chain's
    program)."""
    return jax.lax.dynamic_update_index_in_dim(a, jnp.asarray(value).astype(a.dtype), i, 0)


# --------------------------------------------------------------------------- history
class History(eqx.Module):
    """Fixed-size record of the best objective value against evaluations spent.

    ``evals[i]`` is the number of function evaluations used when ``f[i]`` was the
    best value so far. Only the first ``length`` entries are valid; the rest hold
    the last valid entry repeated, so the arrays can be plotted directly.
    Swarm solvers write one entry per generation. Nelder–Mead's run length is
    unknown in advance, so it keeps every ``stride``-th step and doubles the stride
    (halving the buffer) whenever it fills: memory stays fixed, the record stays
    evenly spread over the run.
    """

    evals: Int[Array, " H"]
    f: Float[Array, " H"]
    length: Int[Array, ""]
    stride: Int[Array, ""]
    counter: Int[Array, ""]

    @classmethod
    def empty(cls, size: int, dtype) -> "History":
        return cls(
            evals=jnp.zeros((size,), count_dtype()),
            f=jnp.full((size,), jnp.inf, dtype),
            length=jnp.array(0, jnp.int32),
            stride=jnp.array(1, jnp.int32),
            counter=jnp.array(0, jnp.int32),
        )

    @classmethod
    def first(cls, size: int, num_evals, f_best) -> "History":
        """``empty(size, f_best.dtype).record(num_evals, f_best)`` (the same arrays), written
        directly: a run's first entry cannot fill a buffer of 2 or more, so it needs none
        of `record`'s stride and compression logic, whose compiled copy it saved."""
        if size < 2:
            return cls.empty(size, jnp.result_type(f_best)).record(num_evals, f_best)
        f_best = jnp.asarray(f_best)
        evals = put(jnp.zeros((size,), count_dtype()), 0, num_evals)
        f = put(jnp.full((size,), jnp.inf, f_best.dtype), 0, f_best)
        one = jnp.array(1, jnp.int32)
        return cls(evals=evals, f=f, length=one, stride=one, counter=one)

    @classmethod
    def from_arrays(cls, evals, f) -> "History":
        n = evals.shape[0]
        return cls(
            evals=evals.astype(count_dtype()),
            f=f,
            length=jnp.array(n, jnp.int32),
            stride=jnp.array(1, jnp.int32),
            counter=jnp.array(n, jnp.int32),
        )

    def record(self, num_evals, f_best, fills: bool = True) -> "History":
        """Append ``(num_evals, f_best)`` under the stride-doubling rule (jit-safe).
        ``fills=False`` (static): the caller knows the buffer holds every entry of the
        run, so the compression that a full buffer takes is left out of the program (the
        same arrays: it would never run)."""
        size = self.f.shape[0]
        take = (self.counter % self.stride) == 0
        idx = jnp.minimum(self.length, size - 1)
        # Counters arrive as int32 or int64 (count_dtype) and f in the solver's dtype:
        # cast to the buffer's, so strict dtype promotion (optimistix's tests) holds.
        # One element is written (its old value where the step is not kept): a select
        # over the whole buffer cost a pass over 4096 entries at every step.
        ev_k = jnp.where(take, jnp.asarray(num_evals).astype(self.evals.dtype), self.evals[idx])
        f_k = jnp.where(take, jnp.asarray(f_best).astype(self.f.dtype), self.f[idx])
        evals, f = put(self.evals, idx, ev_k), put(self.f, idx, f_k)
        length = self.length + take.astype(jnp.int32)
        if not fills:
            return History(evals, f, length, self.stride, self.counter + 1)

        def compress(ev, fv):
            # Keep every other entry, so the buffer is half full again.
            half = (size + 1) // 2
            return (jnp.concatenate([ev[::2], jnp.zeros((size - half,), ev.dtype)]),
                    jnp.concatenate([fv[::2], jnp.full((size - half,), jnp.inf, fv.dtype)]))

        full = length >= size
        evals, f = jax.lax.cond(full, compress, lambda ev, fv: (ev, fv), evals, f)
        length = jnp.where(full, (size + 1) // 2, length)
        stride = jnp.where(full, self.stride * 2, self.stride)
        return History(evals, f, length, stride, self.counter + 1)

    def close(self, num_evals, f_best) -> "History":
        """Record the run's last ``(num_evals, f_best)`` whatever the stride, so the
        history always ends at the reported result (no-op if it is already there)."""
        last = jnp.maximum(self.length - 1, 0)
        num_evals = jnp.asarray(num_evals).astype(self.evals.dtype)
        f_best = jnp.asarray(f_best).astype(self.f.dtype)
        missing = (self.length == 0) | (self.evals[last] != num_evals) | (self.f[last] != f_best)
        forced = History(self.evals, self.f, self.length, jnp.ones_like(self.stride),
                         jnp.zeros_like(self.counter)).record(num_evals, f_best)
        forced = eqx.tree_at(lambda h: (h.stride, h.counter), forced,
                             (jnp.maximum(forced.stride, self.stride), self.counter + 1))
        return jax.tree_util.tree_map(lambda a, b: jnp.where(missing, a, b), forced, self)

    def filled(self) -> "History":
        """Pad entries past ``length`` with the last valid entry."""
        size = self.f.shape[0]
        last = jnp.maximum(self.length - 1, 0)
        valid = jnp.arange(size) < self.length
        return eqx.tree_at(
            lambda h: (h.evals, h.f),
            self,
            (
                jnp.where(valid, self.evals, self.evals[last]),
                jnp.where(valid, self.f, self.f[last]),
            ),
        )


# -------------------------------------------------------------------------- solution
class Solution(eqx.Module):
    """Result of [`jaxfric.minimise`][jaxfric.optim.minimise] (a pytree: works under ``jit``/``vmap``).

    Attributes:
        value: the best parameters found, with the structure of the bounds.
        f: the objective at ``value`` (``+inf`` if no finite value was ever seen).
        result: an ``optimistix.RESULTS`` code.
        stats: ``{"num_steps": generations or NM steps, "num_evals": exact number
            of objective evaluations}``.
        history: [`History`][jaxfric.optim.History] of best ``f`` against evaluations.
        state: the solver's final state (``None`` for solutions built elsewhere):
            pass the solution back as ``minimise(..., warm_start=solution)`` to
            continue the run with a larger budget.
    """

    def __repr__(self):  # what was found, not array shapes
        try:
            f = np.asarray(self.f)
            value = jax.tree_util.tree_map(np.asarray, self.value)
            evals = np.asarray(self.stats.get("num_evals"))
            code = np.asarray(self.result._value)
            names = {int(item._value): name for name, item in RESULTS._name_to_item.items()}
            res = names.get(int(code), str(code)) if code.ndim == 0 else code
            with np.printoptions(precision=6, threshold=20, edgeitems=3):
                return (f"Solution(value={value!r}, f={f!r}, num_evals={evals!r}, "
                        f"result={res})")
        except Exception:  # under tracing: fall back to equinox's structural repr
            return eqx.Module.__repr__(self)

    __str__ = __repr__

    value: Any
    f: Float[Array, ""]
    result: RESULTS
    stats: dict[str, Array]
    history: History
    state: Any = None

    @property
    def success(self):
        return self.result == RESULTS.successful


# ------------------------------------------------------------------------- utilities
def safe_value(f):
    """Map NaN and +/-inf to +inf: a non-finite value is the worst, never the best."""
    f = jnp.asarray(f)
    return jnp.where(jnp.isfinite(f), f, jnp.inf)


def batch_objective(fn: Callable, args) -> Callable:
    """``X (P, D) -> f (P,)``: vmapped, NaN-safe version of ``fn(x, args)``.

    If ``fn`` carries a device ``layout`` (set by [`jaxfric.minimise`][jaxfric.optim.minimise] when there
    are several devices) the population is split by agents across them.
    """
    layout = getattr(fn, "layout", None)

    def f_batch(X):
        if layout is not None:
            X = layout.constrain_rows(X)
        return safe_value(jax.vmap(lambda x: fn(x, args))(X))

    return f_batch


def clip(x, lower, upper):
    """``jnp.clip(x, lower, upper)`` as two selects: ``lower`` where ``x < lower``,
    ``upper`` where ``x > upper``, else ``x`` (a NaN stays NaN, as with ``jnp.clip``).

    The swarms clip every coordinate two or three times a generation (§3.2, §3.3).
    ``jnp.clip`` is ``min(max(x, lower), upper)``, and XLA:CPU writes each NaN-propagating
    ``max``/``min`` as a compare-and-select chain that stays scalar inside the swarm's
    fused loops; two plain selects vectorise. Same value for every input but a signed
    zero on a bound of zero.
    """
    return jnp.where(x < lower, lower, jnp.where(x > upper, upper, x))


def linear_inertia(i, num, w_max, w_min):
    """Inertia weight falling linearly from ``w_max`` to ``w_min`` (docs/algorithms.md §3.3, §10):
    ``w(i) = w_max - (w_max - w_min) * i / G``."""
    return w_max - (w_max - w_min) * i / jnp.maximum(num, 1)


def uniform_flat(key, shape, dtype):
    """``jax.random.uniform(key, shape, dtype)``, drawn flat and reshaped: the same
    numbers (threefry's counter is the element's flat index; tests/test_rng.py checks),
    but XLA compiles a 1-D threefry 1.5–3× faster than a 2-D one on the CPU (0.3 s
    instead of 0.75 s for 16×6), and every solver program compiles its start."""
    return jax.random.uniform(key, (math.prod(shape),), dtype=dtype).reshape(shape)


def uniform_flat_each(keys, shape, dtype):
    """``uniform_flat(k, shape, dtype)`` for each of the stacked ``keys``, as one threefry
    (``vmap`` over the keys): the same numbers as separate calls, but one generator for
    XLA to compile instead of one per key (each costs 0.3–0.5 s of a solver program's
    compilation on the CPU, a new objective's program compiling them all again)."""
    return jax.vmap(lambda k: uniform_flat(k, shape, dtype))(keys)


def uniform_in_box(key, shape, lower, upper):
    """``U(lower, upper)`` of ``shape`` (`uniform_flat`)."""
    return lower + uniform_flat(key, shape, lower.dtype) * (upper - lower)


class Drawn(eqx.Module):
    """A run's ``key`` with the random numbers its start draws from it (``draws``),
    computed beforehand by a program of their own (a solver's ``start_draws``).

    [`jaxfric.minimise`][jaxfric.optim.minimise] passes it as the key of a solver that has
    ``start_draws``: a swarm's first population (threefry, about a quarter of a small
    solver program's machine code) then compiles once per solver and shape instead of
    with every new objective (issue 47). The numbers are those the start would draw."""

    key: Any
    draws: Any


def split_drawn(key):
    """``(key, draws)`` of a ``Drawn`` key, ``(key, None)`` of a plain one."""
    return (key.key, key.draws) if isinstance(key, Drawn) else (key, None)


def result_from_f(f_best):
    return RESULTS.where(jnp.isfinite(f_best), RESULTS.successful, RESULTS.nonfinite)


# ------------------------------------------------------------------ counters, checks
def count_dtype():
    """Integer dtype of evaluation counters: int64 when JAX runs with 64-bit types
    (``jax.enable_x64``), else int32 (the driver then refuses budgets of 2³¹ or more
    before running, instead of letting a count wrap negative)."""
    return jax.dtypes.canonicalize_dtype(jnp.int64)


#: The step cap of a solver that gives none (its ``Capabilities.max_steps`` is ``None``).
NO_STEP_CAP = 2**31 - 1


def check_positive_int(name: str, value, minimum: int = 1) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")


def check_range(name: str, value, lo=None, hi=None, *, lo_open=False, hi_open=False):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not np.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise ValueError(f"{name} must be {'>' if lo_open else '>='} {lo}, got {v}")
    if hi is not None and (v > hi or (hi_open and v == hi)):
        raise ValueError(f"{name} must be {'<' if hi_open else '<='} {hi}, got {v}")
