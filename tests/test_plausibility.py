"""Physical plausibility rules (jaxfric.plausibility): a constructed unphysical fit
warns with its reason and evidence, in the diagnostics, the summary and the file; an
identifiable fit does not."""

import re
import warnings

import numpy as np
import pytest

from jaxfric import Fit, load_fit, models
from jaxfric.plausibility import PlausibilityWarning, check_plausibility, travel_since_reversal
from jaxfric.uncertainty import assess_fit

DT = 1e-3


def _trapezoid_velocity():
    """EMPS-like: trapezoidal moves at 0.05-0.2 m/s with fast reversals (1.2 s, 1 kHz)."""
    t = np.arange(12000) * DT
    v = 0.2 * np.clip(4 * np.sin(2 * np.pi * 0.5 * t), -1, 1) * (0.6 + 0.4 * np.cos(2 * np.pi * 0.13 * t))
    return v


def _fit(model, v, **params):
    return Fit(model=model, theta=np.asarray(model.from_physical(**params), np.float64), velocity_scaler=None,
               friction_scaler=None, dt=DT, n_train=v.size, n_samples=v.size + 100, metrics={})


def test_travel_since_reversal_against_a_loop():
    rng = np.random.default_rng(0)
    v = rng.standard_normal(300)
    v[::7] = 0.0
    ref, acc, sign = np.empty_like(v), 0.0, 0.0
    for i, x in enumerate(v):
        s = np.sign(x)
        if s != 0 and s != sign:
            acc, sign = 0.0, s
        acc += x * 0.01
        ref[i] = abs(acc)
    np.testing.assert_allclose(travel_since_reversal(v, 0.01), ref, atol=1e-12)


def test_emps_like_lugre_warns_with_evidence(tmp_path):
    """The fit of the EMPS report: Fs- = 3 Fc with vs = 0.13 mm/s, a 7 N offset beside
    asymmetric levels, and a stiffness whose elastic range is a few nanometres."""
    v = _trapezoid_velocity()
    model = models.LuGre(asymmetric=True, offset=True)
    fit = _fit(model, v, sigma0=1e9, sigma1=300.0, sigma2_pos=170.0, sigma2_neg=240.0, Fc_pos=17.0,
               Fc_neg=23.0, Fs_pos=17.1, Fs_neg=69.0, vs=1.3e-4, F_off=7.0)
    with pytest.warns(PlausibilityWarning) as rec:
        fit = assess_fit(fit, (v, np.zeros_like(v), DT))
    found = {d["rule"]: d for d in fit.diagnostics["implausible"]}
    assert set(found) == {"stribeck_spike", "offset_asymmetric", "presliding_unvisited"}
    assert found["stribeck_spike"]["name"] == "Fs_neg"
    assert found["stribeck_spike"]["evidence"]["fraction"] < 0.01
    assert found["stribeck_spike"]["evidence"]["ratio"] == pytest.approx(69.0 / 23.0)
    assert found["offset_asymmetric"]["evidence"]["F_off"] == pytest.approx(7.0)
    assert found["presliding_unvisited"]["evidence"]["range_m"] == pytest.approx(20.0 / 1e9)
    assert len(rec) == 3 and "Fs/Fc_neg = 3" in str(rec[0].message)
    assert "So F_off is not identifiable from these data" in str(rec[1].message)  # what it means
    assert re.search(r"!   Fs_neg: Fs/Fc_neg = 3.*plausibility rule stribeck_spike", fit.summary())
    assert re.search(r"Fs_neg=\S+ \[not identifiable\]", fit.summary())
    fit = fit.replace(uncertainty=None)     # no uncertainty needed for the file check
    fit.save(tmp_path / "f.npz")
    assert load_fit(tmp_path / "f.npz").diagnostics["implausible"] == fit.diagnostics["implausible"]


@pytest.mark.parametrize("model, params", [
    (models.Coulomb(), dict(Fc=20.0, sigma2=200.0)),
    (models.Coulomb(asymmetric=True, offset=True),
     dict(Fc_pos=21.0, Fc_neg=19.0, sigma2_pos=200.0, sigma2_neg=210.0, F_off=0.5)),
    (models.Stribeck(), dict(Fc=20.0, Fs=30.0, vs=0.02, sigma2=200.0)),
    (models.LuGre(), dict(sigma0=1e5, sigma1=300.0, sigma2=200.0, Fc=20.0, Fs=50.0, vs=0.03)),
    (models.Dahl(), dict(sigma0=1e5, Fc=20.0)),
])
def test_identifiable_fits_do_not_warn(model, params):
    v = _trapezoid_velocity()
    fit = _fit(model, v, **params)
    with warnings.catch_warnings():
        warnings.simplefilter("error", PlausibilityWarning)
        fit = assess_fit(fit, (v, np.zeros_like(v), DT))
    assert fit.diagnostics["implausible"] == []


def test_each_rule_needs_its_evidence():
    """The same peak is plausible where the data visit it, and the offset where the
    record stands still often enough."""
    v = _trapezoid_velocity()
    lugre = models.Stribeck()
    spike = dict(Fc=20.0, Fs=60.0, vs=1e-4, sigma2=200.0)
    assert [f.rule for f in check_plausibility(lugre, spike, v, DT)] == ["stribeck_spike"]
    slow = np.concatenate([v, np.linspace(-2e-4, 2e-4, 2000)])    # a slow sweep through zero
    assert check_plausibility(lugre, spike, slow, DT) == []
    coul = models.Coulomb(asymmetric=True, offset=True)
    p = dict(Fc_pos=30.0, Fc_neg=10.0, sigma2_pos=200.0, sigma2_neg=200.0, F_off=-10.0)
    assert [f.rule for f in check_plausibility(coul, p, v, DT)] == ["offset_asymmetric"]
    still = np.concatenate([v, np.zeros(2000)])
    assert check_plausibility(coul, p, still, DT) == []
    gms = models.GMS()
    base = dict(alpha1=0.5, alpha2=0.3, alpha3=0.2, C=100.0, Fc=20.0, Fs=25.0, vs=0.02, sigma2=200.0)
    stiff = check_plausibility(gms, {**base, "k1": 1e10, "k2": 1e5, "k3": 1e5}, v, DT)
    assert [(f.rule, f.name) for f in stiff] == [("presliding_unvisited", "k1")]
    assert check_plausibility(gms, {**base, "k1": 1e5, "k2": 1e5, "k3": 1e5}, v, DT) == []


def test_networks_and_bad_velocity():
    assert check_plausibility(models.Elman(neurons=2), {}, np.ones(5)) == []
    with pytest.raises(ValueError, match="finite"):
        check_plausibility(models.Coulomb(), {"Fc": 1.0, "sigma2": 1.0}, np.array([1.0, np.nan]))
