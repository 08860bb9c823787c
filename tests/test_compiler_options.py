"""Per-computation XLA options (jaxfric/_xla.py): validation, platform choice, and that
the options change speed only, never results."""

import os
import re
import subprocess
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfric as jf
from jaxfric import _xla
from jaxfric import functions as F


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


def test_auto_leaves_out_options_this_xla_does_not_know(monkeypatch):
    """'auto' never fails a run because XLA dropped an option jaxfric chose (as jax
    0.11's XLA dropped xla_cpu_use_fusion_emitters); a user's explicit dict still does."""
    chosen = {"xla_cpu_prefer_vector_width": 512, "xla_cpu_no_such_option_jaxfric": True}
    monkeypatch.setitem(_xla.CPU_OPTIONS, "solver", chosen)
    assert jf.compiler_options("solver", "cpu") == {"xla_cpu_prefer_vector_width": 512}
    assert dict(_xla.resolve("auto", "solver", "cpu")) == {
        "xla_cpu_prefer_vector_width": 512, _xla.SINGLE_KERNEL: True}
    lo, hi = F.get("sphere").bounds(3, np.float32)
    sol = jf.minimise(F.objective("sphere"), jf.PSO(num_particles=8, num_generations=5),
                      (lo, hi), key=jax.random.key(0))
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
    jf.PSO(num_particles=16, num_generations=40),
    jf.MAPSO(lattice_size=4, num_generations=25),
    jf.MAPSONMDS(mapso=jf.MAPSO(lattice_size=3, num_generations=10),
                 nelder_mead=jf.NelderMead(max_steps=200)),
], ids=["pso", "mapso", "mapso_nmds"])
def test_options_change_speed_not_results(solver):
    """'auto', XLA's defaults and a hand-written set reach the same run (the swarm's
    decisions are comparisons of sums: allow float32 reassociation, nothing more)."""
    lo, hi = F.get("rosenbrock").bounds(6, np.float32)
    fn = F.objective("rosenbrock")
    runs = [jf.minimise(fn, solver, (lo, hi), key=jax.random.key(3), compiler_options=o)
            for o in ("auto", None, {"xla_cpu_prefer_vector_width": 128})]
    for sol in runs[1:]:
        np.testing.assert_allclose(sol.f, runs[0].f, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(sol.value, runs[0].value, rtol=1e-4, atol=1e-5)
        assert int(sol.stats["num_evals"]) == int(runs[0].stats["num_evals"])


def test_minimise_many_takes_options():
    lo, hi = F.get("sphere").bounds(4, np.float32)
    keys = jax.random.split(jax.random.key(1), 3)
    s = jf.MAPSO(lattice_size=3, num_generations=15)
    a = jf.minimise_many(F.objective("sphere"), s, (lo, hi), keys=keys)
    b = jf.minimise_many(F.objective("sphere"), s, (lo, hi), keys=keys, compiler_options=None)
    np.testing.assert_allclose(a.f, b.f, rtol=1e-5, atol=1e-12)
    with pytest.raises(ValueError, match="compiler_options"):
        jf.minimise_many(F.objective("sphere"), s, (lo, hi), keys=keys, compiler_options=[1])


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


# ---------------------------------------------------------------- single-kernel loops
def _lowered_text(solver, fn, dim, options, many=False):
    """StableHLO of minimise's (or minimise_many's) executable for these options."""
    from jaxfric.optim.minimise import _prepare, _run, _run_many

    lo, hi = F.get("rosenbrock").bounds(dim, np.float32)
    flat, lower, upper, x0 = _prepare(fn, solver, (lo, hi), None, None, None)
    opts = _xla.resolve(options, "solver", "cpu")
    if many:
        keys = jax.random.split(jax.random.key(0), 2)
        return _xla.filter_jit(_run_many, opts).lower(
            solver, flat, lower, upper, None, keys, x0, None).as_text()
    return _xla.filter_jit(_run, opts).lower(
        solver, flat, lower, upper, None, jax.random.key(0), x0, None).as_text()


SMALL_CALL = "xla_cpu_small_call"


def _marked_calls(text):
    """Names of the functions called with the one-kernel mark, outermost first."""
    return re.findall(r"call @(\w+)\(.*" + SMALL_CALL, text)


def test_single_kernel_marks_swarm_loops_only_when_asked():
    s = jf.MAPSO(lattice_size=3, num_generations=3)
    fn = F.objective("rosenbrock")
    assert dict(_xla.resolve("auto", "solver", "cpu"))[_xla.SINGLE_KERNEL] is True
    assert _xla.SINGLE_KERNEL not in dict(_xla.resolve("auto", "solver", "gpu"))
    assert _xla.SINGLE_KERNEL not in dict(_xla.resolve("auto", "rollout", "cpu"))
    # a small swarm: the whole generation loop is one kernel, with self-learning
    # inside it traced plain (one kernel is never nested in another)
    text = _lowered_text(s, fn, 6, "auto")
    assert _marked_calls(text)[0] == "loop"
    assert "call @run(" not in text
    assert SMALL_CALL not in _lowered_text(s, fn, 6, None)
    off = {**jf.compiler_options("solver", "cpu"), _xla.SINGLE_KERNEL: False}
    assert SMALL_CALL not in _lowered_text(s, fn, 6, off)
    # vmapped runs stay plain (batched, the loop gained nothing and outgrew one kernel)
    assert SMALL_CALL not in _lowered_text(s, fn, 6, "auto", many=True)
    pso = jf.PSO(num_particles=4, num_generations=2)
    assert _marked_calls(_lowered_text(pso, fn, 6, "auto"))[0] == "loop"
    # too much work per generation for one kernel: MAPSO keeps only self-learning's
    # loop as one kernel, PSO has nothing left to mark
    big = jf.MAPSO(lattice_size=20, num_generations=2)
    marked = _marked_calls(_lowered_text(big, fn, 100, "auto"))
    assert marked[0] == "run" and "loop" not in marked
    assert SMALL_CALL not in _lowered_text(jf.PSO(num_particles=400, num_generations=2), fn,
                                           100, "auto")
    with pytest.raises(ValueError, match="must be True or False"):
        _xla.resolve({_xla.SINGLE_KERNEL: "yes"}, "solver")


def test_single_kernel_needs_a_loop():
    """A function with no loop, or only a zero-length one, is never marked: MAPSO with
    sl_generations=0 aborted the whole process inside XLA:CPU when it was (0.4.0)."""
    x = jnp.ones(5)
    assert not _marked(lambda y: y * 2.0 + 1.0, x)
    assert not _marked(lambda y: jax.lax.scan(lambda c, _: (c * 2.0, c), y, None, length=0)[0], x)
    assert _marked(lambda y: jax.lax.scan(lambda c, _: (c * 2.0, c), y, None, length=1)[0], x)
    s0 = jf.MAPSO(lattice_size=3, num_generations=3, sl_generations=0)
    assert SMALL_CALL not in _lowered_text(s0, F.objective("rosenbrock"), 6, "auto")
    assert SMALL_CALL in _lowered_text(eqx.tree_at(lambda m: m.sl_generations, s0, 1),
                                       F.objective("rosenbrock"), 6, "auto")


def _run_script(script):
    """Run ``script`` in a fresh CPU-only Python process (an XLA abort or log line stays
    there); fail with its stderr unless it exits cleanly."""
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=300, env=dict(os.environ, JAX_PLATFORMS="cpu"))
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc


