"""Motion identification that does not depend on luck: several starts polished on the free
run, the least-squares baseline beside every fit, one sample-time tolerance, and the
command line's checks (docs/motion.md, docs/algorithms.md §13.2)."""

import dataclasses
import json
import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfric import models
from jaxfric._warnings import BaselineWarning
from jaxfric.fit import ExtrapolationWarning
from jaxfric.motion import (NARROW_GATE, MotionData, MotionSearch, baseline_motion_fit, compare_motion, friction_step,
                            identify_motion, load_motion_fit, simulate_motion)
from jaxfric.motion._baseline import BASELINE_LABEL, least_squares, least_squares_start
from jaxfric.motion._layout import Layout
from jaxfric.motion._pipeline import distinct_starts
from jaxfric.records import SAMPLE_TIME_RTOL, same_sample_time

TRUTH = dict(Fc=12.0, sigma2=60.0)
MASS, OFFSET = 2.5, 3.0
SMALL = MotionSearch(particles=10, generations=6, global_window=150, horizons=(300, None), steps=(10, 20),
                     starts=2, least_squares_start=True)


def _record(n=1500, dt=1e-3, seed=0, v_eps=1e-3, gain=1.0):
    """Noise-free motion of a Coulomb + viscous axis (2.5 kg, offset 3 N) under two tones
    (their amplitudes times ``gain``)."""
    model = models.Coulomb(v_eps=v_eps)
    t = np.arange(n) * dt
    u = gain * (30 * np.sin(2 * np.pi * 1.3 * t) + 12 * np.sin(2 * np.pi * 3.1 * t + 1.0 + seed))
    with jax.enable_x64(True):
        out = simulate_motion(friction_step(model), jnp.asarray(model.from_physical(**TRUTH), jnp.float64),
                              MASS, u - OFFSET, dt, 0.0, 0.0)
    return MotionData.from_arrays(u, np.asarray(out["x"]), dt)


def test_distinct_starts_keeps_the_best_distinct_finite_points_in_order():
    pts = np.array([[0.0, 0.0], [0.5, 0.5], [0.50001, 0.5], [0.9, 0.1], [0.2, 0.2]])
    f = np.array([3.0, 1.0, 0.5, np.nan, 2.0])
    got = distinct_starts(pts, f, 3, [0.0, 0.0], [1.0, 1.0])
    # 0.50001 (f 0.5) first; 0.5 lies within 1e-3 of it; NaN never; then 0.2 and 0.0
    np.testing.assert_array_equal(np.array(got), pts[[2, 4, 0]])
    assert distinct_starts(pts, np.full(5, np.inf), 2, [0, 0], [1, 1]) == []


def test_least_squares_solves_the_inverse_dynamics_of_the_simulated_states():
    """IDIM-LS on the record's filtered velocity equals least squares on the simulator's
    exact states (an independent reference: numpy.linalg.lstsq on the true v and a); the mass
    and the offset of the axis come out, while Fc and Fv carry least squares' known bias
    from the samples where the axis sticks (sign(v) cannot express static friction)."""
    rec = _record(4000)
    model = models.Coulomb(v_eps=1e-3)
    with jax.enable_x64(True):
        v = np.asarray(simulate_motion(friction_step(model), jnp.asarray(model.from_physical(**TRUTH)), MASS,
                                       rec.force - OFFSET, rec.dt, 0.0, 0.0)["v"])
    a = np.gradient(v, rec.dt, edge_order=2)
    keep = slice(20, -20)
    A = np.stack([a, v, np.sign(v), np.ones_like(v)], axis=1)[keep]
    ref, *_ = np.linalg.lstsq(A, rec.force[keep], rcond=None)
    est = least_squares([rec])
    np.testing.assert_allclose([est.M, est.Fv, est.Fc, est.offset], ref, rtol=0.03)
    assert est.M == pytest.approx(MASS, rel=0.05) and est.offset == pytest.approx(OFFSET, abs=0.2)
    fixed = least_squares([rec], mass=MASS)
    assert fixed.M == MASS and fixed.offset == pytest.approx(OFFSET, abs=0.2)


