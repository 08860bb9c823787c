"""Per-computation XLA options (jaxfric/_xla.py): validation, platform choice, and that
the options change speed only, never results."""

import os
import subprocess
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from processes import jax_subprocess

import jaxfric as jf
from jaxfric import _xla
from jaxfric import functions as F


# One PSO problem for every test that runs a PSO, so its 'auto' program compiles once.
PSO = jf.PSO(num_particles=16, num_generations=40)
ROSENBROCK_6 = F.get("rosenbrock").bounds(6, np.float32)


def _xla_accepts(name, value):
    try:
        _xla.check_known(((name, value),))
        return True
    except ValueError:
        return False


def test_auto_options_are_cpu_only():
    # Every chosen option this XLA knows is passed; the others are left out (jax 0.11's
    # XLA no longer has xla_cpu_use_fusion_emitters).
    for kind in ("solver", "rollout"):
        expected = {k: v for k, v in _xla.CPU_OPTIONS[kind].items() if _xla_accepts(k, v)}
        assert jf.compiler_options(kind, "cpu") == expected
    assert jf.compiler_options("rollout", "cpu") == {"xla_cpu_prefer_vector_width": 512}
    assert jf.compiler_options("solver", "gpu") == {}
    assert jf.compiler_options("rollout", "tpu") == {}
    # A returned dict is a copy: changing it does not change what jaxfric uses.
    d = jf.compiler_options("solver", "cpu")
    d["xla_cpu_prefer_vector_width"] = 128
    assert jf.compiler_options("solver", "cpu")["xla_cpu_prefer_vector_width"] == 512
    with pytest.raises(ValueError, match="kind must be one of"):
        jf.compiler_options("everything")


def test_resolve_freezes_and_validates():
    assert _xla.resolve(None, "solver") == ()
    assert _xla.resolve(False, "solver") == ()
    assert _xla.resolve("auto", "solver", "gpu") == ()
    assert dict(_xla.resolve("auto", "rollout", "cpu")) == {"xla_cpu_prefer_vector_width": 512}
    given = {"xla_cpu_enable_fast_math": False, "xla_cpu_prefer_vector_width": 256}
    frozen = _xla.resolve(given, "solver")
    assert frozen == tuple(sorted(given.items()))
    assert given == {"xla_cpu_enable_fast_math": False, "xla_cpu_prefer_vector_width": 256}
    hash(frozen)
    # 'fast-compile': 'auto' plus LLVM at level 0 on CPU, nothing elsewhere
    assert dict(_xla.resolve("fast-compile", "solver", "cpu")) == {
        **jf.compiler_options("solver", "cpu"), "xla_backend_optimization_level": 0}
    assert _xla.resolve("fast-compile", "solver", "gpu") == ()


def test_auto_leaves_out_options_this_xla_does_not_know(monkeypatch):
    """'auto' never fails a run because XLA dropped an option jaxfric chose (as jax
    0.11's XLA dropped xla_cpu_use_fusion_emitters); a user's explicit dict still does."""
    # jaxfric's own choice plus an option no XLA knows: what is left is what 'auto'
    # passes unpatched, so the run below is the program 'auto' compiles anyway
    chosen = {"xla_cpu_prefer_vector_width": 512, "xla_cpu_use_fusion_emitters": False,
              "xla_cpu_no_such_option_jaxfric": True}
    known = {k: v for k, v in chosen.items() if _xla_accepts(k, v)}
    assert known["xla_cpu_prefer_vector_width"] == 512 and "xla_cpu_no_such_option_jaxfric" not in known
    monkeypatch.setitem(_xla.CPU_OPTIONS, "solver", chosen)
    assert jf.compiler_options("solver", "cpu") == known
    assert dict(_xla.resolve("auto", "solver", "cpu")) == known
    # the run test_options_change_speed_not_results[pso] compiles with 'auto': one program
    lo, hi = ROSENBROCK_6
    sol = jf.minimise(F.objective("rosenbrock"), PSO, (lo, hi), key=jax.random.key(3))
    assert np.isfinite(float(sol.f))
    with pytest.raises(ValueError, match="XLA rejected compiler_options"):
        _xla.resolve(chosen, "solver")
    assert _xla.supported(tuple(chosen.items()), "no_such_platform") == ()