def test_mapso_without_self_learning_generations_runs_with_auto_options():
    """End to end, in a subprocess (a regression aborts the process, not just the test):
    MAPSO(sl_generations=0) with the default options runs and equals XLA's defaults."""
    script = (
        "import jax, numpy as np, jaxfric as jf\n"
        "from jaxfric import functions as F\n"
        "lo, hi = F.get('rosenbrock').bounds(30, np.float32)\n"
        "s = jf.MAPSO(lattice_size=5, num_generations=20, sl_generations=0)\n"
        "a = jf.minimise(F.objective('rosenbrock'), s, (lo, hi), key=jax.random.key(0))\n"
        "b = jf.minimise(F.objective('rosenbrock'), s, (lo, hi), key=jax.random.key(0),"
        " compiler_options=None)\n"
        "print('RESULT', float(a.f), float(b.f), int(a.stats['num_evals']), s.evaluations())\n"
    )
    proc = _run_script(script)
    fa, fb, evals, expected = proc.stdout.split("RESULT")[1].split()
    assert np.isfinite(float(fa)) and float(fa) == float(fb)
    assert int(evals) == int(expected)


def _marked(fn, *args):
    with _xla._single_kernel_enabled(True):
        return SMALL_CALL in jax.jit(lambda *a: _xla.single_kernel(fn, *a)).lower(*args).as_text()


