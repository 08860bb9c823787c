"""``jaxfric.sweep`` and ``jaxfric sweep``: every run equals its single identify call,
an interrupted sweep resumes without recomputing finished runs, bad input fails first."""

from __future__ import annotations

import csv
import os
import warnings

import jax
import numpy as np
import pytest

import jaxfric
from jaxfric.records import FrictionData
from jaxfric.sweeps import read_table, sweep

# The solver, record length (300 samples, dt 0.01) and dtype (float64) of tests/test_records.py's
# Coulomb fits: the sweep's Coulomb runs reuse their compiled programs.
SOLVER = jaxfric.MAPSONMDS(mapso=jaxfric.MAPSO(lattice_size=3, num_generations=8),
                           nelder_mead=jaxfric.NelderMead(max_steps=150))
MODELS = ["coulomb", "stribeck"]
SEEDS = [0, 5]


def _record(phase: float, n: int = 300) -> FrictionData:
    t = np.arange(n) * 0.01
    v = 0.05 * np.sin(2 * np.pi * 0.5 * t + phase)
    f = 20 * np.tanh(v / 0.002) + 100 * v + 0.3 * np.sin(7 * t + phase)
    return FrictionData.from_arrays(v, f, 0.01)


RECORDS = {"a": _record(0.0), "b": _record(1.0)}


def _quiet_sweep(*args, **kwargs):
    with warnings.catch_warnings(), jax.enable_x64(True):
        warnings.simplefilter("ignore")  # the tiny budget's fits warn about their validation error
        return sweep(*args, progress=False, solver=SOLVER, **kwargs)


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    """The sweep run once, uninterrupted."""
    out = tmp_path_factory.mktemp("sweep") / "whole"
    return _quiet_sweep(MODELS, RECORDS, SEEDS, out)


def _without_time(rows):
    return [{k: v for k, v in r.items() if k != "run_s"} for r in rows]


def test_every_run_equals_its_single_identify_call(whole):
    assert [(r["model"], r["record"], r["seed"]) for r in whole.rows] == [
        (m, r, s) for m in MODELS for r in RECORDS for s in SEEDS]
    for model, record, seed in [("coulomb", "a", 0), ("stribeck", "b", 5)]:
        with warnings.catch_warnings(), jax.enable_x64(True):
            warnings.simplefilter("ignore")
            single = jaxfric.identify(model, RECORDS[record], key=seed, solver=SOLVER)
        saved = whole.fit(model, record, seed)
        np.testing.assert_array_equal(saved.theta, single.theta)
        row = next(r for r in whole.rows if (r["model"], r["record"], r["seed"]) == (model, record, seed))
        assert row["valid_mse_percent"] == single.metrics["valid"]["mse_percent"]
        assert row["cost"] == single.metrics["cost"]
    # different seeds are different runs (a sweep that ignored the key would repeat one)
    a0, a5 = whole.fit("stribeck", "a", 0), whole.fit("stribeck", "a", 5)
    assert not np.array_equal(a0.theta, a5.theta)


def test_the_table_holds_every_run_and_reads_back(whole):
    rows = read_table(whole.table)
    assert _without_time(rows) == _without_time(whole.rows)
    assert all(os.path.exists(whole.out_dir / r["fit_file"]) for r in rows)
    assert all(np.isfinite(r["cost"]) for r in rows)


def test_an_interrupted_sweep_resumes_without_recomputing(whole, tmp_path):
    out = tmp_path / "resumed"

    class Stop(Exception):
        pass

    seen = []

    def stop_after_three(run, fit):
        seen.append(run)
        if len(seen) == 3:
            raise Stop

    with pytest.raises(Stop):
        _quiet_sweep(MODELS, RECORDS, SEEDS, out, on_run=stop_after_three)
    first = {run.fit_file: os.stat(out / run.fit_file).st_mtime_ns for run in seen}
    assert len(read_table(out / "results.csv")) == 3  # the table was whole after every run
    assert not [p for p in out.rglob("*") if p.name.endswith(".jaxfric-tmp")]

    again = _quiet_sweep(MODELS, RECORDS, SEEDS, out)
    assert [r.fit_file for r in again.done] == [r.fit_file for r in seen]
    assert len(again.computed) == len(whole.runs) - 3
    assert {r.fit_file for r in again.computed}.isdisjoint(first)
    for path, mtime in first.items():  # finished runs were not written again
        assert os.stat(out / path).st_mtime_ns == mtime
    assert _without_time(again.rows) == _without_time(whole.rows)
    assert _without_time(read_table(out / "results.csv")) == _without_time(whole.rows)
    for run in whole.runs:
        np.testing.assert_array_equal(again.fit(run.model, run.record, run.seed).theta,
                                      whole.fit(run.model, run.record, run.seed).theta)

    finished = _quiet_sweep(MODELS, RECORDS, SEEDS, out)
    assert finished.computed == [] and len(finished.done) == len(whole.runs)


def test_process_shares_partition_the_runs(whole, tmp_path):
    out = tmp_path / "shared"
    parts = [_quiet_sweep(MODELS, RECORDS, SEEDS, out, process_index=i, process_count=3) for i in range(3)]
    computed = [run.index for p in parts for run in p.computed]
    assert sorted(computed) == list(range(len(whole.runs)))
    assert [run.index for run in parts[1].computed] == list(range(1, len(whole.runs), 3))
    # the last share sees every file, so its table is the whole sweep
    assert _without_time(parts[-1].rows) == _without_time(whole.rows)


