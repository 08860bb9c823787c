"""Friction compensation on the rig simulator (docs/algorithms.md §13.3)."""

import dataclasses

import jax
import numpy as np
import pytest

from jaxfric import Fit, compensation as C, models
from jaxfric.rig import Rig, SealFriction


class _SpyFit:
    """A fit stand-in that records what the compensator asks of it."""

    def __init__(self, level):
        self.level, self.dt, self.calls = level, 4e-3, []

    def predict(self, velocity, dt=None):
        self.calls.append((np.asarray(velocity).copy(), dt))
        return self.level * np.tanh(np.asarray(velocity) / 1e-3)


def _short_ref():
    return C.reference(fs=250.0, amplitude=3e-3, period=3.0, ramp_time=1.0, hold=0.2)


def test_feedforward_sees_only_fit_and_reference():
    """The compensator's signal is computed from the fit and the reference velocity alone:
    the same for rigs with different true friction, and exactly the fit's prediction."""
    ref = _short_ref()
    spy = _SpyFit(300.0)
    ff = C.feedforward(spy, ref)
    (v_seen, dt_seen), = spy.calls
    np.testing.assert_array_equal(v_seen, ref.v)
    assert dt_seen == ref.dt
    np.testing.assert_allclose(ff, 300.0 * np.tanh(ref.v / 1e-3))
    # the loop never calls the fit: a rig with other friction sees the same feed-forward
    other = dataclasses.replace(Rig(), friction=SealFriction(coulomb_pos=50.0, coulomb_neg=50.0))
    with jax.enable_x64(True):
        a = C.track(Rig(), ref, ff, substeps=2)
        b = C.track(other, ref, ff, substeps=2)
    assert len(spy.calls) == 1
    np.testing.assert_array_equal(a["feedforward"], ff)
    np.testing.assert_array_equal(b["feedforward"], ff)
    assert not np.allclose(a["friction"], b["friction"])


@pytest.mark.slow
def test_ideal_compensation_beats_none_and_zero_fit_equals_none():
    ref = _short_ref()
    zero = Fit(model=models.Coulomb(), theta=np.array([0.0, 0.0]), velocity_scaler=None,
               friction_scaler=None, dt=ref.dt, n_train=10, n_samples=10, metrics={})
    ff0 = C.feedforward(zero, ref)
    assert np.allclose(ff0, 1.0 * ref.v)  # Fc = 0, sigma2 = 10**0 = 1 N s/m
    with jax.enable_x64(True):
        rows, runs = C.compensation_study({}, ref=ref, substeps=2)
        none = C.track(Rig(), ref, None, substeps=2)
    by = {r["compensation"]: r for r in rows}
    np.testing.assert_array_equal(none["x"], runs["none"]["x"])
    assert by["ideal (true friction)"]["rms_mm"] < 0.6 * by["none"]["rms_mm"]
    assert "| none |" in C.compensation_table(rows)


def test_track_rejects_bad_feedforward():
    ref = _short_ref()
    with pytest.raises(ValueError, match="one value per reference sample"):
        C.track(Rig(), ref, np.zeros(3))
    bad = np.zeros(ref.v.size)
    bad[3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        C.track(Rig(), ref, bad)
