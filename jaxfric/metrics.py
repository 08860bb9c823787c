"""Error metrics for friction identification (ALGORITHMS.md §6; PEERS.md on FIT %).

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
"""Formula of each key returned by :func:`friction_metrics`, for reports."""


def _as_checked_pair(y, y_hat) -> tuple[np.ndarray, np.ndarray]:
    y = np.asarray(y, dtype=np.float64)
    y_hat = np.asarray(y_hat, dtype=np.float64)
    if y.shape != y_hat.shape:
        raise ValueError(f"y and y_hat must have the same shape, got {y.shape} and {y_hat.shape}")
    if y.size == 0:
        raise ValueError("y and y_hat must not be empty")
    for name, arr in (("y", y), ("y_hat", y_hat)):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} holds NaN or inf; metrics are undefined")
    return y.ravel(), y_hat.ravel()


def friction_metrics(y: ArrayLike, y_hat: ArrayLike) -> dict[str, float]:
    """All metrics of the module table for measured ``y`` and predicted ``y_hat``.

    Implements ALGORITHMS.md §6 (MSE %, MAX) and the MATLAB FIT % of PEERS.md.
    Accepts NumPy or JAX arrays of equal shape (flattened; computed in
    float64) and returns plain Python floats.

    Raises ``ValueError`` for mismatched shapes, empty input, NaN/inf, or a
    measured signal with zero variance (every normalised metric would divide by
    zero).
    """
    y, y_hat = _as_checked_pair(y, y_hat)
    e = y - y_hat
    dev = y - y.mean()
    ss_tot = float(dev @ dev)
    y_range = float(y.max() - y.min())
    if not ss_tot > 0.0 or y_range == 0.0:
        raise ValueError(
            "measured friction y has zero variance (a constant signal); "
            "mse_percent, fit_percent and r2 are undefined"
        )
    n = y.size
    ss_err = float(e @ e)
    mse = ss_err / n
    max_abs = float(np.max(np.abs(e)))
    y_absmax = float(np.max(np.abs(y)))
    rrse = float(np.sqrt(ss_err / ss_tot))
    return {
        "mse": mse,
        "rmse": float(np.sqrt(mse)),
        "mse_percent": 100.0 * ss_err / ss_tot,
        "mse_scaled_percent": 100.0 * mse * (2.0 / y_range) ** 2,
        "max_abs": max_abs,
        "max_percent": 100.0 * max_abs / y_absmax,
        "fit_percent": 100.0 * (1.0 - rrse),
        "rrse": rrse,
        "r2": 1.0 - ss_err / ss_tot,
    }


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
