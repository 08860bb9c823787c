"""``identify_motion`` with a k-step ``horizon`` or a velocity ``error`` and the default
search: one Levenberg–Marquardt stage on the terms of that cost (it once handed the
scalar J to Levenberg–Marquardt and crashed). The truth of a simulated Coulomb + viscous
axis comes back."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfric import models
from jaxfric.motion import MotionData, friction_step, identify_motion, simulate_motion


@pytest.fixture(scope="module")
def drive():
    model = models.Coulomb(v_eps=1e-3)
    n, dt = 600, 1e-3
    t = np.arange(n) * dt
    u = 30 * np.sin(2 * np.pi * 1.3 * t) + 12 * np.sin(2 * np.pi * 3.1 * t + 1.0)
    with jax.enable_x64(True):
        out = simulate_motion(friction_step(model), jnp.asarray(model.from_physical(Fc=12.0, sigma2=60.0)),
                              2.5, u, dt, 0.0, 0.0)
    return MotionData.from_arrays(u, np.asarray(out["x"]), dt)


@pytest.mark.parametrize("option", [{"horizon": 50}, {"error": "velocity"}])
def test_k_step_and_velocity_costs_recover_the_truth_with_the_default_search(drive, option):
    with jax.enable_x64(True):
        fit = identify_motion(models.Coulomb(v_eps=1e-3), drive, key=0, mass=2.5, dtype=jnp.float64, **option)
    assert fit.params["Fc"] == pytest.approx(12.0, rel=0.01)
    assert fit.params["sigma2"] == pytest.approx(60.0, rel=0.01)
    assert fit.metrics["train"]["rmse_mm"] < 0.01 * 1e3 * np.ptp(drive.position)