def test_least_squares_start_maps_the_solution_into_a_richer_model():
    est = least_squares([_record(4000)])
    model = models.LuGre()
    layout = Layout(model.num_params, True, True, False)
    v = _record(4000).velocity
    lower, upper = (list(b) for b in model.bounds(model.search_box(None, v, _record(4000).force)))
    lower += [np.log10(0.5), -10.0]
    upper += [np.log10(10.0), 10.0]
    y = least_squares_start(model, est, v, model.search_box(None, v, _record(4000).force), layout,
                            np.array(lower), np.array(upper))
    phys = model.to_physical(jnp.asarray(y[:model.num_params]))
    assert float(phys["Fc"]) == pytest.approx(est.Fc, rel=0.05)
    assert 10 ** y[-2] == pytest.approx(est.M) and y[-1] == pytest.approx(est.offset)
    assert least_squares_start(models.Elman(neurons=2), est, v, None, Layout(12, False, False, False),
                               np.zeros(12), np.ones(12)) is None


@pytest.fixture(scope="module")
def small_fit():
    """One fit with the small search (2 personal bests + the least-squares start), and the
    BaselineWarnings it raised."""
    with jax.enable_x64(True), warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", BaselineWarning)
        fit = identify_motion(models.Coulomb(v_eps=1e-3), _record(), key=0, mass=(0.5, 10.0), fit_offset=True,
                              search=SMALL, dtype=jnp.float64)
    return fit, [w for w in caught if issubclass(w.category, BaselineWarning)]


def test_every_start_is_polished_and_the_lowest_free_run_wins(small_fit):
    fit, _ = small_fit
    starts = sorted({s["start"] for s in fit.stages if s["start"] is not None})
    assert starts == [0, 1, 2]          # 2 personal bests + the least-squares start
    final = [s["J"] for s in fit.stages if s["stage"] == "free_run"]
    assert len(final) == 3
    assert fit.metrics["cost"] == pytest.approx(min(final), rel=1e-9)


def test_every_fit_carries_the_least_squares_baseline_and_beats_it_here(small_fit):
    fit, caught = small_fit
    assert caught == []
    base = fit.metrics["baseline"]
    assert set(base) == {"train", "valid"}
    assert fit.metrics["train"]["rmse_mm"] <= base["train"]["rmse_mm"]
    assert fit.mechanics.baseline["M"] == pytest.approx(MASS, rel=0.05)


def test_a_fit_worse_than_the_baseline_on_its_training_data_warns_with_both_numbers():
    """A search with no gradient stage and a box that excludes the truth (Fc in [30, 40] N
    where it is 12 N) ends worse than least squares: it must say so."""
    # the swarm and window of SMALL (the module fixture's search): its compiled global stage is reused
    crippled = MotionSearch(particles=10, generations=1, global_window=150, horizons=(None,), steps=(0,))
    with jax.enable_x64(True), pytest.warns(BaselineWarning, match=r"free-run RMSE .* mm against .* mm"):
        fit = identify_motion(models.Coulomb(v_eps=1e-3), _record(), key=0, mass=(0.5, 10.0), fit_offset=True,
                              box={"Fc": (30.0, 40.0), "sigma2": (300.0, 500.0)}, data_bounds=False,
                              search=crippled, dtype=jnp.float64)
    assert fit.metrics["train"]["rmse_mm"] > fit.metrics["baseline"]["train"]["rmse_mm"]


def test_the_ranking_shows_the_baseline_as_a_row(small_fit):
    from jaxfric.motion._compare import rank_fits

    fit, _ = small_fit
    cmp = rank_fits({"coulomb": fit})
    rows = cmp.rows()
    assert [r["model"] for r in rows] == ["coulomb", BASELINE_LABEL] and rows[-1]["rank"] is None
    assert rows[-1]["valid_rmse_mm"] == fit.metrics["baseline"]["valid"]["rmse_mm"]
    assert rows[0]["beats_baseline"] is (fit.metrics["valid"]["rmse_mm"] < rows[-1]["valid_rmse_mm"])
    assert BASELINE_LABEL in cmp.table()


def test_one_sample_time_tolerance(small_fit):
    """Two 1 kHz recordings whose float32 stamps round differently are one rate. (The
    module's fit of the 1 kHz record serves: any fit at the record's rate shows it.)"""
    assert same_sample_time(0.0010000080, 0.0009999840)
    assert not same_sample_time(1e-3 * (1 + 3 * SAMPLE_TIME_RTOL), 1e-3)
    fit, _ = small_fit
    rec = _record()
    assert fit.dt == rec.dt
    with jax.enable_x64(True):
        other = MotionData.from_arrays(rec.force, rec.position, 0.0010000080 / 0.0009999840 * rec.dt)
        assert np.isfinite(fit.score(other, init_window=20)["rmse_mm"])
        far = MotionData.from_arrays(rec.force, rec.position, rec.dt * 1.01)
        with pytest.raises(ValueError, match="differs from the fit's"):
            fit.score(far, init_window=20)


