"""The measurement pipeline: filter, derivatives, force balance, FrictionData, input checks."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal

from jaxfric import rig
from model_recovery import nmse_percent

FS = 128.0


# --------------------------------------------------------------------------- accuracy
def test_pipeline_friction_matches_true_friction(rig_record):
    data = rig.estimate_friction(rig_record.measurements(), rig.Cylinder())
    assert data.n_samples == 2000 and data.n_train == 1600
    f_true, f_est = np.asarray(rig_record.friction), np.asarray(data.friction)
    assert nmse_percent(f_true, f_est) < 1.0
    assert nmse_percent(f_true[:1600], f_est[:1600]) < 1.0
    assert nmse_percent(f_true[1600:], f_est[1600:]) < 1.0
    assert nmse_percent(rig_record.velocity, data.velocity) < 0.1
    np.testing.assert_allclose(float(data.dt), 1 / FS, rtol=1e-6)


def test_synthetic_friction_data_is_simulate_then_measure(rig_record):
    one_call = rig.synthetic_friction_data(jax.random.key(0))
    two_steps = rig.estimate_friction(rig_record.measurements(), rig.Rig())
    np.testing.assert_array_equal(np.asarray(one_call.friction), np.asarray(two_steps.friction))
    assert one_call.n_train == 1600


def test_frictionless_force_balance_is_zero_up_to_noise():
    r = rig.Rig(friction=rig.SealFriction.off())
    clean = rig.simulate(r, jax.random.key(0), sensors=rig.Sensors.ideal())
    est = np.asarray(rig.estimate_friction(clean.measurements(), r.cylinder).friction)
    assert np.all(np.asarray(clean.friction) == 0.0)
    # bookkeeping: ~0.5 N rms against pressure forces of ~30 kN and a load varying by kN
    assert np.sqrt(np.mean(est**2)) < 1.0

    noisy = rig.simulate(r, jax.random.key(0))
    est = np.asarray(rig.estimate_friction(noisy.measurements(), r.cylinder).friction)
    a1, a2 = (float(a) for a in rig.piston_areas(0.1, 0.07))
    as64 = lambda a: np.asarray(a, np.float64)  # noqa: E731
    noise_force = ((as64(noisy.p1) - as64(noisy.p1_true)) * a1 - (as64(noisy.p2) - as64(noisy.p2_true)) * a2
                   - (as64(noisy.load) - as64(noisy.load_true)))
    expected = rig.lowpass(noise_force, FS)
    # what is left is exactly the filtered sensor noise (plus the ~0.5 N of the clean case)
    assert np.sqrt(np.mean((est - expected) ** 2)) < 1.0
    assert np.sqrt(np.mean(est**2)) < 1.2 * np.sqrt(np.mean(expected**2)) + 1.0


def test_vertical_axis_gravity_sign():
    r = rig.Rig(cylinder=rig.Cylinder(gravity=9.81))
    rec = rig.simulate(r, jax.random.key(1))
    with_g = rig.estimate_friction(rec.measurements(), r.cylinder)
    without = rig.estimate_friction(rec.measurements(), r.cylinder, gravity=0.0)
    assert nmse_percent(rec.friction, with_g.friction) < 1.0
    np.testing.assert_allclose(np.asarray(without.friction) - np.asarray(with_g.friction),
                               r.cylinder.mass * 9.81, rtol=1e-4)


# --------------------------------------------------------------------------- filter
def _response_at(f, n=16384, cutoff=5.0, order=4):
    """Gain and phase of the pipeline's low-pass at ``f`` Hz, measured on a sinusoid."""
    t = np.arange(n) / FS
    y = rig.lowpass(np.sin(2 * np.pi * f * t), FS, cutoff, order)
    mid = slice(n // 4, 3 * n // 4)  # away from the filtfilt edge transients
    basis = np.stack([np.sin(2 * np.pi * f * t[mid]), np.cos(2 * np.pi * f * t[mid])], axis=1)
    (s, c), *_ = np.linalg.lstsq(basis, y[mid], rcond=None)
    return np.hypot(s, c), np.arctan2(c, s)


@pytest.mark.parametrize("f", [0.2, 1.0, 3.0, 4.5])
def test_filter_has_no_phase_lag_in_the_pass_band(f):
    gain, phase = _response_at(f)
    _, h = scipy.signal.sosfreqz(rig.butterworth_sos(FS), worN=[f], fs=FS)
    assert abs(phase) < 1e-6
    np.testing.assert_allclose(gain, np.abs(h[0]) ** 2, rtol=1e-5)
    if f <= 1.0:
        assert gain > 0.999


@pytest.mark.parametrize("f", [7.0, 10.0, 20.0])
def test_filter_attenuates_above_cutoff_as_designed(f):
    gain, _ = _response_at(f)
    sos = scipy.signal.butter(4, 5.0 / (FS / 2), output="sos")  # independent design in normalised units
    _, h = scipy.signal.sosfreqz(sos, worN=[f], fs=FS)
    np.testing.assert_allclose(gain, np.abs(h[0]) ** 2, rtol=1e-3, atol=1e-9)
    # forward-backward digital Butterworth (bilinear, pre-warped): |H|^2 = 1 / (1 + (W/Wc)^8), W = tan(pi f/fs)
    warped = np.tan(np.pi * f / FS) / np.tan(np.pi * 5.0 / FS)
    np.testing.assert_allclose(gain, 1.0 / (1.0 + warped**8), rtol=1e-3, atol=1e-9)
    assert gain < 0.1


def test_differentiate_matches_analytic_derivatives():
    t = np.arange(2000) / FS
    w, h = 2 * np.pi * 0.3, 1 / FS
    v, a = rig.differentiate(0.01 * np.sin(w * t), h)
    inner = slice(3, -3)
    # the analytic derivatives, within the second-order truncation error of central differences
    np.testing.assert_allclose(v[inner], (0.01 * w * np.cos(w * t))[inner], atol=0.01 * w * (w * h) ** 2 / 6)
    np.testing.assert_allclose(a[inner], (-0.01 * w**2 * np.sin(w * t))[inner], atol=0.01 * w**2 * (w * h) ** 2)
    # and exactly the central-difference values on a sinusoid
    np.testing.assert_allclose(v[inner], (0.01 * np.cos(w * t) * np.sin(w * h) / h)[inner], atol=1e-12)
    np.testing.assert_allclose(a[inner], (-0.01 * np.sin(w * t) * (np.sin(w * h) / h) ** 2)[inner], atol=1e-10)


def test_force_balance_areas():
    one = np.ones(3)
    f = rig.force_balance(2e6 * one, 1e6 * one, 500.0 * one, 0.1 * one, bore=0.1, rod=0.07, mass=100.0)
    expected = 2e6 * np.pi * 0.01 / 4 - 1e6 * np.pi * (0.01 - 0.0049) / 4 - 500.0 - 10.0
    np.testing.assert_allclose(f, expected, rtol=1e-12)


# --------------------------------------------------------------------------- FrictionData
def test_friction_data_split_views_and_pytree(rig_record):
    data = rig.estimate_friction(rig_record.measurements(), rig.Cylinder())
    tr, va = data.train(), data.valid()
    assert (tr.n_samples, tr.n_train) == (1600, 1600)
    assert (va.n_samples, va.n_train) == (400, 0)
    np.testing.assert_array_equal(np.asarray(va.velocity), np.asarray(data.velocity)[1600:])
    assert data.with_split(0.5).n_train == 1000 and data.with_split(n_train=1234).n_train == 1234

    @jax.jit
    def mse_train(scale, d):
        return jnp.mean((d.friction[: d.n_train] - scale * d.velocity[: d.n_train]) ** 2)

    assert np.isfinite(float(mse_train(1.0, data)))
    stacked = jax.tree.map(lambda a, b: jnp.stack([a, b]), data, data)
    out = jax.vmap(mse_train, in_axes=(None, 0))(1.0, stacked)
    assert out.shape == (2,)


def test_friction_data_from_arrays():
    v = np.sin(np.linspace(0, 6, 100))
    d = rig.FrictionData.from_arrays(v, 2 * v, 0.01)
    assert d.n_train == 80 and float(d.dt) == pytest.approx(0.01)
    d = rig.FrictionData.from_arrays(v, 2 * v, 5.0 + 0.01 * np.arange(100), train_fraction=0.5)
    assert d.n_train == 50 and float(d.t[0]) == pytest.approx(5.0)
    assert d.acceleration is None and d.p1 is None
    with pytest.raises(ValueError, match="not uniform"):
        rig.FrictionData.from_arrays(v, v, np.cumsum(np.linspace(0.01, 0.02, 100)))
    with pytest.raises(ValueError, match="train_fraction"):
        rig.FrictionData.from_arrays(v, v, 0.01, train_fraction=1.5)
    with pytest.raises(ValueError, match="friction"):
        rig.FrictionData.from_arrays(v, v[:50], 0.01)
    with pytest.raises(ValueError, match="dt"):
        rig.FrictionData.from_arrays(v, v, -0.01)


# --------------------------------------------------------------------------- bad input
def _measurements(n=400, **override):
    t = np.arange(n) / FS
    ch = dict(t=t, x=0.01 * np.sin(t), p1=4e6 + 0 * t, p2=6e6 + 0 * t, load=5e3 + 0 * t)
    ch.update(override)
    return ch


@pytest.mark.parametrize("channel, value, match", [
    ("p1", np.nan, "channel 'p1' has 1 non-finite samples \\(NaN"),
    ("load", np.inf, "channel 'load' has 1 non-finite samples \\(inf"),
    ("x", -np.inf, "channel 'x'"),
])
def test_non_finite_samples_are_rejected(channel, value, match):
    ch = _measurements()
    ch[channel] = ch[channel].copy()
    ch[channel][17] = value
    with pytest.raises(ValueError, match=match):
        rig.Measurements.from_arrays(**ch)


def test_time_stamp_errors():
    ch = _measurements()
    t = ch["t"].copy()
    t[10] = t[9]
    with pytest.raises(ValueError, match="duplicate time stamps"):
        rig.Measurements.from_arrays(**{**ch, "t": t})
    t = ch["t"].copy()
    t[10], t[11] = t[11], t[10]
    with pytest.raises(ValueError, match="not sorted"):
        rig.Measurements.from_arrays(**{**ch, "t": t})
    with pytest.raises(ValueError, match="channel 'p2' has 399 samples"):
        rig.Measurements.from_arrays(**{**ch, "p2": ch["p2"][:-1]})
    irregular = rig.Measurements.from_arrays(**{**ch, "t": np.cumsum(np.linspace(0.007, 0.009, 400))})
    with pytest.raises(ValueError, match="not uniform"):
        rig.estimate_friction(irregular, rig.Cylinder())


def test_filter_and_geometry_errors_come_before_computation():
    meas = rig.Measurements.from_arrays(**_measurements())
    short = rig.Measurements.from_arrays(**_measurements(n=15))  # padlen of order 4 is 15
    with pytest.raises(ValueError, match="too short.*padlen"):
        rig.estimate_friction(short, rig.Cylinder())
    with pytest.raises(ValueError, match="too short"):
        rig.lowpass(np.zeros(15), FS)
    for cutoff in (64.0, 100.0):
        with pytest.raises(ValueError, match="Nyquist"):
            rig.estimate_friction(meas, rig.Cylinder(), cutoff=cutoff)
    with pytest.raises(ValueError, match="cutoff"):
        rig.estimate_friction(meas, rig.Cylinder(), cutoff=-1.0)
    with pytest.raises(ValueError, match="bore"):
        rig.estimate_friction(meas, bore=-0.1, rod=0.05, mass=100.0)
    with pytest.raises(ValueError, match="rod"):
        rig.estimate_friction(meas, bore=0.1, rod=-0.05, mass=100.0)
    for rod in (0.1, 0.12):
        with pytest.raises(ValueError, match="smaller than the bore"):
            rig.estimate_friction(meas, bore=0.1, rod=rod, mass=100.0)
        with pytest.raises(ValueError, match="smaller than the bore"):
            rig.Cylinder(bore=0.1, rod=rod)
    with pytest.raises(ValueError, match="mass"):
        rig.estimate_friction(meas, bore=0.1, rod=0.05, mass=-1.0)
    with pytest.raises(ValueError, match="'mass' is required"):
        rig.estimate_friction(meas, bore=0.1, rod=0.05)


def test_one_record_type_and_one_split_rule():
    """Issue 19 item 1: the loaders' FrictionData is identify's record, split by one rule
    (round(fraction * n) training samples), and its channels stay float64 under x32."""
    from jaxfric.identification import Record, as_record

    assert Record is rig.FrictionData
    v = np.sin(np.linspace(0, 6, 101)) + 1e-9 * np.arange(101)  # not representable in float32
    f = 2 * v + 0.1 * v**3
    for n in (20, 101):
        for frac in (0.3, 0.5, 0.8, 0.95):
            d = rig.FrictionData.from_arrays(v[:n], f[:n], 0.01, frac)
            rec = as_record((v[:n], f[:n], 0.01), frac)
            assert d.n_train == rec.n_train == int(round(frac * n))
            assert type(rec) is rig.FrictionData and as_record(d).n_train == d.n_train
    assert d.velocity.dtype == np.float64 and np.array_equal(d.velocity, v)
    assert d.with_split(n_train=7).n_train == 7 and d.with_split(1).n_train == 101
