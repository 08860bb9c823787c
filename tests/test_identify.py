"""jaxfric.identify end to end: parameter recovery on noise-free LuGre data, the cost and
metrics against independent recomputation, reproducibility, no recompilation for new data,
gradient refinement, and clear errors raised before any optimisation.

Budgets are tiny (a 4x4 lattice, a few dozen generations, records of 1000 samples) and
one solver configuration is reused, so the jit cache keeps the file fast.
"""

from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxfric
from jaxfric.identification import GradientRefinement, identify
from jaxfric import pipeline  # where identify's global search calls minimise
from jaxfric.identification import _api
from jaxfric._timing import Stopwatch
from jaxfric.models import Elman, LuGre
from jaxfric.rig import FrictionData

FS = 128.0
DT = 1.0 / FS
N = 1000
TRUTH = dict(sigma0=1e7, sigma1=3e3, sigma2=4e3, Fc=200.0, Fs=300.0, vs=2e-3)
# Shared by every LuGre test, so the solver compiles once per dtype.
SMALL = jaxfric.mapso_nmds(lattice_size=4, num_generations=30, sl_generations=3, nm_max_steps=1200)
SMALL_ENN = jaxfric.mapso_nmds(lattice_size=3, num_generations=10, sl_generations=2, nm_max_steps=300)


def velocity_profile(n: int = N) -> np.ndarray:
    """docs/algorithms.md §7 stand-in profile: two sines with reversals, 128 Hz."""
    t = np.arange(n) / FS
    return 0.010 * np.sin(2 * np.pi * 0.2 * t) + 0.004 * np.sin(2 * np.pi * 0.53 * t)


def lugre_friction(v, **params) -> np.ndarray:
    model = LuGre()
    theta = model.from_physical(**params)
    # dt as identify passes it (a float64 scalar, not a weakly typed Python float): in
    # float64 the data's rollout is the program identify's metrics compile
    return np.asarray(model.simulate(theta, jnp.asarray(v), np.float64(DT)))


def hysteretic_friction(v) -> np.ndarray:
    """LuGre plus a slow first-order hysteretic term: something an ENN can fit."""
    f = lugre_friction(v, **TRUTH)
    h = np.zeros_like(v)
    for k in range(1, len(v)):
        h[k] = 0.97 * h[k - 1] + 0.03 * 4e3 * v[k]
    return f + h


# ---------------------------------------------------------------------- recovery
def test_lugre_recovered_from_noise_free_lugre_data():
    """Known truth: MSE % < 0.01 % on prediction and Fc, Fs, sigma2 within 2 %."""
    with jax.enable_x64(True):
        v = velocity_profile()
        f = lugre_friction(v, **TRUTH)
        fit = identify("lugre", (v, f, DT), key=jax.random.key(0), solver=SMALL)
        for window in ("train", "valid", "all"):
            assert fit.metrics[window]["mse_percent"] < 0.01
        p = fit.params
        for name in ("Fc", "Fs", "sigma2"):
            assert abs(float(p[name]) / TRUTH[name] - 1.0) < 0.02, (name, float(p[name]))
        # The prediction reproduces the truth on data never seen in training.
        np.testing.assert_allclose(np.asarray(fit.predict(v)), f, rtol=0, atol=0.01 * np.std(f))
        assert fit.metrics["num_params"] == 6
        assert fit.settings["dtype"] == "float64"


def test_new_data_same_shapes_never_recompiles(run_cache_size):
    with jax.enable_x64(True):
        v = velocity_profile()
        f1 = lugre_friction(v, **TRUTH)
        f2 = lugre_friction(v, **{**TRUTH, "Fc": 150.0, "sigma2": 2e3})
        fit1 = identify("lugre", (v, f1, DT), key=1, solver=SMALL)
        size = run_cache_size()
        with Stopwatch() as sw:
            fit2 = identify("lugre", (v, f2, DT), key=1, solver=SMALL)
        assert sw.num_compiles == 0
        assert run_cache_size() == size
        assert fit2.timings["compile_s"] < fit2.timings["total_s"]
        # ...and the new data really were used.
        assert abs(float(fit2.params["Fc"]) - 150.0) < 3.0
        assert abs(float(fit1.params["Fc"]) - 200.0) < 3.0


