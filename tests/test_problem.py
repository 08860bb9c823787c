"""The problem interface (jaxfric.problem, issue 46): a fit names its problem, and both
problems' methods (search coordinates and box, training records, residuals, training
velocity, score) against independent computations: a NumPy Stribeck curve for the force
balance, the fit's own free run for the motion problem. No registry is left."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfric.uncertainty
from jaxfric import Fit, FrictionData, models
from jaxfric.identification import RecordSet, as_records
from jaxfric.motion import MotionData, MotionFit, friction_step, simulate_motion
from jaxfric.motion import MotionProblem
from jaxfric.problem import AbstractProblem, ForceBalanceProblem, TrainingRecords

DT = 1e-3
FC, FS, VS, SIGMA2 = 20.0, 32.0, 4e-3, 150.0


def _stribeck_numpy(v, fc=FC, fs=FS, vs=VS, sigma2=SIGMA2, v_eps=1e-4):
    """F = tanh(v / v_eps) (Fc + (Fs - Fc) exp(-(v / vs)^2)) + sigma2 v, in NumPy."""
    return np.tanh(v / v_eps) * (fc + (fs - fc) * np.exp(-((v / vs) ** 2))) + sigma2 * v


def _static_record(n=600, n_train=450, seed=0, phase=0.0):
    v = 0.02 * np.sin(np.arange(n) * 0.02 + phase)
    f = _stribeck_numpy(v) + 0.5 * np.random.default_rng(seed).standard_normal(n)
    return FrictionData.from_arrays(v, f, DT, n_train=n_train)


def _stribeck_fit(n_train=450, n=600):
    model = models.Stribeck()
    # a fit slightly off the truth, so that the residuals are not only the noise
    theta = np.asarray(model.from_physical(Fc=FC + 1.0, Fs=FS - 2.0, vs=VS * 1.1, sigma2=SIGMA2), np.float64)
    return Fit(model=model, theta=theta, velocity_scaler=None, friction_scaler=None, dt=DT,
               n_train=n_train, n_samples=n, metrics={})


def test_each_fit_names_its_problem_and_no_registry_is_left():
    assert isinstance(Fit.problem(), ForceBalanceProblem) and isinstance(MotionFit.problem(), MotionProblem)
    assert isinstance(MotionProblem(), AbstractProblem) and isinstance(ForceBalanceProblem(), AbstractProblem)
    assert issubclass(RecordSet, TrainingRecords)
    with pytest.raises(TypeError):
        AbstractProblem()  # the interface alone is abstract
    for gone in ("register_fit_kind", "register_training_records", "FitKind", "_registered", "_FIT_KINDS"):
        assert not hasattr(jaxfric.uncertainty, gone), gone


def test_force_balance_problem_against_numpy():
    with jax.enable_x64(True):
        fit, rec = _stribeck_fit(), _static_record()
        problem = fit.problem()
        coords = problem.coordinates(fit)
        res = problem.residuals(fit, rec)
        r = np.asarray(res.fn(jnp.asarray(res.y)))
        score = problem.score(fit, rec)
    assert coords.names == ("Fc", "Fs", "vs", "sigma2") and coords.kinds == ("linear", "ratio", "log10", "log10")
    np.testing.assert_array_equal(coords.y, fit.theta)
    lo, hi = fit.model.bounds(fit.box)
    np.testing.assert_array_equal(coords.lower, lo)
    np.testing.assert_array_equal(coords.upper, hi)
    assert (res.names, res.kinds, res.segments, res.unit) == (coords.names, coords.kinds, (450,), "friction [N]")
    pred = _stribeck_numpy(rec.velocity, fc=FC + 1.0, fs=FS - 2.0, vs=VS * 1.1)
    np.testing.assert_allclose(r, pred[:450] - rec.friction[:450], rtol=1e-9, atol=1e-9)
    (window,) = problem.training_records(fit, rec)
    assert window.n_train == 450 and window.velocity.shape == (600,)
    np.testing.assert_array_equal(problem.train_velocity(fit, rec), rec.velocity[:450])
    # the score: MSE % of the free run over the whole record (§6: 100 mean(e^2) / var(y))
    e = rec.friction - pred
    mse_percent = 100 * np.mean(e**2) / np.var(rec.friction)
    assert score[problem.metric] == pytest.approx(mse_percent, rel=1e-9)


def test_force_balance_problem_reads_a_record_set_and_a_tuple():
    """A RecordSet's training records (a TrainingRecords), each its own segment; a
    (velocity, friction, dt) tuple as the one record."""
    with jax.enable_x64(True):
        fit = _stribeck_fit(n_train=1000, n=1500)
        a, b, c = (_static_record(500, 400, seed=k, phase=k) for k in range(3))
        records = as_records(train=[a, b], valid=c)
        problem = fit.problem()
        res = problem.residuals(fit, records)
        r = np.asarray(res.fn(jnp.asarray(res.y)))
        tup = problem.residuals(fit.replace(n_train=400, n_samples=500), (a.velocity, a.friction, DT))
        r_tup = np.asarray(tup.fn(jnp.asarray(tup.y)))
    assert [w.n_train for w in problem.training_records(fit, records)] == [500, 500]
    assert res.segments == (500, 500) and tup.segments == (400,)
    want = [_stribeck_numpy(x.velocity, fc=FC + 1.0, fs=FS - 2.0, vs=VS * 1.1) - x.friction for x in (a, b)]
    np.testing.assert_allclose(r, np.concatenate(want), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(r_tup, want[0][:400], rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(problem.train_velocity(fit, records), np.concatenate([a.velocity, b.velocity]))


def _motion_fit(n=800, n_train=600):
    model = models.Coulomb(v_eps=1e-3)
    theta = np.asarray(model.from_physical(Fc=12.0, sigma2=60.0), np.float64)
    t = np.arange(n) * DT
    u = 30 * np.sin(2 * np.pi * 1.3 * t) + 12 * np.sin(2 * np.pi * 3.1 * t + 1.0)
    out = simulate_motion(friction_step(model), jnp.asarray(theta), 2.5, jnp.asarray(u - 3.0), DT, 0.0, 0.0)
    x = np.asarray(out["x"]) + 2e-6 * np.random.default_rng(0).standard_normal(n)
    data = MotionData.from_arrays(u, x, DT)
    # slightly off the truth: the residuals are the fit's error, not only the noise
    y = [theta[0] * 1.05, theta[1], np.log10(2.6), 3.0]
    fit = MotionFit.given(model, np.asarray(y[:2]), mass=2.6, offset=3.0, dt=DT, n_train=n_train, n_samples=n,
                          mechanics={"error": "position", "horizon": None, "y": y,
                                     "search_names": list(model.param_names) + ["log10_mass", "offset"]})
    return fit, data


def test_motion_problem_against_the_fits_own_free_run():
    with jax.enable_x64(True):
        fit, data = _motion_fit()
        problem = fit.problem()
        coords = problem.coordinates(fit)
        res = problem.residuals(fit, data)
        r = np.asarray(res.fn(jnp.asarray(res.y)))
        free_run = fit.simulate_from(data, 0, 600)["x"]
        score = problem.score(fit, data)
        x_hat = fit.simulate(data, init_window=20)["x"]
    assert coords.names == ("Fc", "sigma2", "mass", "offset") and coords.kinds[2] == "log10"
    np.testing.assert_allclose(coords.y, [fit.theta[0], fit.theta[1], np.log10(2.6), 3.0])
    assert coords.lower.shape == coords.upper.shape == (4,)
    assert res.names == coords.names and res.segments == (600,) and res.unit == "position [m]"
    np.testing.assert_allclose(r, free_run - data.position[:600], rtol=1e-7, atol=1e-12)
    assert np.max(np.abs(r)) > 1e-5  # the fit is off: the comparison is not 0 == 0
    (window,) = problem.training_records(fit, data)
    assert window.n_samples == 600
    np.testing.assert_array_equal(window.position, data.position[:600])
    np.testing.assert_array_equal(problem.train_velocity(fit, data), data.velocity[:600])
    rmse_mm = 1e3 * np.sqrt(np.mean((x_hat[20:] - data.position[20:]) ** 2))
    assert problem.metric == "rmse_mm" and score["rmse_mm"] == pytest.approx(rmse_mm, rel=1e-9)


def test_motion_problem_cuts_whole_training_records():
    fit, data = _motion_fit()
    fit = fit.replace(mechanics=fit.mechanics.replace(records={"train": [250, 350], "valid": []}))
    first, second = fit.problem().training_records(fit, data)
    np.testing.assert_array_equal(first.force, data.force[:250])
    np.testing.assert_array_equal(second.force, data.force[250:600])


def test_a_motion_fit_read_as_a_force_balance_fit_is_told_so(tmp_path):
    """A motion fit's file read by load_fit is refused naming load_motion_fit (it used to come
    back as a plain Fit without its mechanics); load_motion_fit reads every field of the
    mechanics back and refuses a force-balance file; the force-balance residuals refuse a
    motion fit by its problem; the mechanics are as immutable as the fit."""
    import dataclasses

    from jaxfric.fit import FitKindError, load_fit
    from jaxfric.motion import load_motion_fit

    fit, data = _motion_fit()
    fit = fit.replace(mechanics=fit.mechanics.replace(baseline={"M": 2.4, "Fc": 1.0, "Fv": 2.0, "offset": 0.5},
                                                      stopped="max_time", records={"train": [600], "valid": []}))
    fit.save(tmp_path / "motion.npz")
    with pytest.raises(FitKindError, match="load_motion_fit"):
        load_fit(tmp_path / "motion.npz")
    back = load_motion_fit(tmp_path / "motion.npz")
    assert back.mechanics == fit.mechanics and "motion" not in back.settings
    plain = Fit(**{k: getattr(fit, k) for k in Fit.FIELDS if k != "uncertainty"})
    assert isinstance(plain.problem(), ForceBalanceProblem) and not isinstance(fit.problem(), ForceBalanceProblem)
    plain.save(tmp_path / "plain.npz")
    with pytest.raises(FitKindError, match="load_fit"):
        load_motion_fit(tmp_path / "plain.npz")
    with pytest.raises(ValueError, match="MotionProblem"):
        ForceBalanceProblem().residuals(fit, _static_record())
    with pytest.raises(dataclasses.FrozenInstanceError):
        fit.mechanics.mass = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        fit.mechanics = fit.mechanics
