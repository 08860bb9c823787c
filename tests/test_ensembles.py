"""Ensembles (``identify(..., keys=K)``): member i against ``identify(..., key=keys[i])``.

The contract (docs/identify.md, "Ensembles"): on a CPU the global stage runs member i
as the single run with key i, to the bit, for every model and solver of the default
layout, and a physical model's whole fit is that single fit; a network's gradient
stage runs the members side by side (``GradientRefinement(batching="auto")``, the
default), so its members agree with the single fits up to the reassociation of the
batched sums (J within 1e-6 relative on a small float64 problem,
tests/test_identify_stages.py), or one after another (``batching="map"``), to the bit.
Every reference here is the single run, on its own.
"""

from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfric as jf
from jaxfric.fit import predict
from jaxfric.identification import GradientRefinement, identify, stages
from jaxfric.identification._refine import refine_impl, refine_many
from jaxfric.models import Elman, LuGre

DT = 1.0 / 128.0
KEYS = jax.random.split(jax.random.key(11), 3)


def _record(n=900, n_train=700):
    """A noisy tanh-plus-viscous record; its lengths are tests/test_identify_stages.py's, so
    programs that compare the same stages there come back from the compilation cache."""
    t = np.arange(n) * DT
    v = 0.01 * np.sin(2 * np.pi * 0.25 * t) + 0.003 * np.sin(2 * np.pi * 0.61 * t)
    f = 150.0 * np.tanh(v / 1e-3) + 3e3 * v + np.random.default_rng(3).normal(0, 2, n)
    return jf.rig.FrictionData.from_arrays(v, f, DT, n_train=n_train)


def _quiet(fn):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn()


def test_cpu_layout_maps_large_swarms_and_chains_and_batches_small_network_swarms():
    if jax.default_backend() != "cpu":
        pytest.skip("the layout rule under test is the CPU's")
    big = jf.MAPSO(lattice_size=8, num_generations=2)  # the default ENN swarm: 64 agents
    small = jf.MAPSO(lattice_size=3, num_generations=2)  # 9 agents
    assert (big.capabilities(3).population_size >= stages.CPU_BATCH_SATURATION
            > small.capabilities(3).population_size)
    assert stages.ensemble_batching(Elman(neurons=3), big) == "map"
    assert stages.ensemble_batching(Elman(neurons=3), small) == "vmap"
    assert stages.ensemble_batching(LuGre(), small) == "map"
    assert stages.ensemble_batching(LuGre(), jf.mapso_nmds(lattice_size=3, num_generations=2)) == "map"


def test_network_members_leave_the_global_stage_as_the_single_runs_to_the_bit():
    """The default ENN layout on a CPU (a swarm of at least CPU_BATCH_SATURATION agents,
    members mapped): after the global stage member i *is* the single run with key i."""
    if jax.default_backend() != "cpu":
        pytest.skip("the bit-for-bit global stage is the CPU layout's")
    model = Elman(neurons=3, context_weight_bound=1.0)
    solver = jf.MAPSO(lattice_size=6, num_generations=2)
    records = stages.records_stage(_record())
    bounds = stages.box_stage(model, records)
    obj = stages.objective_stage(model, records, jnp.float32)
    many, _ = stages.global_stage(obj, solver, bounds, stages.resolve_keys(None, KEYS),
                                  dtype=jnp.float32)
    for i in range(3):
        one, _ = stages.global_stage(obj, solver, bounds, stages.resolve_keys(KEYS[i]),
                                     dtype=jnp.float32)
        np.testing.assert_array_equal(np.asarray(many.value[i]), np.asarray(one.value))
        np.testing.assert_array_equal(np.asarray(many.f[i]), np.asarray(one.f))


def test_physical_members_are_the_single_fits_to_the_bit():
    """LuGre: members run one after another on a CPU, so θ and J of member i are those of
    the single fit with key i, and its validation MSE (from one batched prediction of
    all members) is the single fit's to float32 rounding; the fit is the best member."""
    if jax.default_backend() != "cpu":
        pytest.skip("members run one after another on a CPU only")
    solver = jf.MAPSO(lattice_size=3, num_generations=3)
    data = _record()
    fit = _quiet(lambda: identify("lugre", data, keys=KEYS, solver=solver))
    for i in range(3):
        one = _quiet(lambda i=i: identify("lugre", data, key=KEYS[i], solver=solver))
        np.testing.assert_array_equal(fit.ensemble["theta"][i], one.theta)
        assert fit.ensemble["J"][i] == one.metrics["cost"]
        assert fit.ensemble["valid_mse_percent"][i] == pytest.approx(
            one.metrics["valid"]["mse_percent"], rel=1e-5)
    best = int(np.argmin(fit.ensemble["J"]))
    assert fit.ensemble["best"] == best
    np.testing.assert_array_equal(fit.theta, fit.ensemble["theta"][best])


