"""Shared pieces of every jaxfric optimiser: the result pytree, the fixed-size
history buffer, bounds validation and the NaN-safe objective wrapper.

Conventions (DESIGN.md): objectives are ``fn(y, args) -> scalar``; solvers see a
flat 1-D parameter vector ``x`` inside a box ``[lower, upper]``; NaN and inf
fitness are mapped to ``+inf`` so they can never be reported as the best.
"""

from __future__ import annotations

import abc
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
            evals=jnp.zeros((size,), jnp.int32),
            f=jnp.full((size,), jnp.inf, dtype),
            length=jnp.array(0, jnp.int32),
            stride=jnp.array(1, jnp.int32),
            counter=jnp.array(0, jnp.int32),
        )

    @classmethod
    def from_arrays(cls, evals, f) -> "History":
        n = evals.shape[0]
        return cls(
            evals=evals.astype(jnp.int32),
            f=f,
            length=jnp.array(n, jnp.int32),
            stride=jnp.array(1, jnp.int32),
            counter=jnp.array(n, jnp.int32),
        )

    def record(self, num_evals, f_best) -> "History":
        """Append ``(num_evals, f_best)`` under the stride-doubling rule (jit-safe)."""
        size = self.f.shape[0]
        take = (self.counter % self.stride) == 0
        idx = jnp.minimum(self.length, size - 1)
        evals = jnp.where(take, self.evals.at[idx].set(num_evals), self.evals)
        f = jnp.where(take, self.f.at[idx].set(f_best), self.f)
        length = self.length + take.astype(jnp.int32)

        def compress(ev, fv):
            # Keep every other entry, so the buffer is half full again.
            half_idx = jnp.minimum(jnp.arange(size) * 2, size - 1)
            half_ok = jnp.arange(size) * 2 < size
            return (
                jnp.where(half_ok, ev[half_idx], 0),
                jnp.where(half_ok, fv[half_idx], jnp.inf).astype(fv.dtype),
            )

        full = length >= size
        evals, f = jax.lax.cond(full, compress, lambda ev, fv: (ev, fv), evals, f)
        length = jnp.where(full, (size + 1) // 2, length)
        stride = jnp.where(full, self.stride * 2, self.stride)
        return History(evals, f, length, stride, self.counter + 1)

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

    def offset(self, num_evals) -> "History":
        """Shift the evaluation axis by ``num_evals`` (a later phase of a hybrid)."""
        return eqx.tree_at(lambda h: h.evals, self, self.evals + num_evals)


def concat_histories(first: History, second: History) -> History:
    """Join two histories (``second`` already offset), keeping fixed total size."""
    first, second = first.filled(), second.filled()
    return History(
        evals=jnp.concatenate([first.evals, second.evals]),
        f=jnp.concatenate([first.f, jnp.minimum(second.f, first.f[-1])]),
        length=jnp.array(first.f.shape[0] + second.f.shape[0], jnp.int32),
        stride=jnp.array(1, jnp.int32),
        counter=first.counter + second.counter,
    )


# -------------------------------------------------------------------------- solution
class Solution(eqx.Module):
    """Result of :func:`jaxfric.minimise` (a pytree: works under ``jit``/``vmap``).

    Attributes:
        value: the best parameters found, with the structure of the bounds.
        f: the objective at ``value`` (``+inf`` if no finite value was ever seen).
        result: an ``optimistix.RESULTS`` code.
        stats: ``{"num_steps": generations or NM steps, "num_evals": exact number
            of objective evaluations}``.
        history: :class:`History` of best ``f`` against evaluations.
    """

    value: Any
    f: Float[Array, ""]
    result: RESULTS
    stats: dict[str, Array]
    history: History

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

    If ``fn`` carries a device ``layout`` (set by :func:`jaxfric.minimise` when there
    are several devices) the population is split by agents across them.
    """
    layout = getattr(fn, "layout", None)

    def f_batch(X):
        if layout is not None:
            X = layout.constrain_rows(X)
        return safe_value(jax.vmap(lambda x: fn(x, args))(X))

    return f_batch


def scalar_objective(fn: Callable, args) -> Callable:
    def f_one(x):
        return safe_value(fn(x, args))

    return f_one


def linear_inertia(i, num, w_max, w_min):
    """Inertia weight falling linearly from ``w_max`` to ``w_min`` (ALGORITHMS §3.3, §10):
    ``w(i) = w_max - (w_max - w_min) * i / G``."""
    return w_max - (w_max - w_min) * i / jnp.maximum(num, 1)


_GOLDEN = 0x9E3779B9  # 2^32 / golden ratio: the Weyl increment of the counter


def _fmix32(h):
    """MurmurHash3's 32-bit finaliser: a bijection with full avalanche."""
    h = h ^ (h >> 16)
    h = h * jnp.uint32(0x85EBCA6B)
    h = h ^ (h >> 13)
    h = h * jnp.uint32(0xC2B2AE35)
    return h ^ (h >> 16)


def counter_seed(key, *words):
    """Two 32-bit seed words from a PRNG key and integer ``words`` (generation, stream).

    No random-number generator runs: the key's raw words (themselves threefry output)
    and the words are folded through :func:`_fmix32`. Different ``words`` give
    unrelated seeds, so a swarm draws generation ``i``'s numbers from
    ``counter_seed(key, i, stream)`` without splitting or advancing the key; a run
    resumed at generation ``i`` therefore draws what the uninterrupted run drew.
    """
    a = jnp.uint32(0x243F6A88)
    b = jnp.uint32(0x85A308D3)
    data = jax.random.key_data(key).reshape(-1).astype(jnp.uint32)
    for w in [data[j] for j in range(data.shape[0])] + [jnp.asarray(w).astype(jnp.uint32) for w in words]:
        a = _fmix32(a ^ w)
        b = _fmix32(b + w * jnp.uint32(_GOLDEN))
    return a, b


def counter_uniform(seed, shape, dtype):
    """``U[0, 1)`` numbers from a counter-based hash keyed by ``seed`` (:func:`counter_seed`).

    Element ``c`` is ``fmix32(fmix32(c·φ ⊕ a) + b)`` (``φ`` the golden-ratio
    increment), scaled to 24 bits for float32 and combined from two such words to
    53 bits for float64. Unlike ``jax.random`` (threefry: 20 rounds per word, on CPU
    a loop of its own inside the generation loop) these are a few integer operations
    that XLA fuses into the arithmetic that uses them. Swarm steps on CPU spent most
    of their time in threefry (PEERS.md §b). Because XLA fuses the hash into *every*
    consumer, recomputing it in each, swarms draw generation ``i + 1``'s numbers
    while running generation ``i`` and carry them through the loop
    (:meth:`~jaxfric.optim.pso.AbstractSwarm.advance`), which stores them once. The
    hash passes the moment, bucket and correlation checks in ``tests/test_rng.py``;
    it is not meant for cryptography.
    """
    dtype = jnp.dtype(dtype)
    a, b = seed
    n = math.prod(shape)
    wide = dtype.itemsize > 4
    c = jnp.arange(n * (2 if wide else 1), dtype=jnp.uint32)
    h = _fmix32(_fmix32((c * jnp.uint32(_GOLDEN)) ^ a) + b)
    if wide:
        hi = (h[0::2] >> 5).astype(dtype)  # 27 bits
        lo = (h[1::2] >> 6).astype(dtype)  # 26 bits
        u = (hi * 67108864.0 + lo) * (1.0 / 9007199254740992.0)
    else:
        u = (h >> 8).astype(dtype) * (1.0 / 16777216.0)
    return u.reshape(shape)


def uniform_in_box(key, shape, lower, upper):
    u = jax.random.uniform(key, shape, dtype=lower.dtype)
    return lower + u * (upper - lower)


def best_of(x, f):
    i = jnp.argmin(f)
    return x[i], f[i]


def result_from_f(f_best):
    return RESULTS.where(jnp.isfinite(f_best), RESULTS.successful, RESULTS.nonfinite)


# -------------------------------------------------------------------- solver contract
class AbstractSolver(eqx.Module):
    """What :func:`jaxfric.minimise` needs from a solver.

    ``run`` receives an objective on a flat parameter vector, the box bounds as
    1-D arrays of one floating dtype, a PRNG key, an optional start ``x0`` and an
    optional :class:`~jaxfric.optim.progress.ProgressHook`; it returns a
    :class:`Solution` whose ``value`` is the flat vector. It must be pure and
    traceable: ``minimise`` jits it, and ``minimise_many`` vmaps it over keys.
    """

    @abc.abstractmethod
    def run(self, fn: Callable, lower, upper, args, key, x0=None, progress=None) -> Solution: ...

    def progress_totals(self) -> tuple[int | None, int | None]:
        """(global generations, local step cap) for a progress display."""
        return None, None

    def check(self) -> None:
        """Raise ``ValueError`` on invalid hyperparameters (before any tracing)."""


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
