"""Parameter uncertainty of a friction model identified inside the mechanics
(identify_motion): the Jacobian of the simulated position against central finite
differences of the public simulate_motion, and the Fit API on a MotionFit."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfric.uncertainty
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


def _chirp_record(model, theta, noise=0.0, seed=1):
    """A record of the same mechanics driven by an excitation the fit never saw (a chirp),
    its positions with white noise of standard deviation ``noise`` [m]."""
    t = np.arange(1000) * DT
    u = 25 * np.sin(2 * np.pi * (0.5 * t + 2.0 * t ** 2))
    out = simulate_motion(friction_step(model), jnp.asarray(theta), 2.5, jnp.asarray(u - 3.0), DT, 0.0, 0.0)
    x = np.asarray(out["x"]) + noise * np.random.default_rng(seed).standard_normal(t.size)
    return MotionData.from_arrays(u, x, DT)


def test_motion_position_band_is_the_linearised_free_run():
    """MotionFit.prediction_interval on a new noisy record: its centre is simulate(record,
    init_window=N)'s free run, and its half-width t sqrt(j Σ jᵀ + σ_w² h hᵀ + s²) equals the
    one built from central finite differences of public MotionFit.given(...).simulate runs,
    in the search coordinates (θ, log10 mass, offset; j) and in the N window positions (h),
    with the same covariance and σ_w² the residual variance of a quadratic np.polyfit of
    the window; noise=False leaves out s², so it is narrower."""
    with jax.enable_x64(True):
        model, fit, data, y = _motion_fit()
        fit = fit.replace(uncertainty=functools.partial(parameter_uncertainty, fit, data))
        new = _chirp_record(model, fit.theta, noise=2e-6)
        x_hat, low, high = fit.prediction_interval(new, 0.9, init_window=20)
        _, low0, high0 = fit.prediction_interval(new, 0.9, init_window=20, noise=False)

        def run(yy, record=new):
            return MotionFit.given(model, yy[:2], mass=10.0 ** yy[2], offset=yy[3], dt=DT).simulate(
                record, init_window=20)["x"]

        def moved(k, by):  # the record with window position k moved
            x = new.position.copy()
            x[k] += by
            return MotionData.from_arrays(new.force, x, DT)

        h = 1e-6 * np.maximum(np.abs(y), 1.0)
        jac = np.stack([(run(y + h[i] * np.eye(4)[i]) - run(y - h[i] * np.eye(4)[i])) / (2 * h[i])
                        for i in range(4)], axis=1)
        head = np.stack([(run(y, moved(k, 1e-8)) - run(y, moved(k, -1e-8))) / 2e-8 for k in range(20)], axis=1)
        u = fit.uncertainty
        np.testing.assert_allclose(x_hat, fit.simulate(new, init_window=20)["x"], rtol=0, atol=1e-15)
    tau = (np.arange(20) - 19) * DT
    window = new.position[:20]
    s_w2 = np.sum((window - np.polyval(np.polyfit(tau, window, 2), tau)) ** 2) / 17
    var = np.einsum("ta,ab,tb->t", jac, u.box_capped("hac", 0.9), jac) + s_w2 * np.sum(head ** 2, axis=1)
    t = u.t_quantile(0.9)
    np.testing.assert_allclose(high - x_hat, t * np.sqrt(var + u.s2), rtol=1e-4)
    np.testing.assert_allclose(high0 - x_hat, t * np.sqrt(var), rtol=1e-4, atol=1e-15)
    np.testing.assert_allclose(x_hat - low, high - x_hat, rtol=1e-12)
    assert np.all(high0 - low0 < high - low)
    head_var = s_w2 * np.sum(head ** 2, axis=1)
    assert head_var[-1] > 3 * np.einsum("a,ab,b->", jac[-1], u.box_capped("hac", 0.9), jac[-1])  # noise dominates


def test_motion_position_band_holds_a_correct_models_new_recording():
    """The fit at the true parameters of a simulated axis (2 µm white position noise),
    bands of 20 new noisy chirp recordings: the 95 % band holds at least 85 % of their
    samples on average. Without the initial state's share (σ_w² h hᵀ) it held well under
    half: the velocity fitted to 20 noisy positions starts a drift the friction damps."""
    held = []
    with jax.enable_x64(True):
        model, fit, data, _ = _motion_fit()
        fit = fit.replace(uncertainty=functools.partial(parameter_uncertainty, fit, data))
        for seed in range(20):
            new = _chirp_record(model, fit.theta, noise=2e-6, seed=100 + seed)
            _, lo, hi = fit.prediction_interval(new, 0.95, init_window=20)
            held.append(np.mean(((new.position >= lo) & (new.position <= hi))[20:]))
    assert np.mean(held) >= 0.85, held


def test_motion_position_band_rejects_what_it_cannot_do():
    with jax.enable_x64(True):
        model, fit, data, _ = _motion_fit()
        with pytest.raises(ValueError, match="no parameter uncertainty"):
            fit.replace(uncertainty=None).prediction_interval(data)
        fit = fit.replace(uncertainty=functools.partial(parameter_uncertainty, fit, data))
        with pytest.raises(ValueError, match="level"):
            fit.prediction_interval(data, 95)
        with pytest.raises(ValueError, match="sample time"):
            fit.prediction_interval(MotionData.from_arrays(data.force, data.position, 2 * DT))
        with pytest.raises(ValueError, match="init_window"):
            fit.prediction_interval(data.window(0, 10))
        with pytest.raises(ValueError, match="about position"):
            jaxfric.uncertainty.prediction_interval(fit, data.velocity)
        vfit = fit.replace(mechanics=fit.mechanics.replace(error="velocity"), uncertainty=None)
        vfit = vfit.replace(uncertainty=functools.partial(parameter_uncertainty, vfit, data))
        with pytest.raises(ValueError, match="velocity"):  # s² in (m/s)² is no position variance
            vfit.prediction_interval(data)
        x, lo, hi = vfit.prediction_interval(data, noise=False)
        assert np.all(lo <= x) and np.all(x <= hi) and np.all(np.isfinite(hi))


def test_motion_position_band_covers_new_emps_motion_only_with_the_newey_west_covariance():
    """docs/uncertainty.md's measured claim (benchmarks/results/motion_band.md): a Coulomb fit
    on EMPS block 0 (80 %), its 95 % band on blocks 1 and 2 run from their first 20 samples:
    the Newey–West band holds at least 80 % of their samples and is at least twice as wide as
    the i.i.d. Jacobian band with s², which holds less than half of block 2's. Skipped
    without the file."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from _harness import emps_file
    from motion_judge import emps_blocks

    from jaxfric.motion import identify_motion

    path = emps_file()
    if path is None:
        pytest.skip("DATA_EMPS.mat not found (JAXFRIC_DATA, ../shared/data)")
    blocks = emps_blocks(path)
    with jax.enable_x64(True):
        fit = identify_motion("coulomb", blocks["block0"], key=0, train=0.8, mass=(50.0, 200.0),
                              fit_offset=True, dtype=jnp.float64, progress=False)
        for name in ("block1", "block2"):
            b = blocks[name]
            held = {}
            for method in ("hac", "jacobian"):
                x, lo, hi = fit.prediction_interval(b, method=method)
                held[method] = (np.mean((b.position >= lo) & (b.position <= hi)), np.mean(hi - lo))
            assert held["hac"][0] >= 0.8 and held["hac"][1] > 2 * held["jacobian"][1], (name, held)
        assert held["jacobian"][0] < 0.5, held


