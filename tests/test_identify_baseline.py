"""The least-squares baseline beside every force-balance fit (issue 45 item 3 for
``identify``; docs/identify.md "The baseline"): its solution against scipy's least squares
on independently built regressors, its metrics scored like the fit's, the warning when the
fit is worse, and the round trip through ``save``/``load_fit``."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.linalg

import jaxfric as jf
from jaxfric._warnings import BaselineWarning
from jaxfric.identification import as_records
from jaxfric.identification.stages import least_squares_baseline
from jaxfric.metrics import friction_metrics


def _record(n=800, n_train=640, dt=1e-2, noise=3.0):
    """Coulomb 120 N, viscous 900 N s/m, offset -15 N along two tones, with noise."""
    t = np.arange(n) * dt
    v = 0.05 * np.sin(2 * np.pi * 0.3 * t) + 0.02 * np.sin(2 * np.pi * 0.71 * t + 0.4)
    f = 120.0 * np.tanh(v / 1e-4) + 900.0 * v - 15.0
    f = f + np.random.default_rng(1).normal(0.0, noise, n)
    return jf.rig.FrictionData.from_arrays(v, f, dt, n_train=n_train)


def test_baseline_is_the_least_squares_solution_scored_on_each_window():
    data = _record()
    out = least_squares_baseline(as_records(data))
    v, f, n = np.asarray(data.velocity), np.asarray(data.friction), 640
    X = np.stack([np.tanh(v / 1e-4), v, np.ones_like(v)], axis=1)   # built here, not by jaxfric
    coef, *_ = scipy.linalg.lstsq(X[:n], f[:n])
    got = out["params"]
    np.testing.assert_allclose([got["Fc"], got["sigma2"], got["F_off"]], coef, rtol=1e-9)
    np.testing.assert_allclose(coef, [120.0, 900.0, -15.0], rtol=0.05, atol=1.0)
    pred = X @ coef
    for window, part in (("train", slice(0, n)), ("valid", slice(n, None))):
        want = friction_metrics(f[part], pred[part])
        assert out[window]["mse_percent"] == pytest.approx(want["mse_percent"], rel=1e-9)
        assert out[window]["max_abs"] == pytest.approx(want["max_abs"], rel=1e-9)


def test_identify_carries_the_baseline_and_warns_when_the_fit_is_worse(tmp_path):
    data = _record()
    tiny = jf.PSO(num_particles=4, num_generations=1)   # cannot reach the baseline
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fit = jf.identify("stribeck", data, key=0, solver=tiny, refine=None)
    base = least_squares_baseline(as_records(data))
    assert fit.metrics["baseline"] == {"train": base["train"], "valid": base["valid"]}
    assert fit.settings["baseline"]["params"] == base["params"]
    mine, theirs = fit.metrics["train"]["mse_percent"], base["train"]["mse_percent"]
    got = [str(w.message) for w in caught if issubclass(w.category, BaselineWarning)]
    assert mine > theirs and len(got) == 1
    assert f"{mine:.4g} % against {theirs:.4g} %" in got[0]
    assert f"train MSE {theirs:.4g} %" in fit.summary()
    fit.save(tmp_path / "fit.npz")
    back = jf.load_fit(tmp_path / "fit.npz")
    assert back.metrics["baseline"] == fit.metrics["baseline"]
    assert back.settings["baseline"] == fit.settings["baseline"]


def test_a_fit_better_than_the_baseline_does_not_warn():
    data = _record(noise=0.5)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fit = jf.identify("coulomb", data, key=0, offset=True)
    assert not [w for w in caught if issubclass(w.category, BaselineWarning)]
    # the same model family: the search reaches the least-squares optimum (within 1 %)
    assert fit.metrics["train"]["mse_percent"] <= 1.01 * fit.metrics["baseline"]["train"]["mse_percent"]