def test_a_record_faster_than_the_training_motion_is_warned(small_fit, tmp_path):
    """A motion fit keeps its training velocity range (saved and loaded with it), and
    simulating a record that moves outside it says so: the one failure no judge computed on
    the training data can see. Inside the range it stays silent."""
    fit, _ = small_fit
    rec = _record()
    v_train = rec.velocity[:fit.n_train]
    assert fit.velocity_range == (pytest.approx(v_train.min()), pytest.approx(v_train.max()))
    fast = _record(gain=3.0)
    assert np.mean(np.abs(fast.velocity) > 1.2 * np.abs(v_train).max()) > 0.1  # the record is faster
    with jax.enable_x64(True):
        with warnings.catch_warnings():
            warnings.simplefilter("error", ExtrapolationWarning)
            inside = fit.score(rec.window(0, fit.n_train), init_window=20)
        with pytest.warns(ExtrapolationWarning, match=r"% of the record's velocity samples lie outside the "
                                                      r"training range .* velocities it was never trained on"):
            outside = fit.score(fast, init_window=20)
        with pytest.warns(ExtrapolationWarning, match="outside the training range"):
            fit.evaluate(fast, fit.n_train)  # a held-back tail is checked as a record is
    assert np.isfinite(inside["rmse_mm"]) and np.isfinite(outside["rmse_mm"])  # a warning, not a refusal
    fit.save(tmp_path / "fit.npz")
    assert load_motion_fit(tmp_path / "fit.npz").velocity_range == fit.velocity_range


def _csv(tmp_path, n=810):
    """The record as the command reads it, at 1 024 Hz. 810 samples: the training block (648)
    cuts into three equal blocks, so the gated judge's folds share one compiled fit, and
    tests/test_motion_api.py's command-line record is the same."""
    rec = _record(n, dt=2.0**-10)
    path = tmp_path / "m.csv"
    np.savetxt(path, np.c_[np.arange(n) * rec.dt, rec.force, rec.position], delimiter=",", header="t,F,x",
               comments="")
    return path


def test_cli_refuses_an_unknown_model_before_any_fit(tmp_path, capsys):
    from jaxfric.cli import main

    out = tmp_path / "r"
    rc = main(["identify-motion", str(_csv(tmp_path)), "--force-col", "F", "--x-col", "x", "--time-col", "t",
               "--mass", "2.5", "--model", "coulomb,foo", "--quiet", "--no-cache", "--out", str(out)])
    assert rc != 0
    assert "unknown model 'foo'" in capsys.readouterr().err
    assert not out.exists()


def test_cli_mass_option_is_required_and_says_so(capsys):
    from jaxfric.cli.parser import build_parser

    parser = build_parser()
    sub = parser._subparsers._group_actions[0].choices["identify-motion"]
    assert "(--mass KG | --mass-range LO,HI)" in sub.format_usage()
    with pytest.raises(SystemExit):
        parser.parse_args(["identify-motion", "f.csv", "--force-col", "F", "--x-col", "x"])
    assert "one of the arguments --mass --mass-range is required" in capsys.readouterr().err
    args = parser.parse_args(["identify-motion", "f.csv", "--force-col", "F", "--x-col", "x", "--mass", "2"])
    assert args.x64 is True      # motion computes in float64 unless --float32
    args = parser.parse_args(["identify-motion", "f.csv", "--force-col", "F", "--x-col", "x", "--mass", "2",
                              "--float32"])
    assert args.x64 is False
    import inspect

    from jaxfric.motion import compare_motion

    assert args.keys == (inspect.signature(compare_motion).parameters["keys"].default or 1)  # the same default
    assert parser.parse_args(["identify-motion", "f.csv", "--force-col", "F", "--x-col", "x", "--mass", "2",
                              "--keys", "3"]).keys == 3


@pytest.mark.slow
def test_cli_prints_the_ranking_with_the_baseline_and_writes_results_json(tmp_path, capsys):
    from jaxfric.cli import main

    out = tmp_path / "r"
    rc = main(["identify-motion", str(_csv(tmp_path)), "--force-col", "F", "--x-col", "x", "--time-col", "t",
               "--mass-range", "0.5,10", "--offset", "--model", "coulomb", "--quick", "--quiet", "--no-cache",
               "--window", "0.25", "--keys", "2", "--out", str(out)])  # 810 samples at 1024 Hz: 3 windows of 256
    printed = capsys.readouterr().out
    assert rc == 0
    assert "| rank | model |" in printed and BASELINE_LABEL in printed
    results = json.loads((out / "results.json").read_text())
    assert [r["model"] for r in results["ranking"]] == ["coulomb", BASELINE_LABEL]
    assert results["float64"] is True and "held-back" in results["split"]
    from jaxfric.motion import load_motion_fit

    assert len(load_motion_fit(out / "models" / "coulomb.npz").ensemble["train_rmse_mm"]) == 2  # --keys 2


