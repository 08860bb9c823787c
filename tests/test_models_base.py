"""The shared model interface, the registry and the Scaler, checked for every model."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfric import models
from jaxfric.models import AbstractFrictionModel, Scaler, check_theta

SMALL = {"elman": dict(neurons=3), "elman_full": dict(neurons=3)}
NAMES = ("elman", "elman_full", "lugre", "dahl", "coulomb", "stribeck", "gms")
#: Models that also need measured inputs (chamber pressures): tested in test_models_realdrive.py;
#: the grey-box (a physical model plus a network): tested in test_models_greybox.py.
REGISTRY = NAMES + ("cylinder", "greybox")


def make(name):
    return models.get(name, **SMALL.get(name, {}))


def test_registry_lists_all_models():
    assert models.available() == REGISTRY
    assert isinstance(models.get("LuGre"), models.LuGre)
    assert isinstance(models.get("elman-full"), models.ElmanFull)
    assert models.get("elman", neurons=20).num_params == 120


def test_registry_unknown_name_lists_valid_names():
    with pytest.raises(ValueError, match="valid names: elman, elman_full, lugre, dahl, coulomb, stribeck, gms, cylinder"):
        models.get("gms2")
    with pytest.raises(ValueError):
        models.get(3)


@pytest.mark.parametrize("name", NAMES)
def test_interface_shapes_and_bounds(name):
    model = make(name)
    assert isinstance(model, AbstractFrictionModel)
    lower, upper = model.bounds()
    assert lower.dtype == upper.dtype == np.float64
    assert lower.shape == upper.shape == (model.num_params,) == (len(model.param_names),)
    assert np.all(lower < upper)
    assert model.needs_scaling == name.startswith("elman")


@pytest.mark.parametrize("name", NAMES)
def test_rollout_shapes_batching_and_dtype(name):
    model = make(name)
    lower, upper = model.bounds()
    rng = np.random.default_rng(0)
    # the shapes of test_simulate_transformations_agree, whose references reuse these programs
    thetas = rng.uniform(lower, upper, (4, model.num_params))
    v = 0.8 * np.sin(np.linspace(0, 9, 40)) * (1.0 if model.needs_scaling else 0.01)
    with jax.enable_x64(True):
        batch = model.simulate_batch(thetas, v, 1 / 128)
        vm = jax.vmap(model.simulate, in_axes=(0, None, None))(thetas, v, 1 / 128)
        single = model.simulate(thetas[1], v, 1 / 128)
        assert batch.shape == (4, 40) and batch.dtype == jnp.float64
        np.testing.assert_allclose(vm, batch, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(single, batch[1], rtol=1e-12, atol=1e-12)
    f32 = model.simulate(thetas[0].astype(np.float32), v.astype(np.float32), 1 / 128)
    assert f32.dtype == jnp.float32 and np.all(np.isfinite(np.asarray(f32)))


@pytest.mark.parametrize("name", NAMES)
def test_physical_round_trip(name):
    model = make(name)
    lower, upper = model.bounds()
    theta = np.random.default_rng(1).uniform(lower, upper, (2, model.num_params))
    with jax.enable_x64(True):
        # one program (eagerly, every conversion's jnp operations compiled one by one)
        back = jax.jit(lambda t: model.from_physical(**model.to_physical(t)))(theta)
    np.testing.assert_allclose(back, theta, rtol=1e-12)


@pytest.mark.parametrize("name", NAMES)
def test_input_errors(name):
    model = make(name)
    n = model.num_params
    with pytest.raises(ValueError, match="parameters"):
        model.simulate(np.zeros(n + 1), np.zeros(4), 0.01)
    with pytest.raises(ValueError, match="1-D"):
        model.simulate(np.zeros(n), np.zeros((4, 2)), 0.01)
    with pytest.raises(ValueError, match="1-D"):
        model.simulate(np.zeros(n), np.float32(0.1), 0.01)
    with pytest.raises(ValueError, match="non-finite"):
        model.check_theta(np.full(n, np.nan))


@pytest.mark.parametrize("name", NAMES)
def test_initial_guess_inside_bounds_and_data_bounds(name):
    model = make(name)
    v = 0.01 * np.sin(np.linspace(0, 12, 300))
    F = 100 * np.tanh(v / 1e-3) + 600 * v
    box = model.search_box(None, v, F)
    assert box is None if model.needs_scaling else set(box) == set(model.box_keys)
    lower, upper = model.bounds(box)
    guess = model.initial_guess(v, F, box)
    assert guess.shape == (model.num_params,)
    assert np.all((guess >= lower) & (guess <= upper))


def test_check_theta_helper():
    assert check_theta([1.0, 2.0], 2).shape == (2,)
    with pytest.raises(ValueError, match="non-finite"):
        check_theta([1.0, np.inf], 2)
    with pytest.raises(ValueError, match="3 entries"):
        check_theta([1.0, 2.0, 3.0], 2)
    with pytest.raises(ValueError, match="1-D"):
        check_theta(np.zeros((2, 2, 2)), 2)


def test_models_are_immutable_hashable_static_configs():
    a, b = models.LuGre(stribeck_exponent=1), models.LuGre(stribeck_exponent=1.0)
    assert a == b and hash(a) == hash(b)
    assert jax.tree_util.tree_leaves(models.Elman()) == []  # no data inside a model
    with pytest.raises(Exception):
        a.stribeck_exponent = 3.0
    # the search box is data beside the model, and as immutable and hashable
    box, same = models.SearchBox(Fc=(1, 2)), models.SearchBox({"Fc": [1.0, 2.0]})
    assert box == same and hash(box) == hash(same) and box == {"Fc": (1.0, 2.0)}
    with pytest.raises(Exception):
        box.Fc = (3, 4)
    with pytest.raises(TypeError):
        box["Fc"] = (3, 4)


def test_scaler_maps_training_range_to_unit_interval_and_back():
    x = np.array([2.0, 5.0, -1.0, 3.0])
    s = Scaler.fit(x)
    with jax.enable_x64(True):
        y = s.scale(x)
        np.testing.assert_allclose(y, 2 * (x + 1) / 6 - 1, rtol=1e-15)
        assert float(y.min()) == -1.0 and float(y.max()) == 1.0
        np.testing.assert_allclose(s.unscale(y), x, rtol=1e-15)
        np.testing.assert_allclose(s.unscale_difference(jnp.array([0.5])), [1.5])
        np.testing.assert_allclose(s.gain, 1 / 3)
    # float32 in, float32 out; validation data may leave [-1, 1]
    y32 = s.scale(np.array([8.0], np.float32))
    assert y32.dtype == jnp.float32 and float(y32[0]) == pytest.approx(2.0)
    # per-column scaling of a (T, C) array, usable inside jit
    xs = np.stack([x, 10 * x], axis=1)
    s2 = Scaler.fit(xs)
    out = jax.jit(lambda sc, a: sc.scale(a))(s2, xs)
    np.testing.assert_allclose(out[:, 0], out[:, 1], atol=1e-6)


@pytest.mark.parametrize("bad", [np.ones(5), np.array([]), np.array([1.0, np.nan]), np.float64(3.0)])
def test_scaler_rejects_degenerate_data(bad):
    with pytest.raises(ValueError):
        Scaler.fit(bad)


def test_vmap_over_theta_takes_the_batched_path():
    """vmap(simulate) over theta is routed to simulate_batch: the Elman scan then
    carries an (N, P) state, which JAX's default batching would lay out as (P, N, 1)."""
    model = models.Elman(neurons=5)
    jaxpr = str(jax.make_jaxpr(jax.vmap(model.simulate, in_axes=(0, None, None)))(jnp.zeros((7, 30)), jnp.zeros(11), None))
    assert "f32[5,7]" in jaxpr
    default = str(
        jax.make_jaxpr(jax.vmap(lambda t, x: model.simulate_batch(t[None], x, None)[0], in_axes=(0, None)))(
            jnp.zeros((7, 30)), jnp.zeros(11)
        )
    )
    assert "f32[5,7]" not in default


