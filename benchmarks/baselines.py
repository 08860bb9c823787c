"""Plain-NumPy Elman rollouts, the baselines for the rollout speed benchmark.

They implement the same recursion as :class:`jaxfric.models.Elman`
(ALGORITHMS.md §2.2, parameter layout ``[w | r | b | v | alpha | c0] (+ b_o)``)
without JAX, so ``benchmarks/rollout_speed.py`` can compare like with like:

- :func:`elman_rollout_vectorised`: a Python loop over time, NumPy-vectorised
  over candidates and neurons (the usual "numpy PSO" way to score a swarm);
- :func:`elman_rollout_loop`: a Python loop over candidates and over time,
  vectorised over neurons only (scoring particles one at a time).

Both compute in ``dtype`` (float64 by default, float32 for a like-for-like
comparison with JAX's default precision), return ``(P, T)`` arrays, and are
tested against the JAX rollout.
"""

from __future__ import annotations

import numpy as np

__all__ = ["elman_rollout_loop", "elman_rollout_vectorised", "unpack_elman"]


def unpack_elman(thetas, neurons: int, output_bias: bool = False, dtype=np.float64) -> dict[str, np.ndarray]:
    """Split a ``(P, 6N [+1])`` batch into ``(P, N)`` blocks (and ``b_o`` of shape ``(P,)``)."""
    thetas = np.atleast_2d(np.asarray(thetas, dtype=dtype))
    n = int(neurons)
    expected = 6 * n + int(output_bias)
    if thetas.shape[-1] != expected:
        raise ValueError(f"expected {expected} parameters per candidate, got {thetas.shape[-1]}")
    names = ("w", "r", "b", "v", "alpha", "c0")
    out = {name: thetas[:, i * n : (i + 1) * n] for i, name in enumerate(names)}
    out["b_o"] = thetas[:, 6 * n] if output_bias else np.zeros(thetas.shape[0], dtype)
    return out


def elman_rollout_vectorised(thetas, velocity, neurons: int, output_bias: bool = False, dtype=np.float64) -> np.ndarray:
    """Free-run outputs of ``P`` Elman networks; loop over time, vectorised over candidates."""
    p = unpack_elman(thetas, neurons, output_bias, dtype)
    u = np.asarray(velocity, dtype=dtype)
    w, r, b, v, alpha = p["w"], p["r"], p["b"], p["v"], p["alpha"]
    c = p["c0"].copy()
    y = np.empty((c.shape[0], u.shape[0]), dtype)
    for k in range(u.shape[0]):
        h = np.tanh(w * u[k] + r * c + b)
        y[:, k] = np.einsum("pn,pn->p", v, h)
        c = alpha * c + h
    return y + p["b_o"][:, None]


def elman_rollout_loop(thetas, velocity, neurons: int, output_bias: bool = False, dtype=np.float64) -> np.ndarray:
    """Free-run outputs of ``P`` Elman networks, one candidate at a time."""
    p = unpack_elman(thetas, neurons, output_bias, dtype)
    u = np.asarray(velocity, dtype=dtype)
    n_cand = p["w"].shape[0]
    y = np.empty((n_cand, u.shape[0]), dtype)
    for i in range(n_cand):
        w, r, b, v, alpha = (p[k][i] for k in ("w", "r", "b", "v", "alpha"))
        c = p["c0"][i].copy()
        for k in range(u.shape[0]):
            h = np.tanh(w * u[k] + r * c + b)
            y[i, k] = v @ h
            c = alpha * c + h
        y[i] += p["b_o"][i]
    return y
