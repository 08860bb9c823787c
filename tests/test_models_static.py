"""Static friction maps (Coulomb + viscous, Stribeck) against their formulas."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfric.models import Coulomb, Stribeck

V = np.r_[np.linspace(-0.03, 0.03, 41), 0.0, 1e-6]


def test_coulomb_formula():
    model = Coulomb(v_eps=2e-4)
    assert model.param_names == ("Fc", "log10_sigma2") and not model.uses_dt
    with jax.enable_x64(True):
        theta = model.from_physical(Fc=120.0, sigma2=900.0)
        F = np.asarray(model.simulate(theta, V, None))
    np.testing.assert_allclose(F, 120.0 * np.tanh(V / 2e-4) + 900.0 * V, rtol=1e-13, atol=1e-12)
    assert F[V == 0.0][0] == 0.0


def test_coulomb_without_viscous_term():
    model = Coulomb(viscous=False)
    assert model.num_params == 1
    F = model.simulate(np.array([50.0]), V, 0.01)
    np.testing.assert_allclose(F, 50.0 * np.tanh(V / 1e-4), rtol=1e-5, atol=1e-4)


def test_stribeck_formula_and_dt_is_ignored():
    model = Stribeck()
    p = dict(Fc=100.0, Fs=180.0, vs=2e-3, sigma2=500.0)
    with jax.enable_x64(True):
        theta = model.from_physical(**p)
        F = np.asarray(model.simulate(theta, V, 0.01))
        F_other_dt = np.asarray(model.simulate(theta, V, 1.0))
    g = p["Fc"] + (p["Fs"] - p["Fc"]) * np.exp(-((V / p["vs"]) ** 2))
    np.testing.assert_allclose(F, np.tanh(V / 1e-4) * g + p["sigma2"] * V, rtol=1e-13, atol=1e-12)
    np.testing.assert_array_equal(F, F_other_dt)


def test_stribeck_free_exponent_is_a_parameter_with_finite_gradient():
    model = Stribeck(fit_exponent=True)
    assert model.param_names[-1] == "delta" and model.num_params == 5
    p = dict(Fc=100.0, Fs=180.0, vs=2e-3, sigma2=500.0, delta=0.7)
    with jax.enable_x64(True):
        theta = model.from_physical(**p)
        F = np.asarray(model.simulate(theta, V, None))
        g = p["Fc"] + (p["Fs"] - p["Fc"]) * np.exp(-(np.abs(V / p["vs"]) ** p["delta"]))
        np.testing.assert_allclose(F, np.tanh(V / 1e-4) * g + p["sigma2"] * V, rtol=1e-12, atol=1e-12)
        grad = jax.grad(lambda th: jnp.sum(model.simulate(th, V, None) ** 2))(theta)
    assert bool(jnp.all(jnp.isfinite(grad)))


def test_stribeck_static_curve_is_lugre_steady_state():
    """Far from v = 0 (tanh = ±1) the Stribeck map is LuGre's steady state (§8.1)."""
    from jaxfric.models import LuGre

    p = dict(Fc=100.0, Fs=180.0, vs=2e-3, sigma2=500.0)
    with jax.enable_x64(True):
        static = Stribeck(v_eps=1e-9)
        lugre = LuGre()
        th_l = lugre.from_physical(sigma0=1e6, sigma1=100.0, **p)
        for vel in (-0.01, 0.003):
            F_l = lugre.simulate(th_l, jnp.full(8, vel), 1 / 128)[-1]
            F_s = static.simulate(static.from_physical(**p), jnp.array([vel]), None)[0]
            np.testing.assert_allclose(F_l, F_s, rtol=1e-10)


@pytest.mark.parametrize("cls", [Coulomb, Stribeck])
def test_bad_v_eps(cls):
    with pytest.raises(ValueError, match="v_eps"):
        cls(v_eps=0.0)


def test_initial_guess_recovers_coulomb_viscous_levels():
    model = Coulomb()
    v = 0.02 * np.sin(np.linspace(0, 12, 500))
    F = 80.0 * np.tanh(v / 1e-4) + 1500.0 * v
    guess = model.to_physical(model.initial_guess(v, F))
    assert float(guess["Fc"]) == pytest.approx(80.0, rel=1e-3)
    assert float(guess["sigma2"]) == pytest.approx(1500.0, rel=1e-3)