def test_multi_start_nelder_mead_from_the_best_agents():
    """MAPSONMDS(num_starts=k) refines the k best agents; identify takes it as any solver."""
    with jax.enable_x64(True):
        v = velocity_profile()
        f = lugre_friction(v, **TRUTH)
        solver = jaxfric.MAPSONMDS(mapso=SMALL.mapso, nelder_mead=SMALL.nelder_mead, num_starts=3)
        fit = identify("lugre", (v, f, DT), key=0, solver=solver)
    assert fit.stages[1]["J"] <= fit.stages[0]["J"]
    assert fit.metrics["all"]["mse_percent"] < 0.01


def test_same_key_same_fit_other_key_other_run():
    with jax.enable_x64(True):
        v = velocity_profile()
        f = lugre_friction(v, **TRUTH) + 5.0 * np.sin(3.0 * v / 0.01)  # not exactly LuGre
        a = identify("lugre", (v, f, DT), key=jax.random.key(7), solver=SMALL)
        b = identify("lugre", (v, f, DT), key=jax.random.key(7), solver=SMALL)
        c = identify("lugre", (v, f, DT), key=jax.random.key(8), solver=SMALL)
    assert np.array_equal(a.theta, b.theta)
    assert a.metrics == b.metrics
    assert not np.array_equal(a.theta, c.theta)
    assert a.key_data == np.asarray(jax.random.key_data(jax.random.key(7))).tolist()


# -------------------------------------------------------- cost, metrics, scalers
@pytest.fixture(scope="module")
def enn_fit():
    v = velocity_profile()
    f = hysteretic_friction(v)
    data = FrictionData.from_arrays(v, f, DT, train_fraction=0.75)
    model = Elman(neurons=4, context_weight_bound=2.0)
    with warnings.catch_warnings():
        # A 4-neuron net on a tiny budget extrapolates poorly; the warning is expected.
        warnings.simplefilter("ignore", RuntimeWarning)
        fit = identify(model, data, key=3, solver=SMALL_ENN,
                       refine=GradientRefinement(method="bfgs", max_steps=40))
    # FrictionData stores JAX arrays (float32 here): compare against what it holds.
    return fit, np.asarray(data.velocity, np.float64), np.asarray(data.friction, np.float64)


def test_enn_scalers_cost_and_metrics_match_independent_recomputation(enn_fit):
    fit, v, f = enn_fit
    n = 750
    assert fit.n_train == n and fit.n_samples == N
    # mapminmax scalers from the training window only (§2.4)
    assert fit.velocity_scaler.lo == v[:n].min() and fit.velocity_scaler.hi == v[:n].max()
    assert fit.friction_scaler.lo == f[:n].min() and fit.friction_scaler.hi == f[:n].max()
    # Independent forward pass of the diagonal Elman network in float64 NumPy.
    p = {k: np.asarray(x, np.float64) for k, x in fit.params.items()}
    u = 2 * (v - v[:n].min()) / (v[:n].max() - v[:n].min()) - 1
    c = p["c0"].copy()
    y = np.empty(N)
    for k in range(N):
        h = np.tanh(p["w"] * u[k] + p["r"] * c + p["b"])
        y[k] = p["v"] @ h
        c = p["alpha"] * c + h
    f_hat = (y + 1) * 0.5 * (f[:n].max() - f[:n].min()) + f[:n].min()
    np.testing.assert_allclose(np.asarray(fit.predict(v)), f_hat, rtol=1e-3, atol=1e-3 * np.ptp(f))
    y_scaled = 2 * (f[:n] - f[:n].min()) / np.ptp(f[:n]) - 1
    assert fit.metrics["cost"] == pytest.approx(np.mean((y_scaled - y[:n]) ** 2), rel=1e-3)
    for window, sl in (("train", slice(0, n)), ("valid", slice(n, N)), ("all", slice(0, N))):
        e = f[sl] - f_hat[sl]
        assert fit.metrics[window]["mse_percent"] == pytest.approx(
            100 * np.mean(e**2) / np.var(f[sl]), rel=1e-2)
        assert fit.metrics[window]["max_abs"] == pytest.approx(np.max(np.abs(e)), rel=1e-2, abs=1e-3)
    assert fit.metrics["num_params"] == 24


