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

def sphere_or_nan(y, args):
    """``shifted_sphere(y, target)``, NaN where ``y[0] < nan_below``; ``args = (target,
    nan_below)``. With ``nan_below = -inf`` (`SPHERE`) NaN nowhere: the shifted sphere."""
    target, nan_below = args
    return jnp.where(y[0] < nan_below, jnp.nan, shifted_sphere(y, target))


SPHERE = (TARGET, np.float32(-np.inf))  # sphere_or_nan's args for the plain shifted sphere

# One counted objective for the module: every single run of shifted_sphere (and the NaN
# test's objective, another member of the same family) is counted through this one
# function, so each solver's single-run program compiles once (a counter per test would
# be a new function, and a new program, in every test).
COUNTER = CallCounter()
COUNTED_SPHERE = COUNTER.wrap(sphere_or_nan)


@pytest.fixture
def sphere_counter():
    """The module's counter, emptied for this test."""
    COUNTER.points.clear()
    return COUNTER


@pytest.mark.parametrize("name", sorted(SOLVERS))
def test_points_in_bounds_exact_counts_and_history(name, sphere_counter):
    counter = sphere_counter
    solver = SOLVERS[name]
    sol = jf.minimise(COUNTED_SPHERE, solver, (LOWER, UPPER), args=SPHERE, key=3)
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
    one = jf.minimise(COUNTED_SPHERE, solver, (LOWER, UPPER), args=SPHERE, key=keys[1])
    again = jf.minimise(COUNTED_SPHERE, solver, (LOWER, UPPER), args=SPHERE, key=keys[1])
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


