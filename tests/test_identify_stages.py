"""The stages of ``identify`` (jaxfric.identification.stages), each run alone.

records → box → objective → global stage → gradient stage → Fit: every stage is
checked against an independent reference (NumPy's cost, a direct ``minimise`` or
``refine_impl`` call, the single-network adjoint), and an ensemble's members against
the single runs with the same keys.
"""

from __future__ import annotations

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfric as jf
from jaxfric.identification import GradientRefinement, FrictionSignWarning, identify, stages
from jaxfric.identification._objective import (
    CostData,
    OutputErrorCost,
    _elman_value_and_grad,
    _elman_value_and_grad_batch,
)
from jaxfric.identification._refine import refine_impl, refine_many
from jaxfric.models import Coulomb, Elman, LuGre

DT = 1.0 / 128.0
TINY_NM = jf.mapso_nmds(lattice_size=3, num_generations=4, nm_max_steps=30, nm_max_evals=30)


def _record(n=900, n_train=700, seed=0, sign=1.0):
    t = np.arange(n) * DT
    v = 0.01 * np.sin(2 * np.pi * 0.2 * t) + 0.004 * np.sin(2 * np.pi * 0.53 * t + seed)
    f = 200.0 * np.tanh(v / 1e-3) + 4e3 * v + np.random.default_rng(seed).normal(0, 3, n)
    return jf.rig.FrictionData.from_arrays(v, sign * f, DT, n_train=n_train)


def _prepared(model, data=None, head=None, dtype=jnp.float32):
    records = stages.records_stage(data if data is not None else _record())
    bounds = stages.box_stage(model, records)
    return records, bounds, stages.objective_stage(model, records, dtype, head)


# ------------------------------------------------------------------ records
def test_records_stage_splits_and_names_a_crossed_sign():
    records = stages.records_stage(_record(n=900, n_train=700))
    assert records.single is not None and records.n_train == 700 and records.n_samples == 900
    with pytest.warns(FrictionSignWarning):
        stages.records_stage(_record(sign=-1.0))
    with pytest.raises(ValueError):
        stages.records_stage(_record(n=900, n_train=899))  # no validation window left


# ---------------------------------------------------------------------- box
def test_box_stage_completes_a_partial_box_from_the_data():
    records = stages.records_stage(_record())
    model = LuGre()
    full = stages.box_stage(model, records)
    partial = stages.box_stage(model, records, {"vs": (1e-4, 0.5)})
    i = model.param_names.index("log10_vs")
    lo, hi = model.bounds(partial.box)
    np.testing.assert_array_equal(partial.lower, lo)
    np.testing.assert_array_equal(partial.upper, hi)
    # the given entry wins; every other entry is the data-centred one
    assert (partial.lower[i], partial.upper[i]) != (full.lower[i], full.upper[i])
    rest = [j for j in range(model.num_params) if j != i]
    np.testing.assert_array_equal(partial.lower[rest], full.lower[rest])
    assert stages.box_stage(Elman(neurons=3), records).box is None
    with pytest.raises(ValueError, match="sigma0"):
        stages.box_stage(Coulomb(), records, {"sigma0": (1.0, 2.0)})


# ---------------------------------------------------------------- objective
def test_objective_stage_is_the_variance_normalised_mse_and_cuts_the_head():
    data = _record()
    model = Coulomb()
    with jax.enable_x64(True):
        records, bounds, obj = _prepared(model, data, head=300, dtype=jnp.float64)
        theta = 0.5 * (bounds.lower + bounds.upper)
        f = data.friction[: data.n_train]
        y = np.asarray(model.simulate(jnp.asarray(theta), jnp.asarray(data.velocity[: data.n_train]), DT))
        expected = np.mean((f - y) ** 2) / np.var(f)
        assert float(obj.cost(jnp.asarray(theta), obj.data)) == pytest.approx(expected, rel=1e-12)
    assert obj.data.y.shape[0] == data.n_train and obj.data_global.y.shape[0] == 300
    assert stages.objective_stage(model, records, jnp.float32).data_global.y.shape[0] == data.n_train