@pytest.mark.parametrize(
    "bad, match",
    [
        ("fast", "must be 'auto', None or a dict"),
        (3, "must be 'auto', None or a dict"),
        ({3: True}, "keys must be XLA option names"),
        ({"xla_cpu_prefer_vector_width": [512]}, "must be a bool, int, float or str"),
        ({"xla_no_such_option": 1}, "XLA rejected compiler_options.*xla_no_such_option"),
        ({"xla_cpu_prefer_vector_width": "wide"}, "XLA rejected compiler_options"),
    ],
)
def test_bad_options_fail_before_the_run(bad, match):
    calls = []

    def fn(y, args):
        calls.append(1)  # traced at most by the shape check, never run
        return F.sphere(y)

    lo, hi = F.get("sphere").bounds(3, np.float32)
    with pytest.raises(ValueError, match=match):
        jf.minimise(fn, jf.PSO(num_particles=4, num_generations=2), (lo, hi),
                    key=jax.random.key(0), compiler_options=bad)
    assert len(calls) <= 1


@pytest.mark.parametrize("solver", [
    PSO,
    jf.MAPSO(lattice_size=4, num_generations=25),
    jf.mapso_nmds(lattice_size=3, num_generations=40, sl_generations=2, nm_max_steps=60),
], ids=["pso", "mapso", "mapso_nmds"])
def test_options_change_speed_not_results(solver):
    """'full' ('auto' at XLA's full optimisation), XLA's defaults and (for PSO, the
    cheapest to compile) a hand-written set reach the same run (the swarm's decisions are
    comparisons of sums: allow float32 reassociation, nothing more). 'auto' compiles runs
    this cheap at LLVM level 0, which rounds differently (test_fast_compile_reaches_the_auto_run,
    test_auto_picks_the_level_from_the_run_work)."""
    lo, hi = ROSENBROCK_6
    fn = F.objective("rosenbrock")
    options = ["full", None]
    if isinstance(solver, jf.PSO):
        options.append({"xla_cpu_prefer_vector_width": 128})
    runs = [jf.minimise(fn, solver, (lo, hi), key=jax.random.key(3), compiler_options=o)
            for o in options]
    for sol in runs[1:]:
        np.testing.assert_allclose(sol.f, runs[0].f, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(sol.value, runs[0].value, rtol=1e-4, atol=1e-5)
        assert int(sol.stats["num_evals"]) == int(runs[0].stats["num_evals"])


def test_fast_compile_reaches_the_auto_run():
    """'fast-compile' (LLVM at level 0) rounds differently (fewer fused multiply-adds),
    not another algorithm: in float64 a 40-generation PSO on 6-D Rosenbrock ends at the
    same point to rounding, after the same evaluations."""
    lo, hi = F.get("rosenbrock").bounds(6, np.float64)
    fn = F.objective("rosenbrock")
    with jax.enable_x64(True):
        auto, fast = (jf.minimise(fn, PSO, (lo, hi), key=jax.random.key(3), compiler_options=o)
                      for o in ("auto", "fast-compile"))
    assert fast.value.dtype == np.float64
    np.testing.assert_allclose(fast.f, auto.f, rtol=1e-9)
    np.testing.assert_allclose(fast.value, auto.value, rtol=1e-9, atol=1e-12)
    assert int(fast.stats["num_evals"]) == int(auto.stats["num_evals"])


def test_minimise_many_takes_options():
    """The options reach minimise_many's batched program (PSO, the cheapest swarm to
    compile: what is checked is the plumbing, not the solver)."""
    lo, hi = ROSENBROCK_6
    keys = jax.random.split(jax.random.key(1), 3)
    fn = F.objective("rosenbrock")
    a = jf.minimise_many(fn, PSO, (lo, hi), keys=keys)
    b = jf.minimise_many(fn, PSO, (lo, hi), keys=keys, compiler_options=None)
    np.testing.assert_allclose(a.f, b.f, rtol=1e-5, atol=1e-12)
    assert not np.allclose(a.f[0], a.f[1:])  # three runs, not one copied
    with pytest.raises(ValueError, match="compiler_options"):
        jf.minimise_many(fn, PSO, (lo, hi), keys=keys, compiler_options=[1])


@pytest.mark.parametrize("x64", [False, True])
def test_rollout_bit_identical_to_plain_jit(x64):
    """The eager rollout (compiled with the 'rollout' options) equals the same rollout
    under a plain jax.jit, bit for bit: wider vectors do not reorder any sum."""
    el = jf.Elman(neurons=12)
    lo, hi = el.bounds()
    rng = np.random.default_rng(0)
    with jax.enable_x64(x64):
        dt = jnp.float64 if x64 else jnp.float32
        th = jnp.asarray(rng.uniform(lo, hi, (7, el.num_params)), dt)
        u = jnp.asarray(np.sin(np.linspace(0, 6, 300)), dt)
        eager = el.simulate_batch(th, u)
        plain = jax.jit(lambda a, b: el._simulate_batch(a, b, None))(th, u)
        assert eager.dtype == dt
        np.testing.assert_array_equal(np.asarray(eager), np.asarray(plain))


def test_rollout_under_transformations():
    """Options go to top-level jits only: inside a caller's jit, vmap, grad or
    eval_shape the eager path's compiled options must not be requested."""
    el = jf.Elman(neurons=5)
    lo, hi = el.bounds()
    th = jnp.asarray(np.random.default_rng(1).uniform(lo, hi, (3, el.num_params)), jnp.float32)
    u = jnp.linspace(-1.0, 1.0, 50)
    eager = el.simulate_batch(th, u)
    # On a GPU the eager and jitted programs fuse differently: float32 rounding (7e-6
    # relative was seen on an H100) that the recurrence carries forward.
    rtol = 1e-6 if jax.default_backend() == "cpu" else 1e-4
    np.testing.assert_allclose(jax.jit(lambda t: el.simulate_batch(t, u))(th), eager, rtol=rtol)
    np.testing.assert_allclose(jax.jit(lambda: el.simulate_batch(th, u))(), eager, rtol=rtol)
    np.testing.assert_allclose(jax.vmap(lambda t: el.simulate(t, u))(th), eager, rtol=rtol)
    assert jax.eval_shape(lambda t: el.simulate_batch(t, u), th).shape == (3, 50)
    g = jax.grad(lambda t: jnp.sum(el.simulate(t, u) ** 2))(th[0])
    assert g.shape == th[0].shape and bool(jnp.all(jnp.isfinite(g)))


def _run_script(script):
    """Run ``script`` in a fresh CPU-only Python process (an XLA abort or log line stays
    there); fail with its stderr unless it exits cleanly."""
    with jax_subprocess():
        proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                              timeout=300, env=dict(os.environ, JAX_PLATFORMS="cpu"))
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc


def test_mapso_without_self_learning_generations_runs_with_auto_options():
    """End to end, in a subprocess (0.4.0's one-kernel loop aborted the process here):
    MAPSO(sl_generations=0) with the default options runs (a run this cheap at LLVM level
    0), and jaxfric's options at full optimisation ('full') equal XLA's defaults."""
    script = (
        "import jax, numpy as np, jaxfric as jf\n"
        "from jaxfric import functions as F\n"
        "lo, hi = F.get('rosenbrock').bounds(30, np.float32)\n"
        "s = jf.MAPSO(lattice_size=5, num_generations=20, sl_generations=0)\n"
        "d = jf.minimise(F.objective('rosenbrock'), s, (lo, hi), key=jax.random.key(0))\n"
        "a = jf.minimise(F.objective('rosenbrock'), s, (lo, hi), key=jax.random.key(0),"
        " compiler_options='full')\n"
        "b = jf.minimise(F.objective('rosenbrock'), s, (lo, hi), key=jax.random.key(0),"
        " compiler_options=None)\n"
        "print('RESULT', float(a.f), float(b.f), int(a.stats['num_evals']), s.evaluations(),"
        " float(d.f), int(d.stats['num_evals']))\n"
    )
    proc = _run_script(script)
    fa, fb, evals, expected, fd, evals_d = proc.stdout.split("RESULT")[1].split()
    assert np.isfinite(float(fa)) and float(fa) == float(fb)
    assert int(evals) == int(expected)
    assert np.isfinite(float(fd)) and int(evals_d) == int(expected)