def _in_loop(f):
    """``f`` (shape-preserving) applied twice in a scan: a loop, so the primitives inside
    are the only thing that decides whether it is marked."""
    return lambda a: jax.lax.scan(lambda c, _: (f(c), None), a, None, length=2)[0]


def test_single_kernel_declines_what_it_cannot_or_should_not_compile():
    x = jnp.linspace(-1.0, 1.0, 12).reshape(3, 4)
    assert _marked(_in_loop(lambda a: a * jnp.sum(jnp.cos(a) * a, axis=1, keepdims=True)), x)
    assert _marked(lambda a: jax.lax.scan(lambda c, r: (c + jnp.tanh(r), c), a[0], a)[1], x)
    # operations XLA's one-kernel emitter cannot compile (jax 0.10)
    assert not _marked(_in_loop(lambda a: jnp.sort(a, axis=1)), x)
    assert not _marked(_in_loop(lambda a: (a @ a.T) @ a), x)
    assert not _marked(_in_loop(lambda a: a.at[jnp.array([0, 2])].add(1.0)), x)
    assert not _marked(_in_loop(
        lambda a: a + jnp.linalg.solve(a[:, :3] + 3 * jnp.eye(3), a[:, 3])[:, None]), x)
    assert not _marked(_in_loop(
        lambda a: jax.lax.while_loop(lambda c: c[0, 0] < 5, lambda c: c + 1, a)), x)
    # too much work: a long scan (like a friction-model rollout)
    long = jnp.ones((3, 200_000))
    assert not _marked(lambda a: jax.lax.scan(lambda c, r: (c * 0.5 + r, c), a[:, 0], a.T)[1],
                       long)
    # and nothing is marked unless a jaxfric entry point enabled it
    plain = jax.jit(lambda a: _xla.single_kernel(_in_loop(lambda b: b * 2.0), a)).lower(x).as_text()
    assert SMALL_CALL not in plain
    assert _xla._work(jax.make_jaxpr(lambda a: jnp.sort(a))(x).jaxpr) == float("inf")


def _loop_marked(fn, *args, elements):
    with _xla._single_kernel_enabled(True):
        return SMALL_CALL in jax.jit(
            lambda *a: _xla.single_kernel_loop(fn, *a, elements=elements)).lower(*args).as_text()


def test_single_kernel_loop_limits():
    """Whole swarm loops: the work limit is per iteration, the population and every
    array in the loop are bounded, and the total length does not matter."""
    def hundred(a):
        return jax.lax.scan(lambda c, _: (jnp.sin(c) * 2.0, None), a, None, length=100)[0]

    jp = jax.make_jaxpr(hundred)(jnp.ones(50)).jaxpr
    once, total = _xla._work(jp, per_iteration=True), _xla._work(jp)
    assert total - 50 == pytest.approx(100 * (once - 50))  # 50: the scan's own output
    assert _xla._largest(jax.make_jaxpr(lambda a: jnp.outer(a, a).sum())(jnp.ones(30)).jaxpr) == 900
    x = jnp.ones((10, 8))
    step = _in_loop(lambda a: a * 0.5 + 1.0)
    assert _loop_marked(step, x, elements=x.size)
    assert not _loop_marked(step, x, elements=_xla.SINGLE_KERNEL_LOOP_MAX_ELEMENTS + 1)
    wide = _in_loop(lambda a: a + jnp.sum(jnp.broadcast_to(a[:, :, None], (10, 8, 300)) ** 2, 2))
    assert not _loop_marked(wide, x, elements=x.size)  # a 24 000-element intermediate
    def long(a):
        return jax.lax.scan(lambda c, _: (c * 0.5 + 1.0, None), a, None, length=100_000)[0]

    assert _loop_marked(long, x, elements=x.size)
    assert not _marked(long, x)  # single_kernel's limit is on the whole call's work


