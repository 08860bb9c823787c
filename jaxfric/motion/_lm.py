"""Levenberg–Marquardt on the simulated positions, with exact forward-mode Jacobians, §13.2.

The residuals of a motion fit are the ``T`` weighted position errors of one
``lax.scan`` (`jaxfric.motion._shooting.shoot`); its Jacobian with respect to the
``n`` search parameters costs about ``n`` forward passes by forward mode (``jax.jacfwd``)
and, unlike reverse mode through a 20 000-step scan, stores no tape (timings:
docs/motion.md). ``n`` is small for the physical models (a dozen), so each step solves the
damped normal equations ``(JᵀJ + μ D) δ = −Jᵀr`` (Marquardt's scaling, ``D = diag JᵀJ``)
in NumPy and adapts μ by Nielsen's rule (gain ratio ρ: accept if ρ > 0, then
``μ ← μ·max(1/3, 1 − (2ρ − 1)³)``; else ``μ ← μ·ν``, ``ν ← 2ν``).

The search runs on ``z`` with θ = lo + (hi − lo)(1 + sin z)/2
([`jaxfric.identification.to_box`][jaxfric.identification.to_box]), so every iterate is inside the box.
Each step is one compiled call; between steps the loop checks the budget (steps,
evaluations, wall time) and reports progress, so a run can end at any step with the best
point so far (the accepted iterate never gets worse).
"""

from __future__ import annotations

import dataclasses
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..identification import from_box, to_box

__all__ = ["LMOutcome", "levenberg_marquardt"]


@dataclasses.dataclass
class LMOutcome:
    """``theta`` (box coordinates) and ``f`` = Σ r² at it; ``steps`` taken, ``evals``
    (residual passes; a Jacobian counts ``1 + n``), ``reason`` why the loop ended."""

    theta: np.ndarray
    f: float
    steps: int
    evals: int
    reason: str


def _residuals(z, args):
    fn, lower, upper, data = args
    return fn(to_box(z, lower, upper), data)


def _res_and_jac(z, args):
    def both(zz):
        r = _residuals(zz, args)
        return r, r

    jac, r = jax.jacfwd(both, has_aux=True)(z)
    return r, jac


_res_jit = eqx.filter_jit(_residuals)
_jac_jit = eqx.filter_jit(_res_and_jac)


def _sumsq(r) -> float:
    r = np.asarray(r, np.float64)
    if not np.all(np.isfinite(r)):
        return float("inf")
    return float(r @ r)


def levenberg_marquardt(fn, theta0, lower, upper, data, *, max_steps: int = 100, rtol: float = 1e-6,
                        patience: int = 3, edge: float = 1e-4, deadline: float | None = None,
                        max_evals: int | None = None, on_step=None) -> LMOutcome:
    """Minimise ``Σ fn(θ, data)²`` over the box from ``theta0`` (module docstring).

    ``fn`` must be an equinox-compatible callable (a Module or a module-level function)
    returning the residual vector. Stops after ``max_steps`` steps, when ``patience``
    accepted steps in a row lower f by less than ``rtol·f``, at ``deadline``
    (``time.perf_counter()`` value), or before a step would pass ``max_evals``.
    ``on_step(step, f)`` is called after every step.
    """
    lower = jnp.asarray(lower)
    upper = jnp.asarray(upper)
    args = (fn, lower, upper, data)
    z = from_box(jnp.asarray(theta0, lower.dtype), lower, upper, edge)
    n = int(z.shape[0])
    r, jac = (np.asarray(a, np.float64) for a in _jac_jit(z, args))
    evals = 1 + n
    f = _sumsq(r)
    if not np.isfinite(f):
        return LMOutcome(np.asarray(theta0, np.float64), f, 0, evals, "non-finite start")
    a = jac.T @ jac
    g = jac.T @ r
    mu = 1e-3 * float(np.max(np.diag(a))) if np.max(np.diag(a)) > 0 else 1e-3
    nu = 2.0
    calm = 0
    reason = "max_steps"
    step = 0
    while step < max_steps:
        if deadline is not None and time.perf_counter() >= deadline:
            reason = "max_time"
            break
        if max_evals is not None and evals + 1 > max_evals:
            reason = "max_evals"
            break
        step += 1
        d = np.maximum(np.diag(a), 1e-12 * max(float(np.max(np.diag(a))), 1e-300))
        try:
            dz = np.linalg.solve(a + mu * np.diag(d), -g)
        except np.linalg.LinAlgError:
            dz = np.linalg.lstsq(a + mu * np.diag(d), -g, rcond=None)[0]
        z_new = z + jnp.asarray(dz, z.dtype)
        f_new = _sumsq(_res_jit(z_new, args))
        evals += 1
        predicted = -(2.0 * dz @ g + dz @ a @ dz)
        rho = (f - f_new) / predicted if predicted > 0 else -1.0
        if np.isfinite(f_new) and rho > 0:
            gain = f - f_new
            z = z_new
            if max_evals is not None and evals + 1 + n > max_evals:
                f = f_new
                reason = "max_evals"
                break
            r, jac = (np.asarray(q, np.float64) for q in _jac_jit(z, args))
            evals += 1 + n
            f = _sumsq(r)
            a = jac.T @ jac
            g = jac.T @ r
            mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
            calm = calm + 1 if gain < rtol * f else 0
            if on_step is not None:
                on_step(step, f)
            if calm >= patience:
                reason = "converged"
                break
        else:
            mu *= nu
            nu *= 2.0
            if on_step is not None:
                on_step(step, f)
            if mu > 1e20 * max(float(np.max(np.diag(a))), 1.0):
                reason = "converged"
                break
    theta = np.asarray(to_box(z, lower, upper), np.float64)
    return LMOutcome(theta, f, step, evals, reason)
