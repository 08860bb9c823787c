"""Several records, ensembles, parameters on a bound and honest prediction (issue 17.4-17.7, 20.6).

References are independent of the code under test: per-record metrics and the pooled
cost are recomputed with NumPy from each record's own rollout; the ensemble's members
are compared with separate ``identify`` calls; resampled predictions are compared with
a prediction on the fit's own grid.
"""

from __future__ import annotations

import json
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfric as jf
from jaxfric.fit import ExtrapolationWarning, Fit, ResamplingWarning, load_fit
from jaxfric.identification import BoundWarning, identify
from jaxfric.identification._pooled import PooledOutputErrorCost, pooled_cost_data
from jaxfric.identification._data import as_records
from jaxfric.metrics import friction_metrics
from jaxfric.plot import predict_on
from jaxfric.models import Coulomb, Cylinder, Elman, LuGre, Scaler

DT = 0.01
TINY = jf.mapso_nmds(lattice_size=3, num_generations=8, nm_max_steps=150)
COULOMB_TRUTH = dict(Fc=40.0, sigma2=800.0)


def velocity(phase: float, n: int = 300, dt: float = DT) -> np.ndarray:
    t = np.arange(n) * dt
    return 0.02 * np.sin(2 * np.pi * 0.5 * t + phase) + 0.005 * np.sin(2 * np.pi * 1.3 * t)


def coulomb_record(phase: float, n: int = 300):
    v = velocity(phase, n)
    model = Coulomb()
    f = np.asarray(model.simulate(model.from_physical(**COULOMB_TRUTH), jnp.asarray(v)), np.float64)
    return v, f, DT


def lugre_record(phase: float, n: int = 300):
    model = LuGre()
    v = velocity(phase, n)
    theta = model.from_physical(sigma0=1e5, sigma1=300.0, sigma2=800.0, Fc=40.0, Fs=60.0, vs=3e-3)
    return v, np.asarray(model.simulate(theta, jnp.asarray(v), DT), np.float64), DT


def cylinder_record(phase: float, n: int = 300, name: str = "", truth=None):
    """Pressure-dependent friction without breakaway, written out in NumPy:
    F = tanh(v / v_eps)·(F_pr + f_cfr·(p1 + p2)) + sigma2·v (docs/algorithms.md §13.1)."""
    truth = truth or CYLINDER_TRUTH
    v = velocity(phase, n)
    t = np.arange(n) * DT
    p1 = 3e5 + 1e5 * np.sin(2 * np.pi * 0.3 * t + phase)
    p2 = 2e5 + 5e4 * np.cos(2 * np.pi * 0.7 * t + 2 * phase)
    f = (np.tanh(v / Cylinder().v_eps) * (truth["F_pr"] + truth["f_cfr"] * (p1 + p2))
         + truth["sigma2"] * v)
    return jf.FrictionData.from_arrays(v, f, DT, p1=p1, p2=p2, name=name)


CYLINDER_TRUTH = dict(F_pr=20.0, f_cfr=4e-5, sigma2=800.0)


# ------------------------------------------------------------------ several records
def test_pooled_cost_gives_each_record_its_own_pressures():
    """Whole records keep their chamber pressures, and the pooled cost rolls each record
    out with its own (NumPy reference of the module docstring's J)."""
    recs = [cylinder_record(0.0, 200), cylinder_record(1.0, 300)]
    model = Cylinder(breakaway=False)
    guess = dict(F_pr=25.0, f_cfr=3e-5, sigma2=700.0)
    with jax.enable_x64(True):
        theta = jnp.asarray(model.from_physical(**guess))
        got = float(PooledOutputErrorCost(model)(
            theta, pooled_cost_data(model, as_records(train=recs), (None, None), jnp.float64)))
    pred = [cylinder_record(0.0, 200, truth=guess), cylinder_record(1.0, 300, truth=guess)]
    errs = np.concatenate([r.friction - q.friction for r, q in zip(recs, pred)])
    f_all = np.concatenate([r.friction for r in recs])
    assert got == pytest.approx(np.sum(errs**2) / f_all.size / np.var(f_all), rel=1e-9)