def test_stages_never_get_worse_and_record_their_work(enn_fit):
    fit, _, _ = enn_fit
    names = [s["stage"] for s in fit.stages]
    assert names == ["mapso", "nelder_mead", "bfgs"]
    J = [s["J"] for s in fit.stages]
    assert J[0] >= J[1] >= J[2]
    assert fit.stages[0]["num_evals"] == SMALL_ENN.mapso.evaluations()
    assert 1 <= fit.stages[2]["num_steps"] <= 40
    assert fit.solution is not None and float(fit.solution.f) == pytest.approx(J[1])
    # stage-wise MSE % of the thetas we hold: Nelder-Mead's result and the refined one
    assert fit.stages[2]["mse_percent_valid"] == fit.metrics["valid"]["mse_percent"]
    assert fit.stages[1]["mse_percent_train"] >= fit.stages[2]["mse_percent_train"] * 0.999
    assert len(fit.history["f"]) >= 2 and np.all(np.diff(fit.history["f"]) <= 0)
    t = fit.timings
    assert {"compile_s", "run_s", "refine_compile_s", "refine_run_s", "total_s"} <= set(t)
    assert all(v >= 0 for v in t.values())
    # theta stays inside the box (the sine reparametrisation keeps it there)
    lo, hi = fit.model.bounds(fit.box)
    assert np.all(fit.theta >= lo) and np.all(fit.theta <= hi)


def test_gradient_refinement_lowers_the_cost_from_a_poor_start():
    """Started by Nelder-Mead alone from a fixed point, BFGS must lower J and the
    reported J must be the cost of the returned theta."""
    v = velocity_profile()
    f = hysteretic_friction(v)
    model = Elman(neurons=4, context_weight_bound=2.0)
    lo, hi = model.bounds()
    theta0 = lo + 0.3 * (hi - lo)
    nm = jaxfric.NelderMead(max_steps=20)
    # enn_fit's model, training window (750 samples) and BFGS budget: its compiled
    # gradient stage is reused
    fit = identify(model, (v, f, DT), key=0, solver=nm, theta0=theta0, train=750,
                   refine=GradientRefinement(method="bfgs", max_steps=40))
    assert [s["stage"] for s in fit.stages] == ["neldermead", "bfgs"]
    assert fit.stages[1]["improved"] and fit.stages[1]["J"] < 0.5 * fit.stages[0]["J"]
    assert fit.metrics["cost"] == fit.stages[1]["J"]


def test_tuple_and_frictiondata_splits():
    v = velocity_profile()
    f = lugre_friction(v, **TRUTH)
    rec = _api.as_record((v, f, DT))
    assert rec.n_train == 800 and rec.n_valid == 200  # paper's 80 / 20 split by default
    assert _api.as_record((v, f, DT), train=600).n_train == 600
    assert _api.as_record((v, f, DT), train=0.5).n_train == 500
    data = FrictionData.from_arrays(v, f, DT, n_train=900)
    assert _api.as_record(data).n_train == 900
    assert _api.as_record(data, train=700).n_train == 700
    assert _api.as_record(data).dt == pytest.approx(DT)


def test_named_models_get_the_documented_defaults_and_options():
    m = _api.resolve_model("elman", None)
    assert m.context_weight_bound == _api.NAMED_MODEL_DEFAULTS["elman"]["context_weight_bound"]
    assert _api.resolve_model("Elman", {"neurons": 20, "context_weight_bound": 5.0}).num_params == 120
    assert _api.resolve_model("lugre", None) == LuGre()
    enn = _api.resolve_model("elman", None)
    for solver in (_api.paper_solver(enn), _api.default_solver(enn, "paper")):
        assert solver.mapso.num_agents == 64  # docs/algorithms.md §3.5: Lsize 8 for the ENN
        assert solver.nelder_mead.max_evals == 200 * 180  # fminsearch's MaxFunEvals
    # The default pipeline's global stage: the same lattice, a short run (BFGS follows).
    fast = _api.default_solver(enn)
    assert isinstance(fast, jaxfric.MAPSO) and fast.num_agents == 64
    assert fast.num_generations == _api.FAST_GENERATIONS_BLACK_BOX
    assert _api.default_solver(LuGre()) == _api.paper_solver(LuGre())
    with pytest.raises(ValueError, match="method must be one of"):
        _api.default_solver(enn, "fast")