@pytest.mark.parametrize("fname, solver", [
    ("rosenbrock", jf.MAPSO(lattice_size=4, num_generations=6)),
    ("ackley", jf.MAPSO(lattice_size=4, num_generations=6)),
    ("griewank", jf.MAPSO(lattice_size=4, num_generations=6)),
    ("schwefel", jf.MAPSO(lattice_size=4, num_generations=6)),
    ("rosenbrock", jf.PSO(num_particles=9, num_generations=12)),
    ("ackley", jf.PSO(num_particles=9, num_generations=12)),
])
def test_single_kernel_changes_speed_not_the_run(fname, solver):
    """With and without one-kernel loops: the same run, up to the order XLA sums in
    (float32), with the same evaluation count."""
    lo, hi = F.get(fname).bounds(8, np.float32)
    off = {**jf.compiler_options("solver"), _xla.SINGLE_KERNEL: False}
    a = jf.minimise(F.objective(fname), solver, (lo, hi), key=jax.random.key(2))
    b = jf.minimise(F.objective(fname), solver, (lo, hi), key=jax.random.key(2),
                    compiler_options=off)
    np.testing.assert_allclose(a.history.f, b.history.f, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(a.value, b.value, rtol=1e-5, atol=1e-6)
    assert int(a.stats["num_evals"]) == int(b.stats["num_evals"]) == solver.evaluations()


def test_large_swarms_compile_once_without_xla_warnings():
    """In a subprocess (XLA logs to the process's stderr): a PSO whose generation XLA
    would split across threads (100 x 45) is left plain, so XLA neither warns
    "Compute function stack is not empty" nor compiles the run twice; MAPSO on its
    10x10 lattice at D = 30 and PSO at 100 x 40 are one kernel, also without a warning."""
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


def test_single_kernel_float64():
    lo, hi = F.get("rosenbrock").bounds(5, np.float64)
    s = jf.MAPSO(lattice_size=3, num_generations=8)
    off = {**jf.compiler_options("solver"), _xla.SINGLE_KERNEL: False}
    with jax.enable_x64(True):
        a = jf.minimise(F.objective("rosenbrock"), s, (lo, hi), key=jax.random.key(4))
        b = jf.minimise(F.objective("rosenbrock"), s, (lo, hi), key=jax.random.key(4),
                        compiler_options=off)
        assert a.value.dtype == jnp.float64
    np.testing.assert_allclose(a.history.f, b.history.f, rtol=1e-12)


@pytest.mark.skipif(jax.default_backend() != "cpu",
                    reason="the one-kernel loop is an XLA:CPU mechanism; minimise runs on this backend")
def test_single_kernel_falls_back_when_xla_cannot_compile_it(monkeypatch):
    """Should XLA fail to compile a marked loop, the run is compiled again without
    the marks, the failure remembered (not retried), and the result is the plain run's."""
    # Let sort through the pre-check: XLA's one-kernel emitter has no sort (jax 0.10).
    monkeypatch.setattr(_xla, "_SINGLE_KERNEL_PRIMITIVES",
                        _xla._SINGLE_KERNEL_PRIMITIVES | {"sort"})

    def fn(y, args):
        return jnp.sum(jnp.sort(y) ** 2 * jnp.arange(1.0, y.shape[0] + 1))

    lo, hi = F.get("sphere").bounds(4, np.float32)
    s = jf.MAPSO(lattice_size=3, num_generations=4)
    opts = _xla.resolve("auto", "solver", "cpu")
    from jaxfric.optim.minimise import _run

    compiled = _xla.filter_jit(_run, opts)
    before = len(compiled.failed)
    a = jf.minimise(fn, s, (lo, hi), key=jax.random.key(0))
    assert len(compiled.failed) == before + 1  # it was tried, failed, and remembered
    again = jf.minimise(fn, s, (lo, hi), key=jax.random.key(0))
    assert len(compiled.failed) == before + 1
    b = jf.minimise(fn, s, (lo, hi), key=jax.random.key(0),
                    compiler_options={**jf.compiler_options("solver"), _xla.SINGLE_KERNEL: False})
    for sol in (again, b):
        np.testing.assert_array_equal(sol.history.f, a.history.f)
        np.testing.assert_array_equal(sol.value, a.value)


def test_fallback_only_for_compiler_failures(monkeypatch):
    """Other errors pass through; an emitter failure switches to the plain executable."""
    calls = []

    class Fake:
        def __init__(self, exc):
            self.exc = exc

        def __call__(self, *a, **k):
            calls.append(self.exc)
            raise self.exc

    c = _xla._Compiled(lambda x: x, ((_xla.SINGLE_KERNEL, True),), False)
    c.jitted = Fake(jax.errors.JaxRuntimeError("UNIMPLEMENTED: Fusion kind not implemented on CPU"))
    assert float(c(jnp.float32(3.0))) == 3.0
    assert float(c(jnp.float32(4.0))) == 4.0  # same signature: not retried
    assert len(calls) == 1
    c.jitted = Fake(jax.errors.JaxRuntimeError("INTERNAL: something else"))
    with pytest.raises(jax.errors.JaxRuntimeError, match="something else"):
        c(jnp.zeros(3))
