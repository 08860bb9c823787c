"""``identify_motion`` with a k-step ``horizon`` or a velocity ``error`` and the default
search: one Levenberg–Marquardt stage on the terms of that cost (it once handed the
scalar J to Levenberg–Marquardt and crashed). The truth of a simulated Coulomb + viscous
axis comes back."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from conftest import coulomb_drive
from jaxfric import models
from jaxfric.motion import identify_motion


@pytest.fixture(scope="module")
def drive():
    return coulomb_drive()


@pytest.mark.parametrize("option", [{"horizon": 50}, {"error": "velocity"}])
def test_k_step_and_velocity_costs_recover_the_truth_with_the_default_search(drive, option):
    with jax.enable_x64(True):
        fit = identify_motion(models.Coulomb(v_eps=1e-3), drive, key=0, mass=2.5, dtype=jnp.float64, **option)
    assert fit.params["Fc"] == pytest.approx(12.0, rel=0.01)
    assert fit.params["sigma2"] == pytest.approx(60.0, rel=0.01)
    assert fit.metrics["train"]["rmse_mm"] < 0.01 * 1e3 * np.ptp(drive.position)
