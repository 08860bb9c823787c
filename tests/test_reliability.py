"""Reliability: no NaN escapes, and an interrupted or failed run loses nothing.

* Objectives built from the real models that overflow or turn NaN (LuGre with stiffness
  and damping ranges beyond float32, an Elman network whose output overflows, a diverging
  recursion) are minimised with NaN/inf treated as worst, and the optimiser's report is
  checked with the same properties as the random-function tests (test_optim_properties).
* ``jaxfric.identify`` on random small records never reports NaN/inf metrics or parameters
  (hypothesis), and ``friction_metrics`` never returns NaN/inf for finite input.
* Model files, report files and the command's CSV are written atomically: when the final
  ``os.replace`` (or the write before it) fails or is interrupted, the previous file is
  intact and no temporary is left.
* ``jaxfric identify`` interrupted with SIGINT once its progress bar is moving exits with
  status 130, no traceback, and says what was kept.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import matplotlib.image as mpimg
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import jaxfric as jf
from jaxfric import report
from jaxfric.fit import Fit
from jaxfric.identification._data import as_record
from jaxfric.identification._objective import OutputErrorCost, cost_data, fit_scalers
from jaxfric.rig import FrictionData
from test_optim_properties import Recorder, check_solution

ROOT = Path(__file__).resolve().parents[1]
SOLVER = jf.mapso_nmds(lattice_size=3, num_generations=4, sl_generations=2, nm_max_steps=60)


# ============================================================ numerical safety
def _lugre_record(n=64, dt=1 / 128):
    t = np.arange(n) * dt
    v = 0.01 * np.sin(2 * np.pi * 1.5 * t) + 0.003 * np.sin(2 * np.pi * 4.1 * t)
    truth = jf.LuGre().from_physical(sigma0=1e7, sigma1=3e3, sigma2=4e3, Fc=200.0, Fs=300.0, vs=2e-3)
    f = np.asarray(jf.LuGre().simulate(truth, v, dt), np.float64)
    return v, f, dt


def _minimise_recorded(model, data, bounds, seed=0, solver=SOLVER):
    """Minimise ``model``'s output-error cost with every evaluation recorded."""
    record = as_record(data, train=0.75)
    args = cost_data(model, record, fit_scalers(model, record), jnp.float32)
    cost = OutputErrorCost(model)
    rec = Recorder()
    sol = jf.minimise(rec.wrap(cost), solver, bounds, args=args, key=jax.random.key(seed), dtype=jnp.float32)
    points, values = rec.arrays()
    return sol, points, values, cost, args


def test_lugre_with_overflowing_parameters_is_never_reported_as_best():
    # sigma0 and sigma1 up to 1e45 and 1e40 N/m: 10**theta overflows float32 for part of the box.
    model = jf.LuGre()
    lo, hi = model.bounds({"sigma0": (1e4, 1e45), "sigma1": (10.0, 1e40)})
    bounds = (lo.astype(np.float32), hi.astype(np.float32))
    sol, points, values, cost, args = _minimise_recorded(model, _lugre_record(), bounds)
    assert np.isnan(values).any() or np.isinf(values).any(), "the box should hold non-finite costs"
    assert np.isfinite(values).any()
    check_solution("lugre", SOLVER, *bounds, sol, points, values)
    assert np.isfinite(float(sol.f))
    np.testing.assert_allclose(float(cost(sol.value, args)), float(sol.f), rtol=1e-5)


def test_elman_with_overflowing_output_is_never_reported_as_best():
    # Saturated hidden units (|w|, |b|, |r| up to 1e30: tanh = +-1) and output weights up to
    # 1e19, so the squared error overflows float32 for many candidates.
    model = jf.Elman(neurons=3, weight_bound=1e30, context_weight_bound=1e30, output_weight_bound=1e19)
    lo, hi = model.bounds()
    bounds = (lo.astype(np.float32), hi.astype(np.float32))
    solver = jf.PSO(num_particles=16, num_generations=8)  # (a small program: compiles fast)
    sol, points, values, cost, args = _minimise_recorded(model, _lugre_record(), bounds, seed=1, solver=solver)
    assert np.isinf(values).any() and np.isfinite(values).any()
    check_solution("elman", solver, *bounds, sol, points, values)
    np.testing.assert_allclose(float(cost(sol.value, args)), float(sol.f), rtol=1e-5)


