"""Fit: prediction, JSON summary, text summary, and the file format (atomic writes,
bit-identical round trip, clear errors for corrupted, truncated or newer files).

Fits are built directly from known parameters (no optimisation), so this file is fast.
"""

from __future__ import annotations

import json
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfric import fit as fit_module
from jaxfric import models
from jaxfric.fit import FORMAT_VERSION, Fit, load_fit
from jaxfric.metrics import friction_metrics
from jaxfric.models import Elman, LuGre, Scaler

DT = 1.0 / 128.0


def profile(n=300):
    t = np.arange(n) * DT
    return 0.010 * np.sin(2 * np.pi * 0.2 * t) + 0.004 * np.sin(2 * np.pi * 0.53 * t)


def make_enn_fit(seed=0, dtype=np.float32):
    model = Elman(neurons=5, context_weight_bound=2.0)
    lo, hi = model.bounds()
    theta = (lo + np.random.default_rng(seed).uniform(size=lo.shape) * (hi - lo)).astype(dtype)
    v = profile()
    f = 150.0 * np.tanh(v / 0.002) + 3e3 * v
    return Fit(model=model, theta=theta, velocity_scaler=Scaler.fit(v[:240]),
               friction_scaler=Scaler.fit(f[:240]), dt=DT, n_train=240, n_samples=300,
               metrics={"train": friction_metrics(f[:240], f[:240] + 1.0), "num_params": 30},
               stages=[{"stage": "mapso", "J": 0.5, "num_evals": 10}],
               history={"evals": np.array([5, 10]), "f": np.array([0.9, 0.5])},
               timings={"compile_s": 1.0, "run_s": 2.0, "total_s": 3.5},
               key_data=[0, 3], key_impl="threefry2x32", seed=3,
               settings={"dtype": str(np.dtype(dtype))})


def make_lugre_fit(dtype=np.float32):
    model = LuGre()
    theta = np.asarray(model.from_physical(sigma0=1e6, sigma1=1e3, sigma2=2e3, Fc=120.0,
                                           Fs=180.0, vs=2e-3), dtype)
    return Fit(model=model, theta=theta, velocity_scaler=None, friction_scaler=None, dt=DT,
               n_train=240, n_samples=300, metrics={"num_params": 6}, box={"Fc": (20.0, 400.0)})


# ----------------------------------------------------------------- prediction
def test_predict_equals_scaled_model_rollout():
    fit = make_enn_fit()
    v = profile(500)  # longer than the identification record: free run continues
    sv, sf = fit.velocity_scaler, fit.friction_scaler
    u = 2 * (v - sv.lo) / (sv.hi - sv.lo) - 1
    y = np.asarray(fit.model.simulate(jnp.asarray(fit.theta), jnp.asarray(u, jnp.float32)))
    expect = (y + 1) * 0.5 * (sf.hi - sf.lo) + sf.lo
    np.testing.assert_allclose(np.asarray(fit.predict(v)), expect, rtol=1e-5, atol=1e-3)


def test_predict_rejects_bad_input():
    fit = make_lugre_fit()
    with pytest.raises(ValueError, match="1-D"):
        fit.predict(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="NaN or inf"):
        fit.predict(np.array([0.0, np.nan]))
    with pytest.raises(ValueError, match="positive"):
        fit.predict(profile(), dt=-1.0)


def test_physical_params_and_dt_override():
    fit = make_lugre_fit(np.float64)
    with jax.enable_x64(True):
        assert float(fit.params["Fc"]) == pytest.approx(120.0)
        assert float(fit.params["Fs"]) == pytest.approx(180.0)
        a = np.asarray(fit.predict(profile()))
        b = np.asarray(fit.predict(profile(), dt=DT / 4))
    assert a.shape == (300,) and not np.allclose(a, b)  # LuGre's bristles integrate over dt


