"""identify_motion's default search, records, budget, initial-state rule and model choice
(docs/motion.md, docs/algorithms.md §13.2)."""

import json
import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import least_squares

from jaxfric import models
from jaxfric.motion import (MotionData, MotionFit, MotionSearch, OverfitWarning, compare_motion,
                            friction_step, identify_motion, simulate_motion)
from jaxfric.motion._compare import rank_fits
from jaxfric.motion._lm import levenberg_marquardt
from jaxfric.motion._shooting import schedule, shoot

TRUTH = dict(Fc=12.0, sigma2=60.0)
MASS, OFFSET = 2.5, 3.0
#: A small search for the unit tests (the defaults are sized for long records).
SMALL = MotionSearch(particles=10, generations=8, global_window=150, horizons=(300, None), steps=(15, 25))
#: The command line's ``--quick`` search: the model-comparison test runs the command's
#: configuration (record, models, budget), so the command-line test reuses its programs.
QUICK = MotionSearch(particles=4, generations=2, horizons=(None,), steps=(2,))
#: Their sample time: binary, so the command's median of the CSV stamps' differences is
#: exactly it (with 1e-3 it is 1 ulp off, and the programs, which compile dt in, differ).
CLI_DT = 2.0**-10
#: Their record length: the training block (80 %, 648 samples) cuts into three equal blocks,
#: so the gated judge's three blocked folds of a model train on records of one shape and
#: share one compiled fit (800 samples gave folds of 426 and 427 samples: two fits compiled
#: per model). tests/test_motion_dependable.py's command-line record has the same length.
CLI_N = 810


def _record(n=1500, dt=1e-3, phase=0.0, seed=0, model=None, theta=None, velocity=False):
    """Noise-free motion of a Coulomb+viscous axis (mass 2.5 kg, offset 3 N) under a
    two-tone force (and the true velocity with ``velocity=True``)."""
    model = models.Coulomb(v_eps=1e-3) if model is None else model
    theta = model.from_physical(**TRUTH) if theta is None else theta
    t = np.arange(n) * dt
    u = 30 * np.sin(2 * np.pi * 1.3 * t + phase) + 12 * np.sin(2 * np.pi * 3.1 * t + 1.0 + seed)
    with jax.enable_x64(True):
        out = simulate_motion(friction_step(model), jnp.asarray(theta, jnp.float64), MASS, u - OFFSET,
                              dt, 0.0, 0.0)
        x = np.asarray(out["x"])
    rec = MotionData.from_arrays(u, x, dt)
    return (rec, np.asarray(out["v"])) if velocity else rec


def _fit(**kw):
    kw.setdefault("search", SMALL)
    with jax.enable_x64(True):
        return identify_motion(models.Coulomb(v_eps=1e-3), key=0, mass=(0.5, 10.0), fit_offset=True,
                               box={"Fc": (2.0, 40.0), "sigma2": (5.0, 500.0)}, data_bounds=False,
                               dtype=jnp.float64, **kw)


# ----------------------------------------------------------------- building blocks
def _rosenbrock(theta, data):
    return jnp.stack([10.0 * (theta[1] - theta[0] ** 2), 1.0 - theta[0]])


def test_levenberg_marquardt_finds_scipys_optimum_inside_the_box():
    """Rosenbrock residuals from (-1.2, 1): scipy's least_squares and ours reach (1, 1)."""
    with jax.enable_x64(True):
        lo, hi = jnp.asarray([-2.0, -2.0]), jnp.asarray([2.0, 3.0])
        out = levenberg_marquardt(_rosenbrock, jnp.asarray([-1.2, 1.0]), lo, hi, None, max_steps=200,
                                  rtol=1e-14)
    ref = least_squares(lambda p: np.asarray(_rosenbrock(p, None)), [-1.2, 1.0], bounds=([-2, -2], [2, 3]))
    np.testing.assert_allclose(out.theta, ref.x, atol=1e-6)
    assert out.f < 1e-12
    assert out.evals >= out.steps


def test_levenberg_marquardt_stops_at_its_budget():
    with jax.enable_x64(True):
        lo, hi = jnp.asarray([-2.0, -2.0]), jnp.asarray([2.0, 3.0])
        out = levenberg_marquardt(_rosenbrock, jnp.asarray([-1.2, 1.0]), lo, hi, None, max_steps=200,
                                  max_evals=10)
    assert out.reason == "max_evals" and out.evals <= 10


