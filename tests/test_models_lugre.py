"""LuGre and Dahl: exact zero-order-hold update against a stiff reference integrator,
finiteness over the whole search box, gradients at v = 0, interface details."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from jaxfric.models import DEFAULT_RANGES, Dahl, LuGre

FS = 128.0
DT = 1.0 / FS


def reversal_profile(n: int = 384) -> np.ndarray:
    """Low-speed profile with many reversals, a dwell at exactly v = 0 and a fast burst."""
    t = np.arange(n) / FS
    v = 0.006 * np.sin(2 * np.pi * 1.1 * t) + 0.004 * np.sin(2 * np.pi * 2.9 * t + 0.4)
    v[100:112] = 0.0  # exact standstill exercises the a = 0 branch of phi
    v[200:210] *= 5.0  # short burst well past the Stribeck velocity
    return v


def reference_zoh(v, dt, sigma0, sigma1, sigma2, g_of_v, z0):
    """Integrate dz/dt = v_k - sigma0 |v_k| z / g(v_k) over each sample with LSODA.

    Velocity is held constant over each interval (zero-order hold), exactly the
    assumption the exact update makes, so any difference is the update's error.
    """
    z = np.empty(len(v))
    zk = z0
    scale = max(abs(z0), max(g_of_v(vk) for vk in v) / sigma0)
    for k, vk in enumerate(v):
        z[k] = zk
        a = sigma0 * abs(vk) / g_of_v(vk)
        sol = solve_ivp(
            lambda t, y: [vk - a * y[0]],
            (0.0, dt),
            [zk],
            method="LSODA",
            rtol=1e-12,
            atol=1e-14 * scale,
            jac=lambda t, y: [[-a]],
        )
        zk = sol.y[0, -1]
    a = sigma0 * np.abs(v) / np.array([g_of_v(vk) for vk in v])
    return sigma0 * z + sigma1 * (v - a * z) + sigma2 * v


LUGRE_CASES = [
    # stiff hydraulic-scale set of §8.2 (a h up to ~20 at the burst)
    dict(sigma0=1e7, sigma1=2e3, sigma2=800.0, Fc=150.0, Fs=220.0, vs=3e-3),
    # soft bristles: pre-sliding hysteresis visible, a h << 1 for small |v|
    dict(sigma0=3e4, sigma1=50.0, sigma2=30.0, Fc=40.0, Fs=100.0, vs=1e-3),
]


@pytest.mark.parametrize("params", LUGRE_CASES)
def test_lugre_exact_update_matches_stiff_reference(params):
    v = reversal_profile()
    model = LuGre()
    with jax.enable_x64(True):
        theta = model.from_physical(**params)
        F = np.asarray(model.simulate(theta, jnp.asarray(v), DT))
        assert F.dtype == np.float64

    def g(vk):
        return params["Fc"] + (params["Fs"] - params["Fc"]) * np.exp(-((vk / params["vs"]) ** 2))

    z0 = np.sign(v[0]) * g(v[0]) / params["sigma0"]
    F_ref = reference_zoh(v, DT, params["sigma0"], params["sigma1"], params["sigma2"], g, z0)
    rel = np.max(np.abs(F - F_ref)) / np.max(np.abs(F_ref))
    print(f"LuGre exact update vs LSODA reference: max rel error {rel:.2e}")
    assert rel < 1e-6, rel
    # The profile really is reversal-rich.
    assert np.sum(np.diff(np.sign(v[v != 0])) != 0) >= 8


def test_reference_case_is_stiff_for_explicit_euler():
    """Case 0 has a h > 2 somewhere, where explicit Euler would diverge (§8.2)."""
    p, v = LUGRE_CASES[0], reversal_profile()
    g = p["Fc"] + (p["Fs"] - p["Fc"]) * np.exp(-((v / p["vs"]) ** 2))
    assert np.max(p["sigma0"] * np.abs(v) / g * DT) > 2.0


def test_dahl_exact_update_matches_stiff_reference():
    v = reversal_profile()
    sigma0, Fc, sigma2 = 5e5, 120.0, 400.0
    model = Dahl(viscous=True)
    with jax.enable_x64(True):
        theta = model.from_physical(sigma0=sigma0, Fc=Fc, sigma2=sigma2)
        F = np.asarray(model.simulate(theta, jnp.asarray(v), DT))
    z0 = np.sign(v[0]) * Fc / sigma0
    F_ref = reference_zoh(v, DT, sigma0, 0.0, sigma2, lambda vk: Fc, z0)
    rel = np.max(np.abs(F - F_ref)) / np.max(np.abs(F_ref))
    print(f"Dahl exact update vs LSODA reference: max rel error {rel:.2e}")
    assert rel < 1e-6, rel


def test_dahl_is_lugre_with_fs_equal_fc_and_no_damping():
    v = reversal_profile()
    with jax.enable_x64(True):
        dahl = Dahl(viscous=True)
        lugre = LuGre()
        F_d = dahl.simulate(dahl.from_physical(sigma0=2e6, Fc=90.0, sigma2=300.0), v, DT)
        F_l = lugre.simulate(
            lugre.from_physical(sigma0=2e6, sigma1=1e-12, sigma2=300.0, Fc=90.0, Fs=90.0, vs=1e-3), v, DT
        )
        np.testing.assert_allclose(F_d, F_l, rtol=0, atol=1e-9)


def test_lugre_steady_sliding_reaches_stribeck_curve():
    """At constant velocity the output settles at sgn(v) g(v) + sigma2 v (§8.1)."""
    p = LUGRE_CASES[0]
    model = LuGre()
    with jax.enable_x64(True):
        theta = model.from_physical(**p)
        for vel in (-0.02, -1e-3, 5e-4, 0.01):
            v = jnp.full(64, vel)
            F = model.simulate(theta, v, DT)
            g = p["Fc"] + (p["Fs"] - p["Fc"]) * np.exp(-((vel / p["vs"]) ** 2))
            np.testing.assert_allclose(F[-1], np.sign(vel) * g + p["sigma2"] * vel, rtol=1e-9)


def test_lugre_starts_from_steady_state():
    """z(0) = sgn(v0) g(v0)/sigma0: a record starting while sliding has no transient."""
    p = LUGRE_CASES[0]
    model = LuGre()
    with jax.enable_x64(True):
        # 64 samples: the steady-sliding test's rollout program
        F = model.simulate(model.from_physical(**p), jnp.full(64, 0.004), DT)
        np.testing.assert_allclose(F, F[0], rtol=1e-12)


def _theta_strategy(model):
    lower, upper = model.bounds()
    return st.tuples(*[st.floats(float(lo), float(hi)) for lo, hi in zip(lower, upper)])


VEL_EXTREME = np.concatenate([reversal_profile(192), np.zeros(8), np.full(8, 0.3), np.full(8, -1e-7)])


@pytest.mark.parametrize("x64", [False, True], ids=["float32", "float64"])
@pytest.mark.parametrize("model", [LuGre(), Dahl(), Dahl(viscous=True)], ids=["lugre", "dahl", "dahl_viscous"])
def test_no_nan_anywhere_in_search_box(model, x64):
    with jax.enable_x64(x64):
        dtype = jnp.float64 if x64 else jnp.float32
        run = jax.jit(lambda th, v, dt: model.simulate(th, v, dt))
        v = jnp.asarray(VEL_EXTREME, dtype)

        @settings(max_examples=40, deadline=None, derandomize=True)
        @given(theta=_theta_strategy(model), dt=st.sampled_from([1e-3, 1.0 / 128.0, 0.1]))
        def check(theta, dt):
            F = run(jnp.asarray(theta, dtype), v, dt)
            assert F.dtype == dtype
            assert bool(jnp.all(jnp.isfinite(F))), theta

        check()


@pytest.mark.parametrize("x64", [False, True], ids=["float32", "float64"])
def test_gradient_finite_at_standstill(x64):
    model = LuGre()
    with jax.enable_x64(x64):
        v = jnp.asarray(np.r_[np.zeros(10), reversal_profile(40), np.zeros(10)])
        theta = model.from_physical(**LUGRE_CASES[0])
        loss = jax.jit(jax.grad(lambda th, v: jnp.mean(model.simulate(th, v, DT) ** 2)))
        assert bool(jnp.all(jnp.isfinite(loss(theta, v))))
        # Also on an all-zero record, where every step takes the phi series branch.
        grad0 = loss(theta, jnp.zeros_like(v))
        assert bool(jnp.all(jnp.isfinite(grad0)))


def test_vmapped_rollout_equals_per_candidate():
    model = LuGre()
    lower, upper = model.bounds()
    thetas = np.random.default_rng(1).uniform(lower, upper, (5, model.num_params))
    v = reversal_profile()  # the exact-update tests' length: their rollout program per candidate
    with jax.enable_x64(True):
        per = np.stack([model.simulate(th, v, DT) for th in thetas])
        vm = jax.vmap(model.simulate, in_axes=(0, None, None))(thetas, v, DT)
        batch = model.simulate_batch(thetas, v, DT)
    np.testing.assert_allclose(vm, per, rtol=1e-12, atol=0)
    np.testing.assert_allclose(batch, per, rtol=1e-12, atol=0)


def test_new_data_does_not_recompile():
    model = LuGre()
    theta = model.from_physical(**LUGRE_CASES[1])
    traces = []

    @jax.jit
    def run(th, v, dt):
        traces.append(1)
        return model.simulate(th, v, dt)

    rng = np.random.default_rng(0)
    for _ in range(3):
        run(theta, jnp.asarray(rng.normal(0, 0.01, 64), jnp.float32), jnp.float32(rng.uniform(1e-3, 1e-2)))
    assert len(traces) == 1


def test_lugre_search_coordinates():
    model = LuGre()
    assert model.num_params == 6
    assert model.param_names == ("log10_sigma0", "log10_sigma1", "log10_sigma2", "Fc", "Fs_over_Fc", "log10_vs")
    lower, upper = model.bounds()
    np.testing.assert_allclose(lower, [4, 1, 1, 10, 1, -4])
    np.testing.assert_allclose(upper, [9, 6, 5, 2000, 3, np.log10(5e-2)])
    with jax.enable_x64(True):
        p = LUGRE_CASES[0]
        theta = model.from_physical(**p)
        back = model.to_physical(theta)
        for k, val in p.items():
            np.testing.assert_allclose(back[k], val, rtol=1e-12)
    # Fs >= Fc everywhere in the box, by construction
    rng = np.random.default_rng(0)
    phys = model.to_physical(rng.uniform(lower, upper, (200, 6)))
    assert bool(jnp.all(phys["Fs"] >= phys["Fc"]))


def test_lugre_user_ranges_and_data_bounds():
    model = LuGre()
    user = {"Fc": (50, 500), "vs": [1e-3, 1e-2]}
    lower, upper = model.bounds(user)
    assert (lower[3], upper[3]) == (50.0, 500.0)
    np.testing.assert_allclose((lower[5], upper[5]), (-3.0, -2.0))

    v = reversal_profile()
    F = 150.0 * np.tanh(v / 1e-3) + 800.0 * v
    fitted = model.search_box(user, v, F)
    assert fitted["Fc"] == (50.0, 500.0)  # explicit ranges are kept
    assert fitted["sigma0"] != DEFAULT_RANGES["sigma0"]  # unset ranges are filled from the data
    level = np.percentile(np.abs(F), 95)
    auto = model.search_box(None, v, F)
    assert auto["Fc"] == pytest.approx((0.05 * level, 1.2 * level))
    # the data-centred box contains the generating Coulomb level and the guess lies inside
    lo, hi = model.bounds(auto)
    guess = model.initial_guess(v, F, auto)
    assert np.all((guess >= lo) & (guess <= hi))
    assert lo[3] < 150.0 < hi[3]
    assert model.to_physical(guess)["Fc"] == pytest.approx(150.0, rel=0.1)


@pytest.mark.parametrize(
    "box, kwargs",
    [({"Fc": (0.0, 10.0)}, {}), ({"sigma0": (1e5, 1e4)}, {}), ({"Fs_ratio": (0.5, 2.0)}, {}),
     (None, dict(stribeck_exponent=0.0))],
)
def test_lugre_rejects_bad_ranges(box, kwargs):
    with pytest.raises(ValueError):
        LuGre(**kwargs).bounds(box)


def test_lugre_from_physical_requires_all_names():
    with pytest.raises(ValueError, match="missing"):
        LuGre().from_physical(sigma0=1e6)


def test_stribeck_exponent_option():
    """A non-default exponent changes g(v) as |v/vs|^delta and stays differentiable."""
    p = LUGRE_CASES[0]
    model = LuGre(stribeck_exponent=1.0)
    with jax.enable_x64(True):
        theta = model.from_physical(**p)
        vel = 2e-3
        F = model.simulate(theta, jnp.full(64, vel), DT)
        g = p["Fc"] + (p["Fs"] - p["Fc"]) * np.exp(-abs(vel / p["vs"]))
        np.testing.assert_allclose(F[-1], g + p["sigma2"] * vel, rtol=1e-9)
        grad = jax.jit(jax.grad(lambda th: jnp.sum(model.simulate(th, jnp.zeros(4), DT))))(theta)
        assert bool(jnp.all(jnp.isfinite(grad)))


@pytest.mark.parametrize("model", [LuGre(), Dahl()], ids=["lugre", "dahl"])
def test_sample_time_is_required(model):
    theta = 0.5 * sum(model.bounds())
    with pytest.raises(ValueError, match="sample time"):
        model.simulate(theta, np.zeros(4), None)
    with pytest.raises(ValueError, match="scalar"):
        model.simulate(theta, np.zeros(4), np.ones(4))


def test_float32_rollout_tracks_float64():
    """The exact update loses nothing to float32 beyond rounding, even when stiff."""
    model, v = LuGre(), reversal_profile()
    for p in LUGRE_CASES:
        with jax.enable_x64(True):
            F64 = np.asarray(model.simulate(model.from_physical(**p), v, DT))
        theta32 = np.asarray(model.from_physical(**p), np.float32)
        F32 = np.asarray(model.simulate(theta32, v.astype(np.float32), DT))
        assert F32.dtype == np.float32
        assert np.max(np.abs(F32 - F64)) / np.max(np.abs(F64)) < 1e-5