def test_static_map_recovered_by_levenberg_marquardt():
    """Coulomb + viscous data from the model itself: a few NM steps from the box
    centre, then LM on the residuals must find the truth."""
    from jaxfric.models import Coulomb

    v = velocity_profile(600)
    model = Coulomb()
    truth = dict(Fc=180.0, sigma2=2.5e3)
    f = np.asarray(model.simulate(model.from_physical(**truth), jnp.asarray(v)))
    lo, hi = model.bounds(model.search_box(None, v[:480], f[:480]))
    # the budgets of tests/test_identify_pipeline.py's progress test (also 600 samples):
    # its compiled stages come from the compilation cache
    fit = identify(model, (v, f, DT), key=0, solver=jaxfric.NelderMead(max_steps=3),
                   theta0=0.5 * (lo + hi), refine=GradientRefinement(method="lm", max_steps=120))
    assert fit.stages[-1]["stage"] == "lm" and fit.stages[-1]["improved"]
    assert fit.stages[-1]["J"] < 1e-3 * fit.stages[0]["J"]
    assert fit.metrics["valid"]["mse_percent"] < 1e-3
    assert float(fit.params["Fc"]) == pytest.approx(180.0, rel=1e-3)
    assert float(fit.params["sigma2"]) == pytest.approx(2.5e3, rel=1e-2)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(4, 3000), data=st.data())
def test_split_property(n, data):
    """Any count in [2, n-1] is honoured; a fraction rounds; the windows cover the record."""
    v = np.linspace(-1.0, 1.0, n)
    f = v**3 + 0.1
    count = data.draw(st.integers(2, n - 1))
    rec = _api.as_record((v, f, 0.01), train=count)
    assert rec.n_train == count and rec.n_train + rec.n_valid == n
    assert np.array_equal(rec.velocity, v) and np.array_equal(rec.friction, f)
    frac = data.draw(st.floats(0.05, 0.95))
    expect = int(round(frac * n))
    if 2 <= expect < n:
        assert _api.as_record((v, f, 0.01), train=frac).n_train == expect
    else:
        with pytest.raises(ValueError):
            _api.as_record((v, f, 0.01), train=frac)


# ------------------------------------------------------------------ bad inputs
@pytest.fixture
def no_optimiser(monkeypatch):
    """Fail the test if identify reaches the optimiser: errors must come first."""

    def forbidden(*a, **k):
        raise AssertionError("identify started optimising before rejecting the input")

    monkeypatch.setattr(pipeline, "minimise", forbidden)


def _good():
    v = velocity_profile(400)
    return v, lugre_friction(v, **TRUTH)


@pytest.mark.parametrize(
    "make, words",
    [
        (lambda v, f: dict(data=(v, f[:-1], DT)), ["same length", "400", "399"]),
        (lambda v, f: dict(data=(np.where(np.arange(400) == 7, np.nan, v), f, DT)),
         ["velocity", "non-finite", "NaN", "index 7"]),
        (lambda v, f: dict(data=(v, np.where(np.arange(400) == 9, np.inf, f), DT)),
         ["friction", "non-finite", "inf"]),
        (lambda v, f: dict(data=(v, f, DT), train=500), ["shorter than the training split"]),
        (lambda v, f: dict(data=(v, f, DT), train=400), ["validation window is empty"]),
        (lambda v, f: dict(data=FrictionData.from_arrays(v, f, DT, train_fraction=1.0)),
         ["validation window is empty"]),
        (lambda v, f: dict(data=(v, np.full(400, 3.0), DT)), ["zero variance"]),
        (lambda v, f: dict(data=(v, f, 0.0)), ["dt", "positive"]),
        (lambda v, f: dict(data=(v, f)), ["(velocity, friction, dt)"]),
        (lambda v, f: dict(data=(v, f, DT), model="elman", model_options={"neurons": 0}),
         ["neurons", ">= 1"]),
        (lambda v, f: dict(data=(v, f, DT), model="lugre", theta0=[7, 3, 3, 100, 1.5, np.nan]),
         ["theta", "non-finite"]),
        (lambda v, f: dict(data=(v, f, DT), model="lugre", theta0=[7, 3, 3, 100, 1.5]),
         ["theta", "6 parameters"]),
        (lambda v, f: dict(data=(v, f, DT), model="gms2"), ["unknown friction model", "lugre"]),
        (lambda v, f: dict(data=(v, f, DT), solver="mapso"), ["solver", "jaxfric solver"]),
        (lambda v, f: dict(data=(v, f, DT), refine="adam"), ["refine"]),
        (lambda v, f: dict(data=(v, f, DT), key=None), ["key"]),
        (lambda v, f: dict(data=(v, f, DT), key=jax.random.split(jax.random.key(0), 3)),
         ["one JAX PRNG key", "batch"]),
    ],
)
def test_bad_input_raises_value_error_before_optimising(no_optimiser, make, words):
    v, f = _good()
    kwargs = dict(model="lugre", key=0)
    kwargs.update(make(v, f))
    model = kwargs.pop("model")
    data = kwargs.pop("data")
    with pytest.raises(ValueError) as info:
        identify(model, data, **kwargs)
    for w in words:
        assert w in str(info.value), (w, str(info.value))


