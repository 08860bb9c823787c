"""The default identification pipeline and its gradient stage (issue 17 items 2-3, issue 20 item 10).

* the Elman network's hand-written adjoint against JAX's own reverse mode (float64);
* the cost's derivative (which uses that adjoint) against plain autodiff of the same formula;
* ``method="jaxfric"`` (default) against ``method="paper"``: which stages run, on which samples;
* the gradient stage's progress: a bar that ends at 100 % after an early stop, and a
  display that never changes the result.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfric
from jaxfric.identification import GradientRefinement, identify
from jaxfric.identification import _api
from jaxfric.identification._objective import CostData, OutputErrorCost, _plain_cost
from jaxfric.optim.progress import GRADIENT_PHASE
from jaxfric.models import Coulomb, Elman

DT = 1.0 / 128.0


def _theta(model, seed=0):
    lo, hi = model.bounds()
    return lo + (hi - lo) * np.random.default_rng(seed).random(lo.size)


def _adjoint(model):
    """``(y, ∂/∂θ of g·y)`` by the network's hand-written adjoint, jitted: one program
    (run op by op, its loops and small operations compiled dozens)."""

    def run(theta, u, g):
        y, pullback = model.simulate_vjp(theta, u)
        return y, pullback(g)

    return jax.jit(run)


def _reverse_mode(model):
    """The same pair by JAX's own reverse mode of ``model.simulate``, jitted."""

    def run(theta, u, g):
        y, vjp = jax.vjp(lambda t: model.simulate(t, u), theta)
        return y, vjp(g)[0]

    return jax.jit(run)


@pytest.mark.parametrize("output_bias", [False, True])
def test_elman_adjoint_matches_jax_reverse_mode(output_bias):
    model = Elman(neurons=5, context_weight_bound=1.0, output_bias=output_bias)
    rng = np.random.default_rng(1)
    with jax.enable_x64(True):
        theta = jnp.asarray(_theta(model))
        u = jnp.asarray(np.sin(np.linspace(0.0, 20.0, 300)) + 0.1 * rng.standard_normal(300))
        g = jnp.asarray(rng.standard_normal(300))
        y, got = _adjoint(model)(theta, u, g)
        y_ref, expected = _reverse_mode(model)(theta, u, g)
        np.testing.assert_allclose(y, y_ref, rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-12 * float(jnp.abs(expected).max()))


def test_cost_derivatives_match_plain_autodiff():
    model = Elman(neurons=4, context_weight_bound=1.0)
    rng = np.random.default_rng(2)
    with jax.enable_x64(True):
        theta = jnp.asarray(_theta(model, 3))
        data = CostData(u=jnp.asarray(np.sin(np.linspace(0, 9, 200))), y=jnp.asarray(rng.standard_normal(200)),
                        dt=jnp.asarray(DT), inv_norm=jnp.asarray(1.3))
        cost = OutputErrorCost(model)
        plain = lambda t, d: _plain_cost(model, t, d)  # noqa: E731
        # every derivative jitted (one program each), as the optimisers run them
        jit = jax.jit
        assert jit(cost)(theta, data) == pytest.approx(float(jit(plain)(theta, data)), rel=1e-14)
        g_ref = jit(jax.grad(plain))(theta, data)
        scale = float(jnp.abs(g_ref).max())
        np.testing.assert_allclose(jit(jax.grad(cost))(theta, data), g_ref, atol=1e-11 * scale)
        np.testing.assert_allclose(jit(jax.jacfwd(cost))(theta, data), g_ref, atol=1e-11 * scale)
        np.testing.assert_allclose(jit(jax.grad(cost, argnums=1))(theta, data).y,
                                   jit(jax.grad(plain, argnums=1))(theta, data).y, atol=1e-14)
        # vmap over candidates (the swarm's path) gives each candidate's own J
        batch = jnp.stack([theta, jnp.asarray(_theta(model, 4))])
        np.testing.assert_allclose(jit(jax.vmap(cost, (0, None)))(batch, data),
                                   [jit(plain)(t, data) for t in batch], rtol=1e-12)


def _record(n=2300, n_train=2100):
    t = np.arange(n) * DT
    v = 0.01 * np.sin(2 * np.pi * 0.2 * t) + 0.004 * np.sin(2 * np.pi * 0.53 * t)
    f = 200.0 * np.tanh(v / 1e-3) + 4e3 * v
    return jaxfric.rig.FrictionData.from_arrays(v, f, DT, n_train=n_train)