def test_nan_is_never_the_best(sphere_counter):
    # NaN on the left half of the box, where the unconstrained minimum (the origin) lies;
    # the same function and solver as test_points_in_bounds_exact_counts_and_history[CMA_ES]
    # (its arguments differ), so the same compiled run
    lo, hi = -np.ones(D, np.float32), np.ones(D, np.float32)
    half_nan = (np.zeros(D, np.float32), np.float32(0.0))
    sol = jf.minimise(COUNTED_SPHERE, SOLVERS["CMA_ES"], (lo, hi), args=half_nan, key=1)
    assert np.isfinite(float(sol.f)) and float(sol.value[0]) >= 0.0
    assert float(sol.f) == pytest.approx(float(np.sum((np.asarray(sol.value) / SCALE) ** 2)), rel=1e-5)


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
    full = jf.minimise(COUNTED_SPHERE, solver, (LOWER, UPPER), args=SPHERE, key=5)
    chunked = jf.minimise(COUNTED_SPHERE, solver, (LOWER, UPPER), args=SPHERE, key=5,
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


# ------------------------------------------------------------------ IPOP restarts
def _steps(solver, fn, args, lower, upper, key, n):
    """The state after each of ``n`` steps, the steps taken one by one from Python
    (jaxfric.optim.rounds' compiled start and step, as the driver's loop takes them).
    ``args`` is an operand of the programs, not a constant in them: the two tests below
    minimise one function (`_scaled_sphere`) with the same strategy settings but for
    ``num_generations`` (which the step does not read), so they run the same compiled
    start and step."""
    from jaxfric.optim.driver import _prepare
    from jaxfric.optim.problem import check_key
    from jaxfric.optim.rounds import compiled_start, compiled_step

    args = jnp.asarray(args, lower.dtype)
    proto, flat, lo, hi, _ = _prepare(fn, solver, (lower, upper), args, None, None)
    state = jax.jit(lambda k, a: compiled_start(proto, flat, lo, hi, a, k))(check_key(key), args)
    # strongly typed, as the driver's loop carries it (the start leaves some leaves weak and
    # the step returns them strong: the step would compile twice); the same bits every step
    state = jax.tree_util.tree_map(lambda a: jnp.asarray(a, a.dtype), state)
    step = jax.jit(lambda s, a: compiled_step(proto, flat, lo, hi, a, s))
    states = []
    for _ in range(n):
        state = step(state, args)
        states.append(jax.device_get(state))
    return states


def _scaled_sphere(y, a):
    """``a·Σ(y − 0.3)²``: the sphere for ``a = 1``, a constant (0) for ``a = 0``."""
    return a * jnp.sum((y - 0.3) ** 2)


def test_ipop_doubles_the_population_after_stagnation():
    """CMA-ES on a 2-D sphere (float64) converges in some hundred generations; IPOP then
    restarts from a new mean with twice the population: a generation of population P·2^j
    takes 2^j steps (batches of P points), the strategy is told once per generation, and
    restarts come only at a generation's end, after the values stagnated."""
    P, R = 6, 2
    solver = Evosax("CMA_ES", num_generations=2000, restarts=R)
    assert solver.population(2) == P
    with jax.enable_x64(True):
        states = _steps(solver, _scaled_sphere, 1.0, -np.ones(2), np.ones(2), key=3, n=1500)
    level = np.array([int(s.ipop.level) for s in states])
    batch = np.array([int(s.ipop.batch) for s in states])
    restarts = np.array([int(s.restarts) for s in states])
    tells = np.array([int(s.inner.generation_counter) for s in states])
    assert restarts[-1] >= R + 1, "no restarts after convergence"
    np.testing.assert_array_equal(level, np.minimum(restarts, R))
    firsts = [int(np.argmax(restarts >= k)) for k in range(1, R + 1)]
    assert firsts[0] > 20  # converged first: no restart in the early generations
    f_then = float(states[firsts[0] - 1].f_best)
    assert f_then < 1e-10, f_then
    for k in range(R + 1):
        # the steps of the k-th run (after k restarts): batches 0 .. 2^j − 1 in turn,
        # one tell per generation (evosax counts them from 0 at each start)
        idx = np.flatnonzero(restarts == k)[1:-1]  # inside the run
        j = min(k, R)
        assert np.all(batch[idx] < 2**j)
        np.testing.assert_array_equal(np.diff(batch[idx]) % 2**j, np.ones(len(idx) - 1) % 2**j)
        told = np.flatnonzero(np.diff(tells[idx]) == 1)
        assert np.all(np.diff(told) == 2**j), f"run {k}: a tell every {2 ** j} steps"
        assert np.all(batch[idx][told + 1] == 0)
    # a restart ends a generation: the step before it was the generation's last batch
    for i in np.flatnonzero(np.diff(restarts) == 1) + 1:
        assert batch[i] == 0 and batch[i - 1] == 2 ** int(level[i - 1]) - 1


def test_ipop_same_key_same_result_exact_counts_and_chunks(tmp_path, sphere_counter):
    solver = Evosax("CMA_ES", num_generations=400, restarts=3)
    one = jf.minimise(COUNTED_SPHERE, solver, (LOWER, UPPER), args=SPHERE, key=9)
    assert sphere_counter.count == int(one.stats["num_evals"]) == solver.evaluations(D)
    # one objective for every run, so the chunks run the same compiled program as the whole run
    again = jf.minimise(COUNTED_SPHERE, solver, (LOWER, UPPER), args=SPHERE, key=9)
    chunked = jf.minimise(COUNTED_SPHERE, solver, (LOWER, UPPER), args=SPHERE, key=9,
                          checkpoint=tmp_path / "ipop.ckpt", checkpoint_every=37)
    for other in (again, chunked):
        assert bool(eqx.tree_equal(one.value, other.value)) and float(one.f) == float(other.f)
        assert int(one.state.restarts) == int(other.state.restarts)
    assert int(one.state.restarts) >= 1  # float32 stagnates within 400 steps
    other_key = jf.minimise(COUNTED_SPHERE, solver, (LOWER, UPPER), args=SPHERE, key=10)
    assert not np.array_equal(np.asarray(other_key.value), np.asarray(one.value))


def _plain_cmaes(fn, lower, upper, key, generations):
    """The adapter's one-run CMA-ES written out with evosax directly (the reference for
    ``restarts=0``): same keys, unit box, projection and std_init."""
    from evosax.algorithms import CMA_ES

    n = lower.shape[0]
    es = CMA_ES(population_size=4 + int(np.floor(3 * np.log(n))), solution=jnp.zeros(n))
    params = es.default_params.replace(std_init=jnp.asarray(0.3))
    k_init, k_start, key = jax.random.split(key, 3)
    mean = jax.random.uniform(k_start, (n,), jnp.float64)
    inner = es.init(k_init, mean, params)
    # init leaves some leaves weakly typed and tell returns them strong: made strong here
    # (the same values), so evosax's jitted ask and tell compile once, not again at g = 1
    inner = jax.tree_util.tree_map(lambda a: jnp.asarray(a, a.dtype), inner)
    box = lambda u: jnp.clip(lower + u * (upper - lower), lower, upper)  # noqa: E731
    best = float(fn(box(mean)))
    for g in range(generations):
        k_ask, k_tell = jax.random.split(jax.random.fold_in(key, g))
        U, inner = es.ask(k_ask, inner, params)
        U = jnp.clip(U, 0.0, 1.0)
        F = jax.vmap(fn)(box(U))
        inner, _ = es.tell(k_tell, U, F, inner, params)
        best = min(best, float(jnp.min(F)))
    return best


def test_restarts_zero_is_one_plain_run():
    """restarts=0 is CMA-ES run once, as before restarts existed: its best value follows
    evosax driven directly, also past the point where IPOP would have restarted."""
    fn = lambda y: jnp.sum((y - 0.3) ** 2)  # noqa: E731
    with jax.enable_x64(True):
        lo, hi = -np.ones(2), np.ones(2)
        plain = jf.minimise(lambda y, a: fn(y), Evosax("CMA_ES", num_generations=250, restarts=0),
                            (lo, hi), key=3)
        ipop = jf.minimise(lambda y, a: fn(y), Evosax("CMA_ES", num_generations=250, restarts=2),
                           (lo, hi), key=3)
        ref = _plain_cmaes(fn, jnp.asarray(lo), jnp.asarray(hi), jax.random.key(3), 250)
    assert plain.state.ipop is None and int(plain.state.restarts) == 0
    assert int(ipop.state.restarts) >= 1
    assert float(plain.f) == pytest.approx(ref, rel=1e-6, abs=1e-300)
    assert float(plain.f) < 1e-20


def test_padded_generation_equals_the_smaller_strategy():
    """For CMA-ES and Sep-CMA-ES restarts run one strategy object of the largest
    population: a generation of λ points told with λ's parameters (weights padded with
    zeros) and the other points valued +inf updates the state as the strategy of
    population λ does."""
    from evosax.algorithms import CMA_ES, Sep_CMA_ES

    n, lam, big = 3, 7, 28
    with jax.enable_x64(True):
        for cls in (CMA_ES, Sep_CMA_ES):
            small = cls(population_size=lam, solution=jnp.zeros(n))
            large = cls(population_size=big, solution=jnp.zeros(n))
            p_small = small.default_params.replace(std_init=jnp.asarray(0.3))
            p_pad = p_small.replace(weights=jnp.pad(p_small.weights, (0, big - lam)))
            state = small.init(jax.random.key(0), jnp.full(n, 0.4), p_small)
            X, state = small.ask(jax.random.key(1), state, p_small)
            F = jnp.sum((X - 0.5) ** 2 * jnp.arange(1, n + 1), axis=1)
            ref, _ = small.tell(jax.random.key(2), X, F, state, p_small)
            # the padding rows are arbitrary points (valued +inf below), drawn in NumPy
            pad = np.random.default_rng(3).uniform(0.0, 1.0, (big - lam, n))
            Xp = jnp.concatenate([X, jnp.asarray(pad)])
            Fp = jnp.concatenate([F, jnp.full(big - lam, jnp.inf)])
            got, _ = large.tell(jax.random.key(2), Xp, Fp, state, p_pad)
            for name in ("mean", "std", "p_std", "p_c", "C"):
                np.testing.assert_allclose(getattr(got, name), getattr(ref, name),
                                           rtol=1e-12, atol=1e-15, err_msg=f"{cls.__name__}.{name}")


def test_restarts_refuse_strategies_that_keep_a_population():
    with pytest.raises(ValueError, match="distribution-based"):
        jf.minimise(shifted_sphere, Evosax("DE", population_size=12, restarts=2), (LOWER, UPPER),
                    args=TARGET, key=0)
    with pytest.raises(ValueError, match="restarts"):
        Evosax("CMA_ES", restarts=-1)


def test_ipop_with_a_strategy_object_per_population_size(counter):
    """SNES is not run padded (one strategy object per population size): its restarts
    double the population too, with exact counts and the best point kept."""
    solver = Evosax("SNES", num_generations=600, restarts=2)
    lo, hi = -np.ones(2, np.float32), np.ones(2, np.float32)
    sol = jf.minimise(counter.wrap(lambda y, a: jnp.sum((y - 0.3) ** 2)), solver, (lo, hi), key=0)
    assert counter.count == int(sol.stats["num_evals"]) == solver.evaluations(2)
    assert int(sol.state.restarts) >= 1
    assert int(sol.state.ipop.level) == min(int(sol.state.restarts), 2)
    assert float(sol.f) < 1e-8


def test_flat_values_restart_on_the_second_flat_generation():
    """pycma's ``tolflatfitness`` (1): a generation whose best value equals its
    ⌊0.75·λ⌋-th best is flat, and the second flat generation in a row restarts. On a
    constant function every generation is flat, so with P = 6 and R = 2 the restarts end
    steps 2 (two generations of one batch), 6 (two of two), 14 (two of four), then every
    8 steps (population P·2^R, two generations of four batches). R = 2 as in
    test_ipop_doubles_the_population_after_stagnation, and the same function (times 0):
    the same compiled start and step."""
    solver = Evosax("CMA_ES", num_generations=100, restarts=2)
    with jax.enable_x64(True):
        states = _steps(solver, _scaled_sphere, 0.0, -np.ones(2), np.ones(2), key=0, n=70)
    restarts = np.array([int(s.restarts) for s in states])
    ends = np.flatnonzero(np.diff(np.concatenate([[0], restarts]))) + 1  # 1-based steps
    np.testing.assert_array_equal(ends, [2, 6, 14, 22, 30, 38, 46, 54, 62, 70])
    np.testing.assert_array_equal([int(s.ipop.level) for s in states], np.minimum(restarts, 2))


def _schwefel_2_26(y, a):
    return 418.9828872724338 * y.shape[0] - jnp.sum(y * jnp.sin(jnp.sqrt(jnp.abs(y))))


def test_ipop_solves_a_deceptive_function_a_single_run_does_not():
    """Schwefel 2.26 on [−500, 500]² (minimum 0 at 420.97…, near a bound, far from the
    next-best minima): with the same 6001 evaluations and the same keys, CMA-ES run once
    finds it for at most two of eight keys, IPOP (pycma's bound transformation and
    restart criteria) for all eight."""
    lo, hi = np.full(2, -500.0), np.full(2, 500.0)
    keys = jax.random.split(jax.random.key(0), 8)
    with jax.enable_x64(True):
        once = jf.minimise_many(_schwefel_2_26, Evosax("CMA_ES", num_generations=1000, restarts=0),
                                (lo, hi), keys=keys)
        ipop = jf.minimise_many(_schwefel_2_26, Evosax("CMA_ES", num_generations=1000, restarts=4),
                                (lo, hi), keys=keys)
    assert np.sum(np.asarray(once.f) < 1e-5) <= 2, np.asarray(once.f)
    assert np.all(np.asarray(ipop.f) < 1e-5), np.asarray(ipop.f)
    assert np.all(np.asarray(ipop.state.restarts) >= 1)
    np.testing.assert_allclose(np.asarray(ipop.value), 420.9687, atol=1e-3)


def test_linquad_is_pycmas_bound_transform():
    """The IPOP path's bound handling is pycma's BoundTransform on the unit box
    (cma.transformations.BoxConstraintsLinQuadTransformation), its inverse too; every
    genotype maps into [0, 1] and the middle of the box is left alone."""
    from jaxfric.optim.evosax_adapter import _linquad, _linquad_inverse

    G = np.random.default_rng(0).normal(0.5, 3.0, 4000)
    U = np.random.default_rng(1).uniform(0.0, 1.0, 1000)
    with jax.enable_x64(True):
        # compiled, as inside a run (a program per shape, not each operation on its own)
        linquad, inverse = jax.jit(_linquad), jax.jit(_linquad_inverse)
        mapped = np.asarray(linquad(jnp.asarray(G)))
        back = np.asarray(inverse(jnp.asarray(U)))
        round_trip = np.asarray(linquad(jnp.asarray(back)))
    assert np.all((mapped >= 0.0) & (mapped <= 1.0))
    middle = (G > 0.05) & (G < 0.95)
    np.testing.assert_array_equal(mapped[middle], G[middle])
    np.testing.assert_allclose(round_trip, U, rtol=0, atol=1e-15)
    cma = pytest.importorskip("cma")
    ref = cma.transformations.BoxConstraintsLinQuadTransformation([[0.0, 1.0]])
    np.testing.assert_allclose(mapped, np.asarray(ref(list(G))), rtol=0, atol=1e-14)
    np.testing.assert_allclose(back, np.asarray(ref.inverse(list(U))), rtol=0, atol=1e-14)


def test_rescaled_covariance_converges_at_pycmas_rate():
    """evosax adds 1e-8·I to CMA-ES's covariance at every ask: with λ = 96 on a 2-D
    sphere ``C`` reaches that floor in a few generations and only σ shrinks after it.
    ``_rescaled`` (C's largest variance 1, the scale moved into σ) leaves the
    distribution σ²·C unchanged and brings the generations to a 1e-11 spread of values
    to pycma's 28–32 (evosax alone: 95–101)."""
    from evosax.algorithms import CMA_ES

    from jaxfric.optim.evosax_adapter import _rescaled

    n, lam = 2, 96
    with jax.enable_x64(True):
        es = CMA_ES(population_size=lam, solution=jnp.zeros(n))
        params = es.default_params.replace(std_init=jnp.asarray(0.3))
        ask, tell = jax.jit(es.ask), jax.jit(es.tell)
        fn = lambda X: 1.0 + 1e4 * jnp.sum((X - 0.3) ** 2, axis=-1)  # noqa: E731

        def generations(rescale):
            state = es.init(jax.random.key(0), jnp.full(n, 0.5), params)
            # strongly typed as tell returns it: ask and tell compile once (as in _plain_cmaes)
            state = jax.tree_util.tree_map(lambda a: jnp.asarray(a, a.dtype), state)
            bests = []
            for g in range(150):
                k_ask, k_tell = jax.random.split(jax.random.key(g))
                X, state = ask(k_ask, state, params)
                F = fn(X)
                told, _ = tell(k_tell, X, F, state, params)
                if rescale:
                    again = _rescaled(told)
                    np.testing.assert_allclose(again.std**2 * again.C, told.std**2 * told.C,
                                               rtol=1e-12, atol=0)
                    assert float(jnp.max(jnp.diag(again.C))) == pytest.approx(1.0, abs=1e-15)
                    told = again
                state = told
                bests.append(float(jnp.min(F)))
                if len(bests) >= 11 and np.ptp(bests[-11:]) < 1e-11 and float(jnp.ptp(F)) < 1e-11:
                    return g + 1
            return 150

        assert generations(True) <= 40
        assert generations(False) >= 80