def _loop_short_score(fit, rec, window, init=20):
    """The short judge written as its definition: one ``fit.score`` per consecutive window
    of the whole record, the RMSE pooled over the (equal) windows."""
    errs = [fit.score(rec.window(a, a + window), init)["rmse_mm"]
            for a in range(0, rec.n_samples - window + 1, window)]
    return float(np.sqrt(np.mean(np.square(errs))))


@pytest.mark.slow
def test_cli_ranks_by_the_short_judge_and_by_the_tail_on_request(tmp_path, capsys):
    """identify-motion's ``--judge short``: 2 s windows of the whole
    record (2 048 samples at 1 024 Hz), the fits and the baseline ranked by the pooled RMSE
    of their free runs, each from its window's first 20 samples; results.json holds the
    judge, its scores and the baseline's row; ``--judge tail`` ranks by the held-back
    block; a record shorter than the window is refused before any fit."""
    from jaxfric.cli import main
    from jaxfric.motion import load_motion_fit
    from jaxfric.motion._compare import baseline_fit

    n = 4200  # 4.1 s: two whole windows of 2 s, a rest of 104 samples not scored
    path = _csv(tmp_path, n)
    rec = _record(n, dt=2.0**-10)
    cmd = ["identify-motion", str(path), "--force-col", "F", "--x-col", "x", "--time-col", "t", "--mass-range",
           "0.5,10", "--offset", "--model", "coulomb,stribeck", "--quick", "--quiet", "--no-cache", "--judge", "short"]
    assert main([*cmd, "--out", str(tmp_path / "short")]) == 0
    printed = capsys.readouterr().out
    results = json.loads((tmp_path / "short" / "results.json").read_text())
    judge = results["judge"]
    assert judge["name"] == "short" and judge["window_samples"] == 2048 and judge["windows"] == 2
    assert judge["window_s"] == pytest.approx(2.0) and judge["init_window"] == 20
    rows = results["ranking"]
    assert [r["model"] for r in rows[:2]] == sorted(judge["scores"], key=judge["scores"].get)
    assert rows[-1]["model"] == BASELINE_LABEL and rows[-1]["rank"] is None
    with jax.enable_x64(True):
        for r in rows[:2]:
            fit = load_motion_fit(tmp_path / "short" / "models" / f"{r['model']}.npz")
            ref = _loop_short_score(fit, rec, 2048)
            assert judge["scores"][r["model"]] == pytest.approx(ref, rel=1e-9)
            assert r["judge_rmse_mm"] == pytest.approx(ref, rel=1e-9)
            assert r["beats_baseline"] == (ref < judge["baseline"])
        base = _loop_short_score(baseline_fit(fit), rec, 2048)
    assert judge["baseline"] == pytest.approx(base, rel=1e-9)
    assert rows[-1]["judge_rmse_mm"] == pytest.approx(base, rel=1e-9)
    md = (tmp_path / "short" / "motion.md").read_text()
    assert "short RMSE [mm]" in printed and "short RMSE [mm]" in md and "`--judge short`" in md

    assert main([*cmd, "--judge", "tail", "--out", str(tmp_path / "tail")]) == 0
    results = json.loads((tmp_path / "tail" / "results.json").read_text())
    rows = results["ranking"]
    assert results["judge"]["name"] == "tail"
    valid = [r["valid_rmse_mm"] for r in rows[:2]]
    assert valid == sorted(valid) and [r["judge_rmse_mm"] for r in rows[:2]] == valid
    assert results["judge"]["scores"] == {r["model"]: r["valid_rmse_mm"] for r in rows[:2]}
    assert results["judge"]["baseline"] == rows[-1]["valid_rmse_mm"] == rows[-1]["judge_rmse_mm"]
    md = (tmp_path / "tail" / "motion.md").read_text()
    assert "short RMSE" not in md and "`--judge tail`" in md

    capsys.readouterr()
    short = _csv(tmp_path, 800)  # 0.78 s
    assert main([cmd[0], str(short), *cmd[2:], "--out", str(tmp_path / "none")]) != 0
    assert "pass a shorter --window S or --judge tail" in capsys.readouterr().err
    assert main([cmd[0], str(short), *cmd[2:], "--window", "0.01", "--out", str(tmp_path / "none")]) != 0
    assert "window must be an integer >= init_window + 2" in capsys.readouterr().err
    assert not (tmp_path / "none").exists()