# ----------------------------------------------------------- to_dict / summary
def test_to_dict_is_json_and_summary_names_the_windows():
    fit = make_enn_fit()
    d = json.loads(json.dumps(fit.to_dict()))
    assert d["model"]["class"] == "Elman" and d["model"]["name"] == "elman"
    assert d["model"]["config"]["neurons"] == 5
    assert d["num_params"] == 30 and len(d["theta"]) == 30
    assert d["scalers"]["velocity"][0] == pytest.approx(float(fit.velocity_scaler.lo))
    lug = json.loads(json.dumps(make_lugre_fit().to_dict()))
    assert lug["params"]["Fc"] == pytest.approx(120.0, rel=1e-5)
    assert lug["scalers"] == {"velocity": None, "friction": None}
    text = fit.summary()
    assert "Elman" in text and "train" in text and "MSE %" in text and "mapso" in text
    assert "Fc=" in make_lugre_fit().summary()


# ------------------------------------------------------------------ round trip
@pytest.mark.parametrize("make", [make_enn_fit, make_lugre_fit], ids=["elman", "lugre"])
def test_save_load_predict_is_bit_identical(tmp_path, make):
    fit = make()
    path = tmp_path / "fit.npz"
    fit.save(path)
    back = load_fit(path)
    v = profile(400)
    assert np.array_equal(np.asarray(fit.predict(v)), np.asarray(back.predict(v)))
    assert back.theta.dtype == fit.theta.dtype and np.array_equal(back.theta, fit.theta)
    assert back.model == fit.model and back.box == fit.box
    assert back.metrics == json.loads(json.dumps(fit.metrics))
    assert back.stages == fit.stages and back.timings == fit.timings
    assert back.dt == fit.dt and back.n_train == fit.n_train
    assert back.version == fit.version
    assert back.solution is None
    np.testing.assert_array_equal(back.history["f"], fit.history["f"])
    if fit.key_data is not None:
        assert np.array_equal(jax.random.key_data(back.key), jax.random.key_data(jax.random.key(3)))


def test_float64_theta_round_trips_exactly(tmp_path):
    with jax.enable_x64(True):
        fit = make_enn_fit(seed=1, dtype=np.float64)
        fit.save(tmp_path / "f64.npz")
        back = load_fit(tmp_path / "f64.npz")
        assert back.theta.dtype == np.float64
        v = profile()
        assert np.array_equal(np.asarray(fit.predict(v)), np.asarray(back.predict(v)))


def test_save_is_atomic_and_overwrites(tmp_path, monkeypatch):
    path = tmp_path / "fit.npz"
    make_lugre_fit().save(path)
    make_enn_fit().save(path)  # overwrite in place
    assert type(load_fit(path).model).__name__ == "Elman"
    assert sorted(os.listdir(tmp_path)) == ["fit.npz"]  # no temporary left behind
    before = path.read_bytes()

    def explode(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(fit_module.np, "savez", explode)
    with pytest.raises(RuntimeError, match="disk full"):
        make_lugre_fit().save(path)
    assert path.read_bytes() == before  # the old file is untouched
    assert sorted(os.listdir(tmp_path)) == ["fit.npz"]


# ------------------------------------------------------------------- bad files
def _rewrite(path, **changes):
    """Rewrite ``path`` with header keys changed (``None`` deletes)."""
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(arrays["header"].tobytes().decode())
    for k, v in changes.items():
        if v is None:
            header.pop(k, None)
        else:
            header[k] = v
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), np.uint8)
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)


@pytest.fixture
def saved(tmp_path):
    path = tmp_path / "fit.npz"
    make_enn_fit().save(path)
    return path


def test_truncated_file_is_a_clear_error(saved):
    raw = saved.read_bytes()
    for cut in (len(raw) // 2, len(raw) - 30, 10):
        saved.write_bytes(raw[:cut])
        with pytest.raises(ValueError, match="corrupted or truncated"):
            load_fit(saved)


def test_flipped_bytes_are_a_clear_error(saved):
    raw = bytearray(saved.read_bytes())
    # Damage the stored member data (not only the directory): the zip CRC must catch it.
    start = raw.find(b"theta.npy")
    for i in range(start + 200, start + 216):
        raw[i] ^= 0xFF
    saved.write_bytes(bytes(raw))
    with pytest.raises(ValueError, match="corrupted"):
        load_fit(saved)


def test_not_a_fit_file(tmp_path):
    other = tmp_path / "other.npz"
    np.savez(other, x=np.arange(3))
    with pytest.raises(ValueError, match="not a jaxfric fit"):
        load_fit(other)
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"hello, not a zip at all")
    with pytest.raises(ValueError, match="corrupted or truncated"):
        load_fit(junk)


