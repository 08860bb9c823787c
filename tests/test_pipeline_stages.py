"""``identify`` and ``identify_motion`` run through the same stages (jaxfric.pipeline,
docs/architecture.md "Pipeline"): each shared stage is run for both problems, a static
Stribeck force balance and a short simulated drive, and its output checked against an
independent expectation (a direct ``jaxfric.minimise`` run, ``jax.random``'s keys, the
lowest finite score found by hand, hand-made baseline numbers, the training window's
velocity read off the record)."""

from __future__ import annotations

import warnings

import jax
import numpy as np
import pytest

import jaxfric as jf
from conftest import coulomb_drive
from jaxfric import models, pipeline, uncertainty
from jaxfric._warnings import BaselineWarning
from jaxfric.identification import _api as identify_api
from jaxfric.identification import stages as identify_stages
from jaxfric.motion import identify_motion
from jaxfric.motion import _api as motion_api

PROBLEMS = ("force_balance", "motion")
TINY = jf.mapso_nmds(lattice_size=3, num_generations=4, nm_max_steps=30, nm_max_evals=30)
SEED, K = 7, 2
#: where each entry point looks its shared stages up: name -> module namespace
LOOKUP = {
    "force_balance": {"resolve_keys": identify_api, "global_search": identify_stages,
                      "solver_stages": identify_stages, "history": identify_stages,
                      "key_record": identify_stages, "best_member": identify_stages,
                      "baseline_stage": identify_api, "assess_fit": identify_api},
    "motion": {name: motion_api for name in ("resolve_keys", "global_search", "solver_stages", "history",
                                             "key_record", "best_member", "baseline_stage", "assess_fit")},
}
SHARED = {name: getattr(uncertainty if name == "assess_fit" else pipeline, name)
          for name in set(LOOKUP["force_balance"]) | set(LOOKUP["motion"])}


def _stribeck_record(n=700, n_train=560, dt=1.0 / 128.0):
    """A static Stribeck curve (Fc 150 N, Fs 220 N, vs 3 mm/s, Fv 4 kN s/m) along two tones."""
    t = np.arange(n) * dt
    v = 0.01 * np.sin(2 * np.pi * 0.2 * t) + 0.004 * np.sin(2 * np.pi * 0.53 * t)
    f = (150.0 + 70.0 * np.exp(-(v / 3e-3) ** 2)) * np.tanh(v / 1e-4) + 4e3 * v
    return jf.rig.FrictionData.from_arrays(v, f + np.random.default_rng(0).normal(0, 2, n), dt, n_train=n_train)


def _drive_record(n=600, dt=1e-3):
    """A Coulomb + viscous axis (2.5 kg) driven by two tones, simulated in float64."""
    return coulomb_drive(n, dt)


def _identify(problem, data, **kw):
    if problem == "force_balance":
        return jf.identify(models.Stribeck(), data, solver=TINY, **kw)
    return identify_motion(models.Coulomb(v_eps=1e-3), data, mass=2.5, solver=TINY, **kw)


def _spied_run(problem, data, **kw):
    """``(fit, calls)``: one identification with every shared stage wrapped where its entry
    point looks it up; ``calls[name]`` lists ``(args, kwargs, result)``."""
    calls = {name: [] for name in LOOKUP[problem]}
    with pytest.MonkeyPatch.context() as mp, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a 30-step search may warn (bounds, baseline)
        for name, module in LOOKUP[problem].items():
            assert getattr(module, name) is SHARED[name], (problem, name)  # no copy: the shared function

            def spy(*args, _name=name, **kwargs):
                out = SHARED[_name](*args, **kwargs)
                calls[_name].append((args, kwargs, out))
                return out

            mp.setattr(module, name, spy)
        fit = _identify(problem, data, **kw)
    return fit, calls


@pytest.fixture(scope="module")
def runs():
    """Per problem: its record, one fit with key=SEED and one ensemble of K members, each
    with the calls of its shared stages."""
    out = {}
    for problem, data in (("force_balance", _stribeck_record()), ("motion", _drive_record())):
        out[problem] = {"data": data, "one": _spied_run(problem, data, key=SEED),
                        "many": _spied_run(problem, data, key=SEED, keys=K)}
    return out


@pytest.mark.parametrize("problem", PROBLEMS)
def test_each_entry_point_runs_every_shared_stage(runs, problem):
    _, one = runs[problem]["one"]
    _, many = runs[problem]["many"]
    for name in LOOKUP[problem]:
        assert one[name] or many[name], f"{problem} never ran the shared stage {name}"


@pytest.mark.parametrize("problem", PROBLEMS)
def test_keys_stage_gives_the_key_and_the_members_jax_random_gives(runs, problem):
    fit, calls = runs[problem]["one"]
    want = np.asarray(jax.random.key_data(jax.random.key(SEED))).ravel().tolist()
    assert fit.key_data == want and fit.seed == SEED
    keys = calls["resolve_keys"][0][2]
    assert keys.members is None and keys.seed == SEED
    ens, calls = runs[problem]["many"]
    members = next(out.members for _, _, out in calls["resolve_keys"] if out.members is not None)
    split = np.asarray(jax.random.key_data(jax.random.split(jax.random.key(SEED), K)))
    np.testing.assert_array_equal(np.asarray(jax.random.key_data(members)), split)
    assert np.asarray(ens.ensemble["keys"]).tolist() == split.reshape(K, -1).tolist()