@pytest.mark.slow
def test_cli_gated_judge_keeps_the_short_score_only_where_blocked_folds_beat_least_squares(tmp_path):
    """The default judge, ``gated`` (no ``--judge``): each model's 3-fold blocked cross-validation of the training block
    (the library's ``blocked_score`` with the command's settings) against least squares'; the
    score is the short one where it is lower, inf otherwise, and the choice is the lowest score
    among the models that pass, least squares where none does."""
    from jaxfric.cli import main
    from jaxfric.motion import MotionSearch, blocked_score, load_motion_fit

    n = 4200
    path = _csv(tmp_path, n)
    rec = _record(n, dt=2.0**-10)
    cmd = ["identify-motion", str(path), "--force-col", "F", "--x-col", "x", "--time-col", "t", "--mass-range",
           "0.5,10", "--offset", "--model", "coulomb,stribeck", "--quick", "--quiet", "--no-cache",
           "--out", str(tmp_path / "gated")]
    assert main(cmd) == 0
    results = json.loads((tmp_path / "gated" / "results.json").read_text())
    judge = results["judge"]
    assert judge["name"] == "gated" and set(judge["blocked"]) == {"coulomb", "stribeck"}
    for m in ("coulomb", "stribeck"):
        gate = judge["blocked"][m] < judge["baseline_blocked"]
        assert judge["scores"][m] == (judge["short"][m] if gate else math.inf)
    best = min(judge["scores"], key=judge["scores"].get)
    assert results["choice"] == (best if math.isfinite(judge["scores"][best]) else BASELINE_LABEL)
    margin = results["gate_margin"]  # how far the chosen model passes; None where the baseline is chosen
    assert margin == (None if results["choice"] == BASELINE_LABEL else
                      pytest.approx(1 - judge["blocked"][best] / judge["baseline_blocked"]))
    assert ("passes the gate narrowly" in (tmp_path / "gated" / "motion.md").read_text()) == (
        margin is not None and margin < NARROW_GATE)
    n_train = load_motion_fit(tmp_path / "gated" / "models" / "coulomb.npz").n_train
    with jax.enable_x64(True):
        ref, base = blocked_score("coulomb", [rec.window(0, n_train)], 3, key=0, mass=(0.5, 10.0), fit_offset=True,
                                  search=MotionSearch(particles=4, generations=2, horizons=(None,), steps=(2,)),
                                  dtype=jnp.float64)
    assert judge["blocked"]["coulomb"] == pytest.approx(ref, rel=1e-9)
    assert judge["baseline_blocked"] == pytest.approx(base, rel=1e-9)
    assert "`--judge gated`" in (tmp_path / "gated" / "motion.md").read_text()


QUICK = MotionSearch(particles=4, generations=2, horizons=(None,), steps=(2,))


def test_ensemble_members_are_the_fits_of_their_keys_and_predict_together(tmp_path):
    from jaxfric.motion import load_motion_fit

    # the record length of the blocked-judge test below: the fits' programs are compiled once
    rec = _record(1200)
    batch = jnp.stack([jax.random.key(i) for i in range(3)])
    opts = dict(mass=(0.5, 10.0), fit_offset=True, search=QUICK, dtype=jnp.float64)
    with jax.enable_x64(True), warnings.catch_warnings():
        warnings.simplefilter("ignore", BaselineWarning)   # a 2-step search
        fit = identify_motion(models.Coulomb(v_eps=1e-3), rec, keys=batch, **opts)
        one = identify_motion(models.Coulomb(v_eps=1e-3), rec, key=jax.random.key(1), **opts)
        e = fit.ensemble
        np.testing.assert_array_equal(e["theta"][1], one.theta)
        assert e["mass"][1] == one.mass and e["train_rmse_mm"][1] == one.metrics["train"]["rmse_mm"]
        assert e["best"] == int(np.argmin(e["train_rmse_mm"]))
        np.testing.assert_array_equal(fit.theta, e["theta"][e["best"]])
        band = fit.simulate_ensemble(_record(1200, seed=1), init_window=20)
        members = np.stack([fit.member(i).simulate(_record(1200, seed=1), init_window=20)["x"] for i in e["kept"]])
        np.testing.assert_allclose(band["x"], members.mean(axis=0))
        assert np.all(band["lower"] <= band["x"]) and np.all(band["x"] <= band["upper"])
        assert fit.metrics["ensemble"]["valid"]["rmse_mm"] >= 0
        assert "ensemble: 3 members" in fit.summary()
        fit.save(tmp_path / "e.npz")
        back = load_motion_fit(tmp_path / "e.npz")
        np.testing.assert_array_equal(back.simulate_ensemble(rec, init_window=20)["x"],
                                      fit.simulate_ensemble(rec, init_window=20)["x"])


