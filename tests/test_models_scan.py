"""The models' per-platform time loops (jaxfric/models/_scan.py).

On the CPU the sequential loops run; the accelerator forms (associative scan, wide
unroll) are checked here against them, so a GPU computes the same rollouts."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfric.models import Dahl, Elman, ElmanFull, LuGre, _scan, lugre


def _coefficients(rng, p, t, dtype):
    decay = rng.uniform(0.0, 1.0, (p, t))
    decay[:, ::7] = 1.0  # standstill: no decay
    decay[:, 3::11] = 0.0  # full decay: the state forgets everything before
    gain = rng.normal(0.0, 1.0, (p, t))
    z0 = rng.normal(0.0, 1.0, p)
    return (jnp.asarray(a, dtype) for a in (decay, gain, z0))


def _reference(decay, gain, z0):
    """Plain Python loop in float64."""
    d, g, z = (np.asarray(a, np.float64) for a in (decay, gain, z0))
    out = np.empty_like(d)
    for k in range(d.shape[1]):
        out[:, k] = z
        z = d[:, k] * z + g[:, k]
    return out


# Each form compiled as one program per shape and dtype: called eagerly, the associative
# scan's log2(T) levels compiled as a hundred small programs at T = 1600.
_PARALLEL = jax.jit(_scan.linear_recurrence_parallel)
_SEQUENTIAL = jax.jit(_scan.linear_recurrence_sequential)


@pytest.mark.parametrize("t", [1, 2, 7, 64, 1600])
@pytest.mark.parametrize("x64", [False, True])
def test_parallel_linear_recurrence_matches_a_loop(t, x64):
    with jax.enable_x64(x64):
        dtype = jnp.float64 if x64 else jnp.float32
        decay, gain, z0 = _coefficients(np.random.default_rng(t), 5, t, dtype)
        par = _PARALLEL(decay, gain, z0)
        seq = _SEQUENTIAL(decay, gain, z0)
        assert par.shape == seq.shape == (5, t) and par.dtype == seq.dtype == dtype
        ref = _reference(decay, gain, z0)
        tol = 1e-12 if x64 else 2e-5
        scale = np.max(np.abs(ref)) + 1.0
        np.testing.assert_allclose(np.asarray(seq), ref, atol=tol * scale, rtol=0)
        np.testing.assert_allclose(np.asarray(par), ref, atol=tol * scale, rtol=0)


def test_default_linear_recurrence_is_the_platforms_own_form():
    """The sequential loop on the CPU, the associative scan on other platforms (the
    float32 (5, 64) shape of the test above, so the pinned form's program is reused)."""
    decay, gain, z0 = _coefficients(np.random.default_rng(0), 5, 64, jnp.float32)
    own = _SEQUENTIAL if jax.default_backend() == "cpu" else _PARALLEL
    assert jnp.array_equal(jax.jit(_scan.linear_recurrence)(decay, gain, z0),
                           own(decay, gain, z0))


@pytest.mark.parametrize("model", [LuGre(), Dahl()], ids=["lugre", "dahl"])
def test_bristle_models_through_the_accelerator_loop(model, monkeypatch):
    """LuGre and Dahl computed with the GPU's associative scan equal the CPU's loop
    (values and gradients, float64): the recurrence is the only thing that changes."""
    with jax.enable_x64(True):
        rng = np.random.default_rng(1)
        lo, hi = model.bounds()
        th = jnp.asarray(rng.uniform(lo, hi, (6, model.num_params)))
        t = np.arange(1600) / 128.0
        v = jnp.asarray(0.01 * np.sin(2 * np.pi * 0.2 * t) + 0.004 * np.sin(2 * np.pi * 0.53 * t))

        def outputs():
            """Rollout and gradient of its squared sum, as one program."""
            def loss(th):
                y = model.simulate_batch(th, v, 1 / 128.0)
                return jnp.sum(y**2), y

            g, y = jax.jit(jax.grad(loss, has_aux=True))(th)
            return np.asarray(y), np.asarray(g)

        # Pin each form explicitly, so the comparison is the same on every platform.
        monkeypatch.setattr(lugre, "linear_recurrence", _scan.linear_recurrence_sequential)
        cpu = outputs()
        monkeypatch.setattr(lugre, "linear_recurrence", _scan.linear_recurrence_parallel)
        accel = outputs()
    np.testing.assert_allclose(accel[0], cpu[0], rtol=1e-10, atol=1e-9 * np.max(np.abs(cpu[0])))
    np.testing.assert_allclose(accel[1], cpu[1], rtol=1e-8, atol=1e-8 * np.max(np.abs(cpu[1])))


@pytest.mark.parametrize("model", [Elman(neurons=8, context_weight_bound=1.0), ElmanFull(neurons=4)],
                         ids=["elman", "elman_full"])
def test_elman_accelerator_unroll_computes_the_same_rollout(model):
    """The unroll used off the CPU changes the loop's shape, not its arithmetic
    (values and gradients, float32; networks with |r| <= 1 are not chaotic). 483 samples
    are 15 unrolled blocks of 32 and a remainder of 3 (each unrolled step is compiled
    code, so a short remainder keeps the program small); rollout and gradient are one
    program per model."""
    wide = dataclasses.replace(model, unroll=_scan.ACCELERATOR_UNROLL)
    rng = np.random.default_rng(2)
    lo, hi = model.bounds()
    th = jnp.asarray(rng.uniform(lo, hi, (5, model.num_params)), jnp.float32)
    u = jnp.asarray(np.sin(np.arange(15 * _scan.ACCELERATOR_UNROLL + 3) / 30.0), jnp.float32)

    def rollout_and_gradient(m):
        def loss(t):
            y = m.simulate_batch(t, u)
            return jnp.sum(y**2), y

        g, y = jax.jit(jax.grad(loss, has_aux=True))(th)
        return np.asarray(y), np.asarray(g)

    (y_wide, g_wide), (y, g) = rollout_and_gradient(wide), rollout_and_gradient(model)
    np.testing.assert_allclose(y_wide, y, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(g_wide, g, rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize("cls", [Elman, ElmanFull])
def test_explicit_unroll_is_validated_and_kept(cls):
    with pytest.raises(ValueError, match="unroll"):
        cls(neurons=3, unroll=0)
    assert cls(neurons=3, unroll=7).unroll == 7
