"""The position band of a motion fit on a new record (docs/uncertainty.md, "Position band").

A free run ``x̂(y)`` of a record from its first ``N`` samples (the rule of
[`MotionFit.simulate`][jaxfric.motion.MotionFit.simulate]``(record, init_window=N)``) is a function
of the fit's search coordinates ``y`` (the model's θ, then the mass, offset and ``v0`` it
identified). Linearised at the estimate, ``x̂(y) ≈ x̂(ŷ) + J (y − ŷ)`` with
``J = ∂x̂/∂y`` (``jax.jacfwd``), so the band of the simulated position is

    x̂_k ± t_{ν, (1+level)/2} √( j_k Σ j_kᵀ + s² )

with ``Σ`` the fit's box-capped parameter covariance (Newey–West by default: a free run's
residuals drift, so the i.i.d. Jacobian covariance is far too narrow) and ``s²`` the
variance of the fit's own training position residuals (``noise=False`` leaves it out:
the band of the simulated position alone). The spread grows along the run as a wrong
friction level integrates into position. What it misses (a drifting force offset, a
model that cannot represent the friction) is measured, not promised:
``benchmarks/results/motion_band.md``.
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
    """``x̂(y)``: positions of a free run from the initial state the first ``N`` samples set
    (their smoothed positions and slopes ``x_window``, ``v_window``: the friction state is
    tracked along ``v_window`` with the friction parameters in ``y``), driven by the net
    force from sample ``N − 1`` on minus the offset in ``y``. Samples before ``N − 1``
    are the window's and do not depend on ``y``."""

    step: Any
    layout: Layout
    mass: np.ndarray  # used unless "log10_mass" is searched
    dt: np.ndarray
    force: np.ndarray  # net force from sample N - 1 on
    x_window: np.ndarray
    v_window: np.ndarray

    def __call__(self, y):
        theta, mass, offset, _ = self.layout.unpack(y, {"mass": jnp.asarray(self.mass, y.dtype)})
        dt = jnp.asarray(self.dt, y.dtype)
        v_win = jnp.asarray(self.v_window, y.dtype)
        s0 = jax.tree_util.tree_map(lambda a: a[-1], track_states(self.step, theta, v_win, dt))
        run = simulate_motion(self.step, theta, mass, jnp.asarray(self.force, y.dtype) - offset, dt,
                              jnp.asarray(self.x_window[-1], y.dtype), v_win[-1], s0)["x"]
        return jnp.concatenate([jnp.asarray(self.x_window[:-1], y.dtype), run])


@eqx.filter_jit
def _linearised(positions: FreeRunPositions, y):
    return positions(y), jax.jacfwd(positions)(y)


def position_band(positions: FreeRunPositions, y, cov, t: float, s2: float) -> tuple:
    """``(x̂, half-width)`` [m] of the band above for covariance ``cov`` of ``y``, quantile
    ``t`` and residual variance ``s2`` (float64 NumPy)."""
    x_hat, jac = (np.asarray(a, np.float64) for a in _linearised(positions, y))
    var = np.einsum("ta,ab,tb->t", jac, np.asarray(cov, np.float64), jac) + s2
    return x_hat, t * np.sqrt(np.clip(var, 0.0, None))
