"""Real-drive friction forms (docs/algorithms.md §13.1): asymmetric levels and offset,
pressure-dependent cylinder friction, and the parameters a record cannot determine.

References are independent: hand-written NumPy formulas for the static maps, a
per-sample LSODA integration for the asymmetric LuGre/Dahl, and recovery of known
parameters from noise-free data by least squares.
"""

from __future__ import annotations

import jax
import numpy as np
import pytest
from model_recovery import assert_within, lm_recovery
from scipy.integrate import solve_ivp

import jaxfric
from jaxfric import models
from jaxfric.models import Coulomb, Cylinder, Dahl, LuGre, Stribeck, Unidentifiable
from jaxfric.optim import NelderMead

DT = 1e-3
V = np.r_[np.linspace(-0.03, 0.03, 41), 0.0, 1e-6, -2e-5]

# EMPS-like asymmetric levels (SOURCE.md of the EMPS data, Janot et al. 2019).
ASYM = dict(Fc_pos=20.14, Fc_neg=20.63, sigma2_pos=166.71, sigma2_neg=240.42, F_off=-3.1648)


def reversal_profile(n: int = 400) -> np.ndarray:
    t = np.arange(n) * DT * 8
    v = 0.006 * np.sin(2 * np.pi * 1.1 * t) + 0.004 * np.sin(2 * np.pi * 2.9 * t + 0.4) + 0.001
    v[100:112] = 0.0
    return v


# ----------------------------------------------------------------- static maps
def test_asymmetric_coulomb_is_the_emps_formula():
    model = Coulomb(asymmetric=True, offset=True, v_eps=1e-9)
    assert model.param_names == ("Fc_pos", "Fc_neg", "log10_sigma2_pos", "log10_sigma2_neg", "F_off")
    v = V[np.abs(V) > 1e-7]  # hard sign where tanh(v / 1e-9) = +-1 exactly
    with jax.enable_x64(True):
        F = np.asarray(model.simulate(model.from_physical(**ASYM), v))
    p = ASYM
    ref = (p["Fc_pos"] * (v > 0) - p["Fc_neg"] * (v < 0) + p["sigma2_pos"] * v * (v > 0)
           + p["sigma2_neg"] * v * (v < 0) + p["F_off"])
    np.testing.assert_allclose(F, ref, rtol=1e-13, atol=1e-12)


def test_asymmetric_stribeck_formula():
    model = Stribeck(asymmetric=True, offset=True)
    p = dict(Fc_pos=100.0, Fc_neg=70.0, Fs_pos=180.0, Fs_neg=90.0, vs=2e-3, sigma2_pos=500.0,
             sigma2_neg=300.0, F_off=4.0)
    with jax.enable_x64(True):
        F = np.asarray(model.simulate(model.from_physical(**p), V))
    t = np.tanh(V / 1e-4)
    decay = np.exp(-((V / p["vs"]) ** 2))
    g_pos = p["Fc_pos"] + (p["Fs_pos"] - p["Fc_pos"]) * decay
    g_neg = p["Fc_neg"] + (p["Fs_neg"] - p["Fc_neg"]) * decay
    visc = np.where(V > 0, p["sigma2_pos"], p["sigma2_neg"]) * V
    ref = np.maximum(t, 0) * g_pos - np.maximum(-t, 0) * g_neg + visc + p["F_off"]
    np.testing.assert_allclose(F, ref, rtol=1e-13, atol=1e-12)


SYMMETRIC = [
    (Coulomb(), dict(Fc=120.0, sigma2=900.0), {}),
    (Stribeck(), dict(Fc=100.0, Fs=180.0, vs=2e-3, sigma2=500.0), {"Fs": "Fs"}),
    (LuGre(), dict(sigma0=3e4, sigma1=50.0, sigma2=30.0, Fc=40.0, Fs=100.0, vs=1e-3), {}),
    (Dahl(viscous=True), dict(sigma0=5e5, Fc=120.0, sigma2=400.0), {}),
]


@pytest.mark.parametrize("sym,params,_", SYMMETRIC, ids=lambda x: type(x).__name__)
def test_symmetric_special_case_equals_existing_model_exactly(sym, params, _):
    """Equal + and - levels and a zero offset reproduce the paper's symmetric form bit for bit."""
    import dataclasses

    asym = dataclasses.replace(sym, asymmetric=True, offset=True)
    both = {}
    for name, value in params.items():
        if name in ("Fc", "Fs", "sigma2"):
            both[name + "_pos"] = both[name + "_neg"] = value
        else:
            both[name] = value
    v = reversal_profile()
    with jax.enable_x64(True):
        F_sym = np.asarray(sym.simulate(sym.from_physical(**params), v, DT))
        F_asym = np.asarray(asym.simulate(asym.from_physical(**both, F_off=0.0), v, DT))
    np.testing.assert_array_equal(F_asym, F_sym)
    # theta layout of the symmetric model is unchanged by the new options
    assert dataclasses.replace(sym).param_names == sym.param_names


