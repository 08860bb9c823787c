"""Elman networks (docs/algorithms.md §2.2, §2.3): parameter counts, the recursion against
hand-computed values and an independent NumPy loop, batching, errors."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfric.models import Elman, ElmanFull


def numpy_elman(theta, u, n, output_bias=False):
    """Independent loop implementation of §2.2 Option A, written from the equations."""
    w, r, b, v, alpha, c0 = (np.asarray(theta[i * n : (i + 1) * n], float) for i in range(6))
    b_o = float(theta[6 * n]) if output_bias else 0.0
    c = c0.copy()
    y = []
    for uk in u:
        h = np.array([math.tanh(w[j] * uk + r[j] * c[j] + b[j]) for j in range(n)])
        y.append(sum(v[j] * h[j] for j in range(n)) + b_o)
        c = np.array([alpha[j] * c[j] + h[j] for j in range(n)])
    return np.array(y)


def numpy_elman_full(p, u):
    """Independent loop implementation of §2.3 (classic Elman, full context matrix)."""
    c = np.array(p["c0"], float)
    y = []
    for uk in u:
        h = np.tanh(p["w"] * uk + p["W_c"] @ c + p["b"])
        y.append(p["v"] @ h + p["b_o"])
        c = h
    return np.array(y)


def random_theta(model, rng, size=None):
    lower, upper = model.bounds()
    shape = (model.num_params,) if size is None else (size, model.num_params)
    return rng.uniform(lower, upper, shape)


@pytest.mark.parametrize("n, count", [(1, 6), (20, 120), (30, 180), (40, 240)])
def test_parameter_count_is_six_per_neuron(n, count):
    model = Elman(neurons=n)
    assert model.num_params == count
    assert len(model.param_names) == count
    assert len(set(model.param_names)) == count
    lower, upper = model.bounds()
    assert lower.shape == upper.shape == (count,)
    assert Elman(neurons=n, output_bias=True).num_params == count + 1


def test_default_is_the_papers_30_neuron_180_parameter_network():
    model = Elman()
    assert model.neurons == 30 and model.num_params == 180
    assert model.needs_scaling


def test_bounds_follow_the_section_2_4_table():
    model = Elman(neurons=3, output_bias=True)
    lower, upper = model.bounds()
    phys_lo = model.to_physical(lower)
    phys_hi = model.to_physical(upper)
    for name, lo, hi in [("w", -5, 5), ("r", -5, 5), ("b", -5, 5), ("v", -2, 2), ("alpha", 0, 0.99), ("c0", -1, 1)]:
        np.testing.assert_allclose(phys_lo[name], lo)
        np.testing.assert_allclose(phys_hi[name], hi)
    assert (float(phys_lo["b_o"]), float(phys_hi["b_o"])) == (-1.0, 1.0)


def test_two_neuron_three_step_example_by_hand():
    # w, r, b, v, alpha, c0 for neurons 1 and 2
    theta = np.array([1.0, -0.5, 0.5, 2.0, 0.0, 0.1, 1.0, 2.0, 0.5, 0.0, 0.2, -1.0])
    u = np.array([1.0, 0.0, -1.0])
    t = math.tanh
    # k = 1: contexts are c0
    h11, h21 = t(1.0 * 1.0 + 0.5 * 0.2 + 0.0), t(-0.5 * 1.0 + 2.0 * -1.0 + 0.1)
    # k = 2: c = alpha * c + h(k-1)
    c12, c22 = 0.5 * 0.2 + h11, 0.0 * -1.0 + h21
    h12, h22 = t(0.5 * c12), t(2.0 * c22 + 0.1)
    # k = 3
    c13, c23 = 0.5 * c12 + h12, 0.0 * c22 + h22
    h13, h23 = t(-1.0 + 0.5 * c13), t(0.5 + 2.0 * c23 + 0.1)
    expected = [h11 + 2 * h21, h12 + 2 * h22, h13 + 2 * h23]

    model = Elman(neurons=2)
    with jax.enable_x64(True):
        y = np.asarray(model.simulate(theta, u, None))
    np.testing.assert_allclose(y, expected, rtol=1e-14)
    np.testing.assert_allclose(numpy_elman(theta, u, 2), expected, rtol=1e-14)


@pytest.mark.parametrize("output_bias", [False, True])
def test_matches_independent_numpy_loop(output_bias):
    rng = np.random.default_rng(3)
    model = Elman(neurons=5, output_bias=output_bias)
    theta = random_theta(model, rng)
    u = np.sin(np.linspace(0, 6, 60)) + 0.1 * rng.normal(size=60)
    with jax.enable_x64(True):
        y = np.asarray(model.simulate(theta, u, None))
    np.testing.assert_allclose(y, numpy_elman(theta, u, 5, output_bias), rtol=1e-12, atol=1e-12)
    # float32 agrees to single precision
    y32 = np.asarray(model.simulate(theta.astype(np.float32), u.astype(np.float32), None))
    assert y32.dtype == np.float32
    np.testing.assert_allclose(y32, y, atol=5e-5)


def _candidates(model, *, seed, size, t_end, n):
    """``size`` random parameter sets of ``model`` and a sine input of ``n`` samples on [0, t_end]."""
    return random_theta(model, np.random.default_rng(seed), size=size), np.sin(np.linspace(0, t_end, n))


def test_vmapped_rollout_equals_per_candidate_rollouts():
    model = Elman(neurons=30)
    thetas, u = _candidates(model, seed=0, size=6, t_end=20, n=200)
    with jax.enable_x64(True):
        per = np.stack([np.asarray(model.simulate(th, u, None)) for th in thetas])
        vm = np.asarray(jax.vmap(model.simulate, in_axes=(0, None, None))(thetas, u, None))
        batch = np.asarray(model.simulate_batch(thetas, u, None))
    np.testing.assert_allclose(vm, per, rtol=0, atol=1e-13)
    np.testing.assert_allclose(batch, per, rtol=0, atol=1e-13)


def test_output_bounded_by_output_weights():
    """|tanh| <= 1, so |y| <= sum |v_j| for every parameter set in the box."""
    rng = np.random.default_rng(1)
    model = Elman(neurons=30)
    thetas = random_theta(model, rng, size=16)
    y = model.simulate_batch(thetas, np.sin(np.linspace(0, 30, 300)), None)
    bound = np.sum(np.abs(np.asarray(model.to_physical(thetas)["v"])), axis=1)
    assert np.all(np.abs(np.asarray(y)) <= bound[:, None] + 1e-5)


def test_gradient_through_rollout_is_finite():
    model = Elman(neurons=4)
    theta = jnp.asarray(random_theta(model, np.random.default_rng(2)), jnp.float32)
    u = jnp.sin(jnp.linspace(0, 5, 50))
    grad = jax.jit(jax.grad(lambda th: jnp.mean((model.simulate(th, u, None) - u) ** 2)))(theta)
    assert grad.shape == theta.shape and bool(jnp.all(jnp.isfinite(grad)))


def test_physical_round_trip():
    model = Elman(neurons=4, output_bias=True)
    theta = random_theta(model, np.random.default_rng(4), size=3)
    phys = model.to_physical(theta)
    assert phys["w"].shape == (3, 4) and phys["b_o"].shape == (3,)
    np.testing.assert_array_equal(np.asarray(model.from_physical(**phys)), theta.astype(np.float32))


@pytest.mark.parametrize("neurons", [0, -3, 2.5, True])
def test_bad_neuron_count(neurons):
    with pytest.raises(ValueError, match="neurons"):
        Elman(neurons=neurons)
    with pytest.raises(ValueError, match="neurons"):
        ElmanFull(neurons=neurons)


def test_bad_hyperparameters():
    with pytest.raises(ValueError, match="alpha_max"):
        Elman(alpha_max=1.0)
    with pytest.raises(ValueError, match="weight_bound"):
        Elman(weight_bound=0.0)


def test_bad_theta_and_velocity():
    model = Elman(neurons=2)
    u = np.zeros(5)
    with pytest.raises(ValueError, match="12 parameters"):
        model.simulate(np.zeros(11), u, None)
    with pytest.raises(ValueError, match="1-D"):
        model.simulate(np.zeros(12), np.zeros((5, 1)), None)
    with pytest.raises(ValueError, match="1-D"):
        model.simulate(np.zeros((2, 12)), u, None)
    with pytest.raises(ValueError, match="non-finite"):
        model.check_theta(np.r_[np.zeros(11), np.nan])
    with pytest.raises(ValueError, match="non-finite"):
        model.check_theta(np.r_[np.zeros(11), np.inf])
    with pytest.raises(ValueError, match="12 parameters"):
        model.check_theta(np.zeros(13))
    # the errors are raised at trace time, so they also work under jit
    with pytest.raises(ValueError, match="12 parameters"):
        jax.jit(lambda th: model.simulate(th, u, None))(jnp.zeros(10))
    assert model.check_theta(np.zeros((3, 12))).shape == (3, 12)


def test_elman_full_parameter_count_and_recursion():
    assert ElmanFull(neurons=30).num_params == 30 + 900 + 30 + 30 + 30 + 1  # 1021 with c0
    assert ElmanFull(neurons=30, learn_c0=False).num_params == 991
    model = ElmanFull(neurons=3)
    rng = np.random.default_rng(5)
    thetas = random_theta(model, rng, size=2)
    u = np.cos(np.linspace(0, 4, 25))
    with jax.enable_x64(True):
        y = np.asarray(model.simulate_batch(thetas, u, None))
        for i in range(2):
            p = {k: np.asarray(x) for k, x in model.to_physical(thetas[i]).items()}
            np.testing.assert_allclose(y[i], numpy_elman_full(p, u), rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(model.from_physical(**p), thetas[i], rtol=1e-15)
        assert model.to_physical(thetas)["W_c"].shape == (2, 3, 3)


def test_elman_full_without_c0_starts_from_zero_context():
    model = ElmanFull(neurons=2, learn_c0=False, output_bias=False)
    p = dict(w=np.array([0.3, -0.7]), W_c=np.array([[0.5, -0.2], [0.1, 0.4]]), b=np.array([0.1, 0.0]), v=np.array([1.0, -1.0]))
    u = np.array([0.5, -0.2, 0.9])
    with jax.enable_x64(True):
        y = model.simulate(model.from_physical(**p), u, None)
    np.testing.assert_allclose(y, numpy_elman_full(dict(p, c0=np.zeros(2), b_o=0.0), u), rtol=1e-13)
    with pytest.raises(ValueError):
        model.from_physical(**p, c0=np.zeros(2))


def test_context_weight_bound_narrows_only_r():
    model = Elman(neurons=3, context_weight_bound=1.0)
    lower, upper = model.bounds()
    np.testing.assert_allclose(model.to_physical(upper)["r"], 1.0)
    np.testing.assert_allclose(model.to_physical(upper)["w"], 5.0)
    np.testing.assert_allclose(model.to_physical(lower)["b"], -5.0)


def test_unroll_does_not_change_results():
    base = Elman(neurons=4)
    thetas, u = _candidates(base, seed=8, size=3, t_end=3, n=33)
    with jax.enable_x64(True):
        ref = np.asarray(base.simulate_batch(thetas, u, None))
        for unroll in (1, 3):
            out = Elman(neurons=4, unroll=unroll).simulate_batch(thetas, u, None)
            np.testing.assert_allclose(out, ref, rtol=1e-13, atol=1e-13)
    with pytest.raises(ValueError, match="unroll"):
        Elman(unroll=0)
