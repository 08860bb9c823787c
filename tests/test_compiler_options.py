"""Per-computation XLA options (jaxfric/_xla.py): validation, platform choice, and that
the options change speed only, never results."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfric as jf
from jaxfric import _xla
from jaxfric import functions as F


def test_auto_options_are_cpu_only():
    assert jf.compiler_options("solver", "cpu") == {
        "xla_cpu_prefer_vector_width": 512,
        "xla_cpu_use_fusion_emitters": False,
    }
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
    given = {"xla_cpu_use_fusion_emitters": True, "xla_cpu_prefer_vector_width": 256}
    frozen = _xla.resolve(given, "solver")
    assert frozen == tuple(sorted(given.items()))
    assert given == {"xla_cpu_use_fusion_emitters": True, "xla_cpu_prefer_vector_width": 256}
    hash(frozen)


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
    np.testing.assert_allclose(jax.jit(lambda t: el.simulate_batch(t, u))(th), eager, rtol=1e-6)
    np.testing.assert_allclose(jax.jit(lambda: el.simulate_batch(th, u))(), eager, rtol=1e-6)
    np.testing.assert_allclose(jax.vmap(lambda t: el.simulate(t, u))(th), eager, rtol=1e-6)
    assert jax.eval_shape(lambda t: el.simulate_batch(t, u), th).shape == (3, 50)
    g = jax.grad(lambda t: jnp.sum(el.simulate(t, u) ** 2))(th[0])
    assert g.shape == th[0].shape and bool(jnp.all(jnp.isfinite(g)))