def _lsoda_bristles(v, sigma0, sigma1, g, sigma2, f_off):
    """Per-sample LSODA of dz/dt = v - sigma0 |v| z / g(v) with v held over each sample."""
    z = np.empty(len(v))
    zk = np.sign(v[0]) * g(v[0]) / sigma0
    for k, vk in enumerate(v):
        z[k] = zk
        a = sigma0 * abs(vk) / g(vk)
        zk = solve_ivp(lambda t, y: [vk - a * y[0]], (0.0, DT), [zk], method="LSODA",
                       rtol=1e-12, atol=1e-16, jac=lambda t, y: [[-a]]).y[0, -1]
    a = sigma0 * np.abs(v) / np.array([g(vk) for vk in v])
    return sigma0 * z + sigma1 * (v - a * z) + np.array([sigma2(vk) for vk in v]) * v + f_off


def test_asymmetric_lugre_against_lsoda():
    p = dict(sigma0=3e4, sigma1=50.0, sigma2_pos=30.0, sigma2_neg=60.0, Fc_pos=40.0, Fc_neg=25.0,
             Fs_pos=100.0, Fs_neg=45.0, vs=1e-3, F_off=-2.5)
    model = LuGre(asymmetric=True, offset=True)
    v = reversal_profile()
    with jax.enable_x64(True):
        F = np.asarray(model.simulate(model.from_physical(**p), v, DT))

    def g(vk):
        d = "pos" if vk > 0 else "neg"
        return p[f"Fc_{d}"] + (p[f"Fs_{d}"] - p[f"Fc_{d}"]) * np.exp(-((vk / p["vs"]) ** 2))

    ref = _lsoda_bristles(v, p["sigma0"], p["sigma1"], g,
                          lambda vk: p["sigma2_pos"] if vk > 0 else p["sigma2_neg"], p["F_off"])
    assert np.max(np.abs(F - ref)) / np.max(np.abs(ref)) < 1e-6


def test_asymmetric_dahl_against_lsoda():
    p = dict(sigma0=5e5, Fc_pos=120.0, Fc_neg=80.0, sigma2_pos=400.0, sigma2_neg=250.0, F_off=3.0)
    model = Dahl(viscous=True, asymmetric=True, offset=True)
    v = reversal_profile()
    with jax.enable_x64(True):
        F = np.asarray(model.simulate(model.from_physical(**p), v, DT))
    ref = _lsoda_bristles(v, p["sigma0"], 0.0, lambda vk: p["Fc_pos"] if vk > 0 else p["Fc_neg"],
                          lambda vk: p["sigma2_pos"] if vk > 0 else p["sigma2_neg"], p["F_off"])
    assert np.max(np.abs(F - ref)) / np.max(np.abs(ref)) < 1e-6


def test_asymmetric_lugre_steady_state_levels():
    """Sliding steadily, F -> g_pos(v) + sigma2_pos v forwards and -g_neg(v) + sigma2_neg v back."""
    p = dict(sigma0=1e6, sigma1=100.0, sigma2_pos=30.0, sigma2_neg=60.0, Fc_pos=40.0, Fc_neg=25.0,
             Fs_pos=50.0, Fs_neg=30.0, vs=1e-3, F_off=1.0)
    model = LuGre(asymmetric=True, offset=True)
    v = np.r_[np.full(300, 0.02), np.full(300, -0.02)]
    with jax.enable_x64(True):
        F = np.asarray(model.simulate(model.from_physical(**p), v, DT))
    np.testing.assert_allclose(F[299], 40.0 + 30.0 * 0.02 + 1.0, rtol=1e-9)
    np.testing.assert_allclose(F[-1], -25.0 - 60.0 * 0.02 + 1.0, rtol=1e-9)