def test_identify_a_pressure_model_on_several_records():
    """train=[...]/valid=... reach a model with input channels (Cylinder: p1, p2): the
    parameters come back, and every record is predicted from its own pressures."""
    train = {"a": cylinder_record(0.0, 300), "b": cylinder_record(1.0, 250)}
    held_out = cylinder_record(2.0, 200)
    with jax.enable_x64(True):
        fit = identify(Cylinder(breakaway=False), train=train, valid={"c": held_out}, key=0,
                       solver=TINY, dtype=jnp.float64)
    for name, value in CYLINDER_TRUTH.items():
        assert float(fit.params[name]) == pytest.approx(value, rel=0.02), name
    recs = fit.metrics["records"]
    assert [r["name"] for r in recs] == ["a", "b", "c"]
    # predicted in float64, as the fit's metrics were: the rollouts identify compiled are reused
    with jax.enable_x64(True):
        for r, rec in zip(recs, [*train.values(), held_out]):
            own = fit.predict(rec.velocity, inputs=np.stack([rec.p1, rec.p2]))
            expect = friction_metrics(rec.friction, np.asarray(own, np.float64))
            assert r["all"]["mse_percent"] == pytest.approx(expect["mse_percent"], rel=1e-6, abs=1e-9)
        # figures and reports predict with the record's own pressures too
        np.testing.assert_allclose(predict_on(fit, held_out),
                                   np.asarray(fit.predict(held_out.velocity,
                                                          inputs=np.stack([held_out.p1, held_out.p2]))))
    no_pressure = jf.FrictionData.from_arrays(held_out.velocity, held_out.friction, DT)
    with pytest.raises(ValueError, match=r"Cylinder needs the measured channel\(s\) p1, p2"):
        predict_on(fit, no_pressure)
    with pytest.raises(ValueError, match=r"^c: Cylinder needs the measured channel\(s\) p1, p2"):
        identify(Cylinder(breakaway=False), train=train, valid={"c": no_pressure}, key=0,
                 solver=TINY)


def test_pooled_cost_rolls_each_record_out_from_its_own_state():
    """J pools squared errors over records, each rolled out alone (no state across)."""
    recs = [lugre_record(0.0, 200), lugre_record(1.0, 300)]
    model = LuGre()
    rs = as_records(train=recs)
    with jax.enable_x64(True):
        theta = jnp.asarray(model.from_physical(sigma0=2e5, sigma1=200.0, sigma2=700.0, Fc=35.0,
                                                Fs=55.0, vs=2e-3))
        cost = PooledOutputErrorCost(model)
        got = float(cost(theta, pooled_cost_data(model, rs, (None, None), jnp.float64)))
        # dt as the cost holds it (a float64 scalar, not a weakly typed Python float): the
        # rollouts the cost compiled are reused
        errs = [f - np.asarray(model.simulate(theta, jnp.asarray(v), np.float64(DT))) for v, f, _ in recs]
        f_all = np.concatenate([r[1] for r in recs])
        expect = np.sum(np.concatenate(errs) ** 2) / f_all.size / np.var(f_all)
        # the same records glued together would carry the bristle state across the seam
        glued = f_all - np.asarray(model.simulate(theta, jnp.asarray(np.concatenate([r[0] for r in recs])), DT))
        r = cost.residuals(theta, pooled_cost_data(model, rs, (None, None), jnp.float64))
        r2 = float(jnp.sum(r**2))
    assert got == pytest.approx(expect, rel=1e-10)
    assert r2 == pytest.approx(expect, rel=1e-10)
    assert not np.allclose(np.concatenate(errs), glued)


@pytest.mark.slow
def test_identify_on_several_records_reports_metrics_per_record():
    train = [coulomb_record(0.0), coulomb_record(1.0, 250)]
    valid = {"held-out": coulomb_record(2.0, 200)}
    with jax.enable_x64(True):
        fit = identify("coulomb", train=train, valid=valid, key=0, solver=TINY, dtype=jnp.float64)
    # noise-free data of the model itself: known parameters recovered within 2 %
    assert float(fit.params["Fc"]) == pytest.approx(40.0, rel=0.02)
    assert float(fit.params["sigma2"]) == pytest.approx(800.0, rel=0.02)
    recs = fit.metrics["records"]
    assert [r["name"] for r in recs] == ["train[0]", "train[1]", "held-out"]
    assert [r["role"] for r in recs] == ["train", "train", "valid"]
    all_records = [*train, valid["held-out"]]
    # predicted in float64, as the fit's metrics were: the rollouts identify compiled are reused
    with jax.enable_x64(True):
        for r, (v, f, _) in zip(recs, all_records):
            expect = friction_metrics(f, np.asarray(fit.predict(v), np.float64))
            assert r["all"]["mse_percent"] == pytest.approx(expect["mse_percent"], rel=1e-6, abs=1e-9)
        pooled_valid = friction_metrics(valid["held-out"][1], np.asarray(fit.predict(valid["held-out"][0])))
    assert fit.metrics["valid"]["mse_percent"] == pytest.approx(pooled_valid["mse_percent"], rel=1e-6, abs=1e-9)
    assert fit.n_train == 550 and fit.n_samples == 750
    assert "held-out" in fit.summary() and "train[1]" in fit.summary()
    d = json.loads(json.dumps(fit.to_dict()))
    assert [r["name"] for r in d["metrics"]["records"]] == ["train[0]", "train[1]", "held-out"]