def test_members_far_worse_than_the_best_are_dropped():
    from jaxfric.motion._api import ENSEMBLE_DROP, kept_members

    assert kept_members([2.0, 2.9, 3.1, np.nan, 2.5]) == [0, 1, 4]
    assert ENSEMBLE_DROP == 1.5


def test_blocked_judge_scores_each_block_with_a_fit_that_never_saw_it():
    """The blocked judge's score is the pooled RMSE of fits that each leave one block out,
    recomputed here by hand."""
    import math

    rec = _record(1200)
    opts = dict(mass=(0.5, 10.0), fit_offset=True, search=QUICK, dtype=jnp.float64,
                model_options={"v_eps": 1e-3})
    with jax.enable_x64(True), warnings.catch_warnings():
        warnings.simplefilter("ignore", BaselineWarning)
        cmp = compare_motion(["coulomb"], rec, key=0, judge="blocked", folds=2, **opts)
        train = rec.window(0, 960)
        halves = [train.window(0, 480), train.window(480, 960)]
        errs, n = 0.0, 0
        for f in range(2):
            fit = identify_motion("coulomb", train=[halves[1 - f]], valid=[halves[f]], key=0, **opts)
            errs += (480 - 20) * fit.metrics["valid"]["rmse_mm"] ** 2
            n += 480 - 20
    assert cmp.judge == "blocked"
    assert cmp.scores["coulomb"] == pytest.approx(math.sqrt(errs / n), rel=1e-9)
    assert "blocked RMSE [mm]" in cmp.table()
    # the gated judge, the default: the short score where blocked cross-validation beats the baseline's
    from jaxfric.motion._compare import gated_scores, short_judge

    with jax.enable_x64(True), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gated = compare_motion(["coulomb"], rec, key=0, folds=2, window=300, **opts)
    assert gated.judge == "gated"
    with jax.enable_x64(True):
        short, short_base = short_judge(gated.fits, [rec], 300)
    passes = cmp.scores["coulomb"] < cmp.baseline_score
    assert gated.scores["coulomb"] == (short["coulomb"] if passes else math.inf)
    assert gated.blocked == cmp.scores and gated.baseline_blocked == cmp.baseline_score  # kept on the comparison
    assert gated.baseline_score == short_base
    # keys=K: K members per model, judged by the member of lowest training error; the folds stay one fit each
    with jax.enable_x64(True), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ens = compare_motion(["coulomb"], rec, key=0, folds=2, window=300, keys=2, **opts)
        alone = identify_motion("coulomb", rec, key=0, keys=2, **opts)
    assert len(ens.fits["coulomb"].ensemble["train_rmse_mm"]) == 2
    np.testing.assert_array_equal(ens.fits["coulomb"].ensemble["theta"], alone.ensemble["theta"])
    assert ens.blocked == cmp.scores and ens.baseline_blocked == cmp.baseline_score
    assert gated_scores({"a": 1.0, "b": 2.0}, {"a": 5.0, "b": 3.0}, 4.0) == {"a": math.inf, "b": 2.0}
    with pytest.raises(ValueError, match="judge must be one of"):
        compare_motion(["coulomb"], rec, key=0, judge="oracle", **opts)


def test_the_official_emps_script_reads_and_scores_any_emps_format_test_file(tmp_path):
    """A test recording holding only t (float32 stamps that round to another 1 kHz step than
    the estimation file's), qm and vir is read and scored from its first 20 samples."""
    import sys
    from pathlib import Path

    from scipy.io import savemat

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import motion as emps_official  # benchmarks/motion.py --parts official

    rec = _record(1500)
    t = (np.arange(1500) * 1.0000080e-3).astype(np.float32)
    savemat(tmp_path / "test.mat", {"t": t[:, None], "qm": rec.position[:, None],
                                    "vir": (rec.force / emps_official.GTAU)[:, None]})
    test = emps_official.motion_data(tmp_path / "test.mat")
    assert not test.dt == 0.0009999840 and same_sample_time(test.dt, 0.0009999840)
    # the script builds its fixed fits (baseline, published IDIM-LS) with baseline_motion_fit
    fit = baseline_motion_fit(MASS, TRUTH["Fc"], TRUTH["sigma2"], OFFSET, dt=0.0009999840)
    with jax.enable_x64(True):
        score = fit.score(test, init_window=20)
    assert np.isfinite(score["rmse_mm"])