def test_large_swarms_compile_once_without_xla_warnings():
    """In a subprocess (XLA logs to the process's stderr): large swarms run without XLA
    warning "Compute function stack is not empty" (a symptom of 0.6.0's one-kernel loops)."""
    script = (
        "import jax, numpy as np, jaxfric as jf\n"
        "from jaxfric import functions as F\n"
        "for s, d in [(jf.PSO(num_particles=100, num_generations=3), 45),\n"
        "             (jf.PSO(num_particles=100, num_generations=3), 40),\n"
        "             (jf.MAPSO(lattice_size=10, num_generations=3), 30)]:\n"
        "    lo, hi = F.get('rosenbrock').bounds(d, np.float32)\n"
        "    r = jf.minimise(F.objective('rosenbrock'), s, (lo, hi), key=jax.random.key(0))\n"
        "    print('RESULT', float(r.f))\n"
    )
    proc = _run_script(script)
    assert proc.stdout.count("RESULT") == 3
    assert "Compute function stack" not in proc.stderr




def test_no_single_kernel_machinery_left():
    """Issue 15 item 4: no solver marks its loops for XLA, and no private JAX import."""
    from pathlib import Path

    root = Path(jf.__file__).parent
    for path in root.rglob("*.py"):
        text = path.read_text()
        assert "jax._src" not in text, path
        # the driver and ask/tell, which compile the run, may
        if path.parent.name == "optim" and path.name not in ("driver.py", "asktell.py"):
            assert "xla_cpu_small_call" not in text and "_xla" not in text, path


def test_jaxpr_work_counts_loops_and_products():
    """The work estimate behind 'auto' against hand counts: output elements, a matrix
    product's contracted size, a scan's length, a cond's costlier branch; a while loop
    (unknown trips) is infinite."""
    from jaxfric.optim.problem import jaxpr_work

    def work(f, *a):
        return jaxpr_work(jax.make_jaxpr(f)(*a).jaxpr)

    x = jnp.ones(7)
    assert work(lambda x: x * 2.0, x) == 7
    assert work(lambda x: jnp.sum(x * 2.0), x) == 7 + 1
    assert work(lambda m: m @ m, jnp.ones((3, 3))) == 3 * 3 * 3
    assert work(lambda x: jax.lax.scan(lambda c, _: (c * 2.0, None), x, None, length=100)[0], x) == 700
    branches = lambda x: jax.lax.cond(x[0] > 0, lambda y: y * 2.0 + 1.0, lambda y: y, x)  # noqa: E731
    assert work(branches, x) == 4 + 2 * 7  # x[0] (slice, squeeze), the test (gt, convert), the costlier branch
    assert work(lambda x: jax.lax.while_loop(lambda c: c[0] < 3, lambda c: c + 1, x), x) == np.inf