# ------------------------------------------------------------- global stage
def test_global_stage_is_one_minimise_call_and_members_are_the_single_runs():
    model = Coulomb()
    records, bounds, obj = _prepared(model)
    keys = jax.random.split(jax.random.key(3), 3)
    direct = jf.minimise(obj.cost, TINY_NM, (bounds.lower, bounds.upper), args=obj.data_global,
                         key=keys[1], dtype=jnp.float32)
    one, timings = stages.global_stage(obj, TINY_NM, bounds, stages.resolve_keys(keys[1]),
                                       dtype=jnp.float32)
    assert set(timings) == {"compile_s", "run_s"}
    np.testing.assert_array_equal(one.value, direct.value)
    many, _ = stages.global_stage(obj, TINY_NM, bounds, stages.resolve_keys(None, keys),
                                  dtype=jnp.float32)
    assert many.value.shape == (3, model.num_params)
    # On the CPU a chain with Nelder–Mead runs its members one after another: to the bit.
    assert stages.ensemble_batching(model, TINY_NM) == "map"
    np.testing.assert_array_equal(many.value[1], direct.value)
    np.testing.assert_array_equal(many.f[1], direct.f)


def test_ensemble_batching_vmaps_only_swarms_on_networks():
    swarm = jf.MAPSO(lattice_size=3, num_generations=2)
    assert stages.ensemble_batching(Elman(neurons=3), swarm) == "vmap"
    assert stages.ensemble_batching(Elman(neurons=3), TINY_NM) == "map"
    assert stages.ensemble_batching(LuGre(), swarm) == "map"


# ----------------------------------------------------------- gradient stage
def test_gradient_stage_polishes_and_its_members_follow_the_single_runs():
    model = Elman(neurons=3, context_weight_bound=1.0)
    settings = GradientRefinement(max_steps=15)
    with jax.enable_x64(True):
        records, bounds, obj = _prepared(model, dtype=jnp.float64)
        assert stages.gradient_stage(None, obj, None, bounds, jnp.float64) == (None, {})
        rng = np.random.default_rng(0)
        starts = jnp.asarray(bounds.lower + (bounds.upper - bounds.lower) * rng.random((3, model.num_params)))
        lo, hi = jnp.asarray(bounds.lower), jnp.asarray(bounds.upper)
        singles = [refine_impl(settings, obj.cost, s, lo, hi, obj.data) for s in starts]
        # XLA's own options, as refine_impl's default: the same program to the bit
        one, timings = stages.gradient_stage(settings, obj, starts[0], bounds, jnp.float64,
                                             compiler_options=None)
        assert set(timings) == {"refine_compile_s", "refine_run_s"}
        np.testing.assert_array_equal(one.theta, singles[0].theta)
        assert float(one.f) < float(jax.jit(obj.cost)(starts[0], obj.data))  # it polished (one program)
        # 'fast-compile' (LLVM at level 0) rounds differently, the same algorithm: the same point
        fast, _ = stages.gradient_stage(settings, obj, starts[0], bounds, jnp.float64,
                                        compiler_options="fast-compile")
        np.testing.assert_allclose(fast.theta, one.theta, rtol=1e-7, atol=1e-9)
        # an ensemble of one runs the single run's program: to the bit
        alone, _ = stages.gradient_stage(settings, obj, starts[:1], bounds, jnp.float64,
                                         ensemble=True, compiler_options=None)
        np.testing.assert_array_equal(alone.theta[0], singles[0].theta)
        many, _ = stages.gradient_stage(settings, obj, starts, bounds, jnp.float64, ensemble=True)
        for i, s in enumerate(singles):
            assert int(many.num_steps[i]) == int(s.num_steps)
            np.testing.assert_allclose(many.theta[i], s.theta, rtol=1e-8, atol=1e-10)
            np.testing.assert_allclose(many.f[i], s.f, rtol=1e-8)


def _three_networks_on_a_record(model, rng):
    """A 301-sample record (not a multiple of the 64-sample block) and three random θ in
    the model's box; call inside ``jax.enable_x64(True)``."""
    lo, hi = model.bounds()
    data = CostData(u=jnp.asarray(np.sin(np.linspace(0, 13, 301))),
                    y=jnp.asarray(0.3 * rng.standard_normal(301)), dt=jnp.asarray(DT),
                    inv_norm=jnp.asarray(1.7))
    return data, jnp.asarray(lo + (hi - lo) * rng.random((3, lo.size)))


def _blocked_batch(model):
    """The CPU's blocked batch (64-sample blocks) of ``model``, jitted: one program."""
    return jax.jit(lambda thetas, data: _elman_value_and_grad_batch(model, thetas, data, block=64))


