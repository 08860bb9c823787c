"""Loaders: column mapping, unit scales, irregular stamps, and clear errors."""

from __future__ import annotations

import warnings

import jax
import numpy as np
import pytest

from jaxfric import rig


def _write_csv(path, header, rows, delimiter=","):
    with open(path, "w") as fh:
        if header is not None:
            fh.write(delimiter.join(header) + "\n")
        for row in rows:
            fh.write(delimiter.join(f"{v:.10g}" for v in row) + "\n")


@pytest.fixture
def irregular_csv(tmp_path):
    """Linear-in-time channels in lab units (ms, mm, bar, kN) with jittered stamps."""
    rng = np.random.default_rng(0)
    t_ms = np.cumsum(np.r_[0.0, 10.0 + rng.uniform(-3, 3, 299)])
    t_ms[150:] += 40.0  # a gap
    t = t_ms / 1e3
    rows = np.stack([t_ms, 2.0 * t * 1e3, 40 + 0 * t, 60 + 0 * t, 5 + 0.1 * t, t], axis=1)
    path = tmp_path / "rec.csv"
    _write_csv(path, ["time_ms", "pos_mm", "pA_bar", "pB_bar", "F_kN", "extra"], rows)
    return path, t


COLUMNS = {"t": "time_ms", "x": "pos_mm", "p1": "pA_bar", "p2": "pB_bar", "load": "F_kN"}
SCALE = {"t": 1e-3, "x": 1e-3, "p1": 1e5, "p2": 1e5, "load": 1e3}