def _rough(y, data):
    """Residuals of Σ (y_i - c_i)² + a² sin²(w y_i): a bowl with a valley every π/w."""
    c, a, w = data
    return jnp.concatenate([y - c, a * jnp.sin(w * y)])


def test_the_screen_takes_every_key_from_a_local_valley_to_the_global_minimum():
    """Levenberg-Marquardt stops in the first valley of a rough cost; the screening stage
    (MotionSearch.screen) reaches the global minimum from there whatever the key. The
    reference minimum is a dense grid (the cost is separable)."""
    from jaxfric.motion import MotionBudget
    from jaxfric.motion._lm import levenberg_marquardt
    from jaxfric.motion._pipeline import _Clock, screen_free_run

    data = (jnp.array([1.0, -0.5]), 0.3, 15.0)
    lo, hi = np.array([-4.0, -4.0]), np.array([4.0, 4.0])
    grid = np.linspace(-4.0, 4.0, 400001)
    best = sum(np.min((grid - c) ** 2 + 0.09 * np.sin(15.0 * grid) ** 2) for c in (1.0, -0.5))
    with jax.enable_x64(True):
        stuck = levenberg_marquardt(_rough, jnp.array([3.0, 2.5]), jnp.asarray(lo), jnp.asarray(hi), data,
                                    max_steps=100)
        assert stuck.f > 10 * best  # a local valley far above the minimum
        for k in range(3):
            stages = []
            y, f = screen_free_run(MotionSearch(screen=16), _Clock(MotionBudget()), _rough, stuck.theta, stuck.f,
                                   lo, hi, data, jax.random.key(k), jnp.float64, stages)
            assert f == pytest.approx(best, rel=1e-6)
            assert len(stages) == 16 and all(s["stage"] == "screen" for s in stages)
            assert [s["best"] for s in stages] == sorted((s["best"] for s in stages), reverse=True)


def test_every_key_recovers_the_drive_and_reports_each_starts_cost():
    """Simulated Coulomb + viscous drive with known parameters: the search with the
    screening stage recovers them from keys 0 and 1, and the fit lists every start's final
    free-run cost (settings['motion']['starts'], best first)."""
    search = MotionSearch(particles=10, generations=6, global_window=150, horizons=(300, None), steps=(10, 20),
                          starts=2, least_squares_start=True, screen=3, screen_size=16, screen_steps=10)
    costs = []
    with jax.enable_x64(True):
        for k in (0, 1):
            fit = identify_motion(models.Coulomb(v_eps=1e-3), _record(), key=k, mass=(0.5, 10.0), fit_offset=True,
                                  search=search, dtype=jnp.float64)
            assert fit.params["Fc"] == pytest.approx(TRUTH["Fc"], rel=1e-3)
            assert fit.params["sigma2"] == pytest.approx(TRUTH["sigma2"], rel=1e-3)
            assert fit.mechanics.mass == pytest.approx(MASS, rel=1e-3)
            assert fit.mechanics.offset == pytest.approx(OFFSET, rel=1e-3)
            starts = fit.mechanics.starts
            assert sorted(s["start"] for s in starts) == [0, 1, 2]  # 2 personal bests + least squares
            assert [s["J"] for s in starts] == sorted(s["J"] for s in starts)
            assert fit.metrics["cost"] <= starts[0]["J"] * (1 + 1e-9)  # polish and screen only go lower
            assert sum(s["stage"] == "screen" for s in fit.stages) == 3
            costs.append(fit.metrics["cost"])
    assert costs[0] == pytest.approx(costs[1], rel=1e-3, abs=1e-9)


def test_the_screen_settings_are_checked():
    for bad in (MotionSearch(screen=-1), MotionSearch(screen_size=1), MotionSearch(screen_steps=0),
                MotionSearch(screen_spread=0.0)):
        with pytest.raises(ValueError, match="MotionSearch"):
            bad.check()


