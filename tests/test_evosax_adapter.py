"""The evosax adapter (issue 16 item 2): evosax strategies under jaxfric's driver.

References are independent of the adapter: evaluated points and counts come from a
host-side counter (conftest.CallCounter), optima are known (a shifted sphere, the
Rosenbrock valley at 1), and run i of a batch is compared with a single run."""

import subprocess
import sys
import textwrap

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import CallCounter

pytest.importorskip("evosax")

import jaxfric as jf  # noqa: E402
from jaxfric import functions as F  # noqa: E402
from jaxfric.optim.evosax_adapter import Evosax, resolve_strategy  # noqa: E402

D = 4
# An asymmetric box with very different widths, the optimum off-centre.
LOWER = np.array([-5.0, 0.0, -0.01, 10.0], np.float32)
UPPER = np.array([5.0, 100.0, 0.03, 20.0], np.float32)
TARGET = np.array([1.5, 70.0, 0.02, 11.0], np.float32)
SCALE = UPPER - LOWER


def shifted_sphere(y, target):
    # in box widths, so every coordinate counts alike
    return jnp.sum(((y - target) / SCALE) ** 2)


def shifted_sphere_np(y):
    """``shifted_sphere(y, TARGET)`` on the last axis, in NumPy (float32)."""
    return np.sum(((np.asarray(y, np.float32) - TARGET) / SCALE) ** 2, axis=-1)


# CMA-ES (distribution-based) and DE (population-based): the adapter's two code paths.
SOLVERS = {
    "CMA_ES": Evosax("CMA_ES", num_generations=60),
    "DE": Evosax("DE", population_size=12, num_generations=60),
}

# One counted objective for the module: every single run of shifted_sphere is counted
# through this one function, so each solver's single-run program compiles once (a
# counter per test would be a new function, and a new program, in every test).
COUNTER = CallCounter()
COUNTED_SPHERE = COUNTER.wrap(shifted_sphere)


@pytest.fixture
def sphere_counter():
    """The module's counter, emptied for this test."""
    COUNTER.points.clear()
    return COUNTER


@pytest.mark.parametrize("name", sorted(SOLVERS))
def test_points_in_bounds_exact_counts_and_history(name, sphere_counter):
    counter = sphere_counter
    solver = SOLVERS[name]
    sol = jf.minimise(COUNTED_SPHERE, solver, (LOWER, UPPER), args=TARGET, key=3)
    pts = counter.all_points()
    assert counter.count == int(sol.stats["num_evals"]) == solver.evaluations(D)
    expected = (1 if name == "CMA_ES" else 12) + solver.population(D) * 60
    assert counter.count == expected
    assert np.all(pts >= LOWER) and np.all(pts <= UPPER)
    v = np.asarray(sol.value)
    assert np.all(v >= LOWER) and np.all(v <= UPPER)
    # the reported best is the best evaluated point, at its own value
    assert float(sol.f) == pytest.approx(float(shifted_sphere_np(v)), rel=1e-5)
    assert float(sol.f) <= float(shifted_sphere_np(pts).min()) * (1 + 1e-5)
    n = int(sol.history.length)
    assert int(sol.history.evals[n - 1]) == counter.count and float(sol.history.f[n - 1]) == float(sol.f)
    assert np.all(np.diff(np.asarray(sol.history.f)[:n]) <= 0)


@pytest.mark.parametrize("name", sorted(SOLVERS))
def test_same_key_same_result_and_batch_equals_single_runs(name, sphere_counter):
    solver = SOLVERS[name]
    keys = jax.random.split(jax.random.key(7), 3)
    many = jf.minimise_many(shifted_sphere, solver, (LOWER, UPPER), args=TARGET, keys=keys)
    one = jf.minimise(COUNTED_SPHERE, solver, (LOWER, UPPER), args=TARGET, key=keys[1])
    again = jf.minimise(COUNTED_SPHERE, solver, (LOWER, UPPER), args=TARGET, key=keys[1])
    assert sphere_counter.count == 2 * int(one.stats["num_evals"])
    assert bool(eqx.tree_equal(one.value, again.value)) and float(one.f) == float(again.f)
    assert int(many.stats["num_evals"][1]) == int(one.stats["num_evals"])
    np.testing.assert_allclose(np.asarray(many.value[1]), np.asarray(one.value), rtol=1e-4, atol=1e-6)
    # different keys give different runs
    assert not np.allclose(np.asarray(many.value[0]), np.asarray(many.value[2]))


