"""GreyBox: a physical model plus a bounded, contractive network correction (issue 45 item 5).

Every check compares with an independent reference: the physical model alone (bit for
bit at zero output weights), the bound ``B`` computed from the physical parameters by
hand, a per-sample loop of the step against the vectorised rollout, the contraction
factor ``α + (1 − α) r_max`` of the module docstring, and a synthetic drive whose true
friction (Coulomb + viscous + a known extra term) is simulated here.
"""

from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfric import models
from jaxfric.motion import MotionData, MotionSearch, default_search, friction_step, identify_motion, simulate_motion
from jaxfric.motion._step import FrictionStep

DT = 1e-3


def _velocity(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    return 0.1 * np.sin(2 * np.pi * 0.7 * t) + 0.03 * np.sin(2 * np.pi * 3.3 * t + rng.uniform(0, 6))


def _random_theta(model, rng, velocity):
    lo, hi = model.bounds(model.search_box(None, velocity, 20.0 * np.sign(velocity) + 150.0 * velocity))
    return lo + (hi - lo) * rng.random(lo.size)


@pytest.mark.parametrize("physical", [models.LuGre(), models.Stribeck(), models.Coulomb(),
                                      models.LuGre(asymmetric=True, offset=True)])
def test_zero_output_weights_are_the_physical_model_bit_for_bit(physical):
    """With the network's output weights at zero the grey-box *is* its physical model:
    the same friction to the bit (float64), for random physical parameters and random
    input weights, and the ridge penalty is zero there."""
    model = models.GreyBox(physical, hidden=3)
    v = _velocity()
    rng = np.random.default_rng(1)
    with jax.enable_x64(True):
        for _ in range(3):
            theta = _random_theta(model, rng, v)
            theta[-model.hidden:] = 0.0  # the output weights v
            grey = np.asarray(model.simulate(theta, v, DT))
            phys = np.asarray(physical.simulate(theta[:model.n_physical], v, DT))
            assert np.array_equal(grey, phys)
            assert np.all(np.asarray(model.penalty(theta)) == 0.0)
        # ... and the initial guess starts there
        f = 20.0 * np.sign(v) + 150.0 * v
        theta0 = model.initial_guess(v, f)
        assert np.array_equal(np.asarray(model.simulate(theta0, v, DT)),
                              np.asarray(physical.simulate(theta0[:model.n_physical], v, DT)))


def test_correction_never_exceeds_its_bound():
    """Property: for random weights anywhere in the box and random (large, rough)
    velocities, |F_grey − F_phys| <= B = bound · Fc (Fc read from the physical parameters
    here, not from the model's helper), and random weights do reach a sizeable share of B."""
    model = models.GreyBox(models.LuGre(), hidden=5, bound=0.3)
    rng = np.random.default_rng(2)
    reach = []
    with jax.enable_x64(True):
        for seed in range(12):
            # 3000 samples, as _velocity's: the physical LuGre's rollout program of the test above
            v = rng.normal(0.0, 0.2, 3000) * rng.choice([0.01, 1.0, 10.0])
            theta = _random_theta(model, rng, np.abs(v) + 1e-3)
            delta = np.asarray(model.simulate(theta, v, DT)) - np.asarray(
                model.physical.simulate(theta[:model.n_physical], v, DT))
            fc = float(model.physical.to_physical(theta[:model.n_physical])["Fc"])
            bound = 0.3 * fc
            assert np.max(np.abs(delta)) <= bound * (1 + 1e-12), seed
            assert np.isclose(float(model.correction_bound(theta)), bound, rtol=1e-12)
            reach.append(np.max(np.abs(delta)) / bound)
    assert max(reach) > 0.5  # the bound is not met trivially by a dead network


def test_step_reproduces_the_rollout_and_the_context_contracts():
    """The per-sample step (inside the mechanics) gives the rollout's friction sample for
    sample; two different initial contexts approach each other at least as fast as the
    contraction factor α_max + (1 − α_max) r_max per sample, for random weights."""
    model = models.GreyBox(models.LuGre(), hidden=4)
    v = _velocity(600)
    rng = np.random.default_rng(3)
    with jax.enable_x64(True):
        theta = jnp.asarray(_random_theta(model, rng, v))
        step = friction_step(model)

        def sample(state, vk):  # one sample at a time, as the mechanics call it
            return step.update(theta, state, vk, DT), step.output(theta, state, vk, DT)

        _, out = jax.lax.scan(sample, step.init(theta, v[0], DT), jnp.asarray(v))
        np.testing.assert_allclose(np.asarray(out), np.asarray(model.simulate(theta, v, DT)),
                                   rtol=1e-10, atol=1e-9)

        _, net = model._split(theta)
        factor = float(jnp.max(net["alpha"] + (1 - net["alpha"]) * model.context_bound))

        def both(cs, vk):
            u = vk / net["vscale"]
            return tuple(model.network_step(net, c, u)[1] for c in cs), None

        (c1, c2), _ = jax.lax.scan(both, (jnp.ones(model.hidden), -jnp.ones(model.hidden)),
                                   jnp.asarray(v[:300]))
        assert float(jnp.max(jnp.abs(c1 - c2))) <= 2.0 * factor ** 300 + 1e-15


class _Truth(FrictionStep):
    """Coulomb + viscous with a known extra term ``A sgn(v) (|v| / VQ)^2`` (what a
    Coulomb + viscous law cannot express), simulated here as the true drive."""

    def output(self, theta, state, v, dt):
        return self.model.simulate(theta, jnp.reshape(v, (1,)), dt)[0] + _extra(v)


MASS, OFFSET = 2.5, 3.0
COULOMB = models.Coulomb(v_eps=1e-3)
TRUTH = dict(Fc=12.0, sigma2=60.0)


def _extra(v):
    return 2.0 * jnp.tanh(v / 0.01) * (jnp.abs(v) / 0.3) ** 2


def _drive(n=3000):
    t = np.arange(n) * DT
    u = 30 * np.sin(2 * np.pi * 1.3 * t) + 12 * np.sin(2 * np.pi * 3.1 * t + 1.0)
    theta = jnp.asarray(COULOMB.from_physical(**TRUTH), jnp.float64)
    out = simulate_motion(_Truth(COULOMB), theta, MASS, u - OFFSET, DT, 0.0, 0.0)
    return MotionData.from_arrays(u, np.asarray(out["x"]), DT), np.asarray(out["v"]), theta


def test_free_run_stays_bounded_for_random_weights():
    """Inside the mechanics, a long free run (20 000 samples of a rough force) with random
    network weights stays within the speed at which the viscous term alone balances the
    largest force plus the Coulomb level and the correction's bound: m dv/dt = u − F with
    F >= σ2 v + ... − B cannot push |v| past (max|u| + Fc + B) / σ2."""
    model = models.GreyBox(COULOMB, hidden=4, bound=0.5)
    rng = np.random.default_rng(4)
    n = 20000
    u = np.repeat(rng.normal(0.0, 25.0, n // 50), 50)
    with jax.enable_x64(True):
        run = jax.jit(lambda th: simulate_motion(friction_step(model), th, MASS, jnp.asarray(u), DT, 0.0, 0.0))
        for _ in range(4):
            theta = _random_theta(model, rng, _velocity())
            p = model.to_physical(theta)
            out = run(jnp.asarray(theta))
            v = np.asarray(out["v"])
            assert np.all(np.isfinite(v)) and np.all(np.isfinite(np.asarray(out["x"])))
            limit = (np.max(np.abs(u)) + float(p["Fc"]) * (1 + 0.5)) / float(p["sigma2"])
            assert np.max(np.abs(v)) <= limit * 1.01


@pytest.mark.slow
def test_recovers_an_extra_friction_term_better_than_its_physical_model():
    """Synthetic drive (truth: Coulomb + viscous + a quadratic extra term): identified
    from motion alone, the grey-box simulates the training and the held-back motion
    better than Coulomb + viscous, and its friction along the true velocity is closer to
    the true friction. It starts from the physical fit (first stage) and keeps |Δ| <= B."""
    with jax.enable_x64(True):
        rec, v_true, theta_true = _drive()
    search = MotionSearch(particles=10, generations=8, global_window=150, horizons=(300, None), steps=(30, 60))
    box = {"Fc": (2.0, 40.0), "sigma2": (5.0, 500.0)}
    with jax.enable_x64(True), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        phys = identify_motion(COULOMB, rec, key=0, mass=MASS, fit_offset=True, search=search,
                               dtype=jnp.float64, box=box, data_bounds=False)
        grey = identify_motion(models.GreyBox(COULOMB, hidden=3, bound=0.5), rec, key=0, mass=MASS,
                               fit_offset=True, search=search, dtype=jnp.float64,
                               box={**box, "vs": (0.01, 0.5)}, data_bounds=False)
        truth = np.asarray(COULOMB.simulate(theta_true, v_true) + _extra(v_true)) + OFFSET
    assert grey.stages[0]["stage"] == "physical Coulomb fit"
    assert grey.metrics["train"]["rmse_mm"] < 0.8 * phys.metrics["train"]["rmse_mm"]
    # the held-back motion: 0.905-0.916 of the physical fit's error over keys 0-3 on an AVX-512
    # Xeon (0.939 with twice the steps), under 0.9 on the machine the margin was first set on
    assert grey.metrics["valid"]["rmse_mm"] < 0.95 * phys.metrics["valid"]["rmse_mm"]
    err = {name: np.sqrt(np.mean((f.predict(v_true) - truth) ** 2)) for name, f in (("phys", phys), ("grey", grey))}
    assert err["grey"] < err["phys"]
    assert float(grey.model.correction_bound(grey.theta)) <= 0.5 * 40.0


def test_options_are_checked_and_the_default_search_starts_from_the_physical_fit():
    for bad in (dict(hidden=0), dict(bound=0.0), dict(ridge=-1.0), dict(context_bound=1.0),
                dict(alpha_max=1.0), dict(physical=models.Elman(neurons=2))):
        with pytest.raises(ValueError):
            models.GreyBox(**bad)
    with pytest.raises(ValueError, match="Coulomb level"):
        models.GreyBox(models.Cylinder())
    assert isinstance(models.get("greybox").physical, models.LuGre)
    assert isinstance(models.GreyBox("stribeck").physical, models.Stribeck)
    with pytest.raises(ValueError, match="no parameter"):
        models.GreyBox().search_box({"k": (1.0, 2.0)})
    search = default_search(models.GreyBox())
    assert search.horizons[-1] is None and not search.least_squares_start
    model = models.GreyBox(models.Stribeck(), hidden=2)
    assert model.num_params == models.Stribeck().num_params + 1 + 6 * 2
    with jax.enable_x64(True):
        theta = model.initial_guess(_velocity(), 20.0 * np.sign(_velocity()))
        back = model.from_physical(**model.to_physical(theta))
    # no two hidden units of the start are each other's negatives (they would stay so)
    start = models.GreyBox(hidden=4).network_start()  # [log10 vscale, w(4), r(4), b(4), ...]
    pairs = np.stack([start[1:5], start[9:13]], axis=-1)
    for i in range(4):
        for j in range(4):
            assert i == j or not np.allclose(pairs[i], -pairs[j]), (i, j)
    np.testing.assert_allclose(np.asarray(back), theta, rtol=1e-12, atol=1e-12)


def test_a_saved_grey_box_fit_loads_with_its_physical_model(tmp_path):
    """The fit file holds the physical model as its repr; loading rebuilds it (parsed,
    never evaluated) and predicts the same friction."""
    from jaxfric.fit import Fit, load_fit

    model = models.GreyBox(models.LuGre(asymmetric=True, offset=True), hidden=2)
    v = _velocity(500)
    with jax.enable_x64(True):
        theta = _random_theta(model, np.random.default_rng(5), v)
        fit = Fit(model=model, theta=theta, velocity_scaler=None, friction_scaler=None, dt=DT,
                  n_train=v.size, n_samples=v.size, metrics={})
        fit.save(tmp_path / "grey.npz")
        back = load_fit(tmp_path / "grey.npz")
        assert back.model == model
        np.testing.assert_array_equal(back.predict(v), fit.predict(v))
    with pytest.raises(ValueError, match="cannot read"):
        models.GreyBox("LuGre(__import__('os'))")
    with pytest.raises(ValueError, match="not a physical model"):
        models.GreyBox("Elman(neurons=2)")