def test_csv_with_names_scales_and_resampling(irregular_csv):
    path, t = irregular_csv
    with pytest.warns(rig.IrregularSamplingWarning, match="irregular"):
        meas = rig.load_measurements(path, COLUMNS, scale=SCALE)
    d = np.diff(meas.t)
    np.testing.assert_allclose(d, np.median(np.diff(t)), rtol=1e-6)  # CSV holds 10 digits
    assert meas.t[0] == pytest.approx(t[0]) and meas.t[-1] <= t[-1] + 1e-12
    # linear channels are reproduced exactly by linear interpolation, in SI units
    np.testing.assert_allclose(meas.x, 2.0 * meas.t, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(meas.p1, 4e6)
    np.testing.assert_allclose(meas.load, 5e3 + 100.0 * meas.t, rtol=1e-9)

    with pytest.raises(ValueError, match="irregular.*on_irregular='resample'"):
        rig.load_measurements(path, COLUMNS, scale=SCALE, on_irregular="raise")
    with pytest.raises(ValueError, match="on_irregular"):
        rig.load_measurements(path, COLUMNS, scale=SCALE, on_irregular="ignore")


def test_missing_columns_and_channels(irregular_csv):
    path, _ = irregular_csv
    with pytest.raises(ValueError, match="column 'pC_bar' \\(for channel 'p2'\\) is missing"):
        rig.load_measurements(path, {**COLUMNS, "p2": "pC_bar"})
    cols = {k: v for k, v in COLUMNS.items() if k != "p2"}
    with pytest.raises(ValueError, match="missing channel\\(s\\) \\['p2'\\]"):
        rig.load_measurements(path, cols)
    with pytest.raises(ValueError, match="column index 9 .*6 columns"):
        rig.load_measurements(path, {**COLUMNS, "p2": 9})
    with pytest.raises(ValueError, match="unknown channel"):
        rig.load_measurements(path, {**COLUMNS, "force": "F_kN"})
    with pytest.raises(ValueError, match="missing column"):
        rig.load_measurements({"t": np.arange(10.0)}, {"t": "t", "x": "pos"})
    with pytest.raises(ValueError, match="file not found"):
        rig.load_measurements(path.parent / "nope.csv", COLUMNS)


def test_bad_values_and_stamps_in_files(tmp_path):
    t = np.arange(100) * 0.01
    rows = np.stack([t, t, 0 * t + 1, 0 * t + 1, 0 * t], axis=1)
    bad = rows.copy()
    bad[40, 2] = np.nan
    _write_csv(tmp_path / "nan.csv", ["t", "x", "p1", "p2", "load"], bad)
    with pytest.raises(ValueError, match="channel 'p1' has 1 non-finite"):
        rig.load_measurements(tmp_path / "nan.csv", {c: c for c in rig.io.RAW_CHANNELS})
    dup = rows.copy()
    dup[41, 0] = dup[40, 0]
    _write_csv(tmp_path / "dup.csv", ["t", "x", "p1", "p2", "load"], dup)
    for mode in ("resample", "raise"):
        with pytest.raises(ValueError, match="duplicate time stamps"):
            rig.load_measurements(tmp_path / "dup.csv", {c: c for c in rig.io.RAW_CHANNELS}, on_irregular=mode)
    unsorted = rows[::-1]
    _write_csv(tmp_path / "rev.csv", ["t", "x", "p1", "p2", "load"], unsorted)
    with pytest.raises(ValueError, match="not sorted"):
        rig.load_measurements(tmp_path / "rev.csv", {c: c for c in rig.io.RAW_CHANNELS})


def test_whitespace_file_by_index_with_fill_and_skip(tmp_path):
    t = np.arange(200) * 10.0  # ms
    rows = np.stack([t, 0 * t, 0 * t, t / 1e3, 0 * t + 3.0, 0 * t + 50.0], axis=1)
    rows[:5, 4] = 99.0  # deviating starting values, dropped by skip_rows
    _write_csv(tmp_path / "raw.txt", None, rows, delimiter="\t")
    meas = rig.load_measurements(tmp_path / "raw.txt", {"t": 0, "x": 3, "p2": 4, "load": 5}, delimiter=None,
                                 scale={"t": 1e-3, "p2": 1e5, "load": -1.0}, fill={"p1": 0.0}, skip_rows=5)
    assert meas.n_samples == 195
    np.testing.assert_allclose(meas.p2, 3e5)
    np.testing.assert_allclose(meas.p1, 0.0)
    np.testing.assert_allclose(meas.load, -50.0)


def test_arrays_and_friction_pairs(tmp_path):
    t = np.arange(500) * 0.01
    v = 0.01 * np.sin(t)
    data = rig.load_friction_pairs({"t": t, "velocity": v, "friction": 300 * np.tanh(v / 1e-3)})
    assert isinstance(data, rig.FrictionData) and data.n_train == 400
    _write_csv(tmp_path / "pairs.csv", ["time", "v_mm_s", "F"], np.stack([t, v * 1e3, v], axis=1))
    data = rig.load_friction_pairs(tmp_path / "pairs.csv", {"t": "time", "velocity": "v_mm_s", "friction": "F"},
                                   scale={"velocity": 1e-3}, n_train=100)
    np.testing.assert_allclose(np.asarray(data.velocity), v, rtol=1e-6, atol=1e-12)
    assert data.n_train == 100 and data.valid().n_samples == 400
    jitter = t + np.r_[0.0, np.full(498, 0.003), 0.0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(rig.IrregularSamplingWarning):
            rig.load_friction_pairs({"t": jitter, "velocity": v, "friction": v})


def test_csv_round_trip_of_a_simulated_record(tmp_path):
    rec = rig.simulate(rig.Rig(), jax.random.key(0))
    meas = rec.measurements()
    rows = np.stack([meas.t * 1e3, meas.x * 1e3, meas.p1 / 1e5, meas.p2 / 1e5, meas.load], axis=1)
    _write_csv(tmp_path / "sim.csv", ["t_ms", "x_mm", "p1_bar", "p2_bar", "F_N"], rows)
    loaded = rig.load_measurements(tmp_path / "sim.csv",
                                   {"t": "t_ms", "x": "x_mm", "p1": "p1_bar", "p2": "p2_bar", "load": "F_N"},
                                   scale={"t": 1e-3, "x": 1e-3, "p1": 1e5, "p2": 1e5})
    direct = rig.estimate_friction(meas, rig.Cylinder())
    via_csv = rig.estimate_friction(loaded, rig.Cylinder())
    np.testing.assert_allclose(np.asarray(via_csv.friction), np.asarray(direct.friction), atol=0.05)


def test_friction_pairs_carry_chamber_pressures_when_mapped(tmp_path):
    """p1/p2 columns beside velocity and friction are read, scaled to Pa and resampled with
    the rest; without them the record has none, and other extra channels are still refused."""
    t = np.array([0.0, 0.01, 0.02, 0.035, 0.04, 0.05])
    v = np.linspace(-0.01, 0.01, t.size)
    f, p1, p2 = 50 * np.tanh(v / 1e-3), np.linspace(2.0, 3.0, t.size), np.linspace(1.0, 1.5, t.size)
    path = tmp_path / "pairs.csv"
    _write_csv(path, ["t", "v", "F", "pa", "pb"], np.column_stack([t, v, f, p1, p2]))
    cols = {"t": "t", "velocity": "v", "friction": "F"}
    with pytest.warns(rig.IrregularSamplingWarning):
        d = rig.load_friction_pairs(path, {**cols, "p1": "pa", "p2": "pb"}, scale={"p1": 1e5, "p2": 1e5})
    grid = np.arange(6) * 0.01
    np.testing.assert_allclose(d.p1, np.interp(grid, t, p1) * 1e5, rtol=1e-12)
    np.testing.assert_allclose(d.p2, np.interp(grid, t, p2) * 1e5, rtol=1e-12)
    np.testing.assert_allclose(d.velocity, np.interp(grid, t, v), rtol=1e-12, atol=1e-15)
    with pytest.warns(rig.IrregularSamplingWarning):
        plain = rig.load_friction_pairs(path, cols)
    assert plain.p1 is None and plain.p2 is None
    with pytest.raises(ValueError, match=r"unknown channel name\(s\) \['x'\]"):
        rig.load_friction_pairs(path, {**cols, "x": "pa"})