def test_free_run_schedule_is_simulate_motion_and_segments_restart_from_the_measurement():
    model = models.LuGre()
    theta = model.from_physical(sigma0=1e5, sigma1=50.0, sigma2=60.0, Fc=12.0, Fs=15.0, vs=5e-3)
    rec = _record(n=600, model=model, theta=theta)
    with jax.enable_x64(True):
        step = friction_step(model)
        th = jnp.asarray(theta, jnp.float64)
        u = rec.net_force - OFFSET
        ref = simulate_motion(step, th, MASS, u, rec.dt, rec.position[0], rec.velocity[0])["x"]
        free = shoot(step, th, MASS, u, rec.dt, rec.position, rec.velocity, schedule([0], 600))
        np.testing.assert_allclose(np.asarray(free), np.asarray(ref), rtol=0, atol=1e-15)
        plan = schedule([0], 600, segment=100, lead=5)
        seg = np.asarray(shoot(step, th, MASS, u, rec.dt, rec.position, rec.velocity, plan))
    forced = np.asarray(plan.forced)
    assert forced[[0, 1, 5, 100, 105, 200, 205]].all() and not forced[[6, 99, 106, 300 - 6]].any()
    np.testing.assert_array_equal(seg[forced], rec.position[forced])
    assert np.all(np.asarray(plan.weight)[forced] == 0.0)


# ----------------------------------------------------------------- default search, records
@pytest.fixture(scope="module")
def default_fit():
    """The small search on the default record, 80 % for training."""
    return _fit(data=_record(), train=0.8)


def test_default_search_recovers_mass_offset_and_friction(default_fit):
    """Noise-free data: the default pipeline (PSO, shooting, free run) recovers Fc, Fv,
    mass and offset within 1 %."""
    fit = default_fit
    got = fit.params
    for k, val in TRUTH.items():
        assert abs(float(got[k]) - val) <= 0.01 * val, (k, got[k])
    assert abs(fit.mass - MASS) <= 0.01 * MASS
    assert abs(fit.offset - OFFSET) <= 0.01 * OFFSET
    assert [s["stage"] for s in fit.stages] == ["pso", "shooting_300", "free_run"]
    assert fit.metrics["valid"]["fit_percent"] > 99.0
    assert fit.mechanics.stopped is None


@pytest.mark.slow
def test_records_are_used_whole_with_metrics_per_record():
    a, b, c = _record(1200, phase=0.0), _record(1000, phase=1.0, seed=2), _record(900, phase=2.0, seed=4)
    fit = _fit(train=[a, b], valid=c)
    recs = fit.metrics["records"]
    assert len(recs["train"]) == 2 and len(recs["valid"]) == 1
    assert fit.n_train == 2200 and fit.n_samples == 3100
    # the validation record is scored after its 20-sample initial-state window
    with jax.enable_x64(True):
        x_hat = fit.simulate(c, init_window=20)["x"]
    rmse = 1e3 * np.sqrt(np.mean((x_hat[20:] - c.position[20:]) ** 2))
    assert recs["valid"][0]["rmse_mm"] == pytest.approx(rmse, rel=1e-12)
    assert abs(fit.mass - MASS) <= 0.02 * MASS
    assert recs["valid"][0]["fit_percent"] > 98.0


def test_whole_record_trains_with_train_one():
    # as long as the module fixture's training block: its compiled search is reused
    rec = _record(1200)
    fit = _fit(data=rec, train=1.0)
    assert fit.n_train == 1200 and "valid" not in fit.metrics
    assert fit.metrics["train"]["fit_percent"] > 99.0
    # a held-back block shorter than the k-step horizon gets a shorter k, not an error (3
    # samples held back after the same 1200 training samples: the compiled search is reused)
    short = _fit(data=_record(1203), train=1200)
    assert short.metrics["horizon"] == 2 and np.isfinite(short.metrics["valid_kstep"]["rmse_mm"])


