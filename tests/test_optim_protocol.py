"""The step protocol and what the driver adds for every solver:
ask/tell against the compiled run, two-stage chains, stall-based early stopping, warm
starts (initial population, continuing a run), multi-start local stages, and
optimistix minimisers through the adapter."""

import io

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

import jaxfric as jf
from conftest import CallCounter
from jaxfric.optim import AbstractSolver, OptxMinimiser, TqdmProgress

LO, HI = np.full(2, -2.0, np.float32), np.full(2, 3.0, np.float32)
TARGET = np.array([0.5, -0.25], np.float32)


def separable(y, args):
    """``d0² + w d1²`` for ``d = y - target`` and ``(target, w) = args``: one addition of
    two squares, nothing to reassociate, so numpy and XLA agree."""
    target, weight = args
    d = y - target
    return d[0] * d[0] + weight * (d[1] * d[1])


SEP = (jnp.asarray(TARGET), jnp.float32(10.0))  # what separable_np computes
SPHERE = (jnp.zeros(2, jnp.float32), jnp.float32(1.0))  # the sum of squares

# The runs that count evaluations minimise this one function object, which reports each
# evaluated point to COUNTER: tests with the same solver share one compiled run instead
# of each its own. (Uncounted runs minimise separable itself: a program without a host
# callback also comes back from the session's compilation cache on disk.)
COUNTER = CallCounter()
OBJ = COUNTER.wrap(separable)


def sphere(y, args):
    return jnp.sum(y**2)


def counted(solver, args, key, **kw):
    """``minimise(OBJ, ...)`` and the number of points evaluated, counted on the host."""
    COUNTER.points.clear()
    sol = jax.block_until_ready(jf.minimise(OBJ, solver, (LO, HI), args=args, key=key, **kw))
    return sol, COUNTER.count


def separable_np(X):
    d = np.asarray(X, np.float32) - TARGET
    return d[:, 0] * d[:, 0] + np.float32(10.0) * (d[:, 1] * d[:, 1])


