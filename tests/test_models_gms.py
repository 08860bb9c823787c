"""Generalised Maxwell-slip (docs/algorithms.md §8.4): the exact per-sample update against
a fine-step explicit-Euler integration of the published stick/slip law, the weight
parametrisation, finiteness over the box, and recovery of known parameters."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from model_recovery import assert_within, lm_recovery

from jaxfric.models import GMS
from jaxfric.models.gms import _splits_to_weights, _weights_to_splits

DT = 1e-3
P3 = dict(k1=2e4, k2=1e5, k3=5e5, alpha1=0.5, alpha2=0.3, alpha3=0.2, C=2e3, Fc=100.0, Fs=150.0,
          vs=2e-3, sigma2=500.0)


def profile(n: int = 500) -> np.ndarray:
    """Reversals at several amplitudes (pre-sliding loops), a standstill and a fast stretch."""
    t = np.arange(n) * DT
    v = 0.01 * np.sin(2 * np.pi * 2.3 * t) + 0.004 * np.sin(2 * np.pi * 11 * t)
    v[150:170] = 0.0
    seg = v[300:380]
    seg[:] = 1e-3 * np.sin(2 * np.pi * 25 * t[: seg.size])
    return v


def euler_reference(p, n, v, dt, substeps=100, delta=2.0):
    """Explicit Euler of the published GMS law (Al-Bender et al. 2005) at ``substeps``
    times the sample rate, velocity held over each sample; stick -> slip when an
    element reaches alpha_i s(v), slip -> stick when v changes sign."""
    k = np.array([p[f"k{i}"] for i in range(1, n + 1)])
    a = np.array([p[f"alpha{i}"] for i in range(1, n + 1)])
    h = dt / substeps

    def s_of(vk):
        d = "" if "Fc" in p else ("_pos" if vk > 0 else "_neg")
        return p["Fc" + d] + (p["Fs" + d] - p["Fc" + d]) * np.exp(-np.abs(vk / p["vs"]) ** delta)

    def viscous(vk):
        return p["sigma2"] if "sigma2" in p else p["sigma2_pos" if vk > 0 else "sigma2_neg"]

    F = a * s_of(v[0]) * np.sign(v[0])
    slip = np.full(n, np.sign(v[0]))
    out = np.empty(len(v))
    for j, vk in enumerate(v):
        out[j] = F.sum() + viscous(vk) * vk + p.get("F_off", 0.0)
        s, sv = s_of(vk), np.sign(vk)
        slip[slip != sv] = 0.0  # re-stick on a velocity reversal (or standstill)
        for _ in range(substeps):
            start = (slip == 0) & (sv != 0) & (sv * F >= a * s)
            slip[start] = sv
            sticking = slip == 0
            F_new = np.where(sticking, F + k * vk * h, F + p["C"] * (a * sv - F / s) * h)
            reach = sticking & (sv != 0) & (sv * F_new >= a * s)
            F = np.where(reach, a * s * sv, F_new)
            slip[reach] = sv
    return out


def test_gms_exact_update_matches_fine_euler_reference():
    model = GMS(num_elements=3)
    v = profile(400)
    with jax.enable_x64(True):
        F = np.asarray(model.simulate(model.from_physical(**P3), v, DT))
    ref = euler_reference(P3, 3, v, DT)
    err = np.max(np.abs(F - ref)) / np.max(np.abs(ref))
    assert err < 1e-3, err
    # the profile exercises both regimes: loops through most of +-Fc and back
    assert np.max(F) > 0.8 * P3["Fc"] and np.min(F) < -0.2 * P3["Fc"]


def test_asymmetric_gms_matches_fine_euler_reference_and_symmetric_case():
    """docs/algorithms.md §13.1 levels: the rig's kind of truth (270 N one way, 150 N back)."""
    model = GMS(num_elements=3, asymmetric=True, offset=True)
    p = {**{k: x for k, x in P3.items() if k not in ("Fc", "Fs", "sigma2")},
         "Fc_pos": 120.0, "Fc_neg": 70.0, "Fs_pos": 160.0, "Fs_neg": 90.0,
         "sigma2_pos": 500.0, "sigma2_neg": 300.0, "F_off": 4.0}
    v = profile(300)
    with jax.enable_x64(True):
        F = np.asarray(model.simulate(model.from_physical(**p), v, DT))
        sym = GMS(num_elements=3)
        same = {**{k: x for k, x in P3.items() if k not in ("Fc", "Fs", "sigma2")}, "F_off": 0.0,
                **{name + d: P3[name] for name in ("Fc", "Fs", "sigma2") for d in ("_pos", "_neg")}}
        np.testing.assert_array_equal(model.simulate(model.from_physical(**same), v, DT),
                                      sym.simulate(sym.from_physical(**P3), v, DT))
    ref = euler_reference(p, 3, v, DT)
    assert np.max(np.abs(F - ref)) / np.max(np.abs(ref)) < 1e-3


