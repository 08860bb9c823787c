"""EMPS loader and the benchmark's friction recipe (jaxfric.rig.emps).

Synthetic checks use a recording built from a known rigid-body model; the real
file (looked up in JAXFRIC_EMPS_DATA, then next to the repository in shared/data/)
is compared with the published IDIM-LS values of its SOURCE.md, and skipped when absent.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from jaxfric import rig
from jaxfric.rig import emps

GTAU = 35.15065188248547
TRUE = {"M": 95.0, "Fv": 200.0, "Fc": 20.0, "offset": -3.0}
TRUE_ASYM = {"M": 95.0, "Fv_pos": 170.0, "Fv_neg": 240.0, "Fc_pos": 20.0, "Fc_neg": 21.0}


def _trajectory(n=6000, dt=1e-3):
    """A smooth position (content far below 100 Hz) with reversals, and its exact v, a."""
    t = np.arange(n) * dt
    w1, w2 = 2 * np.pi * 0.7, 2 * np.pi * 1.9
    q = 0.05 * np.sin(w1 * t) + 0.01 * np.sin(w2 * t + 0.3)
    v = 0.05 * w1 * np.cos(w1 * t) + 0.01 * w2 * np.cos(w2 * t + 0.3)
    a = -0.05 * w1**2 * np.sin(w1 * t) - 0.01 * w2**2 * np.sin(w2 * t + 0.3)
    return t, q, v, a


def _write_mat(path, t, q, force):
    scipy.io.savemat(path, {"t": t[:, None], "qm": q[:, None], "qg": q[:, None],
                            "vir": (force / GTAU)[:, None], "gtau": np.array([[GTAU]]),
                            "kp": np.array([[160.18]]), "kv": np.array([[243.45]])})


@pytest.fixture
def synthetic(tmp_path):
    t, q, v, a = _trajectory()
    friction = TRUE["Fv"] * v + TRUE["Fc"] * np.sign(v) + TRUE["offset"]
    path = tmp_path / "sym.mat"
    _write_mat(path, t, q, TRUE["M"] * a + friction)
    return path, v, a, friction


def test_load_emps_round_trip(synthetic):
    path, *_ = synthetic
    rec = emps.load_emps(path)
    raw = scipy.io.loadmat(path)
    np.testing.assert_array_equal(rec.qm, raw["qm"].ravel())
    np.testing.assert_allclose(rec.force, raw["vir"].ravel() * GTAU)
    assert rec.gtau == GTAU and rec.kp == 160.18 and rec.kv == 243.45
    assert rec.dt == pytest.approx(1e-3)


def test_states_match_the_exact_derivatives(synthetic):
    path, v, a, _ = synthetic
    s = emps.emps_states(emps.load_emps(path))
    keep = slice(emps.EMPS_DROP, -emps.EMPS_DROP)
    assert s["v"].shape == v[keep].shape
    # A 100 Hz forward-backward filter leaves a 2 Hz signal untouched; central differences
    # are O(dt^2) accurate.
    np.testing.assert_allclose(s["v"], v[keep], atol=1e-4 * np.abs(v).max())
    np.testing.assert_allclose(s["a"], a[keep], atol=2e-3 * np.abs(a).max())


def test_idim_ls_recovers_known_symmetric_parameters(synthetic):
    path, v, a, friction = synthetic
    s = emps.emps_states(emps.load_emps(path))
    est = emps.idim_ls(s["v"], s["a"], s["force"])
    for k, value in TRUE.items():
        assert getattr(est, k) == pytest.approx(value, rel=5e-3), k
    data = emps.emps_friction_data(emps.load_emps(path))
    keep = slice(emps.EMPS_DROP, -emps.EMPS_DROP)
    # Away from the reversals (where sign(v) jumps and the filter smooths), the record's
    # friction is the true friction law.
    moving = np.abs(v[keep]) > 0.02
    np.testing.assert_allclose(np.asarray(data.friction)[moving], friction[keep][moving], atol=0.2)
    assert data.n_train == round(0.8 * data.n_samples)
    # a given mass is used as is
    heavy = emps.emps_friction_data(emps.load_emps(path), mass=200.0)
    np.testing.assert_allclose(np.asarray(heavy.friction), s["force"] - 200.0 * s["a"])


def test_idim_ls_recovers_known_asymmetric_parameters(tmp_path):
    t, q, v, a = _trajectory()
    p = TRUE_ASYM
    friction = np.where(v > 0, p["Fv_pos"] * v + p["Fc_pos"], p["Fv_neg"] * v - p["Fc_neg"])
    path = tmp_path / "asym.mat"
    _write_mat(path, t, q, p["M"] * a + friction)
    s = emps.emps_states(emps.load_emps(path))
    est = emps.idim_ls(s["v"], s["a"], s["force"], asymmetric=True)
    for k, value in p.items():
        assert getattr(est, k) == pytest.approx(value, rel=1e-2), k
    fixed = emps.idim_ls(s["v"], s["a"], s["force"], asymmetric=True, mass=p["M"])
    assert fixed.M == p["M"] and fixed.Fc_neg == pytest.approx(p["Fc_neg"], rel=1e-2)


def test_bad_files_fail_clearly(tmp_path):
    with pytest.raises(FileNotFoundError, match="no EMPS file"):
        emps.load_emps(tmp_path / "absent.mat")
    scipy.io.savemat(tmp_path / "partial.mat", {"t": np.arange(10.0)})
    with pytest.raises(ValueError, match="lacks the EMPS variable"):
        emps.load_emps(tmp_path / "partial.mat")
    (tmp_path / "text.mat").write_text("not a mat file")
    with pytest.raises(ValueError, match="not a readable"):
        emps.load_emps(tmp_path / "text.mat")


# ------------------------------------------------------------------ the real file
def _emps_file() -> Path | None:
    candidates = []
    if os.environ.get("JAXFRIC_EMPS_DATA"):
        candidates.append(Path(os.environ["JAXFRIC_EMPS_DATA"]))
    candidates.append(Path(__file__).resolve().parents[2] / "shared" / "data" / "emps")
    for c in candidates:
        f = c if c.is_file() else c / "DATA_EMPS.mat"
        if f.is_file():
            return f
    return None


EMPS_FILE = _emps_file()
#: SOURCE.md of the data: IDIM-LS on the estimation file (Janot et al. 2019).
PUBLISHED = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "offset": -3.1648}
PUBLISHED_ASYM = {"Fv_pos": 166.71, "Fc_pos": 20.14, "Fv_neg": 240.42, "Fc_neg": 20.63}


@pytest.mark.skipif(EMPS_FILE is None, reason="DATA_EMPS.mat not found (set JAXFRIC_EMPS_DATA)")
def test_real_file_matches_published_idim_ls():
    rec = emps.load_emps(EMPS_FILE)
    assert rec.n_samples == 24841 and rec.dt == pytest.approx(1e-3, rel=1e-4)
    s = emps.emps_states(rec)
    sym = emps.idim_ls(s["v"], s["a"], s["force"])
    for k, value in PUBLISHED.items():
        assert getattr(sym, k) == pytest.approx(value, rel=0.02), k
    asym = emps.idim_ls(s["v"], s["a"], s["force"], asymmetric=True)
    for k, value in PUBLISHED_ASYM.items():
        assert getattr(asym, k) == pytest.approx(value, rel=0.02), k
    data = emps.emps_friction_data(rec)
    assert isinstance(data, rig.FrictionData)
    assert data.n_samples == 24841 - 2 * emps.EMPS_DROP
