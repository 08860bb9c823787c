"""Error metrics for friction identification (docs/algorithms.md §6, with MATLAB's FIT %).

With measured friction ``y``, prediction ``y_hat``, error ``e = y - y_hat``,
``n`` samples, mean ``ybar`` and *population* variance
``var(y) = mean((y - ybar)^2)``:

====================== ========================================================= =========
key                    formula                                                   unit
====================== ========================================================= =========
``mse``                mean(e^2)                                                 N^2
``rmse``               sqrt(mean(e^2))                                           N
``mse_percent``        100 mean(e^2) / var(y)  (normalised MSE, Worden et al.;   %
                       the paper's "MSE %": 100 = no better than the mean)
``mse_scaled_percent`` 100 mean(e_s^2), e_s = e * 2 / (max y - min y) -- MATLAB   %
                       ``mse`` on ``mapminmax``-scaled data (the other reading
                       of the paper's numbers, §6)
``max_abs``            max |e|  (the paper's MAX)                                N
``max_percent``        100 max|e| / max|y|                                       %
``fit_percent``        100 (1 - ||e|| / ||y - ybar||)  (MATLAB ``compare`` FIT;  %
                       100 = perfect, 0 = the mean, can be negative)
``rrse``               ||e|| / ||y - ybar||  (root relative squared error,       -
                       = 1 - fit_percent / 100)
``r2``                 1 - sum(e^2) / sum((y - ybar)^2)                          -
                       (= 1 - mse_percent / 100)
====================== ========================================================= =========

Always state which window (training, validation, all) a metric covers; the
paper does not (§6).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike

__all__ = ["METRIC_FORMULAS", "friction_metrics", "mse_percent_jax"]

METRIC_FORMULAS: dict[str, str] = {
    "mse": "mean(e^2) [N^2]",
    "rmse": "sqrt(mean(e^2)) [N]",
    "mse_percent": "100*mean(e^2)/var(y) [%] (normalised MSE, var with 1/n)",
    "mse_scaled_percent": "100*mean((2e/(max y - min y))^2) [%] (MATLAB mse on mapminmax data)",
    "max_abs": "max|e| [N]",
    "max_percent": "100*max|e|/max|y| [%]",
    "fit_percent": "100*(1 - ||e||/||y - mean(y)||) [%] (MATLAB compare FIT)",
    "rrse": "||e||/||y - mean(y)|| [-]",
    "r2": "1 - sum(e^2)/sum((y - mean(y))^2) [-]",
}
"""Formula of each key returned by [`friction_metrics`][jaxfric.metrics.friction_metrics], for reports."""


def _as_checked_pair(y, y_hat) -> tuple[np.ndarray, np.ndarray]:
    arrays = []
    for name, arr in (("y", y), ("y_hat", y_hat)):
        if np.iscomplexobj(arr):
            raise ValueError(f"{name} holds complex numbers; metrics need real values")
        try:
            arrays.append(np.asarray(arr, dtype=np.float64))
        except (TypeError, ValueError) as err:
            raise ValueError(f"{name} is not numeric: {err}") from None
    y, y_hat = arrays
    if y.shape != y_hat.shape:
        raise ValueError(f"y and y_hat must have the same shape, got {y.shape} and {y_hat.shape}")
    if y.size == 0:
        raise ValueError("y and y_hat must not be empty")
    for name, arr in (("y", y), ("y_hat", y_hat)):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} holds NaN or inf; metrics are undefined")
    return y.ravel(), y_hat.ravel()


def _table(ss_err, ss_tot, mse, rmse, mse_scaled_percent, max_abs, y_absmax) -> dict[str, float]:
    """The metric table from the sums of squares of the error and of ``y - ybar`` (same
    units) and the error sizes; NumPy float64 scalars, so an overflow gives inf rather
    than raising."""
    rrse = np.sqrt(ss_err / ss_tot)
    max_percent = 100.0 * max_abs / y_absmax
    if not np.isfinite(max_percent):  # 100 * max_abs overflowed
        max_percent = 100.0 * (max_abs / y_absmax)
    out = {
        "mse": mse,
        "rmse": rmse,
        "mse_percent": 100.0 * ss_err / ss_tot,
        "mse_scaled_percent": mse_scaled_percent,
        "max_abs": max_abs,
        "max_percent": max_percent,
        "fit_percent": 100.0 * (1.0 - rrse),
        "rrse": rrse,
        "r2": 1.0 - ss_err / ss_tot,
    }
    return {k: float(v) for k, v in out.items()}


def friction_metrics(y: ArrayLike, y_hat: ArrayLike) -> dict[str, float]:
    """All metrics of the module table for measured ``y`` and predicted ``y_hat``.

    Implements docs/algorithms.md §6 (MSE %, MAX, MATLAB's FIT %).
    Accepts NumPy or JAX arrays of equal shape (flattened; computed in
    float64) and returns plain Python floats, never NaN or inf: when the plain
    sums of squares would overflow or underflow (signals near 1e200 or 1e-200)
    they are formed on rescaled data instead.

    Raises ``ValueError`` for mismatched shapes, empty, complex or non-numeric
    input, NaN/inf, a measured signal with zero variance (every normalised
    metric would divide by zero), or errors so large that ``mse`` itself
    exceeds the float64 range.
    """
    y, y_hat = _as_checked_pair(y, y_hat)
    half_range = np.float64(0.5 * y.max() - 0.5 * y.min())  # max - min itself may overflow
    if half_range == 0.0:
        raise ValueError(
            "measured friction y has zero variance (a constant signal); "
            "mse_percent, fit_percent and r2 are undefined"
        )
    n = y.size
    f64 = np.float64
    y_absmax = f64(np.max(np.abs(y)))
    with np.errstate(over="ignore", invalid="ignore", under="ignore", divide="ignore"):
        y_range = 2.0 * half_range  # inf only for |y| near 1e308, where the rescaled path runs
        e = y - y_hat
        dev = y - y.mean()
        ss_tot = dev @ dev
        ss_err = e @ e
        mse = ss_err / n
        out = _table(ss_err, ss_tot, mse, np.sqrt(mse), 100.0 * mse * (2.0 / y_range) ** 2,
                     np.max(np.abs(e)), y_absmax)
        if not (ss_tot > 0.0 and all(np.isfinite(v) for v in out.values())):
            # Rescaled sums: y by max|y| and the error by max|e| (halved first if
            # y - y_hat itself overflows), so nothing overflows or underflows on the way.
            half = not np.all(np.isfinite(e))
            if half:
                e = 0.5 * y - 0.5 * y_hat
            e_max = np.max(np.abs(e))
            y_u = y / y_absmax
            dev_u = y_u - y_u.mean()
            ss_tot_u = dev_u @ dev_u
            if not ss_tot_u > 0.0:
                raise ValueError("measured friction y has (numerically) zero variance; "
                                 "mse_percent, fit_percent and r2 are undefined")
            if e_max == 0.0:
                out = _table(f64(0.0), f64(1.0), f64(0.0), f64(0.0), f64(0.0), f64(0.0), y_absmax)
            else:
                e_u = e / e_max
                e_scale = (2.0 if half else 1.0) * e_max
                ms_u = (e_u @ e_u) / n  # mean square error in units of e_scale^2
                rmse = e_scale * np.sqrt(ms_u)
                ratio = ((e_u @ e_u) / ss_tot_u) * (e_scale / y_absmax) ** 2
                out = _table(ratio, f64(1.0), rmse * rmse, rmse, 100.0 * ms_u * (e_scale / half_range) ** 2,
                             e_scale * np.max(np.abs(e_u)), y_absmax)
    bad = [k for k, v in out.items() if not np.isfinite(v)]
    if bad:
        raise ValueError(
            f"metrics {bad} exceed the float64 range (errors of about {out['rmse']:.3g} N); "
            "the prediction has diverged"
        )
    return out


def mse_percent_jax(y: ArrayLike, y_hat: ArrayLike, axis: int | None = -1) -> Array:
    """Normalised MSE in percent, ``100 mean(e^2) / var(y)`` (§6), traceable.

    For use inside jitted objectives: no input checks, reduces over ``axis``
    (default the last, so ``(P, T)`` predictions against a ``(T,)`` record give
    ``(P,)`` values). A constant ``y`` gives inf or NaN, which jaxfric's
    optimisers treat as the worst fitness.
    """
    y = jnp.asarray(y)
    y_hat = jnp.asarray(y_hat)
    e = y - y_hat
    return 100.0 * jnp.mean(e * e, axis=axis) / jnp.var(y, axis=axis)