def test_records_form_refuses_mixed_and_missing_input():
    rec = _record(300)
    with pytest.raises(ValueError, match="valid= goes with train"):
        identify_motion("coulomb", rec, key=0, mass=1.0, valid=rec)
    with pytest.raises(ValueError, match="no data"):
        identify_motion("coulomb", key=0, mass=1.0, train=0.8)
    with pytest.raises(ValueError, match="init_window"):
        identify_motion("coulomb", key=0, mass=1.0, train=[rec], valid=rec.window(0, 15))
    with pytest.raises(ValueError, match="max_time"):
        identify_motion("coulomb", rec, key=0, mass=1.0, max_time=-1.0)
    with pytest.raises(ValueError, match="one record"):
        identify_motion("coulomb", key=0, mass=1.0, train=[rec], horizon=5)


def test_budget_stops_the_run_with_the_best_so_far():
    # the module fixture's record and split: its compiled stages are reused
    rec = _record()
    fit = _fit(data=rec, train=0.8, max_evals=150)
    assert fit.mechanics.stopped == "max_evals"
    assert sum(s["num_evals"] for s in fit.stages) <= 150
    assert np.isfinite(fit.metrics["cost"])
    # the stages never make it worse: the final J is at most the global stage's on the same cost
    timed = _fit(data=rec, train=0.8, max_time=1e-6)
    assert timed.mechanics.stopped == "max_time"
    assert [s["stage"] for s in timed.stages] == ["pso"]
    assert np.isfinite(timed.metrics["valid"]["rmse_mm"])
    with pytest.raises(ValueError, match="no room"):
        _fit(data=rec, train=0.8, max_evals=5)


@pytest.mark.slow
def test_same_key_same_fit(default_fit):
    # the module fixture's call once more
    a, b = default_fit, _fit(data=_record(), train=0.8)
    np.testing.assert_array_equal(a.theta, b.theta)
    assert a.mass == b.mass


# ----------------------------------------------------------------- initial-state rule
def _reference_fit(rec):
    model = models.Coulomb(v_eps=1e-3)
    return MotionFit.given(model, TRUTH, mass=MASS, offset=OFFSET, dt=rec.dt, n_train=rec.n_samples,
                           n_samples=rec.n_samples)


def test_initial_state_reads_only_its_window():
    """Positions after the window never matter; the force drives the free run after it."""
    rec = _record(800)  # the length of the other initial-state test: its programs are reused
    fit = _reference_fit(rec)
    n = 20
    with jax.enable_x64(True):
        base = fit.simulate(rec, init_window=n)["x"]
        x2 = rec.position.copy()
        x2[n:] += np.random.default_rng(0).normal(0, 1e-2, x2.size - n)  # the whole tail replaced
        other = MotionData.from_arrays(rec.force, x2, rec.dt)
        assert not np.allclose(other.velocity[:n], rec.velocity[:n])  # the filter would read past
        np.testing.assert_array_equal(fit.simulate(other, init_window=n)["x"], base)
        f2 = rec.force.copy()
        f2[n + 5:] += 50.0
        changed = fit.simulate(MotionData.from_arrays(f2, rec.position, rec.dt), init_window=n)["x"]
    np.testing.assert_array_equal(changed[: n + 6], base[: n + 6])
    assert not np.allclose(changed[n + 7:], base[n + 7:])


def test_initial_state_rule_is_a_quadratic_fit_over_the_window():
    """On a quadratic position the rule's x0 and v0 are exact; on the simulated record they
    match the true state within the polynomial's error."""
    rec, v = _record(800, velocity=True)
    fit = _reference_fit(rec)
    dt = rec.dt
    t = np.arange(20) * dt
    with jax.enable_x64(True):
        st = fit.initial_state(0.1 + 0.02 * t + 0.5 * 3.0 * t ** 2, 20)
        assert st["x0"] == pytest.approx(0.1 + 0.02 * t[-1] + 1.5 * t[-1] ** 2, abs=1e-14)
        assert st["v0"] == pytest.approx(0.02 + 3.0 * t[-1], abs=1e-10)
        st = fit.initial_state(rec.position[500:], 20)
        with pytest.raises(ValueError, match="init_window"):
            fit.initial_state(rec.position, 1)
        with pytest.raises(ValueError, match="init_window"):
            fit.simulate(rec)
    assert st["v0"] == pytest.approx(v[519], rel=1e-2)
    assert st["x0"] == pytest.approx(rec.position[519], abs=1e-3 * np.ptp(rec.position))