@pytest.mark.parametrize("name", ["CMA_ES", "DE", "SNES"])
def test_solves_shifted_sphere(name):
    solver = Evosax(name, population_size=12, num_generations=150)
    with jax.enable_x64(True):
        lo, hi, t = (np.asarray(a, np.float64) for a in (LOWER, UPPER, TARGET))
        sol = jf.minimise(shifted_sphere, solver, (lo, hi), args=t, key=0)
    assert float(sol.f) < 1e-8
    np.testing.assert_allclose(np.asarray(sol.value), TARGET, atol=1e-3 * SCALE.max())


def test_nan_is_never_the_best(counter):
    def half_nan(y, args):
        # NaN on the left half of the box, where the unconstrained minimum lies
        return jnp.where(y[0] < 0.0, jnp.nan, jnp.sum(y**2))

    lo, hi = -np.ones(D, np.float32), np.ones(D, np.float32)
    sol = jf.minimise(counter.wrap(half_nan), SOLVERS["CMA_ES"], (lo, hi), key=1)
    assert np.isfinite(float(sol.f)) and float(sol.value[0]) >= 0.0
    assert float(sol.f) == pytest.approx(float(jnp.sum(sol.value**2)), rel=1e-5)


def test_strategy_restarts_when_its_state_breaks_down(counter):
    """Long after convergence CMA-ES's step size underflows (float32: within a few
    hundred generations on a 2-D sphere) and its state turns NaN: the strategy restarts
    (pycma's rule) and the run spends its whole budget, with a finite state, an exact
    count and the best point kept."""
    solver = Evosax("CMA_ES", num_generations=3000)
    lo, hi = -np.ones(2, np.float32), np.ones(2, np.float32)
    sol = jf.minimise(counter.wrap(lambda y, a: jnp.sum((y - 0.3) ** 2)), solver, (lo, hi), key=0)
    assert counter.count == int(sol.stats["num_evals"]) == solver.evaluations(2)
    assert int(sol.stats["num_steps"]) == 3000
    assert int(sol.state.restarts) >= 1
    assert all(bool(jnp.all(jnp.isfinite(a))) for a in jax.tree_util.tree_leaves(sol.state.inner)
               if jnp.issubdtype(a.dtype, jnp.floating))
    assert float(sol.f) < 1e-10 and np.allclose(np.asarray(sol.value), 0.3, atol=1e-4)


def test_points_stay_in_the_box_after_the_unit_box_map():
    """lower + u·(upper − lower) rounds past upper for u = 1 (float64: 1.2000000000000002
    for the box [-1, 1.2]); the evaluated points are clipped back into the box."""
    from jaxfric.optim.evosax_adapter import _to_box

    with jax.enable_x64(True):
        lo, hi = jnp.array([-1.0]), jnp.array([1.2])
        assert float((lo + 1.0 * (hi - lo))[0]) > 1.2  # the rounding this guards against
        assert float(_to_box(jnp.array([1.0]), lo, hi)[0]) == 1.2
        assert float(_to_box(jnp.array([0.0]), lo, hi)[0]) == -1.0