@pytest.mark.parametrize("solver", [
    jf.PSO(num_particles=6, num_generations=8),
    jf.MAPSO(lattice_size=3, num_generations=4, sl_generations=2),
    jf.MAPSO(lattice_size=3, num_generations=3, sl_generations=2, evaluate_replaced=True),
    jf.MAPSO(lattice_size=3, num_generations=3, sl_generations=0),
], ids=["pso", "mapso", "mapso_evaluate_replaced", "mapso_no_sl_generations"])
def test_ask_tell_from_python_follows_the_compiled_run(solver):
    """A simulator outside JAX drives the swarm with ask/tell and visits what minimise
    visits for the same key: the same best point, value and evaluation count."""
    key = jax.random.key(4)
    ref = jf.minimise(separable, solver, (LO, HI), args=SEP, key=key)
    st = jf.ask_init(solver, LO, HI, key)
    asked = 0
    while not jf.ask_done(st):
        X, st = jf.ask(st)
        asked += X.shape[0]
        st = jf.tell(st, X, separable_np(X))
    sol = jf.ask_result(st)
    assert asked == int(ref.stats["num_evals"]) == int(sol.stats["num_evals"])
    np.testing.assert_allclose(sol.value, ref.value, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(sol.f, ref.f, rtol=1e-5, atol=1e-7)


def test_ask_tell_compiles_the_run_once(run_cache_size):
    """ask/tell runs minimise's compiled run: a second run of the same solver and box
    (another key) compiles nothing, and MAPSO asks for the start, then 2 + sGen batches a
    generation."""
    solver = jf.MAPSO(lattice_size=3, num_generations=4, sl_generations=2)
    sizes = []
    for seed in (1, 2):
        st, per_run = jf.ask_init(solver, LO, HI, jax.random.key(seed)), 0
        while not jf.ask_done(st):
            X, st = jf.ask(st)
            st = jf.tell(st, X, separable_np(X))
            per_run += 1
        assert per_run == 1 + 4 * (2 + 2)
        sizes.append(run_cache_size())
    assert sizes[1] == sizes[0]


def test_an_abandoned_ask_tell_run_does_not_block_the_next():
    """A run left half-way (its states dropped) is stopped; a new run goes on as minimise's."""
    import gc

    solver = jf.PSO(num_particles=6, num_generations=8)
    st = jf.ask_init(solver, LO, HI, jax.random.key(2))
    X, st = jf.ask(st)
    st = jf.tell(st, X, separable_np(X))
    stale = st
    X, st = jf.ask(st)
    st = jf.tell(st, X, separable_np(X))
    with pytest.raises(ValueError, match="already told"):
        jf.tell(stale, X, separable_np(X))
    del st, stale
    gc.collect()
    key = jax.random.key(3)
    ref = jf.minimise(separable, solver, (LO, HI), args=SEP, key=key)
    sol, _ = _drive(solver, key, separable_np)
    assert int(sol.stats["num_evals"]) == int(ref.stats["num_evals"])
    np.testing.assert_array_equal(sol.value, ref.value)


def test_scan_request_is_one_loop_compiled_and_relayed():
    """An inner loop yielded as a Scan: the compiled run (one lax.scan) and the same run
    through relay (values transformed, the carry not) agree with a plain Python loop."""
    from jaxfric.optim.rounds import Scan, drive, relay

    xs = jnp.array([0.5, -1.0, 2.0])

    def body(c, x):
        f = yield jnp.stack([c + x, c - x])[:, None]  # two 1-D points
        return c + jnp.min(f)

    def rounds():
        f0 = yield jnp.array([[1.5]])
        return (yield Scan(body, f0[0], xs, 3))

    def square(X):
        return X[:, 0] ** 2

    def by_hand(scale=1.0):
        c = scale * 1.5**2
        for x in [0.5, -1.0, 2.0]:
            c = c + scale * min((c + x) ** 2, (c - x) ** 2)
        return c

    assert float(jax.jit(lambda: drive(rounds(), square))()) == pytest.approx(by_hand())
    doubled = jax.jit(lambda: drive(relay(rounds(), answer=lambda f: 2.0 * f), square))()
    assert float(doubled) == pytest.approx(by_hand(2.0))


def test_tell_refuses_the_wrong_number_of_values():
    pso = jf.PSO(num_particles=6, num_generations=8)
    st = jf.ask_init(pso, LO, HI, jax.random.key(0))
    X, st = jf.ask(st)
    with pytest.raises(ValueError, match="one fitness value per candidate"):
        jf.tell(st, X, np.zeros(3))


def _drive(solver, key, objective):
    """Drive ``solver`` by ask/tell; returns the solution and the batch sizes asked."""
    st = jf.ask_init(solver, LO, HI, key)
    sizes = []
    while not jf.ask_done(st):
        X, st = jf.ask(st)
        sizes.append(X.shape[0])
        st = jf.tell(st, X, objective(X))
    return jf.ask_result(st), sizes


# The sequential rule with two starts on MAPSO-NMDS, the batched trial points on a
# PSO -> NM chain (each also run by a test below, which then compiles nothing new).
@pytest.mark.parametrize("solver", [
    jf.chain(jf.PSO(num_particles=8, num_generations=8), jf.NelderMead(max_steps=120, batched_trials=True)),
    jf.mapso_nmds(lattice_size=3, num_generations=3, sl_generations=2, nm_max_steps=40, num_starts=2),
], ids=["pso_nm_batched", "mapso_nmds_two_starts"])
def test_ask_tell_drives_a_two_stage_chain_as_the_compiled_run(solver):
    """A NumPy objective drives PSO→NM and MAPSO–NMDS from Python: the same best point,
    value and evaluation counts as minimise for the same key; after the global stage
    ask returns the first simplex (n + 1 points), then each step's trial points (one
    at a time or a shrink's n under the sequential rule; all four when batched)."""
    key = jax.random.key(4)
    ref = jf.minimise(separable, solver, (LO, HI), args=SEP, key=key)
    sol, sizes = _drive(solver, key, separable_np)
    assert sum(sizes) == int(ref.stats["num_evals"]) == int(sol.stats["num_evals"])
    assert int(sol.stats["num_evals_global"]) == int(ref.stats["num_evals_global"])
    np.testing.assert_allclose(sol.value, ref.value, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(sol.f, ref.f, rtol=1e-5, atol=1e-7)
    n, ends = 2, np.cumsum(sizes)
    local = sizes[int(np.searchsorted(ends, int(ref.stats["num_evals_global"]))) + 1:]
    starts = solver.num_starts
    assert local[0] == n + 1
    trials = {4, n} if solver.local_solver.batched_trials else {1, n}
    assert set(local[1:]) - {n + 1} <= trials
    assert local.count(n + 1) >= starts  # one first simplex per start


def test_ask_tell_drives_nelder_mead_alone():
    """Nelder–Mead alone, a jaxfric solver itself: the first simplex, then one trial
    point at a time (or a shrink's n), as minimise for the same key."""
    solver = jf.NelderMead(max_steps=30)
    key = jax.random.key(6)
    ref = jf.minimise(separable, jf.NelderMead(max_steps=30), (LO, HI), args=SEP, key=key)
    sol, sizes = _drive(solver, key, separable_np)
    assert sizes[0] == 3 and set(sizes[1:]) <= {1, 2}
    assert sum(sizes) == int(ref.stats["num_evals"]) == int(sol.stats["num_evals"])
    np.testing.assert_allclose(sol.value, ref.value, rtol=1e-5, atol=1e-6)


# beside the next test: the two share the small programs that build evosax strategies
def test_evosax_answers_the_population_capability():
    """Evosax's population_size keyword no longer hides the contract's
    capabilities().population_size: a population-based strategy takes an initial population, a
    distribution-based one a single start (before, both raised TypeError)."""
    pytest.importorskip("evosax")
    pop = np.array([[1.0, 1.0], [0.0, 0.0], [2.0, -1.0]], np.float32)
    de = jf.Evosax("DE", population_size=6, num_generations=2)
    assert (de.capabilities(2).population_size == 6
            and jf.Evosax("CMA_ES").capabilities(2).population_size is None)
    sol = jf.minimise(sphere, de, (LO, HI), key=0, y0=pop)
    assert float(np.asarray(sol.history.f)[0]) < 1e-12  # the optimum, through the unit-box map
    sol = jf.minimise(sphere, jf.Evosax("CMA_ES", num_generations=2), (LO, HI), key=0,
                      y0=pop[1])
    assert float(np.asarray(sol.history.f)[0]) < 1e-12
    with pytest.raises(ValueError, match="this solver takes one start"):
        jf.minimise(sphere, jf.Evosax("CMA_ES"), (LO, HI), key=0, y0=pop)


@pytest.mark.slow
def test_ask_tell_drives_evosax_then_nelder_mead():
    pytest.importorskip("evosax")
    solver = jf.optim.cmaes_nm(num_generations=3, nm_max_steps=20)
    key = jax.random.key(5)
    ref = jf.minimise(separable, solver, (LO, HI), args=SEP, key=key)
    sol, sizes = _drive(solver, key, separable_np)
    assert sum(sizes) == int(ref.stats["num_evals"]) == int(sol.stats["num_evals"])
    np.testing.assert_allclose(sol.value, ref.value, rtol=1e-5, atol=1e-6)


def test_ask_tell_takes_an_objective_jax_cannot_trace():
    """A simulator in Python floats (NaN in part of the box) drives PSO→NM: the count is
    exact, NaN is never the best, and the known optimum is found."""

    def simulator(x):
        a, b = (float(np.float64(v)) for v in x)
        if a > 2.5:
            return float("nan")
        return (a - 0.5) ** 2 + 10.0 * (b + 0.25) ** 2

    with pytest.raises((jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError)):
        jax.jit(simulator)(jnp.zeros(2))
    solver = jf.chain(jf.PSO(num_particles=8, num_generations=8),
                      jf.NelderMead(max_steps=120, batched_trials=True))
    st = jf.ask_init(solver, LO, HI, 0)
    X, st = jf.ask(st)
    st_nan = jf.tell(st, X, np.full(X.shape[0], np.nan))
    assert float(jf.ask_result(st_nan).f) == np.inf  # NaN never becomes a best
    sol, sizes = _drive(solver, 0, lambda X: [simulator(x) for x in np.asarray(X)])
    assert int(sol.stats["num_evals"]) == sum(sizes)
    np.testing.assert_allclose(sol.value, [0.5, -0.25], atol=1e-3)
    assert float(sol.f) == pytest.approx(simulator(sol.value), abs=1e-6)


def test_ask_tell_refuses_what_was_not_asked_for():
    solver = jf.chain(jf.PSO(num_particles=4, num_generations=1), jf.NelderMead(max_steps=3))
    st = jf.ask_init(solver, LO, HI, jax.random.key(0))
    X, st = jf.ask(st)
    with pytest.raises(ValueError, match="one fitness value per candidate"):
        jf.tell(st, X, np.zeros(X.shape[0] + 1))
    with pytest.raises(ValueError, match="the batch ask returned"):
        jf.tell(st, X[:2], np.zeros(2))
    done = st
    while not jf.ask_done(done):
        X, done = jf.ask(done)
        done = jf.tell(done, X, separable_np(X))
    assert int(jf.ask_result(done).stats["num_steps"]) == 1 + 3  # G, then NM's cap
    with pytest.raises(ValueError, match="finished"):
        jf.ask(done)
    with pytest.raises(ValueError, match="ask/tell cannot drive BFGS"):
        jf.ask_init(jf.chain(jf.PSO(), optx.BFGS(rtol=1e-6, atol=1e-6)), LO, HI, 0)
    with pytest.raises(ValueError, match="1-D lower and upper"):
        jf.ask_init(solver, np.zeros((2, 2)), np.ones((2, 2)), 0)


@pytest.mark.parametrize("build, match", [
    (lambda: jf.PSO(num_particles=0), "num_particles must be >= 1"),
    (lambda: jf.PSO(c1=-1.0), "c1 must be >= 0"),
    (lambda: jf.PSO(stall_generations=0), "stall_generations must be >= 1"),
    (lambda: jf.MAPSO(po=1.5), "po must be <= 1"),
    (lambda: jf.MAPSO(vmax_fraction=0.0), "vmax_fraction must be > 0"),
    (lambda: jf.MAPSO(sl_mode="ring"), "sl_mode must be 'multiplicative' or 'additive'"),
    (lambda: jf.NelderMead(initial_step=0.0), "initial_step must be > 0"),
    (lambda: jf.NelderMead(batched_trials=1), "batched_trials must be True or False"),
    (lambda: jf.chain(jf.PSO(), jf.NelderMead(), num_starts=0), "num_starts must be >= 1"),
    (lambda: jf.chain(jf.NelderMead(), jf.NelderMead(), num_starts=2), "needs a swarm"),
    (lambda: jf.chain(jf.PSO(num_particles=4), jf.NelderMead(), num_starts=5),
     r"num_starts \(5\) exceeds the number of agents \(4\)"),
    (lambda: jf.chain("pso", jf.NelderMead()), "must be a jaxfric solver"),
    (lambda: jf.MAPSONMDS(mapso=jf.PSO()), "mapso must be a jaxfric.MAPSO"),
    (lambda: jf.mapso_nmds(nm_max_steps=0), "max_steps must be >= 1"),
    (lambda: OptxMinimiser(jf.NelderMead(rtol=-1.0)), "rtol must be >= 0"),
    (lambda: OptxMinimiser(jf.NelderMead()), "NelderMead is a jaxfric solver"),
], ids=lambda v: v if isinstance(v, str) else "")
def test_solvers_validate_on_construction(build, match):
    """Issue 19 item 3: a bad hyperparameter fails where the solver is written
    (``__check_init__``), with the field's name, not later inside minimise."""
    with pytest.raises(ValueError, match=match):
        build()


def test_evosax_validates_on_construction():
    pytest.importorskip("evosax")
    with pytest.raises(ValueError, match="num_generations must be >= 1"):
        jf.optim.Evosax("CMA_ES", num_generations=0)


def test_mapso_nmds_builds_a_mapsonmds():
    """One object: ``mapso_nmds`` is MAPSONMDS's flat-keyword factory, not a second type."""
    a = jf.mapso_nmds(num_generations=7, sl_generations=2, nm_max_steps=9, num_starts=2)
    b = jf.MAPSONMDS(mapso=jf.MAPSO(num_generations=7, sl_generations=2),
                     nelder_mead=jf.NelderMead(max_steps=9), num_starts=2)
    assert type(a) is jf.MAPSONMDS and a == b


PSO_NM = jf.chain(jf.PSO(num_particles=6, num_generations=5), jf.NelderMead(max_steps=80))


def test_chain_of_any_global_and_local_solver():
    """PSO → Nelder–Mead as a chain: exact evaluation count, never worse than its global
    stage, and MAPSONMDS equals chain(MAPSO, NelderMead) for the same key."""
    sol, count = counted(PSO_NM, SEP, jax.random.key(1))
    assert int(sol.stats["num_evals"]) == count
    assert float(sol.f) <= float(sol.stats["f_global"])
    assert float(sol.f) < 1e-6
    # the MAPSO-NMDS of test_ask_tell_drives_a_two_stage_chain_as_the_compiled_run
    mapso, nm = jf.MAPSO(lattice_size=3, num_generations=3, sl_generations=2), jf.NelderMead(max_steps=40)
    a = jf.minimise(separable, jf.MAPSONMDS(mapso=mapso, nelder_mead=nm, num_starts=2), (LO, HI),
                    args=SEP, key=jax.random.key(2))
    b = jf.minimise(separable, jf.chain(mapso, nm, num_starts=2), (LO, HI), args=SEP,
                    key=jax.random.key(2))
    assert bool(eqx.tree_equal(a.value, b.value)) and float(a.f) == float(b.f)


def test_local_restarts_from_the_best_agents():
    """num_starts = 3 refines the three best personal bests one after another: the
    evaluations add up exactly and the result is at least as good as one start."""
    one = PSO_NM
    three = jf.chain(one.global_solver, one.local_solver, num_starts=3)
    a, _ = counted(one, SEP, jax.random.key(3))
    b, count = counted(three, SEP, jax.random.key(3))
    assert int(b.stats["num_evals"]) == count
    assert int(b.stats["num_evals"]) > int(a.stats["num_evals"])
    assert float(b.f) <= float(a.f)
    with pytest.raises(ValueError, match="num_starts > 1 needs a swarm"):
        jf.minimise(separable, jf.chain(jf.NelderMead(), jf.NelderMead(), num_starts=2), (LO, HI),
                    args=SEP, key=0)


def test_warm_start_for_nelder_mead_and_chain():
    # the run of test_ask_tell_drives_nelder_mead_alone, stopped at its cap of 30 steps
    first = jf.minimise(separable, jf.NelderMead(max_steps=30), (LO, HI), args=SEP,
                        key=jax.random.key(6))
    assert int(first.stats["num_steps"]) == 30
    more = jf.minimise(separable, jf.NelderMead(max_steps=60), (LO, HI), args=SEP,
                       warm_start=first)
    assert int(more.stats["num_steps"]) > 30 and float(more.f) <= float(first.f)
    done, _ = counted(PSO_NM, SEP, 0)  # the run of the two tests above
    with pytest.raises(ValueError, match="cannot be continued"):
        jf.minimise(OBJ, PSO_NM, (LO, HI), args=SEP, warm_start=done)


@pytest.mark.parametrize("solver", [
    jf.PSO(num_particles=10, num_generations=400, stall_generations=10, function_tolerance=1e-3),
    jf.MAPSO(lattice_size=3, num_generations=400, sl_generations=2, stall_generations=10,
             function_tolerance=1e-3),
    jf.chain(jf.PSO(num_particles=10, num_generations=400, stall_generations=10,
                    function_tolerance=1e-3), jf.NelderMead(max_steps=50)),
], ids=["pso", "mapso", "chain"])
def test_stall_stops_early_and_the_rule_holds(solver):
    """MATLAB's MaxStallIterations/FunctionTolerance: the run ends long before G, the
    count is exact, and over the last stall window the best improved by no more than
    the tolerance (checked on the history, one entry per generation)."""
    sol, count = counted(solver, SPHERE, jax.random.key(0))
    assert int(sol.stats["num_evals"]) == count
    swarm = solver.global_solver if isinstance(solver, jf.optim.Chain) else solver
    gens = int(sol.stats["num_steps"]) if swarm is solver else int(sol.state.first.generation)
    assert 10 <= gens < 400
    f = np.asarray(sol.history.f)[: gens + 1]
    window = f[gens - 10], f[gens]
    assert window[0] - window[1] <= 1e-3 * max(1.0, abs(window[1])) + 1e-12
    off = eqx.tree_at(lambda s: s.stall_generations, swarm, None)
    assert int(jf.minimise(sphere, off, (LO, HI), key=jax.random.key(0)).stats["num_steps"]) == 400


def test_stall_is_off_by_default():
    assert jf.PSO().stall_generations is None and jf.MAPSO().stall_generations is None


def test_warm_start_continues_a_finished_run():
    """Continuing an 8-generation PSO under a 12-generation budget runs 4 more
    generations from the stored state (never worse); the same for MAPSO. (The short
    runs are those of the ask/tell tests.)"""
    for short, longer, per_gen in [
        (jf.PSO(num_particles=6, num_generations=8), jf.PSO(num_particles=6, num_generations=12), 6),
        (jf.MAPSO(lattice_size=3, num_generations=4, sl_generations=2),
         jf.MAPSO(lattice_size=3, num_generations=6, sl_generations=2), None),
    ]:
        first = jf.minimise(separable, short, (LO, HI), args=SEP, key=jax.random.key(5))
        more = jf.minimise(separable, longer, (LO, HI), args=SEP, warm_start=first)
        assert int(more.stats["num_steps"]) == longer.num_generations
        assert float(more.f) <= float(first.f)
        assert int(more.stats["num_evals"]) == longer.evaluations()
        if per_gen:
            assert int(more.stats["num_evals"]) - int(first.stats["num_evals"]) == 4 * per_gen
    with pytest.raises(ValueError, match="does not fit this solver"):
        jf.minimise(separable, jf.PSO(num_particles=7, num_generations=12), (LO, HI), args=SEP,
                    warm_start=first)
    with pytest.raises(ValueError, match="warm_start must be a Solution"):
        jf.minimise(separable, jf.PSO(), (LO, HI), args=SEP, warm_start="previous")


def test_initial_population():
    """y0 with a leading axis seeds the first agents: a population holding the optimum
    reports it from the first entry of the history on."""
    pop = np.array([[1.0, 1.0], [0.0, 0.0], [2.0, -1.0]], np.float32)
    for solver in (jf.PSO(num_particles=6, num_generations=3),
                   jf.MAPSO(lattice_size=2, num_generations=2, sl_generations=1),
                   jf.chain(jf.PSO(num_particles=6, num_generations=2), jf.NelderMead(max_steps=5))):
        sol = jf.minimise(sphere, solver, (LO, HI), key=0, y0=pop)
        assert float(np.asarray(sol.history.f)[0]) == 0.0 and float(sol.f) == 0.0
    with pytest.raises(ValueError, match="3 starts but the swarm has 2 agents"):
        jf.minimise(sphere, jf.PSO(num_particles=2), (LO, HI), key=0, y0=pop)
    with pytest.raises(ValueError, match="this solver takes one start"):
        jf.minimise(sphere, jf.NelderMead(), (LO, HI), key=0, y0=pop)


def test_an_optimistix_minimiser_runs_through_the_adapter():
    """optx.BFGS through jaxfric's driver equals optx.minimise on the same start."""
    y0 = jnp.array([1.0, 2.0], jnp.float32)
    solver = optx.BFGS(rtol=1e-6, atol=1e-6)
    ref = optx.minimise(sphere, solver, y0, max_steps=1000, throw=False)
    sol = jf.minimise(sphere, solver, (LO, HI), key=0, y0=y0)
    np.testing.assert_allclose(sol.value, ref.value, rtol=1e-6, atol=1e-7)
    assert isinstance(jf.optim.optx_adapter.as_protocol(solver), OptxMinimiser)
    assert isinstance(OptxMinimiser(solver), AbstractSolver)


def test_progress_bar_ends_at_100_percent_when_a_stage_stops_early():
    """Issue 20.10: a swarm stopped by its stall rule, then Nelder–Mead stopped by its
    tolerance, both end their bars at 100 %."""
    out = io.StringIO()
    c = jf.chain(jf.PSO(num_particles=6, num_generations=300, stall_generations=5,
                        function_tolerance=1e-2), jf.NelderMead(max_steps=2000))
    sink = TqdmProgress(300, 2000, file=out, ascii=True)
    jf.minimise(sphere, c, (LO, HI), key=0, progress=sink)
    text = out.getvalue()
    bars = [line for line in text.replace("\r", "\n").split("\n") if "it" in line or "%" in line]
    finals = [b for b in bars if "100%" in b]
    assert len(finals) >= 2, text[-2000:]
    assert "Nelder" in finals[-1]


def test_print_solution_shows_what_was_found():
    """Issue 20.12: print(solution) shows value, f, evaluations and the result."""
    sol = jf.minimise(separable, jf.PSO(num_particles=6, num_generations=8), (LO, HI), args=SEP, key=0)
    text = str(sol)
    import re

    shown = float(re.search(r"\bf=array\(([-0-9.e+]+)", text).group(1))
    assert shown == pytest.approx(float(sol.f), rel=1e-5)
    assert "value=array([" in text and "shape" not in text
    assert "num_evals=array(54" in text and "result=successful" in text  # 6 × (1 + 8)


def test_int_seed_is_the_same_key():
    """Issue 20.12: one key rule — an int seed is jax.random.key(seed), as in identify."""
    pso = jf.PSO(num_particles=6, num_generations=8)
    a = jf.minimise(separable, pso, (LO, HI), args=SEP, key=3)
    b = jf.minimise(separable, pso, (LO, HI), args=SEP, key=jax.random.key(3))
    c = jf.minimise(separable, pso, (LO, HI), args=SEP, key=np.uint32(3))
    assert bool(eqx.tree_equal(a.value, b.value)) and bool(eqx.tree_equal(a.value, c.value))


class _Clock:
    def __init__(self):
        self.t = 1000.0

    def __call__(self):
        return self.t


def test_first_eta_counts_generations_not_compilation():
    """Issue 20.10: the first report comes after compilation; the bar's rate (and so its
    ETA) is measured from there. Here 10 s of 'compilation' then 10 generations per
    second: the ETA after the second report is 48 s (480 generations left), not the
    ~500 s a clock started at the bar's creation would give."""
    clock = _Clock()
    out = io.StringIO()
    sink = TqdmProgress(500, None, file=out, ascii=True, mininterval=0, smoothing=0)
    sink.bar._time = clock
    sink.bar.reset(total=500)  # the bar's creation time on the fake clock
    clock.t += 10.0  # compilation
    sink(0, 10, 100, 1.0)  # first report: 10 generations done
    clock.t += 1.0
    sink(0, 20, 200, 0.5)  # ten more in one second
    d = sink.bar.format_dict
    rate = (d["n"] - d["initial"]) / d["elapsed"]
    eta = (d["total"] - d["n"]) / rate
    assert rate == pytest.approx(10.0)
    assert eta == pytest.approx(48.0)
    sink.close()


def test_gradient_stage_has_its_own_labelled_bar():
    """The gradient stage reports as phase 2 ('gradient'), drawn as its own bar with its
    own label, not as a Nelder–Mead bar."""
    out = io.StringIO()
    sink = TqdmProgress(10, 100, file=out, ascii=True, gradient_total=50)
    sink(0, 10, 100, 1.0)
    sink(2, 25, 25, 0.5)
    sink.close()
    text = out.getvalue()
    assert "(gradient)" in text and "Nelder" not in text
    assert "25/25" in text and "/50" not in text.split("(gradient)")[-1]  # ended early at 100 %


def test_the_contract_is_small_and_knows_nothing_of_ask_tell():
    """Issue 46 item 3: at most 8 methods on AbstractSolver (the five abstract ones,
    check, solution and the one capabilities record), and ask/tell a driver beside
    minimise that the contract does not import. Dunders are left out of the count:
    ``__check_init__`` is equinox's construction hook (it runs ``check``), and the rest
    (``__init__``, ``__eq__``, ...) is dataclass machinery no caller names."""
    import ast
    from pathlib import Path

    from jaxfric.optim import contract

    methods = [k for k, v in vars(AbstractSolver).items()
               if not k.startswith("__") and (callable(v) or isinstance(v, property))]
    assert len(methods) <= 8, methods
    assert set(AbstractSolver.__abstractmethods__) == {
        "init_rounds", "step_rounds", "finished", "best", "num_evals"}
    tree = ast.parse(Path(contract.__file__).read_text())
    imported = {(n.module or "") for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    imported |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imported |= {a.name for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) for a in n.names}
    assert not any("asktell" in name for name in imported), imported
    for name in ("ask_init", "ask", "tell", "ask_done", "ask_result", "check_ask_tell"):
        assert not hasattr(jf.PSO(), name), name
    # the chain's fields are abstract variables, which a subclass must give
    assert {"global_solver", "local_solver", "num_starts",
            "simplex_from_swarm"} <= jf.optim.AbstractChain.__abstractvars__


def test_generational_fields_are_abstract_so_positional_arguments_follow_each_solver():
    """``num_generations`` is an ``eqx.AbstractVar`` of the generational and swarm bases (a
    stringified annotation would make it a plain field of the base, the first positional
    argument of every subclass: ``PSO(30)`` once set 30 generations of 25 particles)."""
    import dataclasses

    from jaxfric.optim import AbstractGenerational, AbstractSwarm

    assert "num_generations" in AbstractGenerational.__abstractvars__
    assert "num_generations" in AbstractSwarm.__abstractvars__
    positional = [f.name for f in dataclasses.fields(jf.PSO) if not f.kw_only]
    assert positional[:2] == ["num_particles", "num_generations"]
    assert jf.PSO(30, 7) == jf.PSO(num_particles=30, num_generations=7)
    assert [f.name for f in dataclasses.fields(jf.MAPSO) if not f.kw_only][0] == "lattice_size"


def test_a_64_bit_run_after_a_32_bit_run_of_the_same_problem():
    """The blank carry kept per problem shape is kept per counter dtype too: under
    jax.enable_x64 the counters are int64 while the bounds' arrays are as before (a
    float32 search), and the 32-bit blank failed the run's cond on dtypes."""
    solver = jf.PSO(num_particles=4, num_generations=2)
    a = jf.minimise(separable, solver, (LO, HI), args=SEP, key=0, dtype=np.float32)
    with jax.enable_x64(True):
        b = jf.minimise(separable, solver, (LO, HI), args=SEP, key=0, dtype=np.float32)
    assert a.stats["num_evals"].dtype == jnp.int32 and b.stats["num_evals"].dtype == jnp.int64
    np.testing.assert_array_equal(a.value, b.value)
