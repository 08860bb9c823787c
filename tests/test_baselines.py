"""The NumPy Elman baselines used by benchmarks/rollout_speed.py equal the JAX rollout."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from jaxfric.models import Elman
from jaxfric.models.reference_numpy import elman_rollout_loop, elman_rollout_vectorised, unpack_elman


@pytest.mark.parametrize("output_bias", [False, True])
def test_numpy_rollouts_equal_jax(output_bias):
    model = Elman(neurons=30, output_bias=output_bias)
    lower, upper = model.bounds()
    rng = np.random.default_rng(7)
    thetas = rng.uniform(lower, upper, (4, model.num_params))
    u = np.clip(np.sin(np.linspace(0, 12, 120)) + 0.05 * rng.normal(size=120), -1, 1)
    with jax.enable_x64(True):
        y_jax = np.asarray(model.simulate_batch(thetas, u, None))
    y_vec = elman_rollout_vectorised(thetas, u, 30, output_bias)
    y_loop = elman_rollout_loop(thetas, u, 30, output_bias)
    assert y_vec.shape == y_loop.shape == (4, 120)
    np.testing.assert_allclose(y_vec, y_jax, rtol=1e-10, atol=1e-10)  # XLA tanh vs libm tanh, amplified by the recurrence
    np.testing.assert_allclose(y_loop, y_jax, rtol=1e-10, atol=1e-10)  # XLA tanh vs libm tanh, amplified by the recurrence


def test_unpack_rejects_wrong_length():
    with pytest.raises(ValueError, match="expected 12"):
        unpack_elman(np.zeros((1, 13)), 2)


def test_numpy_rollouts_in_float32():
    model = Elman(neurons=4)
    lower, upper = model.bounds()
    thetas = np.random.default_rng(9).uniform(lower, upper, (3, model.num_params)).astype(np.float32)
    u = np.sin(np.linspace(0, 3, 20)).astype(np.float32)
    y_jax = np.asarray(model.simulate_batch(thetas, u, None))
    for fn in (elman_rollout_vectorised, elman_rollout_loop):
        y = fn(thetas, u, 4, dtype=np.float32)
        assert y.dtype == np.float32
        np.testing.assert_allclose(y, y_jax, atol=1e-4)