def test_chain_cmaes_then_nelder_mead(counter):
    """chain(CMA-ES, NelderMead) on 3-D Rosenbrock (one minimum, 0 at ones; from 4-D on
    a second local minimum near (−1, 1, …) can catch a short run)."""
    solver = jf.cmaes_nm(num_generations=60)
    bounds = F.get("rosenbrock").bounds(3, np.float32)
    sol = jf.minimise(counter.wrap(F.objective("rosenbrock")), solver, bounds, key=2)
    assert counter.count == int(sol.stats["num_evals"])
    assert int(sol.stats["num_evals_global"]) == solver.global_solver.evaluations(3)
    assert counter.count > solver.global_solver.evaluations(3)  # Nelder-Mead ran too
    assert float(sol.f) <= float(sol.stats["f_global"])
    assert float(sol.f) < 1e-6  # float32
    np.testing.assert_allclose(np.asarray(sol.value), np.ones(3), atol=1e-2)


def test_checkpointed_run_equals_uninterrupted(tmp_path, sphere_counter):
    solver = SOLVERS["CMA_ES"]
    full = jf.minimise(COUNTED_SPHERE, solver, (LOWER, UPPER), args=TARGET, key=5)
    chunked = jf.minimise(COUNTED_SPHERE, solver, (LOWER, UPPER), args=TARGET, key=5,
                          checkpoint=tmp_path / "run.ckpt", checkpoint_every=25)
    assert bool(eqx.tree_equal(full.value, chunked.value)) and float(full.f) == float(chunked.f)
    assert int(full.stats["num_evals"]) == int(chunked.stats["num_evals"])


def test_bad_settings_fail_before_running():
    with pytest.raises(ValueError, match="unknown evosax strategy"):
        Evosax("NOPE")
    assert resolve_strategy("cma-es") is resolve_strategy("CMA_ES")
    assert resolve_strategy("de").__name__ == "DifferentialEvolution"
    for bad, match in [  # solvers validate on construction: built inside the check
        (lambda: Evosax("CMA_ES", num_generations=0), "num_generations"),
        (lambda: Evosax("CMA_ES", population_size=1), "population_size"),
        (lambda: Evosax("CMA_ES", std_init=-1.0), "std_init"),
        (lambda: Evosax("DE", params={"nonsense": 1.0}), "no parameter"),
        (lambda: Evosax("DE", population_size=3), "refused"),
    ]:
        with pytest.raises(ValueError, match=match):
            jf.minimise(shifted_sphere, bad(), (LOWER, UPPER), args=TARGET, key=0)


NO_EVOSAX = textwrap.dedent(
    """
    import sys
    sys.modules["evosax"] = None          # as if it were not installed
    import jaxfric as jf                  # jaxfric itself must not need it
    try:
        jf.Evosax("CMA_ES")
    except ImportError as err:
        print("IMPORTERROR", err)
    """
)


def test_missing_evosax_names_the_extra(subprocess_slot):
    out = subprocess.run([sys.executable, "-c", NO_EVOSAX], capture_output=True, text=True,
                         timeout=300, env={**__import__("os").environ, "JAX_PLATFORMS": "cpu"})
    assert out.returncode == 0, out.stderr[-2000:]
    assert "IMPORTERROR" in out.stdout and '.[evosax]' in out.stdout


def test_missing_evosax_in_process(monkeypatch):
    for mod in [m for m in sys.modules if m == "evosax" or m.startswith("evosax.")]:
        monkeypatch.setitem(sys.modules, mod, None)
    monkeypatch.setitem(sys.modules, "evosax", None)
    with pytest.raises(ImportError, match=r"\.\[evosax\]"):
        Evosax("CMA_ES")


@pytest.mark.slow
def test_identify_accepts_an_evosax_chain():
    data = jf.rig.synthetic_friction_data(key=jax.random.key(0))
    solver = jf.cmaes_nm(num_generations=30, nm_max_steps=100)
    fit = jf.identify("coulomb", data, solver=solver, key=0)
    assert np.isfinite(fit.metrics["cost"])
    assert fit.stages[0]["stage"] == "evosax"
    assert fit.stages[0]["num_evals"] == solver.global_solver.evaluations(len(fit.theta))
