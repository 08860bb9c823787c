"""The NumPy baselines of benchmarks/ (benchmarks/baselines.py) equal the JAX rollouts."""

from __future__ import annotations

import sys
from pathlib import Path

import jax
import numpy as np
import pytest

from jaxfric.models import Elman

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from baselines import elman_rollout_loop, elman_rollout_vectorised, unpack_elman  # noqa: E402


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


def test_numpy_lugre_rollouts_equal_jax():
    import jax.numpy as jnp

    from baselines import lugre_numpy_hoisted, lugre_numpy_per_step, lugre_python_loop
    from jaxfric.models import LuGre

    model = LuGre()
    lower, upper = model.bounds()
    rng = np.random.default_rng(3)
    th = rng.uniform(lower, upper, (3, model.num_params))
    v = 0.01 * np.sin(np.linspace(0, 8, 200)) + 0.004 * np.sin(np.linspace(0, 21, 200))
    dt = 1.0 / 128.0
    with jax.enable_x64(True):
        phys = {k: np.asarray(x, np.float64) for k, x in model.to_physical(jnp.asarray(th)).items()}
        ref = np.asarray(model.simulate_batch(jnp.asarray(th), jnp.asarray(v), dt))
    tol = dict(rtol=1e-9, atol=1e-9 * np.abs(ref).max())
    np.testing.assert_allclose(lugre_numpy_per_step(phys, v, dt), ref, **tol)
    np.testing.assert_allclose(lugre_numpy_hoisted(phys, v, dt), ref, **tol)
    np.testing.assert_allclose(lugre_python_loop(phys, v, dt), ref, **tol)