@pytest.mark.parametrize("problem", PROBLEMS)
def test_global_search_stage_is_a_direct_minimise_run_and_the_fit_is_made_from_it(runs, problem):
    fit, calls = runs[problem]["one"]
    (args, kwargs, (sol, timings)), = calls["global_search"]
    cost, data, lower, upper, solver, keys = args
    direct = jf.minimise(cost, solver, (lower, upper), args=data, key=jax.random.key(SEED), dtype=kwargs["dtype"])
    np.testing.assert_array_equal(np.asarray(sol.value), np.asarray(direct.value))
    assert float(sol.f) == float(direct.f) and set(timings) == {"compile_s", "run_s"}
    y = fit.theta if problem == "force_balance" else np.asarray(fit.mechanics.y)
    np.testing.assert_allclose(y, np.asarray(direct.value, np.float64), rtol=1e-6)
    # the run's record: the solver's stages (global, then Nelder-Mead) and its history
    rows = fit.stages
    assert [r["stage"] for r in rows] == ["mapso", "nelder_mead"]
    assert sum(r["num_evals"] for r in rows) == int(direct.stats["num_evals"])
    assert rows[-1]["J"] == pytest.approx(float(direct.f), rel=1e-6)
    n = int(direct.history.length)
    np.testing.assert_array_equal(fit.history["f"], np.asarray(direct.history.f)[:n])
    assert np.all(np.diff(fit.history["f"]) <= 0)


@pytest.mark.parametrize("problem", PROBLEMS)
def test_selection_stage_returns_the_member_with_the_lowest_finite_score(runs, problem):
    fit, calls = runs[problem]["many"]
    scores = fit.ensemble["J"] if problem == "force_balance" else fit.ensemble["train_rmse_mm"]
    s = np.asarray(scores, np.float64)
    want = min((i for i in range(K) if np.isfinite(s[i])), key=lambda i: s[i])
    assert fit.ensemble["best"] == want
    assert [out for _, _, out in calls["best_member"]][-1] == want
    np.testing.assert_array_equal(np.asarray(fit.theta), np.asarray(fit.ensemble["theta"][want]))
    # kept members: finite and within ENSEMBLE_DROP of the best, by hand
    kept = [i for i in range(K) if np.isfinite(s[i]) and s[i] <= pipeline.ENSEMBLE_DROP * s[want]]
    assert pipeline.kept_members(scores) == kept
    if problem == "motion":
        assert fit.ensemble["kept"] == kept
    assert pipeline.best_member([np.nan, np.inf, 3.0, 2.0]) == 3
    assert pipeline.best_member([np.nan, np.nan]) == 0


@pytest.mark.parametrize("problem", PROBLEMS)
def test_baseline_stage_puts_the_baseline_beside_the_fit_and_warns_when_the_fit_is_worse(runs, problem):
    fit, calls = runs[problem]["one"]
    metric, unit = fit.problem().metric, fit.problem().metric_unit
    mine = fit.metrics["train"][metric]
    for factor, worse in ((2.0, False), (0.5, True)):
        base = fit.replace(metrics={"train": {metric: factor * mine}, "valid": {metric: 7.0}, "other": 1})
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            out = pipeline.baseline_stage(fit, base.metrics, label="reference", advice="try again")
        got = [str(w.message) for w in caught if issubclass(w.category, BaselineWarning)]
        assert out.metrics["baseline"] == {"train": {metric: factor * mine}, "valid": {metric: 7.0}}
        assert {k: v for k, v in out.metrics.items() if k != "baseline"} == {
            k: v for k, v in fit.metrics.items() if k != "baseline"}
        assert len(got) == int(worse)
        if worse:
            assert f"{mine:.4g} {unit} against {factor * mine:.4g} {unit}" in got[0] and "reference" in got[0]
    # each entry point runs it on its least-squares baseline
    (args, _, out), = calls["baseline_stage"]
    assert out.metrics["baseline"] == {w: args[1][w] for w in ("train", "valid")}
    assert out.metrics["baseline"] == fit.metrics["baseline"]


@pytest.mark.parametrize("problem", PROBLEMS)
def test_assessment_stage_reads_the_training_window_of_either_problem(runs, problem):
    fit, calls = runs[problem]["one"]
    data = runs[problem]["data"]
    (args, _, out), = calls["assess_fit"]
    assert "implausible" in out.diagnostics and "implausible" in fit.diagnostics
    # the plausibility rules and the uncertainty read the training velocity through the problem
    v = fit.problem().train_velocity(fit, args[1])
    n_train = fit.n_train
    np.testing.assert_array_equal(v, np.asarray(data.velocity)[:n_train])