def test_theta0_outside_the_box_is_rejected(no_optimiser):
    v, f = _good()
    model = LuGre()
    lo, hi = model.bounds()
    with pytest.raises(ValueError, match="outside the search box"):
        identify(model, (v, f, DT), key=0, theta0=hi + 1.0, data_bounds=False)


# ------------------------------------------------------------- refinement pieces
def test_refinement_resolution():
    from jaxfric.identification._refine import as_refinement

    assert as_refinement(None, 6) is None and as_refinement(False, 180) is None
    assert as_refinement(True, 6).method == "lm"  # small physical model
    assert as_refinement("auto", 180).method == "bfgs"  # the network
    assert as_refinement("Levenberg-Marquardt", 6).method == "lm"
    custom = GradientRefinement(method="lbfgs", max_steps=7)
    assert as_refinement(custom, 6) is custom
    with pytest.raises(ValueError, match="max_steps"):
        as_refinement(GradientRefinement(max_steps=0), 6)
    with pytest.raises(ValueError, match="edge"):
        as_refinement(GradientRefinement(edge=0.7), 6)


@settings(max_examples=60, deadline=None)
@given(frac=st.floats(0.0, 1.0), lo=st.floats(-1e3, 1e3), width=st.floats(1e-3, 1e3))
def test_sine_reparametrisation_round_trip_and_stays_in_box(frac, lo, width):
    from jaxfric.identification._refine import from_box, to_box

    with jax.enable_x64(True):
        lower, upper = jnp.asarray([lo]), jnp.asarray([lo + width])
        theta = lower + frac * (upper - lower)
        edge = 1e-4
        back = to_box(from_box(theta, lower, upper, edge), lower, upper)
        inside = min(max(frac, edge), 1 - edge)  # a start on a bound is pulled inside
        np.testing.assert_allclose(np.asarray(back), np.asarray(lower + inside * (upper - lower)),
                                   rtol=1e-9, atol=1e-9 * (abs(lo) + width))
        z = jnp.linspace(-50.0, 50.0, 101)
        th = to_box(z, lower, upper)
        assert bool(jnp.all((th >= lower) & (th <= upper)))


def test_divergent_validation_warns():
    good = {"train": {"mse_percent": 0.2}, "valid": {"mse_percent": 0.3}}
    bad = {"train": {"mse_percent": 0.2}, "valid": {"mse_percent": 231.0}}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _api._warn_if_divergent(good)
        _api._warn_if_divergent({"train": good["train"], "valid": None})
    with pytest.warns(RuntimeWarning, match="validation MSE 231 %"):
        _api._warn_if_divergent(bad)


def test_real_fit_saves_loads_and_summarises(enn_fit, tmp_path):
    import json

    from jaxfric.fit import load_fit

    fit, v, _ = enn_fit
    json.dumps(fit.to_dict())  # JSON-able as is
    fit.save(tmp_path / "enn.npz")
    back = load_fit(tmp_path / "enn.npz")
    assert np.array_equal(np.asarray(back.predict(v)), np.asarray(fit.predict(v)))
    assert back.stages == json.loads(json.dumps(fit.stages))
    assert back.settings["refine"]["method"] == "bfgs"
    assert "valid" in fit.summary() and "bfgs" in fit.summary()
