"""Parameter uncertainty of a friction model identified inside the mechanics
(identify_motion): the Jacobian of the simulated position against central finite
differences of the public simulate_motion, and the Fit API on a MotionFit."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxfric import models
from jaxfric.motion import MotionData, MotionFit, friction_step, simulate_motion
from jaxfric.uncertainty import parameter_uncertainty

DT, N, N_TRAIN = 1e-3, 1500, 1200


def _motion_fit():
    model = models.Coulomb(v_eps=1e-3)
    theta = np.asarray(model.from_physical(Fc=12.0, sigma2=60.0), np.float64)
    t = np.arange(N) * DT
    u = 30 * np.sin(2 * np.pi * 1.3 * t) + 12 * np.sin(2 * np.pi * 3.1 * t + 1.0)
    out = simulate_motion(friction_step(model), jnp.asarray(theta), 2.5, jnp.asarray(u - 3.0), DT, 0.0, 0.0)
    x = np.asarray(out["x"]) + 2e-6 * np.random.default_rng(0).standard_normal(N)
    data = MotionData.from_arrays(u, x, DT)
    y = list(theta) + [np.log10(2.5), 3.0]
    fit = MotionFit.given(model, theta, mass=2.5, offset=3.0, dt=DT, n_train=N_TRAIN, n_samples=N,
                          mechanics={"error": "position", "horizon": None, "y": y,
                                     "search_names": list(model.param_names) + ["log10_mass", "offset"]})
    return model, fit, data, np.asarray(y)


def test_motion_jacobian_matches_finite_differences():
    with jax.enable_x64(True):
        model, fit, data, y = _motion_fit()
        u = parameter_uncertainty(fit, data, method="jacobian")

        @jax.jit  # the nine evaluations below: one compiled program
        def simulate(yy):
            return simulate_motion(friction_step(model), yy[:2], 10.0 ** yy[2],
                                   jnp.asarray(data.net_force[:N_TRAIN]) - yy[3], DT,
                                   data.position[0], data.velocity[0])["x"]

        def resid(yy):
            return np.asarray(simulate(jnp.asarray(yy))) - data.position[:N_TRAIN]

        r = resid(y)
        h = 1e-6 * np.maximum(np.abs(y), 1.0)
        jac = np.stack([(resid(y + h[i] * np.eye(4)[i]) - resid(y - h[i] * np.eye(4)[i])) / (2 * h[i])
                        for i in range(4)], axis=1)
    ref = r @ r / (N_TRAIN - 4) * np.linalg.inv(jac.T @ jac)
    np.testing.assert_allclose(u.cov_theta["jacobian"], ref, rtol=1e-3)
    assert u.names == ("Fc", "sigma2", "mass", "offset") and u.residual == "position [m]"
    assert u.intervals()["mass"][0] > 0


def test_motion_fit_shows_intervals():
    with jax.enable_x64(True):
        _, fit, data, _ = _motion_fit()
        fit = fit.replace(uncertainty=functools.partial(parameter_uncertainty, fit, data))
        iv = fit.intervals(0.95)
        assert iv["Fc"][0] < 12.0 < iv["Fc"][1] and iv["mass"][0] < 2.5 < iv["mass"][1]
        assert "uncertainty (hac" in fit.summary()


def test_motion_fit_on_several_records_runs_each_from_its_own_start():
    """identify_motion(train=[...]) attaches its training records concatenated; the
    residuals restart at each record (else the second record's positions, which start
    elsewhere, would leave a residual of the jump) and no Newey–West lag crosses it."""
    with jax.enable_x64(True):
        model, fit, data, y = _motion_fit()
        second = MotionData.from_arrays(data.force[:N_TRAIN], data.position[:N_TRAIN] + 0.05, DT)
        first = MotionData.from_arrays(data.force[:N_TRAIN], data.position[:N_TRAIN], DT)
        both = dataclasses.replace(first, **{k: np.concatenate([getattr(first, k), getattr(second, k)])
                                             for k in ("force", "position", "load", "velocity")})
        fit = fit.replace(n_train=2 * N_TRAIN, mechanics=fit.mechanics.replace(
            records={"train": [N_TRAIN, N_TRAIN], "valid": []}))
        u = parameter_uncertainty(fit, both)
    assert u.segments == (N_TRAIN, N_TRAIN) and u.n == 2 * N_TRAIN
    assert np.sqrt(u.s2) < 1e-4          # 2 µm noise plus filter edges, not a 5 cm jump
