"""Counter-based random numbers for the swarms (docs/algorithms.md §3.3).

A swarm draws generation ``i``'s numbers from ``counter_seed(key, i, stream)``: a pure
function of the run's key and the generation, so a run resumed at generation ``i`` (or
stepped by hand through ``ask``/``tell``) draws exactly what the uninterrupted run drew,
without splitting or carrying a key. Tests: ``tests/test_rng.py``.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

__all__ = ["counter_seed", "counter_uniform", "extend_seed"]


_GOLDEN = 0x9E3779B9  # 2^32 / golden ratio: the Weyl increment of the counter
_GOLDEN64 = 0x9E3779B97F4A7C15  # the same for 64-bit counters


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
    and the words are folded through `_fmix32`. Different ``words`` give
    unrelated seeds, so a swarm draws generation ``i``'s numbers from
    ``counter_seed(key, i, stream)`` without splitting or advancing the key; a run
    resumed at generation ``i`` therefore draws what the uninterrupted run drew.
    """
    data = jax.random.key_data(key).reshape(-1).astype(jnp.uint32)
    seed = extend_seed((jnp.uint32(0x243F6A88), jnp.uint32(0x85A308D3)),
                       *[data[j] for j in range(data.shape[0])])
    return extend_seed(seed, *words)


def extend_seed(seed, *words):
    """``counter_seed(key, *w, *words)`` from ``seed = counter_seed(key, *w)``: the words
    are folded in one after another, so seeds that share their first words (a generation's
    streams) share that work: the same numbers, a smaller program."""
    a, b = seed
    for w in words:
        w = jnp.asarray(w).astype(jnp.uint32)
        a = _fmix32(a ^ w)
        b = _fmix32(b + w * jnp.uint32(_GOLDEN))
    return a, b


def _splitmix64(z):
    """SplitMix64's 64-bit finaliser (Steele, Lea & Flood 2014): a bijection with full
    avalanche, one multiply-xorshift round fewer per 53-bit number than two 32-bit words."""
    z = (z ^ (z >> 30)) * jnp.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> 27)) * jnp.uint64(0x94D049BB133111EB)
    return z ^ (z >> 31)


def counter_uniform(seed, shape, dtype):
    """``U[0, 1)`` numbers from a counter-based hash keyed by ``seed`` ([`counter_seed`][jaxfric.optim.rng.counter_seed]).

    float32: element ``c`` is ``fmix32(fmix32(c·φ ⊕ a) + b)`` (``φ`` the golden-ratio
    increment), its top 24 bits scaled to ``[0, 1)``. float64: ``splitmix64(s + c·φ64)``
    with the 64-bit seed ``s = a·2³² + b``, its top 52 bits placed in the mantissa of a
    number in ``[1, 2)`` (a bit cast, no integer-to-float conversion) minus 1. The
    float64 form costs 0.4× the two-32-bit-word form it replaced (same run, 30-D
    MAPSO's numbers). Unlike ``jax.random`` (threefry: 20 rounds per word, on CPU a loop
    of its own inside the generation loop) these are a few integer operations that XLA
    fuses into the arithmetic that uses them. Swarm steps on CPU spent most of their
    time in threefry (docs/algorithms.md §3.3). Because XLA fuses the hash into *every*
    consumer, recomputing it in each, swarms draw generation ``i + 1``'s numbers while
    running generation ``i`` and carry them through the loop (the swarm state field
    ``u``), which stores them once. Both forms pass the moment, bucket and correlation
    checks in ``tests/test_rng.py``; they are not meant for cryptography.
    """
    dtype = jnp.dtype(dtype)
    a, b = seed
    n = math.prod(shape)
    if dtype.itemsize > 4:
        s = (a.astype(jnp.uint64) << 32) | b.astype(jnp.uint64)
        z = _splitmix64(jnp.arange(n, dtype=jnp.uint64) * jnp.uint64(_GOLDEN64) + s)
        one_to_two = (z >> 12) | jnp.uint64(0x3FF0000000000000)
        u = jax.lax.bitcast_convert_type(one_to_two, dtype) - 1.0
    else:
        c = jnp.arange(n, dtype=jnp.uint32)
        h = _fmix32(_fmix32((c * jnp.uint32(_GOLDEN)) ^ a) + b)
        u = (h >> 8).astype(dtype) * (1.0 / 16777216.0)
    return u.reshape(shape)