# ----------------------------------------------------------------- model choice
def test_overfit_warning_fires_when_a_richer_model_validates_worse():
    """Data from Coulomb+viscous friction; a 'richer' Stribeck fit with a wrong breakaway
    peak validates worse than the true simpler model: the warning names both. With the
    peak right (the richer model containing the truth) it stays silent."""
    rec = _record(1500)
    train, valid = rec.window(0, 1000), rec.window(1000)
    coul = _reference_fit(rec)
    strib_model = models.Stribeck(v_eps=1e-3)

    def strib(fs):
        return MotionFit.given(strib_model, dict(Fc=12.0, Fs=fs, vs=2e-3, sigma2=60.0), mass=MASS, offset=OFFSET,
                               dt=rec.dt, n_train=1000, n_samples=1500)

    fits = {"coulomb": coul, "stribeck": strib(30.0)}
    with jax.enable_x64(True):
        fits = {name: f.replace(metrics={**f.evaluate_records([train], [valid]), "num_params": f.model.num_params + 2})
                for name, f in fits.items()}
        with pytest.warns(OverfitWarning, match="stribeck .* worse than coulomb"):
            out = rank_fits(fits)
        assert out.ranking == ["coulomb", "stribeck"] and out.overfit == [("stribeck", "coulomb")]
        assert "worse than a simpler model" in out.table()
        # under the gated judge a model that fails the gate scores inf: the warning names the gate
        with pytest.warns(OverfitWarning, match="stribeck .*'gated' judge.* does not beat the least-squares"):
            rank_fits(fits, scores={"coulomb": 1.0, "stribeck": float("inf")}, judge="gated")
        good = strib(12.0)  # Fs = Fc: the Coulomb model itself
        good = good.replace(metrics={**good.evaluate_records([train], [valid]), "num_params": 6})
        with warnings.catch_warnings():
            warnings.simplefilter("error", OverfitWarning)
            rank_fits({"coulomb": fits["coulomb"], "stribeck": good})