class _Swarm:
    """A stand-in swarm: its personal bests and its final positions."""

    def __init__(self, pbest, x):
        self.pbest, self.x = pbest, x

    def personal_bests(self, state):
        return self.pbest, None


def test_the_free_run_starts_are_the_swarms_points_of_lowest_whole_cost():
    """free_run_ranked ranks the swarm's personal bests and final positions by the cost
    itself (here the rough bowl, recomputed in NumPy) and skips points already taken."""
    from types import SimpleNamespace

    from jaxfric.motion import MotionBudget
    from jaxfric.motion._pipeline import _Clock, free_run_ranked

    data = (jnp.array([1.0, -0.5]), 0.3, 15.0)
    rng = np.random.default_rng(3)
    pbest, x = rng.uniform(-2, 2, (6, 2)), rng.uniform(-2, 2, (6, 2))
    pool = np.vstack([pbest, x])
    ref = np.sum((pool - [1.0, -0.5]) ** 2 + 0.09 * np.sin(15.0 * pool) ** 2, axis=1)
    order = np.argsort(ref)
    swarm = _Swarm(pbest, x)
    sol = SimpleNamespace(state=swarm)
    lo, hi = np.array([-4.0, -4.0]), np.array([4.0, 4.0])
    with jax.enable_x64(True):
        stages, clock = [], _Clock(MotionBudget())
        got = free_run_ranked(MotionSearch(free_run_starts=3), clock, swarm, sol, _rough, data, [], lo, hi,
                              jnp.float64, stages)
        np.testing.assert_array_equal(np.array(got), pool[order[:3]])
        assert stages[0]["stage"] == "rank" and stages[0]["J"] == pytest.approx(ref[order[0]], rel=1e-12)
        assert clock.evals == 12
        # the lowest point is already a start: the next three come instead
        got = free_run_ranked(MotionSearch(free_run_starts=3), _Clock(MotionBudget()), swarm, sol, _rough, data,
                              [pool[order[0]] + 1e-6], lo, hi, jnp.float64, [])
        np.testing.assert_array_equal(np.array(got), pool[order[1:4]])


def test_the_screen_widens_4x_after_each_round_that_finds_nothing_lower():
    """At the minimum nothing lower is found: each round's spread (stage["spread"]) is 4x the
    last one's, from screen_spread."""
    from jaxfric.motion import MotionBudget
    from jaxfric.motion._pipeline import _Clock, screen_free_run

    def bowl(y, c):
        return jnp.concatenate([y - c, jnp.ones(1, y.dtype)])  # minimum J = 1 at y = c

    c = jnp.array([0.3, -0.2])
    lo, hi = np.array([-1.0, -1.0]), np.array([1.0, 1.0])
    with jax.enable_x64(True):
        stages = []
        y, f = screen_free_run(MotionSearch(screen=5, screen_size=8, screen_steps=5, screen_spread=0.2),
                               _Clock(MotionBudget()), bowl, np.asarray(c), 1.0, lo, hi, c,
                               jax.random.key(0), jnp.float64, stages)
        assert f == 1.0
        np.testing.assert_allclose([s["spread"] for s in stages], 0.2 * 4.0 ** np.arange(5), rtol=1e-12)


def test_the_free_run_settings_are_checked():
    for bad in (MotionSearch(free_run_starts=-1), MotionSearch(free_run_starts=True),
                MotionSearch(free_run_starts=1.5)):
        with pytest.raises(ValueError, match="MotionSearch"):
            bad.check()


def test_free_run_starts_are_polished_beside_the_swarms_best():
    """free_run_starts=1 adds one start (the swarm's point of lowest whole free-run cost) to
    the same window-ranked starts: the winning start can only end lower, and every start's
    final cost is listed."""
    search = MotionSearch(particles=10, generations=6, global_window=150, horizons=(300, None), steps=(10, 20),
                          starts=2, least_squares_start=True)
    with jax.enable_x64(True):
        fits = [identify_motion(models.Coulomb(v_eps=1e-3), _record(), key=1, mass=(0.5, 10.0), fit_offset=True,
                                search=dataclasses.replace(search, free_run_starts=k), dtype=jnp.float64) for k in (0, 1)]
    plain, ranked = fits
    assert "rank" not in [s["stage"] for s in plain.stages]
    assert [s["stage"] for s in ranked.stages][:2] == ["pso", "rank"]
    assert sorted(s["start"] for s in ranked.mechanics.starts) == [0, 1, 2, 3]
    assert ranked.metrics["cost"] <= plain.metrics["cost"] * (1 + 1e-12)