def test_batched_adjoint_equals_the_single_network_adjoint():
    """Value, θ-gradient and y-gradient of K networks at once (time in blocks, the
    record not a multiple of the block) against the single-network path."""
    rng = np.random.default_rng(1)
    for output_bias in (True, False):
        model = Elman(neurons=4, context_weight_bound=1.0, output_bias=output_bias)
        with jax.enable_x64(True):
            data, thetas = _three_networks_on_a_record(model, rng)
            f, grad, g_y = _blocked_batch(model)(thetas, data)
            # Each path jitted as one program, as the stages run it (run op by op, the
            # loops and their small operations compiled ~100 programs per test).
            single = jax.jit(_elman_value_and_grad(model))
            for i in range(3):
                f1, grad1, g_y1 = single(thetas[i], data)
                assert float(f[i]) == pytest.approx(float(f1), rel=1e-13)
                np.testing.assert_allclose(grad[i], grad1, rtol=1e-10,
                                           atol=1e-12 * float(jnp.abs(grad1).max()))
                np.testing.assert_allclose(g_y[i], g_y1, rtol=1e-13)
            # vmap over θ takes the batched path and gives the same numbers
            vf, vgrad, _ = jax.jit(jax.vmap(_elman_value_and_grad(model), (0, None)))(thetas, data)
            np.testing.assert_allclose(vgrad, grad, rtol=1e-12, atol=1e-14)
            # and the cost's gradient under vmap is that gradient
            cost_grad = jax.jit(jax.vmap(jax.grad(OutputErrorCost(model)), (0, None)))
            np.testing.assert_allclose(cost_grad(thetas, data), grad, rtol=1e-10, atol=1e-14)


def test_batched_adjoint_off_the_cpu_equals_the_blocked_batch(monkeypatch):
    """Off the CPU, vmap over θ batches the single network's loops (its adjoint a parallel
    prefix scan): the program a GPU runs, traced here with every platform choice taking
    its accelerator branch, against the CPU's blocked batch."""
    rng = np.random.default_rng(2)
    model = Elman(neurons=4, context_weight_bound=1.0)
    with jax.enable_x64(True):
        data, thetas = _three_networks_on_a_record(model, rng)
        f, grad, g_y = _blocked_batch(model)(thetas, data)
        monkeypatch.setattr(jax.lax, "platform_dependent",
                            lambda *args, default, **branches: default(*args))
        # traced (with the patch in force) and compiled as one program, as a GPU runs it
        vf, vgrad, vg_y = jax.jit(jax.vmap(_elman_value_and_grad(model), (0, None)))(thetas, data)
    np.testing.assert_allclose(vf, f, rtol=1e-12)
    np.testing.assert_allclose(vgrad, grad, rtol=1e-9, atol=1e-12 * float(jnp.abs(grad).max()))
    np.testing.assert_allclose(vg_y, g_y, rtol=1e-12)


# ------------------------------------------------------------------ the fit
def test_fit_stage_picks_the_lowest_finite_member():
    model = Coulomb()
    records, bounds, obj = _prepared(model)
    keys = stages.resolve_keys(None, jax.random.split(jax.random.key(5), 3))
    sol, _ = stages.global_stage(obj, TINY_NM, bounds, keys, dtype=jnp.float32)
    # member 0 made non-finite, member 2 the best finite one
    f = jnp.asarray([jnp.nan, 1.0, 0.5], sol.f.dtype)
    sol = eqx.tree_at(lambda s: s.f, sol, f)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = stages.fit_stage(model, records, bounds, obj, TINY_NM, sol, None, keys,
                               settings={"dtype": "float32", "data_bounds": True, "method": "jaxfric"})
    assert fit.ensemble["best"] == 2
    np.testing.assert_array_equal(fit.theta, np.asarray(sol.value[2]))
    assert fit.key_data == np.asarray(jax.random.key_data(keys.members[2])).ravel().tolist()
    assert fit.metrics["train"]["mse_percent"] > 0 and fit.settings["ensemble_size"] == 3


# -------------------------------------------------------------- whole ensembles
@pytest.mark.slow
def test_network_ensemble_members_equal_single_fits_within_the_stated_tolerance():
    """Member i of ``identify(..., keys=K)`` against ``identify(..., key=keys[i])``: the
    global stage vmapped, the gradient stage batched (float64: J within 1e-6 relative)."""
    kw = dict(neurons=3, solver=jf.MAPSO(lattice_size=3, num_generations=3),
              refine=GradientRefinement(max_steps=15), dtype=jnp.float64)
    keys = jax.random.split(jax.random.key(8), 3)
    with jax.enable_x64(True), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        data = _record()
        fit = identify("elman", data, keys=keys, **kw)
        for i in range(3):
            one = identify("elman", data, key=keys[i], **kw)
            assert fit.ensemble["J"][i] == pytest.approx(one.metrics["cost"], rel=1e-6)
            np.testing.assert_allclose(fit.ensemble["theta"][i], one.theta, rtol=1e-5, atol=1e-6)
