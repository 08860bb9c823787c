"""Parallel-in-time evaluation (DEER) against the sequential ``lax.scan`` on every model
it covers: the Elman network's contexts, and the motion models' (x, v, friction state)
for Coulomb, Stribeck, LuGre and Dahl. Float64 (``jax.enable_x64``) unless stated."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfric.models as M
from jaxfric.motion import friction_step
from jaxfric.motion._forward import simulate_motion
from jaxfric.parallel_scan import deer_scan, elman_rollout, linear_solve, simulate_motion_parallel

#: Agreement with the sequential scan: the Newton iterations stop at a per-component
#: update of sqrt(eps) = 1.5e-8; where the step is smooth the convergence is quadratic
#: and the error is then of order eps (1e-14 measured).
RTOL64 = 1e-11
#: The friction of a static motion model passes the velocity through a steep smooth sign
#: tanh(v / v_eps): a change of the force by 1e-16 relative moved the sequential scan's
#: own friction by 5e-10 relative (Stribeck), so the friction is compared at this level.
RTOL64_FRICTION = 1e-8


@pytest.fixture(autouse=True)
def x64():
    with jax.enable_x64(True):
        yield


def _rel(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def test_the_linear_solve_matches_a_loop():
    rng = np.random.default_rng(0)
    T, n = 37, 3
    jac = rng.uniform(-0.9, 0.9, (T, n, n)) / n
    bias = rng.normal(size=(T, n))
    s0 = rng.normal(size=n)
    s, want = s0, []
    for k in range(T):
        s = jac[k] @ s + bias[k]
        want.append(s)
    # jitted: called eagerly its log2(T) levels compiled as a hundred small programs
    solve = jax.jit(linear_solve, static_argnums=3)
    got = solve(jnp.asarray(jac), jnp.asarray(bias), jnp.asarray(s0), False)
    np.testing.assert_allclose(got, np.array(want), rtol=1e-12, atol=1e-12)
    diag = solve(jnp.asarray(jac[:, 0, :]), jnp.asarray(bias), jnp.asarray(s0), True)
    s, want = s0, []
    for k in range(T):
        s = jac[k, 0] * s + bias[k]
        want.append(s)
    np.testing.assert_allclose(diag, np.array(want), rtol=1e-12, atol=1e-12)


def test_a_nonlinear_pytree_recurrence_equals_lax_scan():
    """A contracting 2-state map with a pytree carry (dense Jacobian)."""
    xs = jnp.sin(jnp.linspace(0.0, 30.0, 500))

    def step(c, x):
        a, b = c
        return jnp.tanh(0.8 * a - 0.3 * b["z"] + x), {"z": 0.5 * b["z"] + 0.2 * jnp.sin(a)}

    init = (jnp.asarray(0.3), {"z": jnp.asarray(-0.1)})
    want = jax.jit(lambda i, x: jax.lax.scan(lambda c, x: (step(c, x), step(c, x)), i, x)[1])(init, xs)
    got = jax.jit(lambda i, x: deer_scan(step, i, x))(init, xs)
    assert bool(got.converged) and not bool(got.fell_back) and int(got.iterations) < 30
    for g, w in zip(jax.tree_util.tree_leaves(got.states), jax.tree_util.tree_leaves(want)):
        assert _rel(g, w) < RTOL64


def test_non_convergence_falls_back_to_the_sequential_scan():
    xs = jnp.linspace(0.0, 1.0, 200)

    def step(c, x):
        return jnp.tanh(0.9 * c + x)

    want = jax.lax.scan(lambda c, x: (step(c, x), step(c, x)), jnp.asarray(0.0), xs)[1]
    cut = deer_scan(step, jnp.asarray(0.0), xs, max_iterations=1, fallback=False)
    assert not bool(cut.converged) and _rel(cut.states, want) > 1e-6  # one iteration is not enough
    fb = deer_scan(step, jnp.asarray(0.0), xs, max_iterations=1)
    assert bool(fb.fell_back)
    np.testing.assert_array_equal(fb.states, want)


@pytest.mark.parametrize("bad, message", [
    (dict(jacobian="full"), "jacobian must be"),
    (dict(rtol=0.0), "rtol must be positive"),
    (dict(max_iterations=0), "max_iterations"),
])
def test_bad_options_are_refused(bad, message):
    with pytest.raises(ValueError, match=message):
        deer_scan(lambda c, x: c + x, jnp.asarray(0.0), jnp.ones(3), **bad)


def test_an_empty_record_is_refused():
    with pytest.raises(ValueError, match="empty"):
        deer_scan(lambda c, x: c + x, jnp.asarray(0.0), jnp.ones(0))


# ------------------------------------------------------------------ Elman
def _elman_case(model, seed=0, P=6, T=600):
    """Parameters and input drawn in NumPy (eager jnp would compile each operation)."""
    lo, hi = model.bounds()
    th = np.random.default_rng(seed).uniform(lo, hi, (P, model.num_params))
    u = 0.9 * np.sin(np.linspace(0.0, 25.0, T)) * np.cos(np.linspace(0.0, 3.0, T))
    return jnp.asarray(th), jnp.asarray(u)


@pytest.mark.parametrize("model", [
    M.Elman(neurons=12, context_weight_bound=0.5, alpha_max=0.9),
    M.Elman(neurons=12, context_weight_bound=1.0, alpha_max=0.5, output_bias=True),
], ids=["slope_below_1.4", "output_bias"])
def test_elman_contexts_in_parallel_equal_the_scan(model):
    th, u = _elman_case(model)
    y, info = jax.jit(lambda t, v: elman_rollout(model, t, v, return_info=True))(th, u)
    assert bool(info.converged) and not bool(info.fell_back)
    assert _rel(y, model.simulate_batch(th, u)) < RTOL64


def test_elman_default_box_is_not_contracting_and_falls_back():
    """With α up to 0.99 and |r| up to 1 the linearised context map can expand
    (|α + r (1 - h²)| up to 1.99), so Newton does not settle in 100 iterations: the
    sequential scan gives the answer (DEER's known limit for unstable recurrences)."""
    model = M.Elman(neurons=12, context_weight_bound=1.0)
    th, u = _elman_case(model, P=4, T=400)
    y, info = jax.jit(lambda t, v: elman_rollout(model, t, v, return_info=True, max_iterations=20))(th, u)
    assert _rel(y, model.simulate_batch(th, u)) < RTOL64
    assert bool(info.fell_back) == (not bool(info.converged))


def test_elman_float32_agrees_to_float32_precision():
    model = M.Elman(neurons=12, context_weight_bound=0.5, alpha_max=0.9)
    th, u = _elman_case(model)
    with jax.enable_x64(False):
        th32, u32 = jnp.asarray(th, jnp.float32), jnp.asarray(u, jnp.float32)
        y, info = jax.jit(lambda t, v: elman_rollout(model, t, v, return_info=True))(th32, u32)
        assert y.dtype == jnp.float32 and bool(info.converged)
        assert _rel(y, model.simulate_batch(th32, u32)) < 1e-5


def test_elman_rollout_refuses_other_models():
    with pytest.raises(ValueError, match="Elman"):
        elman_rollout(M.ElmanFull(neurons=3), jnp.zeros((1, M.ElmanFull(neurons=3).num_params)), jnp.ones(5))


# ------------------------------------------------------------------ motion
#: Every friction model of the motion step with float states: static maps (x, v) and the
#: bristle models (x, v, z), the latter with their §13.1 options.
MOTION_MODELS = [M.Coulomb(), M.Stribeck(), M.LuGre(asymmetric=True, offset=True), M.Dahl(viscous=True)]


@functools.cache
def _motion_case(model, T=400):
    """A two-tone force on 5 kg from (0.01 m, 0.02 m/s), the model's parameters 40 % into
    its data-centred box, and the sequential scan's free run: ``(step, theta, force, dt, T,
    want)``. Cached: the chunked tests compare with the same reference run."""
    dt = 1e-3
    t = np.arange(T) * dt
    force = 30.0 * np.sin(2 * np.pi * 1.3 * t) + 5.0 * np.sin(2 * np.pi * 7.0 * t)
    lo, hi = model.bounds(model.search_box(None, 0.1 * np.sin(t), force))
    theta = jnp.asarray(lo + 0.4 * (hi - lo))
    step = friction_step(model)
    want = jax.jit(lambda th: simulate_motion(step, th, 5.0, force, dt, 0.01, 0.02))(theta)
    return step, theta, force, dt, T, want


@pytest.mark.parametrize("model", MOTION_MODELS, ids=lambda m: repr(m).split("(")[0] + str(len(m.param_names)))
def test_motion_states_in_parallel_equal_the_scan(model):
    step, theta, force, dt, T, want = _motion_case(model)
    got, info = jax.jit(lambda th: simulate_motion_parallel(
        step, th, 5.0, force, dt, 0.01, 0.02, return_info=True, max_iterations=T))(theta)
    assert bool(info.converged) and not bool(info.fell_back)
    assert _rel(got["x"], want["x"]) < RTOL64 and _rel(got["v"], want["v"]) < RTOL64
    assert _rel(got["friction"], want["friction"]) < RTOL64_FRICTION


def test_chunked_motion_equals_the_scan():
    """LuGre with its asymmetric and offset options, as above, so the reference is shared.
    Chunks of 150 steps: three in a row, each from the last state of the one before, and a
    padded tail (150 does not divide 400)."""
    model = M.LuGre(asymmetric=True, offset=True)
    step, theta, force, dt, T, want = _motion_case(model)
    got, info = simulate_motion_parallel(step, theta, 5.0, force, dt, 0.01, 0.02, chunk=150,
                                         return_info=True)
    assert bool(info.converged) and not bool(info.fell_back)
    for k in ("x", "v", "friction"):
        assert got[k].shape == (T,) and _rel(got[k], want[k]) < RTOL64, k


def test_chunk_must_be_positive():
    with pytest.raises(ValueError, match="chunk"):
        deer_scan(lambda c, x: c + x, jnp.asarray(0.0), jnp.ones(3), chunk=0)
