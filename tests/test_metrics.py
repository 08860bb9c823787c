"""Friction metrics (docs/algorithms.md §6, MATLAB FIT %) against hand-computed values."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfric.metrics import METRIC_FORMULAS, friction_metrics, mse_percent_jax


def test_hand_computed_example():
    y = np.array([1.0, 2.0, 3.0, 4.0])  # mean 2.5, var 1.25, ||y - mean|| = sqrt(5)
    y_hat = np.array([1.0, 2.0, 3.0, 2.0])  # e = (0, 0, 0, 2)
    m = friction_metrics(y, y_hat)
    assert m["mse"] == pytest.approx(1.0)  # 4 / 4
    assert m["rmse"] == pytest.approx(1.0)
    assert m["mse_percent"] == pytest.approx(80.0)  # 100 * 1 / 1.25
    assert m["max_abs"] == pytest.approx(2.0)
    assert m["max_percent"] == pytest.approx(50.0)  # 100 * 2 / 4
    assert m["fit_percent"] == pytest.approx(100 * (1 - 2 / np.sqrt(5)))
    assert m["rrse"] == pytest.approx(2 / np.sqrt(5))
    assert m["r2"] == pytest.approx(1 - 4 / 5)
    assert m["mse_scaled_percent"] == pytest.approx(100 * 1.0 * (2 / 3) ** 2)
    assert set(m) == set(METRIC_FORMULAS)
    assert all(type(v) is float for v in m.values())


def test_against_independent_formulas():
    rng = np.random.default_rng(0)
    y = 100 * np.sin(np.linspace(0, 7, 500)) + 5 * rng.normal(size=500)
    y_hat = y + rng.normal(0, 3, size=500)
    e = y - y_hat
    m = friction_metrics(y, y_hat)
    r2 = 1 - np.sum(e**2) / np.sum((y - y.mean()) ** 2)
    assert m["r2"] == pytest.approx(r2, rel=1e-12)
    assert m["fit_percent"] == pytest.approx(100 * (1 - np.linalg.norm(e) / np.linalg.norm(y - np.mean(y))), rel=1e-12)
    assert m["mse_percent"] == pytest.approx(100 * np.mean(e**2) / np.var(y), rel=1e-12)
    assert m["mse_percent"] == pytest.approx(100 * (1 - m["r2"]), rel=1e-9)
    assert m["rrse"] == pytest.approx(1 - m["fit_percent"] / 100, rel=1e-12)
    scaled = lambda a: 2 * (a - y.min()) / (y.max() - y.min()) - 1  # mapminmax on y
    assert m["mse_scaled_percent"] == pytest.approx(100 * np.mean((scaled(y) - scaled(y_hat)) ** 2), rel=1e-12)
    assert m["max_abs"] == pytest.approx(np.abs(e).max())


def test_reference_points():
    y = np.array([3.0, -1.0, 4.0, 1.0, -5.0])
    perfect = friction_metrics(y, y)
    assert perfect["mse"] == 0.0 and perfect["fit_percent"] == 100.0 and perfect["r2"] == 1.0
    mean = friction_metrics(y, np.full_like(y, y.mean()))
    assert mean["mse_percent"] == pytest.approx(100.0) and mean["fit_percent"] == pytest.approx(0.0, abs=1e-12)
    worse = friction_metrics(y, -y)
    assert worse["fit_percent"] < 0 and worse["r2"] < 0


def test_accepts_jax_arrays_and_float32():
    y = jnp.linspace(-1, 1, 11, dtype=jnp.float32)
    m = friction_metrics(y, y * 0.9)
    assert m["mse"] == pytest.approx(float(np.mean((0.1 * np.linspace(-1, 1, 11)) ** 2)), rel=1e-5)


@pytest.mark.parametrize(
    "y, y_hat, match",
    [
        (np.ones(5), np.zeros(5), "zero variance"),
        (np.array([1.0, np.nan, 2.0]), np.zeros(3), "NaN"),
        (np.array([1.0, 2.0, 3.0]), np.array([0.0, np.inf, 1.0]), "NaN or inf"),
        (np.arange(3.0), np.arange(4.0), "same shape"),
        (np.array([]), np.array([]), "empty"),
    ],
)
def test_bad_input(y, y_hat, match):
    with pytest.raises(ValueError, match=match):
        friction_metrics(y, y_hat)


def test_mse_percent_jax_is_traceable_and_batched():
    rng = np.random.default_rng(1)
    y = rng.normal(size=50)
    y_hat = np.stack([y + rng.normal(0, s, 50) for s in (0.1, 0.5)])
    with jax.enable_x64(True):
        out = jax.jit(mse_percent_jax)(y, y_hat)
        assert out.shape == (2,)
        for i in range(2):
            assert float(out[i]) == pytest.approx(friction_metrics(y, y_hat[i])["mse_percent"], rel=1e-12)
        g = jax.grad(lambda yh: mse_percent_jax(y, yh))(y_hat[0])
        assert bool(jnp.all(jnp.isfinite(g)))