def test_records_with_different_sample_times_are_refused():
    v, f, _ = coulomb_record(0.0)
    with pytest.raises(ValueError, match="different sample times"):
        as_records(train=[(v, f, DT)], valid=[(v, f, 2 * DT)])
    with pytest.raises(ValueError, match="valid= needs the training records"):
        as_records((v, f, DT), valid=(v, f, DT))


def test_a_validation_window_too_short_to_mean_anything_is_refused():
    v, f, _ = coulomb_record(0.0, 2000)
    with pytest.raises(ValueError, match=r"validation window has 2 sample\(s\)"):
        identify("coulomb", (v, f, DT), key=0, train=0.999)


# ------------------------------------------------------------------------ ensemble
@pytest.mark.slow
def test_ensemble_members_equal_single_runs_and_the_band_holds_the_best():
    data = coulomb_record(0.0)
    noisy = (data[0], data[1] + 3.0 * np.random.default_rng(0).standard_normal(data[1].size), DT)
    keys = jax.random.split(jax.random.key(5), 3)
    # float64: the vmapped runs equal the single ones up to reassociation (docs of minimise_many)
    with jax.enable_x64(True):
        fit = identify("coulomb", noisy, keys=keys, solver=TINY)
        singles = [identify("coulomb", noisy, key=keys[i], solver=TINY) for i in range(3)]
    e = fit.ensemble
    assert len(e["J"]) == 3 and e["best"] == int(np.argmin(e["J"]))
    for i, single in enumerate(singles):
        # float64: a vmapped member rounds its sums in another order than the single run,
        # and the optimiser's path carries that forward (5e-9 seen since 0.8.0's float64
        # random numbers; 0.7.0's stream happened to stay under 1e-9)
        np.testing.assert_allclose(e["theta"][i], single.theta, rtol=1e-8, atol=1e-9)
        assert e["J"][i] == pytest.approx(float(single.metrics["cost"]), rel=1e-8)
    np.testing.assert_array_equal(fit.theta, e["theta"][e["best"]])
    lo, hi = fit.predict_band(noisy[0])
    best = np.asarray(fit.predict(noisy[0]), np.float64)
    assert np.all(lo <= best + 1e-9) and np.all(best <= hi + 1e-9)
    assert set(e["spread"]) == {"Fc", "sigma2"}
    assert e["spread"]["Fc"]["min"] <= e["params"]["Fc"][e["best"]] <= e["spread"]["Fc"]["max"]
    assert e["params"]["Fc"][e["best"]] == pytest.approx(float(fit.params["Fc"]), rel=1e-6)
    assert "ensemble: 3 members" in fit.summary()


def test_friction_with_a_crossed_sign_convention_is_named_before_the_fit():
    """Friction that mostly pushes along the motion (here: the Coulomb record negated, as a
    force balance with the load cell's sign crossed gives) is named in a
    FrictionSignWarning before the search; a correct record, also one whose offset exceeds
    its Coulomb level, is not."""
    from jaxfric.identification import FrictionSignWarning, friction_sign

    v, f, dt = coulomb_record(0.0)
    vt, ft = v[:240], f[:240]  # the training part, the leading 80 %
    moving = np.abs(vt) > 0.1 * np.max(np.abs(vt))
    level = -np.mean(np.abs(ft[moving]))  # f = Fc sign(v) + sigma2 v, negated
    # float64: the single search of test_ensemble_members_equal_single_runs_and_the_band_holds_the_best
    # (the same record length and solver) is reused instead of compiled again in float32
    with jax.enable_x64(True):
        with pytest.warns(FrictionSignWarning, match=rf"mostly pushes along the motion .*: {level:.4g}\).*negate"):
            identify("coulomb", (v, -f, dt), key=0, solver=TINY)
        with warnings.catch_warnings():
            warnings.simplefilter("error", FrictionSignWarning)
            identify("coulomb", (v, f, dt), key=0, solver=TINY)
    assert friction_sign(v, f + 1.5 * np.max(np.abs(f))) is None  # an offset, both directions
    assert friction_sign(np.zeros(5), np.ones(5)) is None  # no motion: nothing to say
    assert "mostly pushes along" in friction_sign(v, -f)