# ------------------------------------------------------------------ cylinder
def _pressures(n, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    p1 = 3e5 + 2e5 * np.sin(2 * np.pi * 0.7 * t) + 1e4 * rng.standard_normal(n)
    p2 = 4e5 - 1e5 * np.cos(2 * np.pi * 1.3 * t)
    return np.stack([p1, p2])


def test_cylinder_is_the_simscape_formula():
    model = Cylinder()
    assert model.input_names == ("p1", "p2")
    assert model.param_names == ("F_pr", "f_cfr", "K_brk", "log10_vs", "log10_sigma2")
    p = dict(F_pr=20.0, f_cfr=2e-5, K_brk=1.4, vs=5e-3, sigma2=300.0)
    pr = _pressures(V.size)
    with jax.enable_x64(True):
        F = np.asarray(model.simulate(model.from_physical(**p), V, None, pr))
    f_c = p["F_pr"] + p["f_cfr"] * (pr[0] + pr[1])
    ref = np.tanh(V / 1e-4) * f_c * (1 + (p["K_brk"] - 1) * np.exp(-np.abs(V) / p["vs"])) + p["sigma2"] * V
    np.testing.assert_allclose(F, ref, rtol=1e-13, atol=1e-12)


def test_cylinder_needs_pressures_with_a_clear_error():
    model = Cylinder()
    theta = 0.5 * np.add(*model.bounds())
    with pytest.raises(ValueError, match="needs inputs"):
        model.simulate(theta, V)
    with pytest.raises(ValueError, match=r"\(2, T\)"):
        model.simulate(theta, V, None, np.zeros((3, V.size)))
    v_long = np.tile(V, 4)  # a validation window long enough to be accepted on its own
    data = jaxfric.rig.FrictionData.from_arrays(v_long, 10 * np.tanh(v_long / 1e-3), DT)
    with pytest.raises(ValueError, match="p1, p2"):
        jaxfric.identify("cylinder", data, key=0)
    # models that need no inputs ignore them
    c = Coulomb()
    th = c.from_physical(Fc=10.0, sigma2=5.0)
    np.testing.assert_array_equal(c.simulate(th, V, None, _pressures(V.size)), c.simulate(th, V))


@pytest.mark.slow
def test_identify_recovers_pressure_coulomb_from_a_record_with_pressures():
    """identify passes p1, p2 of the record to the model; noise-free data, known parameters."""
    n = 1500
    t = np.arange(n) * DT
    v = 0.05 * np.sin(2 * np.pi * 1.5 * t) + 0.02 * np.sin(2 * np.pi * 4.1 * t)
    pr = _pressures(n)
    truth = dict(F_pr=15.0, f_cfr=3e-5, sigma2=250.0)
    model = Cylinder(breakaway=False)
    with jax.enable_x64(True):
        F = np.asarray(model.simulate(model.from_physical(**truth), v, None, pr))
        data = jaxfric.rig.FrictionData.from_arrays(v, F, DT, p1=pr[0], p2=pr[1])
        fit = jaxfric.identify(model, data, key=1, solver=NelderMead(max_steps=600, max_evals=600),
                               refine="lm")
        got = fit.params
        np.testing.assert_allclose(fit.predict(v, inputs=pr), F, rtol=1e-6, atol=1e-6)
    for name, value in truth.items():
        assert abs(float(got[name]) - value) <= 0.02 * abs(value), (name, got[name], value)


# ----------------------------------------------------- least-squares recovery
def test_asymmetric_coulomb_least_squares_recovers_emps_parameters():
    rng = np.random.default_rng(3)
    v = np.r_[rng.uniform(-0.13, -1e-3, 400), rng.uniform(1e-3, 0.13, 400)]
    p = ASYM
    F = (p["Fc_pos"] * (v > 0) - p["Fc_neg"] * (v < 0) + p["sigma2_pos"] * v * (v > 0)
         + p["sigma2_neg"] * v * (v < 0) + p["F_off"])
    got = Coulomb(asymmetric=True, v_eps=1e-7).fit_least_squares(v, F - p["F_off"])
    for name in ("Fc_pos", "Fc_neg", "sigma2_pos", "sigma2_neg"):
        assert abs(got[name] - p[name]) <= 0.02 * abs(p[name]), (name, got[name], p[name])
    # With an offset too, sliding data fix only Fc_pos + F_off and Fc_neg - F_off.
    model = Coulomb(asymmetric=True, offset=True, v_eps=1e-7)
    got = model.fit_least_squares(v, F)
    np.testing.assert_allclose(got["Fc_pos"] + got["F_off"], p["Fc_pos"] + p["F_off"], rtol=1e-9)
    np.testing.assert_allclose(got["Fc_neg"] - got["F_off"], p["Fc_neg"] - p["F_off"], rtol=1e-9)
    assert "F_off" in model.unidentifiable(v)
    sym = Coulomb(offset=True, v_eps=1e-7)
    F_sym = 20.39 * np.sign(v) + 203.5 * v - 3.16
    got = sym.fit_least_squares(v, F_sym)
    assert set(got) == {"Fc", "sigma2", "F_off"} and sym.unidentifiable(v) == ()
    np.testing.assert_allclose([got["Fc"], got["sigma2"], got["F_off"]], [20.39, 203.5, -3.16], rtol=1e-9)


@pytest.mark.slow
def test_identify_recovers_asymmetric_coulomb():
    """A short identify run (MAPSO-NMDS + LM) on noise-free EMPS-like data."""
    n = 1200
    t = np.arange(n) * DT
    v = 0.1 * np.sin(2 * np.pi * 1.2 * t) + 0.03 * np.sin(2 * np.pi * 3.3 * t)
    model = Coulomb(asymmetric=True, v_eps=1e-4)
    truth = {k: x for k, x in ASYM.items() if k != "F_off"}
    with jax.enable_x64(True):
        F = np.asarray(model.simulate(model.from_physical(**truth), v))
        fit = jaxfric.identify(model, (v, F, DT), key=2, solver=NelderMead(max_steps=800, max_evals=800),
                               refine="lm")
    for name, value in truth.items():
        assert abs(float(fit.params[name]) - value) <= 0.02 * abs(value), (name, fit.params[name])


def test_asymmetric_lugre_recovers_known_parameters_by_least_squares():
    """Noise-free record with pre-sliding: LM from a start 10-20 % off recovers all 10."""
    p = dict(sigma0=3e4, sigma1=50.0, sigma2_pos=30.0, sigma2_neg=60.0, Fc_pos=40.0, Fc_neg=25.0,
             Fs_pos=100.0, Fs_neg=45.0, vs=1e-3, F_off=-2.5)
    model = LuGre(asymmetric=True, offset=True)
    v = reversal_profile(600)
    with jax.enable_x64(True):
        truth = np.asarray(model.from_physical(**p))
    start = truth + np.where([n.startswith("log10") for n in model.param_names], 0.06, 0.0)
    start = np.where(np.isin(model.param_names, ["Fc_pos", "Fc_neg", "F_off"]), truth * 1.15, start)
    assert_within(lm_recovery(model, v, DT, truth, start, tol=1e-14), p)


# --------------------------------------------------------- unidentifiability
def test_unidentifiable_flags_presliding_without_low_speed_samples():
    t = np.arange(4000) * DT
    fast = 0.1 * np.sign(np.sin(2 * np.pi * 0.5 * t)) + 0.02 * np.sin(2 * np.pi * 3 * t)
    assert np.mean((np.abs(fast) > 0) & (np.abs(fast) < 1e-3)) < 0.02
    flagged = LuGre().unidentifiable(fast)
    assert {"sigma0", "sigma1", "Fs", "vs"} <= set(flagged)
    assert "Fc" not in flagged and "sigma2" not in flagged
    assert all(isinstance(x, Unidentifiable) and ("pre-sliding" in x.reason or "Stribeck" in x.reason)
               for x in flagged)
    sine = 0.01 * np.sin(2 * np.pi * 0.5 * t)  # sweeps through low speed in ~1.3 % of samples
    assert "sigma0" in LuGre().unidentifiable(sine)
    slow = sine.copy()
    slow[1000:1400] = 1e-4 * np.sin(2 * np.pi * 20 * t[:400])  # a small-amplitude pre-sliding segment
    assert LuGre().unidentifiable(slow) == ()
    assert Dahl().unidentifiable(fast) == ("sigma0",)
    # records work as well as arrays
    data = jaxfric.rig.FrictionData.from_arrays(fast, np.tanh(fast / 1e-3), DT)
    assert LuGre().unidentifiable(data) == flagged
    assert Coulomb().unidentifiable(fast) == ()


def test_unidentifiable_flags_a_direction_never_visited():
    v = np.abs(0.05 * np.sin(np.linspace(0, 20, 800))) + 1e-3
    flagged = Coulomb(asymmetric=True).unidentifiable(v)
    assert set(flagged) == {"Fc_neg", "sigma2_neg"}
    assert "negative direction" in flagged[0].reason


def test_unidentifiable_cylinder_pressure_split():
    n = 500
    v = 0.05 * np.sin(np.linspace(0, 12, n))
    pr = np.full((2, n), 5e5)
    data = jaxfric.rig.FrictionData.from_arrays(v, np.tanh(v / 1e-3), DT, p1=pr[0], p2=pr[1])
    assert {"F_pr", "f_cfr"} <= set(Cylinder(breakaway=False).unidentifiable(data))
    pr = _pressures(n)
    data = jaxfric.rig.FrictionData.from_arrays(v, np.tanh(v / 1e-3), DT, p1=pr[0], p2=pr[1])
    assert "f_cfr" not in Cylinder(breakaway=False).unidentifiable(data)


def test_registry_and_data_bounds_of_new_options():
    assert {"gms", "cylinder"} <= set(models.available())
    v = 0.01 * np.sin(np.linspace(0, 12, 300))
    F = 100 * np.tanh(v / 1e-3) + 600 * v - 5.0
    m = LuGre(asymmetric=True, offset=True)
    box = m.search_box(None, v, F)
    lo, hi = m.bounds(box)
    i = m.param_names.index("F_off")
    assert lo[i] < 0 < hi[i] and hi[i] < 100
    guess = m.initial_guess(v, F, box)
    assert np.all((guess >= lo) & (guess <= hi))
    pr = _pressures(300)
    c = Cylinder()
    j = c.param_names.index("f_cfr")
    level = np.median(pr[0] + pr[1])
    assert c.bounds(c.search_box(None, v, F, pr))[1][j] * level == pytest.approx(1.2 * np.percentile(np.abs(F), 95))


@pytest.mark.parametrize("model", [LuGre(asymmetric=True, offset=True), models.GMS(num_elements=2),
                                   Cylinder(offset=True)], ids=lambda m: type(m).__name__)
def test_new_models_survive_fit_save_and_load(tmp_path, model):
    """Saved fits rebuild the model with its options and predict bit-identically."""
    lower, upper = model.bounds()
    theta = 0.5 * (lower + upper)
    v = reversal_profile(200)
    pr = _pressures(v.size)
    fit = jaxfric.Fit(model=model, theta=theta, velocity_scaler=None, friction_scaler=None, dt=DT,
                      n_train=150, n_samples=200, metrics={})
    fit.save(tmp_path / "fit.npz")
    back = jaxfric.load_fit(tmp_path / "fit.npz")
    assert back.model == model and back.model.param_names == model.param_names
    np.testing.assert_array_equal(back.predict(v, inputs=pr), fit.predict(v, inputs=pr))


def test_unidentifiable_viscous_slope_at_one_speed_per_direction():
    """Triangular strokes (one speed each way, as the pneumatic seal records) cannot separate
    the viscous slope from the Coulomb level once levels are per direction or offset."""
    t = np.arange(3000) * DT
    one_speed = np.where(np.sin(2 * np.pi * 0.5 * t) > 0, 0.008, -0.012)
    assert set(Coulomb(asymmetric=True).unidentifiable(one_speed)) == {"sigma2_pos", "sigma2_neg"}
    assert Coulomb(offset=True).unidentifiable(one_speed) == ("sigma2",)
    assert Coulomb().unidentifiable(one_speed) == ()  # +-Fc + sigma2 v at two speeds: 2 equations
    levels = np.repeat([0.02, -0.05, 0.1, -0.12, 0.06, -0.03], 500)  # trapezoid-like plateaus
    assert Coulomb(asymmetric=True, offset=True).unidentifiable(levels) == ("F_off",)


def test_inputs_from_a_record_are_checked_by_the_model_that_needs_them():
    n = 50
    v = np.linspace(-0.01, 0.01, n)
    p1 = np.full(n, 3e5)
    p1[7] = np.nan
    data = jaxfric.rig.FrictionData.from_arrays(v, np.tanh(v / 1e-3), DT, p1=np.full(n, 3e5),
                                                p2=np.full(n, 1e5))
    np.testing.assert_array_equal(Cylinder().inputs_from(data), np.stack([np.full(n, 3e5), np.full(n, 1e5)]))
    assert Coulomb().inputs_from(data) is None
    from jaxfric.identification import as_record

    bad = as_record((v, np.tanh(v / 1e-3), DT))
    with pytest.raises(ValueError, match="p1, p2"):
        Cylinder().inputs_from(bad)
    import dataclasses

    bad = dataclasses.replace(bad, p1=p1, p2=np.full(n, 1e5))
    with pytest.raises(ValueError, match="p1 holds NaN"):
        Cylinder().inputs_from(bad)
    with pytest.raises(ValueError, match="expected 60"):
        Cylinder().inputs_from(data, 60)