@pytest.mark.parametrize("name", ["elman", "lugre"])
def test_simulate_transformations_agree(name):
    """Gradients, vmapped gradients, nested vmaps and vmaps over data or dt all
    agree with the plain computation (the custom batching rule is transparent)."""
    model = make(name)
    lower, upper = model.bounds()
    thetas = np.random.default_rng(2).uniform(lower, upper, (4, model.num_params))
    v = 0.5 * np.sin(np.linspace(0, 6, 40)) * (1.0 if model.needs_scaling else 0.02)
    with jax.enable_x64(True):
        loss = lambda th, vel, dt: jnp.sum(model.simulate(th, vel, dt) ** 2)  # noqa: E731

        def transformed(thetas, v):
            """Every transformation at once: one program (measured: 40 % less compile
            time than five)."""
            g = jax.grad(loss)(thetas[0], v, 0.01)
            gv = jax.vmap(jax.grad(loss), in_axes=(0, None, None))(thetas, v, 0.01)
            gb = jax.grad(lambda ths: jnp.sum(jax.vmap(loss, in_axes=(0, None, None))(ths, v, 0.01)))(thetas)
            nested = jax.vmap(jax.vmap(model.simulate, in_axes=(0, None, None)), in_axes=(0, None, None))(
                thetas.reshape(2, 2, -1), v, 0.01
            )
            data = jax.vmap(model.simulate, in_axes=(None, 0, 0))(thetas[0], jnp.stack([v, 2 * v]),
                                                                 jnp.array([0.01, 0.02]))
            return g, gv, gb, nested, data

        g, gv, gb, nested, data = jax.jit(transformed)(thetas, v)
        assert bool(jnp.all(jnp.isfinite(g)))
        np.testing.assert_allclose(gv[0], g, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(gb, gv, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(nested.reshape(4, -1), model.simulate_batch(thetas, v, 0.01), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(data[1], model.simulate(thetas[0], 2 * v, 0.02), rtol=1e-12, atol=1e-12)