def test_auto_picks_the_level_from_the_run_work():
    """'auto' compiles a cheap run (a new objective's 200-generation chain, 2-D to 10-D
    Rosenbrock) with LLVM at level 0 and the speed tables' 30-D runs (100 agents over 100,
    300 or 500 generations; Nelder-Mead at 20 000 evaluations) at XLA's full optimisation, as it does
    an objective whose work is unknown (a while loop) or heavy (a long scan); 'full'
    never lowers the level, 'fast-compile' always does (CPU only)."""
    from jaxfric.optim import driver
    from jaxfric.optim.optx_adapter import as_protocol

    def level(solver, n, fn=F.objective("rosenbrock"), options="auto", platform="cpu"):
        lo, hi = F.get("rosenbrock").bounds(n, np.float64)
        proto, flat, lower, _, _ = driver._prepare(fn, solver, (lo, hi), None, None, None)
        layout = None
        opts = dict(driver._options(options, proto, flat, lower, None, layout)
                    if platform == "cpu" else _xla.resolve(options, "solver", platform, 0.0))
        return opts.get("xla_backend_optimization_level")

    cheap = [jf.chain(jf.PSO(num_generations=200), jf.NelderMead(max_steps=2000)),
             jf.mapso_nmds(num_generations=100, nm_max_steps=2000)]
    for solver in cheap:
        for n in (2, 5, 10):
            assert level(solver, n) == 0, (solver, n)
        assert level(solver, 5, options="full") is None
    speed = [jf.PSO(num_particles=100, num_generations=500), jf.MAPSO(lattice_size=10, num_generations=500),
             jf.PSO(num_particles=100, num_generations=100), jf.PSO(num_particles=100, num_generations=300),
             jf.MAPSO(lattice_size=10, num_generations=100),
             jf.NelderMead(max_steps=20000, max_evals=20000)]
    for solver in speed:
        assert level(solver, 30) is None, solver
        assert level(solver, 30, options="fast-compile") == 0
    pso = jf.PSO(num_particles=8, num_generations=10)

    def looping(y, args):  # a trip count XLA cannot know
        return jax.lax.while_loop(lambda c: c[1] < 3, lambda c: (c[0] * 0.5, c[1] + 1), (jnp.sum(y), 0))[0]

    def long_scan(y, args):  # a rollout of 10^5 steps per evaluation
        return jax.lax.scan(lambda c, _: (c * 0.5 + jnp.sum(y), None), 0.0, None, length=100_000)[0]

    assert level(pso, 5) == 0
    assert level(pso, 5, fn=looping) is None and level(pso, 5, fn=long_scan) is None
    assert level(pso, 5, platform="gpu") is None  # off the CPU nothing is passed
    assert _xla.auto_level(None) is None and _xla.auto_level(_xla.CHEAP_WORK) is None
    assert _xla.auto_level(_xla.CHEAP_WORK / 2) == 0
    assert dict(_xla.resolve("full", "solver", "cpu", 0.0)) == jf.compiler_options("solver", "cpu")


def test_auto_on_a_cheap_run_is_fast_compile_and_ask_tell_follows():
    """On a cheap run 'auto' compiles what 'fast-compile' compiles (the same bits), and
    ask/tell, whose program has no objective, picks the same level: it visits the points
    minimise visits, to the bit."""
    lo, hi = ROSENBROCK_6

    def fn(y, args):  # a maximum of exact differences: NumPy's values are XLA's
        return jnp.max(jnp.abs(y - 0.25))

    solver = jf.chain(jf.PSO(num_particles=6, num_generations=5), jf.NelderMead(max_steps=30))
    auto, fast = (jf.minimise(fn, solver, (lo, hi), key=jax.random.key(2), compiler_options=o)
                  for o in ("auto", "fast-compile"))
    np.testing.assert_array_equal(np.asarray(auto.value), np.asarray(fast.value))
    assert int(auto.stats["num_evals"]) == int(fast.stats["num_evals"])
    st = jf.ask_init(solver, lo, hi, jax.random.key(2))
    while not jf.ask_done(st):
        X, st = jf.ask(st)
        st = jf.tell(st, X, np.max(np.abs(np.asarray(X) - np.float32(0.25)), axis=-1))
    told = jf.ask_result(st)
    np.testing.assert_array_equal(np.asarray(told.value), np.asarray(auto.value))
    assert int(told.stats["num_evals"]) == int(auto.stats["num_evals"])
