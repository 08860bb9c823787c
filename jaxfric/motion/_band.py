"""The position band of a motion fit on a new record (docs/uncertainty.md, "Position band").

A free run ``x̂(y)`` of a record from its first ``N`` samples (the rule of
[`MotionFit.simulate`][jaxfric.motion.MotionFit.simulate]``(record, init_window=N)``) is a function
of the fit's search coordinates ``y`` (the model's θ, then the mass, offset and ``v0`` it
identified). Linearised at the estimate, ``x̂(y) ≈ x̂(ŷ) + J (y − ŷ)`` with
``J = ∂x̂/∂y`` (``jax.jacfwd``), so the band of the simulated position is

    x̂_k ± t_{ν, (1+level)/2} √( j_k Σ j_kᵀ + σ_w² h_k h_kᵀ + s² )

with ``Σ`` the fit's box-capped parameter covariance (Newey–West by default: a free run's
residuals drift, so the i.i.d. Jacobian covariance is far too narrow), ``h_k = ∂x̂_k/∂x̃_w``
the run's sensitivity to the ``N`` window positions ``x̃_w`` the initial state is fitted to
(position and velocity from a polynomial, a linear map of them), ``σ_w²`` the variance of
that polynomial's residuals (the position noise, ``N − degree − 1`` degrees of freedom; 0
when ``N`` leaves none), and ``s²`` the variance of the fit's own training position
residuals (``noise=False`` leaves it out: the band of the simulated position alone). The
spread grows along the run as a wrong friction level integrates into position; a noisy
initial velocity adds a drift the friction then damps. What it misses (a drifting force
offset, a model that cannot represent the friction, a start the rule's polynomial does not
follow) is measured, not promised: ``benchmarks/results/motion_band.md`` and notebook 04.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._forward import simulate_motion, track_states
from ._layout import Layout


class FreeRunPositions(eqx.Module):
    """``x̂(y, d)``: positions of a free run from the initial state the first ``N`` samples
    set (their smoothed positions and slopes ``x_window``, ``v_window``, moved by ``x_map @ d``
    and ``v_map @ d`` when the window's measured positions move by ``d``; the friction state
    is tracked along the slopes with the friction parameters in ``y``), driven by the net
    force from sample ``N − 1`` on minus the offset in ``y``. Samples before ``N − 1`` are
    the window's."""

    step: Any
    layout: Layout
    mass: np.ndarray  # used unless "log10_mass" is searched
    dt: np.ndarray
    force: np.ndarray  # net force from sample N - 1 on
    x_window: np.ndarray
    v_window: np.ndarray
    x_map: np.ndarray  # (N, N): smoothed positions per measured window position
    v_map: np.ndarray  # (N, N): smoothed slopes per measured window position

    def __call__(self, y, d):
        theta, mass, offset, _ = self.layout.unpack(y, {"mass": jnp.asarray(self.mass, y.dtype)})
        dt = jnp.asarray(self.dt, y.dtype)
        x_win = jnp.asarray(self.x_window, y.dtype) + jnp.asarray(self.x_map, y.dtype) @ d
        v_win = jnp.asarray(self.v_window, y.dtype) + jnp.asarray(self.v_map, y.dtype) @ d
        s0 = jax.tree_util.tree_map(lambda a: a[-1], track_states(self.step, theta, v_win, dt))
        run = simulate_motion(self.step, theta, mass, jnp.asarray(self.force, y.dtype) - offset, dt,
                              x_win[-1], v_win[-1], s0)["x"]
        return jnp.concatenate([x_win[:-1], run])


def window_maps(n: int, dt: float, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """``(x_map, v_map)``: the least-squares polynomial of ``degree`` through ``n`` positions
    at ``τ_i = (i − (n − 1)) dt``, its values and slopes at the ``τ_i`` as linear maps of
    the positions (``V V⁺`` and ``V′ V⁺``, ``V`` the Vandermonde matrix)."""
    tau = (np.arange(n) - (n - 1)) * float(dt)
    powers = np.arange(degree, -1, -1)
    vander = tau[:, None] ** powers
    slope = np.where(powers > 0, powers * tau[:, None] ** np.maximum(powers - 1, 0), 0.0)
    pinv = np.linalg.pinv(vander)
    return vander @ pinv, slope @ pinv


@eqx.filter_jit
def _linearised(positions: FreeRunPositions, y, d):
    return positions(y, d), jax.jacfwd(positions, argnums=(0, 1))(y, d)


def position_band(positions: FreeRunPositions, y, cov, window_var: float, t: float, s2: float) -> tuple:
    """``(x̂, half-width)`` [m] of the band above for covariance ``cov`` of ``y``, window
    noise variance ``window_var``, quantile ``t`` and residual variance ``s2`` (float64 NumPy)."""
    d = jnp.zeros(np.shape(positions.x_window), y.dtype)
    x_hat, (jac, head) = _linearised(positions, y, d)
    x_hat, jac, head = (np.asarray(a, np.float64) for a in (x_hat, jac, head))
    var = np.einsum("ta,ab,tb->t", jac, np.asarray(cov, np.float64), jac) + window_var * np.sum(head ** 2, axis=1) + s2
    return x_hat, t * np.sqrt(np.clip(var, 0.0, None))
