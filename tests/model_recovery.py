"""Shared helpers of the model and rig tests: recover known parameters from noise-free
data, and the normalised MSE of docs/algorithms.md §6 written out independently."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from scipy.optimize import least_squares


def lm_recovery(model, velocity, dt, truth, start, tol=1e-15) -> dict[str, float]:
    """Physical parameters found by scipy's Levenberg-Marquardt (JAX Jacobian) from
    ``start`` on the noise-free free-run output of ``model`` at ``truth`` (x64)."""
    with jax.enable_x64(True):
        target = np.asarray(model.simulate(truth, velocity, dt))
        residual = jax.jit(lambda th: model.simulate(th, velocity, dt) - target)
        jac = jax.jit(jax.jacfwd(residual))
        sol = least_squares(lambda th: np.asarray(residual(th)), start,
                            jac=lambda th: np.asarray(jac(th)), method="lm",
                            xtol=tol, ftol=tol, gtol=tol)
        return {k: float(x) for k, x in model.to_physical(jnp.asarray(sol.x)).items()}


def assert_within(got: dict, expected: dict, rel: float = 0.02) -> None:
    for name, value in expected.items():
        assert abs(got[name] - value) <= rel * abs(value), (name, got[name], value)


def nmse_percent(ref, est) -> float:
    """docs/algorithms.md §6: 100 mean((F - F_hat)^2) / var(F), in float64."""
    ref, est = np.asarray(ref, np.float64), np.asarray(est, np.float64)
    return 100.0 * np.mean((ref - est) ** 2) / np.var(ref)
