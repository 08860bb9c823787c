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

__all__ = ["counter_seed", "counter_uniform"]


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
    (the swarm state field ``u``), which stores them once. The
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