def test_ensemble_survives_save_and_load(tmp_path):
    # three members in float64 on a 300-sample record: the search compiled by
    # test_ensemble_members_equal_single_runs_and_the_band_holds_the_best is reused
    with jax.enable_x64(True):
        fit = identify("coulomb", coulomb_record(0.0), keys=3, key=1, solver=TINY)
        fit.save(tmp_path / "f.npz")
        back = load_fit(tmp_path / "f.npz")
        np.testing.assert_array_equal(back.ensemble["theta"], fit.ensemble["theta"])
        v = velocity(0.3)
        np.testing.assert_array_equal(np.asarray(back.predict_band(v)), np.asarray(fit.predict_band(v)))


# --------------------------------------------------------------- bounds, options
def test_a_parameter_stopped_by_its_range_is_flagged():
    data = coulomb_record(0.0)
    # float64, as the ensemble tests above: their compiled single search is reused
    with jax.enable_x64(True), pytest.warns(BoundWarning, match=r"Fc = 20 ended on the upper bound.*box=\{'Fc'"):
        fit = identify("coulomb", data, key=0, solver=TINY, box={"Fc": (1.0, 20.0)})
    (flag,) = fit.diagnostics["on_bound"]
    assert flag["name"] == "Fc" and flag["side"] == "upper" and flag["box_key"] == "Fc"
    assert fit.box["Fc"] == (1.0, 20.0)
    assert flag["range"] == [1.0, 20.0] and flag["value"] == pytest.approx(20.0)
    assert "Fc=20 [on bound]" in fit.summary() and "widen" in fit.summary()
    assert json.loads(json.dumps(fit.to_dict()))["diagnostics"]["on_bound"][0]["name"] == "Fc"
    with warnings.catch_warnings():
        warnings.simplefilter("error", BoundWarning)
        with jax.enable_x64(True):
            ok = identify("coulomb", data, key=0, solver=TINY)  # the data-centred box holds the truth
    assert ok.diagnostics["on_bound"] == []


def test_model_options_as_keywords_reach_the_model(monkeypatch):
    """``identify("elman", ..., neurons=2)`` builds a 2-neuron network (seen by the optimiser)."""
    from jaxfric import pipeline  # where identify's global search calls minimise

    seen = {}

    class Stop(Exception):
        pass

    def capture(cost, solver, bounds, **kwargs):
        seen["model"] = cost.model
        raise Stop

    monkeypatch.setattr(pipeline, "minimise", capture)
    v, f, _ = coulomb_record(0.0, 200)
    with pytest.raises(Stop):
        identify("elman", (v, f, DT), key=0, neurons=2)
    assert isinstance(seen["model"], Elman) and seen["model"].neurons == 2
    with pytest.raises(ValueError, match="given twice"):
        identify("elman", (v, f, DT), key=0, neurons=2, model_options={"neurons": 3})


# ---------------------------------------------------------------------- predict
def _lugre_fit():
    model = LuGre()
    theta = np.asarray(model.from_physical(sigma0=1e5, sigma1=300.0, sigma2=800.0, Fc=40.0,
                                           Fs=60.0, vs=3e-3), np.float32)
    return Fit(model=model, theta=theta, velocity_scaler=None, friction_scaler=None, dt=DT,
               n_train=200, n_samples=300, metrics={}, velocity_range=(-0.03, 0.03),
               box={"Fc": (5.0, 100.0)})


def _enn_fit():
    model = Elman(neurons=4, context_weight_bound=0.5)
    lo, hi = model.bounds()
    theta = (lo + np.random.default_rng(1).uniform(size=lo.shape) * (hi - lo)).astype(np.float32)
    v = velocity(0.0)
    return Fit(model=model, theta=theta, velocity_scaler=Scaler.fit(np.array([-0.03, 0.03])),
               friction_scaler=Scaler.fit(np.array([-60.0, 60.0])), dt=DT, n_train=200,
               n_samples=300, metrics={})