def test_member_validation_errors_are_each_members_own_free_run():
    """``fit.ensemble["valid_mse_percent"]`` (one batched rollout of every member) against
    each member's θ rolled out alone and scored in NumPy."""
    solver = jf.MAPSO(lattice_size=3, num_generations=3)
    data = _record()
    # float64 and the network ensemble of tests/test_identify_stages.py (its global stage)
    with jax.enable_x64(True):
        fit = _quiet(lambda: identify("elman", data, keys=KEYS, neurons=3, solver=solver, refine=False,
                                      dtype=jnp.float64))
        n = data.n_train
        f_valid = np.asarray(data.friction[n:], np.float64)
        for i, theta in enumerate(fit.ensemble["theta"]):
            y = np.asarray(predict(fit.model, jnp.asarray(theta), (fit.velocity_scaler, fit.friction_scaler),
                                   data.velocity, DT), np.float64)
            expected = 100.0 * np.mean((f_valid - y[n:]) ** 2) / np.var(f_valid)  # §6 MSE %
            assert fit.ensemble["valid_mse_percent"][i] == pytest.approx(expected, rel=1e-4)


def test_gradient_stage_map_layout_is_the_single_runs_to_the_bit():
    """``GradientRefinement(batching="map")``: each member runs the single run's program,
    so θ, J and the step count of member i are those of ``refine_impl`` from start i."""
    model = Elman(neurons=3, context_weight_bound=1.0)
    # the model, budget, record and dtype of tests/test_identify_stages.py's gradient-stage
    # test, whose single refine_impl program is this one's reference
    settings = GradientRefinement(max_steps=15, batching="map")
    with jax.enable_x64(True):
        records = stages.records_stage(_record())
        bounds = stages.box_stage(model, records)
        obj = stages.objective_stage(model, records, jnp.float64)
        rng = np.random.default_rng(4)
        starts = jnp.asarray(bounds.lower + (bounds.upper - bounds.lower) * rng.random((3, model.num_params)))
        lo, hi = jnp.asarray(bounds.lower), jnp.asarray(bounds.upper)
        many = refine_many(settings, obj.cost, starts, lo, hi, obj.data)
        for i in range(3):
            one = refine_impl(settings, obj.cost, starts[i], lo, hi, obj.data)
            np.testing.assert_array_equal(np.asarray(many.theta[i]), np.asarray(one.theta))
            np.testing.assert_array_equal(np.asarray(many.f[i]), np.asarray(one.f))
            assert int(many.num_steps[i]) == int(one.num_steps)
            assert float(one.f) < float(jax.jit(obj.cost)(starts[i], obj.data))  # it polished (one program)


def test_gradient_stage_batching_is_checked():
    with pytest.raises(ValueError, match="batching must be one of"):
        GradientRefinement(batching="pmap").check()


def test_members_valid_mse_pools_the_validation_windows_as_the_metrics_table():
    """The vectorised validation MSE of K members against ``record_metrics`` (the §6
    table, one member at a time) on two training records and a validation record, and a
    member whose free run is not finite."""
    rng = np.random.default_rng(5)
    recs = [_record(n=300 + 50 * i, n_train=200) for i in range(2)]
    records = stages.records_stage(train=recs, valid=_record(n=260, n_train=200))
    assert [r.n_train for r in records.records] == [300, 350, 0]  # used whole
    preds = [np.asarray(r.friction)[None, :] + rng.normal(0, 5 + i, (4, r.n_samples))
             for i, r in enumerate(records.records)]
    preds[0][3, 7] = np.nan
    got = stages.members_valid_mse(preds, records)
    for i in range(3):
        expected = stages.record_metrics([p[i] for p in preds], records)["valid"]["mse_percent"]
        assert got[i] == pytest.approx(expected, rel=1e-12)
    assert got[3] is None


def test_refine_batching_maps_physical_models_on_the_cpu_and_batches_networks():
    auto = GradientRefinement(method="lm")
    assert auto.batching == "auto"
    assert stages.refine_batching(Elman(neurons=3), auto).batching == "vmap"
    cpu = jax.default_backend() == "cpu"
    assert stages.refine_batching(LuGre(), auto).batching == ("map" if cpu else "vmap")
    chosen = GradientRefinement(batching="vmap")
    assert stages.refine_batching(LuGre(), chosen) is chosen  # an explicit choice wins