def test_newer_or_unknown_format_version(saved):
    _rewrite(saved, format_version=FORMAT_VERSION + 1)
    with pytest.raises(ValueError, match="newer|upgrade") as info:
        load_fit(saved)
    assert f"version {FORMAT_VERSION + 1}" in str(info.value)
    _rewrite(saved, format_version="one")
    with pytest.raises(ValueError, match="unknown fit format version"):
        load_fit(saved)


def test_unknown_model_class_or_missing_fields(saved):
    _rewrite(saved, model={"class": "os", "config": {}})
    with pytest.raises(ValueError, match="unknown friction model class"):
        load_fit(saved)
    make_enn_fit().save(saved)
    _rewrite(saved, dt=None)
    with pytest.raises(ValueError, match="incomplete or corrupted"):
        load_fit(saved)


def test_a_0_7_fit_file_with_range_fields_loads_its_box(tmp_path):
    """jaxfric 0.6/0.7 kept the search box in the model configuration (``Fc_range``, ...;
    ``None`` = the default) and wrote no ``box``: load_fit maps those keys into Fit.box."""
    fit = make_lugre_fit()
    path = tmp_path / "old.npz"
    fit.save(path)
    with np.load(path) as z:
        header = json.loads(z["header"].tobytes().decode())
    # the 0.7 LuGre configuration: every range a field, two of them set
    config = {"stribeck_exponent": 2.0, "sigma0_range": None, "sigma1_range": None, "sigma2_range": None,
              "Fc_range": [20.0, 400.0], "Fs_ratio_range": None, "vs_range": [1e-4, 1e-2],
              "asymmetric": False, "offset": False, "F_off_range": None}
    _rewrite(path, box=None, model={**header["model"], "config": config})
    back = load_fit(path)
    assert back.model == LuGre()
    expected = {"sigma0": (1e4, 1e9), "sigma1": (1e1, 1e6), "sigma2": (1e1, 1e5), "Fc": (20.0, 400.0),
                "Fs_ratio": (1.0, 3.0), "vs": (1e-4, 1e-2)}  # §8.5 defaults where unset
    assert dict(back.box) == expected
    lo, hi = back.model.bounds(back.box)
    assert (lo[3], hi[3]) == (20.0, 400.0) and np.allclose((lo[5], hi[5]), (-4.0, -2.0))
    v = profile(400)
    assert np.array_equal(np.asarray(fit.predict(v)), np.asarray(back.predict(v)))


def test_missing_file_is_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_fit(tmp_path / "nope.npz")


def test_a_fit_is_frozen_and_replace_returns_a_changed_copy():
    """Issue 46: a fit is immutable: setting or deleting an attribute raises, and
    ``replace`` builds a new fit with the change, leaving the original as it was."""
    import dataclasses

    model = models.Coulomb()
    theta = np.asarray(model.from_physical(Fc=10.0, sigma2=5.0), np.float64)
    fit = Fit(model=model, theta=theta, velocity_scaler=None, friction_scaler=None, dt=0.01,
              n_train=10, n_samples=12, metrics={"train": {"mse_percent": 1.0}})
    for name in ("metrics", "theta", "timings", "settings", "_uncertainty", "new_name"):
        with pytest.raises(dataclasses.FrozenInstanceError, match="immutable"):
            setattr(fit, name, {})
    with pytest.raises(dataclasses.FrozenInstanceError):
        del fit.metrics
    other = fit.replace(timings={"total_s": 1.5}, n_train=11)
    assert type(other) is Fit and other is not fit
    assert other.timings == {"total_s": 1.5} and other.n_train == 11
    assert fit.timings == {} and fit.n_train == 10
    np.testing.assert_array_equal(other.theta, fit.theta)
    assert other.metrics == fit.metrics and other.box == fit.box
    with pytest.raises(TypeError, match="unknown field"):
        fit.replace(thetaa=theta)
    # a pending uncertainty is computed once, on first use, and shared by the copy
    calls = []
    lazy = fit.replace(uncertainty=lambda: calls.append(1))
    assert lazy.uncertainty is None and calls == [1]
    assert lazy.replace(n_train=9).uncertainty is None and calls == [1]