@pytest.mark.parametrize("make", [_lugre_fit, _enn_fit], ids=["lugre", "elman"])
def test_a_finer_record_is_resampled_onto_the_fits_grid(make):
    """On a record 4x finer, every 4th sample lies on the fit's grid: the prediction there
    equals the prediction on the fit's own sampling of the same signal."""
    fit = make()
    t_fine = np.arange(1200) * (DT / 4)
    v_fine = 0.02 * np.sin(2 * np.pi * 0.5 * t_fine)
    reference = np.asarray(fit.predict(v_fine[::4]), np.float64)  # at the fit's dt
    with pytest.warns(ResamplingWarning, match="differs from the fit's"):
        fine = np.asarray(fit.predict(v_fine, dt=DT / 4), np.float64)
    assert fine.shape == v_fine.shape  # one output row per input row
    np.testing.assert_allclose(fine[::4], reference, rtol=1e-5, atol=1e-4)


@pytest.mark.parametrize("make", [_lugre_fit, _enn_fit], ids=["lugre", "elman"])
def test_a_coarser_record_is_interpolated_and_close_to_the_fine_prediction(make):
    fit = make()
    t = np.arange(600) * DT
    v = 0.02 * np.sin(2 * np.pi * 0.3 * t)
    reference = np.asarray(fit.predict(v), np.float64)
    with pytest.warns(ResamplingWarning):
        coarse = np.asarray(fit.predict(v[::2], dt=2 * DT), np.float64)
    assert coarse.shape == (300,)
    scale = np.ptp(reference)
    assert np.max(np.abs(coarse - reference[::2])) < 0.05 * scale


def test_irregular_time_stamps_give_one_output_per_input():
    fit = _lugre_fit()
    t = np.cumsum(np.r_[0.0, np.random.default_rng(0).uniform(0.5, 1.5, 199)]) * DT
    v = 0.02 * np.sin(2 * np.pi * 0.5 * t)
    with pytest.warns(ResamplingWarning, match="irregular"):
        y = np.asarray(fit.predict_at(t, v))
    assert y.shape == (200,) and np.all(np.isfinite(y))


def test_static_maps_ignore_dt_without_resampling():
    model = Coulomb()
    fit = Fit(model=model, theta=np.asarray(model.from_physical(**COULOMB_TRUTH), np.float32),
              velocity_scaler=None, friction_scaler=None, dt=DT, n_train=10, n_samples=20, metrics={})
    v = velocity(0.0, 50)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        np.testing.assert_array_equal(np.asarray(fit.predict(v, dt=3 * DT)), np.asarray(fit.predict(v)))


def test_extrapolation_beyond_the_training_velocity_is_warned():
    fit = _lugre_fit()
    with pytest.warns(ExtrapolationWarning, match="outside the training range"):
        fit.predict(np.linspace(-0.05, 0.05, 100))
    with warnings.catch_warnings():
        warnings.simplefilter("error", ExtrapolationWarning)
        fit.predict(np.linspace(-0.02, 0.02, 100))


def test_unidentifiable_parameters_come_from_the_models_hook(monkeypatch):
    """The models' ``unidentifiable(velocity)`` answer lands in fit.diagnostics and the summary."""
    from jaxfric.identification import _diagnostics

    calls = []

    def hook(self, velocity):
        calls.append(np.asarray(velocity).size)
        return ("sigma2: one sliding speed per direction",)

    monkeypatch.setattr(Coulomb, "unidentifiable", hook, raising=False)
    assert _diagnostics.unidentifiable(Coulomb(), np.ones(5)) == ("sigma2: one sliding speed per direction",)
    # the records, solver and dtype of test_identify_on_several_records_reports_metrics_per_record:
    # its compiled search is reused
    with jax.enable_x64(True):
        fit = identify("coulomb", train=[coulomb_record(0.0), coulomb_record(1.0, 250)], key=0, solver=TINY,
                       dtype=jnp.float64)
    assert calls[-1] == 550  # the training samples of both records
    assert fit.diagnostics["unidentifiable"] == ["sigma2: one sliding speed per direction"]
    # the summary groups the parameters by reason: "!   name: reason" under one "!" heading
    assert "!   sigma2: one sliding speed per direction" in fit.summary()
    assert "Fit(Coulomb, 2 params)" == repr(fit)  # no validation part: no valid MSE