@pytest.mark.slow
def test_default_pipeline_ends_with_bfgs_and_paper_method_is_one_flag_away(monkeypatch):
    # Small budgets keep the test fast; the structure is what is tested.
    monkeypatch.setattr(_api, "FAST_GENERATIONS_BLACK_BOX", 4)
    monkeypatch.setattr(_api, "FAST_REFINE_STEPS", 30)
    monkeypatch.setattr(_api, "DEFAULT_GENERATIONS_BLACK_BOX", 4)
    data = _record()
    opts = {"neurons": 4}  # 24 parameters: a network (> LARGE_MODEL_PARAMS)
    fit = identify("elman", data, key=0, model_options=opts)
    assert [s["stage"] for s in fit.stages] == ["mapso", "bfgs"]
    assert fit.settings["method"] == "jaxfric"
    assert fit.settings["global_stage_samples"] == _api.GLOBAL_STAGE_SAMPLES < data.n_train
    assert fit.stages[0]["num_evals"] == _api.default_solver(fit.model).evaluations()
    assert 1 <= fit.stages[1]["num_steps"] <= 30 and fit.stages[1]["J"] <= fit.stages[0]["J"]
    # J of the global stage is on the first GLOBAL_STAGE_SAMPLES samples, the final J on all
    assert fit.metrics["cost"] == fit.stages[-1]["J"]

    paper = identify("elman", data, key=0, model_options=opts, method="paper")
    assert [s["stage"] for s in paper.stages] == ["mapso", "nelder_mead"]
    assert paper.settings["global_stage_samples"] == data.n_train
    assert paper.settings["refine"] is None

    # an explicit refine=False turns the gradient stage off; an explicit solver wins
    off = identify("elman", data, key=0, model_options=opts, refine=False,
                   solver=jaxfric.MAPSO(lattice_size=3, num_generations=2))
    assert [s["stage"] for s in off.stages] == ["mapso"]
    assert off.settings["global_stage_samples"] == data.n_train
    with pytest.raises(ValueError, match="method must be one of"):
        identify("elman", data, key=0, method="fast")


class _FakeBar:
    instances: list = []

    def __init__(self, total=None, **kwargs):
        self.total, self.n, self.closed, self.postfix = total, 0, False, ""
        _FakeBar.instances.append(self)

    def update(self, k):
        self.n += k

    def reset(self, total=None):  # TqdmProgress restarts a stage's clock at its first report
        self.n = 0
        self.total = self.total if total is None else total

    def refresh(self):
        pass

    def set_postfix(self, *a, **k):
        pass

    def set_postfix_str(self, s, refresh=True):
        self.postfix = s

    def close(self):
        self.closed = True


def test_gradient_progress_ends_at_100_percent_and_never_changes_the_result(monkeypatch):
    import tqdm.auto

    monkeypatch.setattr(tqdm.auto, "tqdm", _FakeBar)
    model = Coulomb()
    t = np.arange(600) * DT
    v = 0.01 * np.sin(2 * np.pi * 0.3 * t)
    f = np.asarray(model.simulate(model.from_physical(Fc=180.0, sigma2=2.5e3), jnp.asarray(v)))
    kw = dict(key=0, solver=jaxfric.NelderMead(max_steps=3),
              refine=GradientRefinement(method="lm", max_steps=120))
    quiet = identify(model, (v, f, DT), **kw)
    calls = []
    seen = identify(model, (v, f, DT), progress=lambda *a: calls.append(a), **kw)
    np.testing.assert_array_equal(quiet.theta, seen.theta)
    lm_calls = [c for c in calls if c[0] == GRADIENT_PHASE]  # the gradient stage's reports
    steps = [c[1] for c in lm_calls]
    assert steps == sorted(steps) and steps[-1] == quiet.stages[-1]["num_steps"]

    _FakeBar.instances.clear()
    barred = identify(model, (v, f, DT), progress=True, **kw)
    np.testing.assert_array_equal(quiet.theta, barred.theta)
    bar = [b for b in _FakeBar.instances if b.total == 120][-1]
    n_steps = barred.stages[-1]["num_steps"]
    assert n_steps < 120, "LM should converge early on noise-free data"
    assert bar.closed and bar.n == bar.total  # 100 % although it stopped early
    assert f"step {n_steps}" in bar.postfix


@pytest.mark.parametrize("parallel", [False, True])
def test_elman_adjoint_both_time_loops(monkeypatch, parallel):
    """The λ recurrence one step after another (the CPU's loop) and as a parallel prefix
    scan (accelerators) against JAX's own reverse mode, float64."""
    import functools

    from jaxfric.models import _scan, elman

    monkeypatch.setattr(elman, "reverse_affine_scan",
                        functools.partial(_scan.reverse_affine_scan, parallel=parallel))
    # the network and record length of test_elman_adjoint_matches_jax_reverse_mode[False]:
    # the reference (JAX's reverse mode, which the patch does not touch) is its compiled program
    model = Elman(neurons=5, context_weight_bound=1.0)
    rng = np.random.default_rng(4)
    with jax.enable_x64(True):
        theta = jnp.asarray(_theta(model, 5))
        u = jnp.asarray(np.sin(np.linspace(0.0, 13.0, 300)) + 0.1 * rng.standard_normal(300))
        g = jnp.asarray(rng.standard_normal(300))
        got = _adjoint(model)(theta, u, g)[1]
        expected = _reverse_mode(model)(theta, u, g)[1]
        np.testing.assert_allclose(got, expected, rtol=1e-10,
                                   atol=1e-12 * float(jnp.abs(expected).max()))