def test_plot_position_band_draws_the_band_and_says_what_it_holds():
    """jaxfric.plot.plot_position_band: the run and the band in the top axes, the error
    inside the band below, whose legend quotes the share of samples held, recomputed here
    from prediction_interval; a force-balance fit or a bare array is refused."""
    from jaxfric.plot import plot_position_band

    with jax.enable_x64(True):
        model, fit, data, _ = _motion_fit()
        fit = fit.replace(uncertainty=functools.partial(parameter_uncertainty, fit, data))
        new = _chirp_record(model, fit.theta, noise=2e-6)
        fig = plot_position_band(fit, new, level=0.9)
        _, lo, hi = fit.prediction_interval(new, 0.9)
        with pytest.raises(TypeError, match="MotionData"):
            plot_position_band(fit, new.position)
    held = np.mean(((new.position >= lo) & (new.position <= hi))[20:])
    top, bottom = fig.axes[:2]
    texts = [t.get_text() for t in bottom.get_legend().get_texts()]
    assert f"90% band: holds {held:.1%} of the samples" in texts, texts
    assert np.allclose(top.lines[0].get_ydata(), 1e3 * new.position)
    with pytest.raises(TypeError, match="MotionFit"):
        plot_position_band(jaxfric.Fit.__new__(jaxfric.Fit), new)