def test_choice_is_the_baseline_where_it_scores_lowest():
    """``choice`` is the judge's pick with the least-squares baseline among the candidates
    (what benchmarks/motion_judge.py counts): the best model where it scores lower than the
    baseline, else the baseline's own fit, with its least-squares parameters, and a warning;
    under the gated judge the baseline only where no model passes the gate."""
    from jaxfric.motion import BaselineWarning, MotionComparison

    ls = {"M": 2.4, "Fc": 11.0, "Fv": 55.0, "offset": 2.0}
    fit = MotionFit.given(models.get("lugre"), dict(sigma0=1e5, sigma1=300.0, sigma2=60.0, Fc=12.0, Fs=15.0,
                                                    vs=0.01), mass=MASS, offset=OFFSET, dt=1e-3,
                          mechanics={"baseline": ls})
    fit = fit.replace(metrics={"num_params": 8, "valid": {"rmse_mm": 2.0},
                               "baseline": {"train": {"rmse_mm": 1.0}, "valid": {"rmse_mm": 3.0}}})
    with warnings.catch_warnings():
        warnings.simplefilter("error", BaselineWarning)
        assert MotionComparison({"lugre": fit}, ["lugre"], [], "short", {"lugre": 2.0}, 2.5).choice is fit
        assert MotionComparison({"lugre": fit}, ["lugre"], [], "tail").choice is fit  # 2.0 < 3.0 on the tail
    cmp = MotionComparison({"lugre": fit}, ["lugre"], [], "short", {"lugre": 2.0}, 1.5)
    with pytest.warns(BaselineWarning, match="1.5 mm against lugre's 2 mm"):
        base = cmp.choice
    assert cmp.best is fit and base is not fit
    assert base.mass == ls["M"] and base.offset == ls["offset"]
    assert base.params["Fc"] == pytest.approx(ls["Fc"]) and base.params["sigma2"] == pytest.approx(ls["Fv"])
    # gated out (its blocked folds no better than least squares'): the table and the warning say so
    from jaxfric.motion._baseline import BASELINE_LABEL

    full = fit.replace(metrics={"num_params": 8, "train": {"rmse_mm": 1.5}, "valid": {"rmse_mm": 2.0, "fit_percent": 90.0},
                                "baseline": {"train": {"rmse_mm": 1.0}, "valid": {"rmse_mm": 3.0, "fit_percent": 80.0}}})
    gated = MotionComparison({"lugre": full}, ["lugre"], [], "gated", {"lugre": math.inf}, 2.5, {"lugre": 4.5}, 4.0)
    assert gated.choice_name == BASELINE_LABEL
    assert "gated out: blocked 4.5 mm, least squares' 4" in gated.table()
    assert [r["blocked_rmse_mm"] for r in gated.rows()] == [4.5, 4.0]
    with pytest.warns(BaselineWarning, match="no model's blocked cross-validation beats least squares', 4 mm"):
        gated.choice
    # a model that passes the gate is the choice even where least squares' short score is lower
    # (EMPS block 0: 9.4 mm on the other blocks against 2.3-4.5 for the models the gate passed)
    passed = MotionComparison({"lugre": full}, ["lugre"], [], "gated", {"lugre": 2.0}, 1.5, {"lugre": 3.5}, 4.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", BaselineWarning)
        assert passed.choice_name == "lugre" and passed.choice is full
    assert passed.rows()[0]["beats_baseline"] is True and "not better than the baseline" not in passed.table()
    assert passed.gate_margin == pytest.approx(0.125) and "narrowly" not in passed.table()
    # a narrow pass (blocked 2.5 % under least squares', under NARROW_GATE): still the choice, with a warning
    from jaxfric.motion import NARROW_GATE, NarrowGateWarning

    narrow = MotionComparison({"lugre": full}, ["lugre"], [], "gated", {"lugre": 2.0}, 1.5, {"lugre": 3.9}, 4.0)
    assert narrow.gate_margin == pytest.approx(0.025) and narrow.gate_margin < NARROW_GATE and narrow.passes_narrowly
    with pytest.warns(NarrowGateWarning, match=r"\(3.9 mm\) beats least squares' \(4 mm\) by 2.5 %"):
        assert narrow.choice is full
    assert "passes narrowly: blocked 2.5 % under least squares'" in narrow.table()
    short = MotionComparison({"lugre": full}, ["lugre"], [], "short", {"lugre": 2.0}, 1.5)
    assert short.choice_name == BASELINE_LABEL  # the same scores under the short judge: the baseline
    assert gated.gate_margin is None and short.gate_margin is None  # the baseline chosen; another judge


@pytest.mark.slow
def test_compare_motion_ranks_and_needs_validation():
    rec = _record(CLI_N, dt=CLI_DT)
    with pytest.raises(ValueError, match="validation"):
        compare_motion(["coulomb"], rec, key=0, mass=2.5, train=1.0)
    with jax.enable_x64(True), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = compare_motion("coulomb,stribeck", rec, key=0, mass=(0.5, 10.0), fit_offset=True, search=QUICK,
                             dtype=jnp.float64, max_evals=40, progress=False, judge="tail")
    scores = [out.fits[k].metrics["valid"]["rmse_mm"] for k in out.ranking]
    assert scores == sorted(scores)
    assert out.best is out.fits[out.ranking[0]]


@pytest.mark.slow
def test_cli_ranks_models_by_validation_and_takes_a_budget(tmp_path, capsys):
    from jaxfric.cli import main

    rec = _record(CLI_N, dt=CLI_DT)
    path = tmp_path / "m.csv"
    np.savetxt(path, np.c_[np.arange(CLI_N) * CLI_DT, rec.force, rec.position], delimiter=",", header="t,F,x",
               comments="")
    rc = main(["identify-motion", str(path), "--force-col", "F", "--x-col", "x", "--time-col", "t",
               "--mass-range", "0.5,10", "--offset", "--model", "coulomb,stribeck", "--quick", "--quiet",
               "--x64", "--max-evals", "40", "--window", "0.25", "--no-cache", "--out", str(tmp_path / "r")])
    assert rc == 0, capsys.readouterr().err
    text = (tmp_path / "r" / "motion.md").read_text()
    assert "| rank | model | parameters |" in text
    ranks = [line.split("|")[2].split(" (")[0].strip() for line in text.splitlines() if line.startswith("| 1 ")
             or line.startswith("| 2 ")]
    assert sorted(ranks) == ["coulomb", "stribeck"]
    res = json.loads((tmp_path / "r" / "results.json").read_text())
    assert res["judge"]["name"] == "gated"  # the default: the baseline only where no model passes the gate
    models = [r for r in res["ranking"] if r["rank"] is not None]
    first = min(models, key=lambda r: r["judge_rmse_mm"])
    chosen = first["model"] if math.isfinite(first["judge_rmse_mm"]) else res["ranking"][-1]["model"]
    assert res["choice"] == chosen and (f"Choice (the lowest score among the models that pass the gate; the "
                                        f"baseline where none does): {chosen}") in text
    from jaxfric.motion import load_motion_fit

    for name in ranks:
        fit = load_motion_fit(tmp_path / "r" / "models" / f"{name}.npz")
        assert sum(s["num_evals"] for s in fit.stages) <= 40


@pytest.mark.slow
def test_elman_inside_the_mechanics_converges_by_its_gradient_stages():
    """A small Elman network learns the Coulomb axis's friction from motion alone: the
    Levenberg-Marquardt stages lower the swarm's free-run cost a hundredfold, to a free
    run with FIT above 90 % (networks get the coarse-to-fine schedule by default)."""
    from jaxfric.motion import default_search

    rec = _record(1000)
    model = models.Elman(neurons=4, context_weight_bound=1.0)
    assert default_search(models.Elman(neurons=10)).horizons == (1000, 5000)
    search = MotionSearch(particles=10, generations=5, global_window=150, horizons=(200, None), steps=(40, 60))
    with jax.enable_x64(True):
        fit = identify_motion(model, rec, key=0, mass=MASS, fit_offset=True, search=search, dtype=jnp.float64)
        swarm_only = identify_motion(model, rec, key=0, mass=MASS, fit_offset=True, search=search,
                                     dtype=jnp.float64, max_time=1e-6)
    assert [s["stage"] for s in swarm_only.stages] == ["pso"]
    assert fit.metrics["cost"] < 0.01 * swarm_only.metrics["cost"]
    assert fit.metrics["train"]["fit_percent"] > 90.0


def test_search_settings_are_checked_before_the_run():
    rec = _record(300)
    for bad in (MotionSearch(generations=0), MotionSearch(horizons=(100,), steps=(1, 2)),
                MotionSearch(horizons=(1,), steps=(5,)), MotionSearch(steps=(-1,))):
        with pytest.raises(ValueError, match="MotionSearch"):
            identify_motion("coulomb", rec, key=0, mass=1.0, search=bad)
    with pytest.raises(ValueError, match="max_evals"):
        identify_motion("coulomb", rec, key=0, mass=1.0, max_evals=0)


def test_evaluate_is_simulate_from_and_k_step():
    """evaluate's one compiled call gives the metrics of the public methods it replaces."""
    from jaxfric.motion import motion_metrics

    model = models.LuGre()
    rec = _record(600)
    fit = MotionFit.given(model, dict(sigma0=1e5, sigma1=50.0, sigma2=60.0, Fc=12.0, Fs=15.0, vs=5e-3),
                          mass=MASS, offset=OFFSET, v0=1e-3, dt=rec.dt, n_train=450, n_samples=600)
    x = rec.position
    with jax.enable_x64(True):
        ev = fit.evaluate(rec, 450, 10)
        tr, va = fit.simulate_from(rec, 0, 450)["x"], fit.simulate_from(rec, 450)["x"]
        ks = fit.k_step(rec, 10)
    assert ev["train"] == motion_metrics(x[:450], tr)
    assert ev["valid"] == motion_metrics(x[450:], va)
    assert ev["valid_kstep"] == motion_metrics(x[10:][440:], ks[440:])


def test_emps_official_benchmark_skips_cleanly_without_the_test_recording(tmp_path):
    """The benchmark's test file is not shipped: the script says so, exits 0, writes nothing."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    env = {k: v for k, v in os.environ.items() if k != "JAXFRIC_EMPS_TEST"}
    out = subprocess.run([sys.executable, str(root / "benchmarks" / "motion.py"), "--parts", "official", "--test",
                          str(tmp_path / "DATA_EMPS_PULSES.mat"), "--out", str(tmp_path / "res")],
                         capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "skipping the official task" in out.stdout
    assert not (tmp_path / "res").exists()


def test_a_motion_fit_of_given_parameters_is_the_one_built_by_hand():
    """``MotionFit.given`` (published parameters, a baseline, a test's truth) holds the
    parameters as θ, the mechanics in ``fit.mechanics``, and predicts friction plus the offset;
    ``baseline_motion_fit`` is the least-squares baseline's model with those values."""
    from jaxfric.motion import baseline_motion_fit

    model = models.Coulomb(v_eps=1e-3)
    by_name = MotionFit.given(model, TRUTH, mass=MASS, offset=OFFSET, dt=1e-3, settings={"model_name": "x"})
    by_theta = MotionFit.given(model, np.asarray(model.from_physical(**TRUTH)), mass=MASS, offset=OFFSET, dt=1e-3)
    np.testing.assert_array_equal(by_name.theta, by_theta.theta)
    assert (by_name.mechanics.mass, by_name.mechanics.offset, by_name.mechanics.v0) == (MASS, OFFSET, 0.0) and by_name.settings["model_name"] == "x"
    v = np.linspace(-0.02, 0.02, 7)
    expected = TRUTH["Fc"] * np.tanh(v / 1e-3) + TRUTH["sigma2"] * v + OFFSET
    np.testing.assert_allclose(np.asarray(by_name.predict(v)), expected, rtol=1e-5, atol=1e-4)
    base = baseline_motion_fit(2.0, -1.0, 3.0, 0.5, dt=1e-3, n_train=5)
    assert base.mass == 2.0 and base.offset == 0.5 and base.n_train == 5
    assert base.params["Fc"] == pytest.approx(0.0, abs=1e-6)  # a negative Coulomb level is held at zero
    assert base.params["sigma2"] == pytest.approx(3.0, rel=1e-6)


def test_a_motion_fit_predicts_its_offset_on_every_path_and_through_the_cli(tmp_path):
    """The fitted offset is in every friction prediction of a motion fit: ``predict`` at the
    fit's sample time, at another (resampled: ``predict_at``, once), ``predict_at`` itself, and
    ``jaxfric predict`` on the saved file (which ``load_fit`` alone refuses: a motion fit)."""
    from jaxfric.cli import main
    from jaxfric.fit import Fit, ResamplingWarning

    lugre = dict(sigma0=1e5, sigma1=300.0, sigma2=60.0, Fc=12.0, Fs=15.0, vs=0.01)
    fit = MotionFit.given(models.get("lugre"), lugre, mass=MASS, offset=OFFSET, dt=1e-3)
    plain = Fit(model=fit.model, theta=fit.theta, velocity_scaler=None, friction_scaler=None, dt=1e-3,
                n_train=0, n_samples=0, metrics={})  # the same friction without the offset
    t = np.arange(400) * 1e-3
    v = 0.02 * np.sin(2 * np.pi * 2.0 * t)
    np.testing.assert_allclose(np.asarray(fit.predict(v)), np.asarray(plain.predict(v)) + OFFSET, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(fit.predict_at(t, v)), np.asarray(plain.predict(v)) + OFFSET, rtol=1e-12)
    with pytest.warns(ResamplingWarning):
        slow = np.asarray(fit.predict(v[::2], 2e-3))
    with pytest.warns(ResamplingWarning):
        expect = np.asarray(plain.predict(v[::2], 2e-3)) + OFFSET
    np.testing.assert_allclose(slow, expect, rtol=1e-12)
    fit.save(tmp_path / "motion.npz")
    csv = tmp_path / "v.csv"
    np.savetxt(csv, np.column_stack([t, v]), delimiter=",", header="t,v", comments="")
    assert main(["predict", str(tmp_path / "motion.npz"), str(csv), "--velocity-col", "v", "--time-col", "t",
                 "--quiet", "--out", str(tmp_path / "pred.csv")]) == 0
    table = np.genfromtxt(tmp_path / "pred.csv", delimiter=",", names=True)
    np.testing.assert_allclose(table["friction_predicted"], np.asarray(fit.predict(v)), rtol=1e-6)
