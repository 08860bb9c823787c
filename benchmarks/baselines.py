"""Plain-NumPy baselines the benchmarks time jaxfric against (not part of the library).

For ``peers.py``: Elman rollouts (the recursion of :class:`jaxfric.models.Elman`,
docs/algorithms.md §2.2, layout ``[w | r | b | v | alpha | c0] (+ b_o)``), vectorised over
candidates (:func:`elman_rollout_vectorised`, the usual "numpy PSO" way) or one candidate at a
time (:func:`elman_rollout_loop`), in ``dtype``, returning ``(P, T)``; LuGre rollouts (exact
zero-order hold, §8.2) recomputed at every step as MATLAB code would
(:func:`lugre_numpy_per_step`), with the v-only coefficients hoisted (jaxfric's layout) or in
scalar Python. ``tests/test_baselines.py`` checks them against the JAX rollouts.
:func:`ls_coulomb_viscous`: the least-squares friction baseline every model must beat.
:func:`numpy_batch`: NumPy test functions on a batch of rows, checked against jaxfric's, for
the peers that take a vectorised objective (pyswarms, SciPy's DE, pycma).
"""

from __future__ import annotations

import math

import numpy as np


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


def _phi_np(x):
    small = x < 1e-8
    xs = np.where(small, 1.0, x)
    return np.where(small, 1.0 - 0.5 * x, -np.expm1(-xs) / xs)


def lugre_numpy_per_step(p, v, dt, dtype=np.float64):
    """REFERENCE (NumPy) LuGre exact-ZOH rollout, docs/algorithms.md §8.2 — everything
    recomputed at every step inside the time loop (how MATLAB code would run it),
    vectorised over candidates. ``p``: physical parameters, each ``(P,)``."""
    s0, s1, s2, fc, fs, vs = (np.asarray(p[k], dtype) for k in ("sigma0", "sigma1", "sigma2", "Fc", "Fs", "vs"))
    v = np.asarray(v, dtype)
    dt = dtype(dt)
    g0 = fc + (fs - fc) * np.exp(-(np.abs(v[0]) / vs) ** 2)
    z = np.sign(v[0]) * g0 / s0
    out = np.empty((s0.shape[0], v.shape[0]), dtype)
    for k in range(v.shape[0]):
        vk = v[k]
        g = fc + (fs - fc) * np.exp(-(np.abs(vk) / vs) ** 2)
        a = s0 * np.abs(vk) / g
        x = a * dt
        out[:, k] = s0 * z + s1 * (vk - a * z) + s2 * vk
        z = np.exp(-x) * z + vk * dt * _phi_np(x)
    return out


def lugre_numpy_hoisted(p, v, dt, dtype=np.float64):
    """REFERENCE (NumPy) LuGre, the coefficients that depend on v only computed
    vectorised over (P, T) first; the time loop is one multiply-add (jaxfric's layout)."""
    s0, s1, s2, fc, fs, vs = (np.asarray(p[k], dtype)[:, None] for k in ("sigma0", "sigma1", "sigma2", "Fc", "Fs", "vs"))
    v = np.asarray(v, dtype)[None, :]
    dt = dtype(dt)
    g = fc + (fs - fc) * np.exp(-(np.abs(v) / vs) ** 2)
    a = s0 * np.abs(v) / g
    x = a * dt
    decay, gain = np.exp(-x), v * dt * _phi_np(x)
    z = np.empty_like(g)
    z[:, 0] = np.sign(v[0, 0]) * g[:, 0] / s0[:, 0]
    for k in range(v.shape[1] - 1):
        z[:, k + 1] = decay[:, k] * z[:, k] + gain[:, k]
    return s0 * z + s1 * (v - a * z) + s2 * v


def lugre_python_loop(p, v, dt):
    """REFERENCE (scalar Python/`math`) LuGre, one candidate at a time, float64."""
    v = [float(x) for x in v]
    P = len(p["sigma0"])
    out = np.empty((P, len(v)))
    for i in range(P):
        s0, s1, s2, fc, fs, vs = (float(p[k][i]) for k in ("sigma0", "sigma1", "sigma2", "Fc", "Fs", "vs"))
        g0 = fc + (fs - fc) * math.exp(-(abs(v[0]) / vs) ** 2)
        z = math.copysign(1.0, v[0]) * g0 / s0 if v[0] != 0 else 0.0
        row = out[i]
        for k, vk in enumerate(v):
            g = fc + (fs - fc) * math.exp(-(abs(vk) / vs) ** 2)
            a = s0 * abs(vk) / g
            x = a * dt
            row[k] = s0 * z + s1 * (vk - a * z) + s2 * vk
            phi = 1.0 - 0.5 * x if x < 1e-8 else -math.expm1(-x) / x
            z = math.exp(-x) * z + vk * dt * phi
    return out


def ls_coulomb_viscous(v, f, n=None):
    """Asymmetric Coulomb + viscous + offset, ``F = Fv± v + Fc+ [v>0] − Fc− [v<0] + o``, by
    least squares on the first ``n`` samples (all if None): ``(prediction on all samples,
    [Fv+, Fv−, Fc+, Fc−, o])``."""
    v, f = np.asarray(v, np.float64), np.asarray(f, np.float64)
    pos, neg = (v > 0).astype(float), (v < 0).astype(float)
    A = np.stack([v * pos, v * neg, pos, -neg, np.ones_like(v)], axis=1)
    coef, *_ = np.linalg.lstsq(A[:n], f[:n], rcond=None)
    return A @ coef, coef


#: NumPy versions (a batch of rows at once) for the peers; :func:`numpy_batch` checks them.
NUMPY_BATCH = {
    "rosenbrock": lambda X: np.sum(100.0 * (X[:, 1:] - X[:, :-1] ** 2) ** 2 + (1.0 - X[:, :-1]) ** 2, axis=1),
    "ackley": lambda X: (-20.0 * np.exp(-0.2 * np.sqrt(np.mean(X * X, axis=1)))
                         - np.exp(np.mean(np.cos(2 * np.pi * X), axis=1)) + 20.0 + np.e),
    "griewank": lambda X: 1.0 + np.sum(X * X, axis=1) / 4000.0
    - np.prod(np.cos(X / np.sqrt(np.arange(1, X.shape[1] + 1))), axis=1),
    "sphere": lambda X: np.sum(X * X, axis=1),
    "schwefel": lambda X: np.sum(np.abs(X), axis=1) + np.prod(np.abs(X), axis=1),
    "rastrigin": lambda X: np.sum(X * X - 10.0 * np.cos(2 * np.pi * X) + 10.0, axis=1),
}


def numpy_batch(name: str):
    """``NUMPY_BATCH[name]``, first checked against jaxfric's function on random points (float64)."""
    import jax

    from jaxfric import functions as F

    probe = np.random.default_rng(1).uniform(-2, 2, (4, 5))
    with jax.enable_x64(True):
        ref = np.asarray(jax.vmap(F.get(name).fn)(jax.numpy.asarray(probe)))
    np.testing.assert_allclose(NUMPY_BATCH[name](probe), ref, rtol=1e-9, atol=1e-9)
    return NUMPY_BATCH[name]