def test_gms_is_stiff_and_stable_at_coarse_steps():
    """C h / s = 20 and k h |v| >> alpha s per sample: still finite and bounded by the levels."""
    model = GMS(num_elements=2)
    p = dict(k1=1e8, k2=1e9, alpha1=0.4, alpha2=0.6, C=1e6, Fc=100.0, Fs=150.0, vs=2e-3, sigma2=1.0)
    v = profile(300)
    with jax.enable_x64(True):
        F = np.asarray(model.simulate(model.from_physical(**p), v, 0.01))
    assert np.all(np.isfinite(F))
    assert np.max(np.abs(F - v)) <= 150.0 + 1e-9


def test_weights_parametrisation():
    rng = np.random.default_rng(0)
    u = rng.uniform(0, 1, (5, 3))
    with jax.enable_x64(True):
        alpha = np.asarray(_splits_to_weights(jnp.asarray(u)))
        np.testing.assert_allclose(alpha.sum(-1), 1.0, rtol=1e-14)
        assert np.all(alpha >= 0)
        np.testing.assert_allclose(_weights_to_splits(jnp.asarray(alpha)), u, rtol=1e-12)
    model = GMS(num_elements=3)
    with pytest.raises(ValueError, match="sum to 1"):
        model.from_physical(**{**P3, "alpha1": 0.9})
    assert model.param_names == ("log10_k1", "log10_k2", "log10_k3", "split1", "split2", "log10_C",
                                 "Fc", "Fs_over_Fc", "log10_vs", "log10_sigma2")
    lo, hi = model.bounds()
    assert lo[3] == 0.0 and hi[3] == 1.0


def test_finite_over_the_box_with_finite_gradients_at_standstill():
    model = GMS(num_elements=2)
    lo, hi = model.bounds()
    thetas = np.random.default_rng(1).uniform(lo, hi, (64, model.num_params))
    v = profile(200)
    F = model.simulate_batch(thetas.astype(np.float32), v.astype(np.float32), DT)
    assert np.all(np.isfinite(np.asarray(F)))
    v0 = np.zeros(50)
    v0[20:] = 1e-3
    # one program (eagerly, the rollout's forward and backward and each jnp operation
    # around them compile one by one)
    grad = jax.jit(jax.grad(lambda th: jnp.sum(model.simulate(th, v0, DT) ** 2)))(jnp.asarray(thetas[0]))
    assert np.all(np.isfinite(np.asarray(grad)))


def test_gms_recovers_known_parameters_by_least_squares():
    """Noise-free record with pre-sliding loops: LM from a start 4-5 % off recovers all 9.

    The record must be long enough to reach steady sliding: on its first 800 samples
    (never at the Coulomb level) a one-parameter family (alpha1, C, Fc, Fs) fits
    exactly, and from 10 % off LM stops in a local minimum (the stick/slip events
    make the cost non-smooth); a global search (identify) is the tool for that."""
    model = GMS(num_elements=2)
    p = dict(k1=3e4, k2=3e5, alpha1=0.6, alpha2=0.4, C=3e3, Fc=100.0, Fs=140.0, vs=3e-3, sigma2=500.0)
    v = profile(1500)
    with jax.enable_x64(True):
        truth = np.asarray(model.from_physical(**p))
    logs = np.array([n.startswith("log10") for n in model.param_names])
    start = np.where(logs, truth + 0.02, truth * 1.04)
    assert_within(lm_recovery(model, v, DT, truth, start), p)


def test_gms_unidentifiable_without_presliding():
    t = np.arange(3000) * DT
    fast = 0.1 * np.sign(np.sin(2 * np.pi * 0.5 * t)) + 0.02 * np.sin(2 * np.pi * 3 * t)
    flagged = GMS(num_elements=2).unidentifiable(fast)
    assert {"k1", "k2", "alpha1", "alpha2", "C", "Fs", "vs"} <= set(flagged)
    assert "Fc" not in flagged and "sigma2" not in flagged