@pytest.mark.parametrize("call, message", [
    (lambda out: sweep([], RECORDS, 1, out), "models is empty"),
    (lambda out: sweep(["coulomb", "Coulomb"], RECORDS, 1, out), "appear twice"),
    (lambda out: sweep(["no_such_model"], RECORDS, 1, out), "unknown friction model"),
    (lambda out: sweep(["coulomb"], {"a b": RECORDS["a"]}, 1, out), "label 'a b'"),
    (lambda out: sweep(["coulomb"], RECORDS, [1, 1], out), "seed twice"),
    (lambda out: sweep(["coulomb"], RECORDS, [-1], out), "int seeds >= 0"),
    (lambda out: sweep(["coulomb"], RECORDS, 0, out), "keys must be"),
    (lambda out: sweep(["coulomb"], RECORDS, 1, out, key=3), "the sweep's own"),
    (lambda out: sweep(["coulomb"], {"x": (np.ones(50), np.ones(50), 0.01)}, 1, out), "record 'x'"),
    (lambda out: sweep(["coulomb"], RECORDS, 1, out, process_index=2, process_count=2), "process_index"),
    (lambda out: sweep(["elman"], RECORDS, 1, out, neurons=0), "model 'elman'"),
])
def test_bad_input_fails_before_any_run(tmp_path, call, message):
    out = tmp_path / "bad"
    with pytest.raises(ValueError, match=message):
        call(out)
    assert not (out / "fits").exists()


def test_a_label_for_other_data_is_refused(whole, tmp_path):
    out = tmp_path / "mixed"
    _quiet_sweep(["coulomb"], {"a": RECORDS["a"]}, [0], out)
    with pytest.raises(ValueError, match="record 'a' stood for other data"):
        _quiet_sweep(["coulomb"], {"a": RECORDS["b"]}, [0, 1], out)
    with pytest.raises(ValueError, match="model 'coulomb' stood for other settings"), jax.enable_x64(True):
        sweep(["coulomb"], {"a": RECORDS["a"]}, [0], out, progress=False, solver=SOLVER, method="paper")


def test_the_command_writes_the_same_runs(in_process_cli, whole, tmp_path):
    paths = []
    for label, rec in RECORDS.items():
        p = tmp_path / f"{label}.csv"
        with open(p, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["t", "v", "F"])
            w.writerows(zip((repr(float(x)) for x in rec.t), (repr(float(x)) for x in rec.velocity),
                            (repr(float(x)) for x in rec.friction)))
        paths.append(p)
    out = tmp_path / "cli"
    args = ["sweep", out, "--model", "coulomb", "--data", paths[0], "--data", paths[1], "--keys", "0,5",
            "--velocity-col", "v", "--friction-col", "F", "--time-col", "t",
            "--generations", "4", "--nm-evals", "40", "--x64", "-q"]  # float64 as the sweeps above
    status, _, err = in_process_cli(*args)
    assert status == 0, err
    rows = read_table(out / "results.csv")
    assert [(r["record"], r["seed"]) for r in rows] == [("a", 0), ("a", 5), ("b", 0), ("b", 5)]
    fit = jaxfric.load_fit(out / rows[1]["fit_file"])
    assert fit.seed is not None and fit.to_dict()["key"]["seed"] == 5
    status, out_text, _ = in_process_cli(*args[:-1])  # again: nothing left to compute
    assert status == 0 and "0 runs computed, 4 found finished" in out_text
    status, _, err = in_process_cli("sweep", out, "--data", paths[0], "--keys", "0-", "--dt", "0.01")
    assert status != 0 and "--keys" in err


@pytest.fixture
def in_process_cli(capsys):
    from jaxfric.cli import main

    def run(*args):
        capsys.readouterr()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            status = main([*map(str, args), "--no-cache"])
        out, err = capsys.readouterr()
        return status, out, err

    return run


@pytest.mark.slow
def test_motion_records_sweep_through_identify_motion(tmp_path):
    """MotionData records go to identify_motion; a run equals its single call."""
    from jaxfric.motion import MotionData, friction_step, identify_motion
    from jaxfric.motion._forward import simulate_motion

    dt, n = 1e-3, 600
    t = np.arange(n) * dt
    force = 30.0 * np.sin(2 * np.pi * 2.0 * t)
    coulomb = jaxfric.models.Coulomb()
    theta = coulomb.from_physical(Fc=8.0, sigma2=20.0)
    x = np.asarray(simulate_motion(friction_step(coulomb), theta, 2.0, force, dt, 0.0, 0.0)["x"])
    data = MotionData.from_arrays(force, x, dt)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = sweep(["coulomb"], {"sim": data}, [0, 1], tmp_path / "motion", progress=False,
                    mass=2.0, solver=SOLVER)
        single = identify_motion("coulomb", data, key=1, mass=2.0, solver=SOLVER)
    assert res.motion and [r["seed"] for r in res.rows] == [0, 1]
    np.testing.assert_array_equal(res.fit("coulomb", "sim", 1).theta, single.theta)
    assert "valid_rmse_mm" in res.rows[1] and np.isfinite(res.rows[1]["valid_rmse_mm"])
    with pytest.raises(ValueError, match="mix MotionData"):
        sweep(["coulomb"], {"sim": data, "a": RECORDS["a"]}, 1, tmp_path / "mixed", progress=False)