def diverging(theta, args):
    """``x <- a x + b sin(x)`` from x = 1 against a decaying target: for |a| > 1 + |b| the
    state overflows to inf and sin(inf) = NaN poisons the rest of the run."""
    a, b = theta[0], theta[1]

    def step(x, target):
        x = a * x + b * jnp.sin(x)
        return x, (x - target) ** 2

    _, sq = jax.lax.scan(step, jnp.asarray(1.0, theta.dtype), args)
    return jnp.mean(sq)


def test_diverging_candidates_are_never_reported_as_best():
    target = jnp.asarray(0.5 ** np.arange(1, 201), jnp.float32)
    bounds = (np.array([-3.0, -1.0], np.float32), np.array([3.0, 1.0], np.float32))
    rec = Recorder()
    solver = jf.PSO(num_particles=16, num_generations=8)
    sol = jf.minimise(rec.wrap(diverging), solver, bounds, args=target, key=jax.random.key(2))
    points, values = rec.arrays()
    assert np.isnan(values).any() and np.isfinite(values).any()
    check_solution("diverging", solver, *bounds, sol, points, values)
    assert abs(float(sol.value[0])) < 1.5


# ------------------------------------------------------------- identify property
N_RECORD = 48  # one record length (and split): one compilation per model


@st.composite
def records(draw):
    """A random short record: two sines of random scale, friction a random Coulomb-viscous
    map with noise, or pure noise; random sample time and force level."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    dt = 10.0 ** draw(st.floats(-4, -1))
    v_scale = 10.0 ** draw(st.floats(-5, 0))
    f_scale = 10.0 ** draw(st.floats(-2, 5))
    t = np.arange(N_RECORD) * dt
    period = N_RECORD * dt
    v = v_scale * (np.sin(2 * np.pi * t / period * draw(st.floats(0.5, 4)))
                   + draw(st.floats(0, 1)) * np.sin(2 * np.pi * t / period * draw(st.floats(4, 12))))
    v = v + v_scale * draw(st.floats(0, 0.3)) * rng.standard_normal(N_RECORD)
    if draw(st.booleans()):
        f = f_scale * (np.tanh(v / (v_scale * draw(st.floats(0.01, 1)))) + draw(st.floats(0, 2)) * v / v_scale)
        f = f + f_scale * draw(st.floats(1e-3, 0.5)) * rng.standard_normal(N_RECORD)
    else:
        f = f_scale * rng.standard_normal(N_RECORD)
    return v, f, dt


IDENTIFY_SOLVER = jf.mapso_nmds(lattice_size=2, num_generations=2, sl_generations=1, nm_max_evals=40)


def _all_finite(tree) -> bool:
    leaves = jax.tree_util.tree_leaves(tree)
    return all(np.all(np.isfinite(np.asarray(x, dtype=float))) for x in leaves if x is not None)


@pytest.mark.parametrize("model", ["lugre", "elman"])
@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=records())
def test_identify_never_reports_nan_or_inf(model, data):
    opts = {"neurons": 2} if model == "elman" else None
    fit = jf.identify(model, data, solver=IDENTIFY_SOLVER, key=0, train=0.75, model_options=opts)
    assert fit.metrics.get("prediction_finite", True)
    for window in ("train", "valid", "all"):
        m = fit.metrics[window]
        assert m is not None and _all_finite(m), (window, m)
    assert np.isfinite(fit.metrics["cost"])
    assert np.all(np.isfinite(fit.theta))
    assert _all_finite(fit.params)
    assert all(np.isfinite(s["J"]) for s in fit.stages)
    assert np.all(np.isfinite(np.asarray(fit.predict(data[0]))))


@settings(max_examples=200, deadline=None)
@given(
    y=st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=2, max_size=20),
    shift=st.floats(-1e300, 1e300),
    gain=st.floats(-1e300, 1e300),
)
def test_friction_metrics_are_finite_or_a_clear_error(y, shift, gain):
    y = np.asarray(y)
    with np.errstate(over="ignore", invalid="ignore"):
        y_hat = gain * y + shift
    if not np.all(np.isfinite(y_hat)):
        return
    try:
        m = jf.friction_metrics(y, y_hat)
    except ValueError as e:
        assert "zero variance" in str(e) or "exceed the float64 range" in str(e), str(e)
        return
    assert all(np.isfinite(v) for v in m.values()), m


# ================================================================ nothing lost
def _small_fit(theta=(40.0, 3.0)):
    return Fit(model=jf.Coulomb(), theta=np.array(theta), velocity_scaler=None, friction_scaler=None,
               dt=0.01, n_train=40, n_samples=50, metrics={"train": None, "valid": None, "all": None})


def _leftovers(folder):
    return sorted(p.name for p in Path(folder).rglob("*") if p.name.startswith("."))


@pytest.mark.parametrize("failure", ["replace", "interrupt-while-writing"])
def test_fit_save_keeps_the_old_file_when_the_write_fails(tmp_path, monkeypatch, failure):
    path = tmp_path / "fit.npz"
    _small_fit().save(path)
    before = path.read_bytes()
    if failure == "replace":
        def fail(*a, **k):
            raise OSError(28, "No space left on device")

        monkeypatch.setattr(os, "replace", fail)
        expected = OSError
    else:
        real_savez = np.savez

        def half_then_interrupt(fh, **arrays):
            real_savez(fh, **dict(list(arrays.items())[:2]))  # part of the file reaches disk
            raise KeyboardInterrupt

        monkeypatch.setattr(np, "savez", half_then_interrupt)
        expected = KeyboardInterrupt
    with pytest.raises(expected):
        _small_fit((99.0, 4.0)).save(path)
    monkeypatch.undo()
    assert path.read_bytes() == before
    assert jf.load_fit(path).theta.tolist() == [40.0, 3.0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fit.npz"], "a temporary was left behind"


@pytest.mark.parametrize("writer", ["text", "bytes", "figure", "fit"])
def test_report_writers_keep_the_old_file_when_replace_fails(tmp_path, monkeypatch, writer):
    import matplotlib.pyplot as plt

    path = tmp_path / "out.file"
    path.write_bytes(b"the previous, complete file")

    def write():
        if writer == "text":
            report.atomic_write_text(path, "new text")
        elif writer == "bytes":
            report.atomic_write_bytes(path, b"new bytes")
        elif writer == "figure":
            fig = plt.figure()
            try:
                report.save_figure(fig, path)
            finally:
                plt.close(fig)
        else:
            report.save_fit(_small_fit(), path)

    def fail(*a, **k):
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(OSError):
        write()
    monkeypatch.undo()
    assert path.read_bytes() == b"the previous, complete file"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.file"], "a temporary was left behind"
    write()  # and the same write succeeds once the disk is back
    assert path.read_bytes() != b"the previous, complete file"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.file"]


def test_write_report_failing_half_way_leaves_only_complete_files(tmp_path, monkeypatch):
    t = np.arange(200) / 100.0
    v = 0.01 * np.sin(2 * np.pi * 0.5 * t)
    data = FrictionData.from_arrays(v, 50 * np.tanh(v / 1e-3) + 3e3 * v, 0.01, n_train=160)
    fits = {"coulomb": _small_fit()}
    report.write_report(tmp_path, data, fits, title="first", save_models=True)
    first = {p.relative_to(tmp_path): p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    assert "first" in (tmp_path / "report.md").read_text()

    real_replace = os.replace
    calls = []

    def replace_then_fail(src, dst):
        calls.append(dst)
        if len(calls) == 3:
            raise OSError(28, "No space left on device")
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", replace_then_fail)
    with pytest.raises(OSError):
        report.write_report(tmp_path, data, fits, title="second", save_models=True)
    monkeypatch.undo()

    assert not _leftovers(tmp_path), _leftovers(tmp_path)
    now = {p.relative_to(tmp_path): p for p in tmp_path.rglob("*") if p.is_file()}
    assert set(now) == set(first)
    # results.json and report.md come last: still the first run's, and complete
    assert now[Path("results.json")].read_bytes() == first[Path("results.json")]
    assert json.loads(now[Path("results.json")].read_text())["title"] == "first"
    assert now[Path("report.md")].read_bytes() == first[Path("report.md")]
    for rel, p in now.items():  # every file under its final name is whole (old or new)
        if p.suffix == ".png":
            assert mpimg.imread(p).shape[0] > 100
        elif p.suffix == ".npz":
            jf.load_fit(p)


def test_cli_predict_failing_to_write_keeps_the_old_csv(tmp_path, monkeypatch, capsys):
    from jaxfric.cli import main

    model = tmp_path / "fit.npz"
    _small_fit().save(model)
    csv = tmp_path / "v.csv"
    csv.write_text("t,v\n" + "\n".join(f"{k / 100},{0.01 * np.sin(k / 5)}" for k in range(50)) + "\n")
    out = tmp_path / "pred.csv"
    out.write_text("an earlier prediction\n")

    def fail(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", fail)
    status = main(["predict", str(model), str(csv), "--velocity-col", "v", "--time-col", "t",
                   "--out", str(out), "--no-cache"])
    monkeypatch.undo()
    err = capsys.readouterr().err.strip().splitlines()
    assert status != 0
    # notes (e.g. about the fit's velocity filter) may precede it; one error, this one
    errors = [line for line in err if line.startswith("jaxfric: error: ")]
    assert len(errors) == 1 and "No space left" in errors[0], err
    assert out.read_text() == "an earlier prediction\n"
    assert not _leftovers(tmp_path)


# ------------------------------------------------------------------------ SIGINT
def test_interrupted_identify_exits_130_and_says_what_was_kept(tmp_path, interruptible, subprocess_slot):
    t = np.arange(200) / 100.0
    v = 0.01 * np.sin(2 * np.pi * 0.5 * t)
    csv = tmp_path / "pairs.csv"
    csv.write_text("t,v,F\n" + "\n".join(f"{a},{b},{50 * np.tanh(b / 1e-3) + 3e3 * b}" for a, b in zip(t, v)))
    out = tmp_path / "report"
    env = dict(os.environ, PYTHONPATH=str(ROOT), JAXFRIC_DEBUG="")
    # 200 000 generations: minutes of work, still going when Ctrl-C comes a second after
    # the first progress report (every 2 000 generations).
    proc = subprocess.Popen(
        [sys.executable, "-m", "jaxfric", "identify", str(csv), "--velocity-col", "v", "--friction-col", "F",
         "--time-col", "t", "--model", "coulomb", "--generations", "200000", "--no-cache", "--out", str(out)],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, **interruptible)
    chunks: list[bytes] = []

    def read_stderr():
        while True:
            b = os.read(proc.stderr.fileno(), 4096)
            if not b:
                return
            chunks.append(b)

    reader = threading.Thread(target=read_stderr, daemon=True)
    reader.start()
    try:
        deadline = time.monotonic() + 300
        # The bar shows "best=" once the compiled run has reported its first generations.
        while b"best=" not in b"".join(chunks) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.2)
        started = b"best=" in b"".join(chunks)
        proc.send_signal(signal.SIGINT)
        status = proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    reader.join(timeout=10)
    stderr = b"".join(chunks).decode(errors="replace")
    assert started, f"the run never reported progress:\n{stderr}"
    assert status == 130, stderr
    assert "Traceback" not in stderr
    assert "jaxfric: interrupted; nothing was written" in stderr, stderr
    assert not [p for p in out.rglob("*") if p.is_file()] if out.exists() else True
    assert proc.stdout.read() == b""
