"""jaxfric's NelderMead as an optimistix citizen, run the way optimistix runs its minimisers.

The minimisation problems, their starting points (pytree ``y0`` included), arguments,
tolerances and the settings they run under (float64, ``jax_numpy_rank_promotion="raise"``,
``jax_numpy_dtype_promotion="strict"``, ``max_steps=10_000``, ``throw=False``,
``options={"autodiff_mode": ...}``, aux output ``(ones((2, 3)), {"smoke_aux": ones(2)})``)
follow optimistix v0.1.0's ``tests/test_minimise.py`` and ``tests/helpers.py``
(https://github.com/patrick-kidger/optimistix, Copyright 2023 Google LLC and the
optimistix authors, Apache License 2.0, http://www.apache.org/licenses/LICENSE-2.0).
The functions are restated here in plain ``jax.numpy`` (trimmed to the Nelder–Mead cases);
changes: the optimistix helpers' ``ω`` tree arithmetic is written out, and the aux also
carries the objective value so that the aux can be checked against the returned point.

Beyond those cases: aux at the best vertex, pytree ``y0``, ``throw``, ``jit``, ``vmap``,
gradients through the solution (``adjoint=optx.ImplicitAdjoint()``, against hand-derived
derivatives), restarts and batched trial points with exact evaluation counts.
"""

from __future__ import annotations

import contextlib

import equinox as eqx
import jax
import jax.flatten_util as jfu
import jax.numpy as jnp
import jax.random as jr
import jax.tree_util as jtu
import numpy as np
import optimistix as optx
import pytest

import jaxfric as jf
from jaxfric import functions as F


@contextlib.contextmanager
def optimistix_settings():
    """What optimistix's tests/conftest.py sets globally, here as context managers."""
    with jax.enable_x64(True), jax.numpy_rank_promotion("raise"), jax.numpy_dtype_promotion("strict"):
        yield


# ------------------------------------------------------------------ problems (Apache-2.0)
def bowl(tree, matrix):
    y, _ = jfu.ravel_pytree(tree)
    return y.T @ matrix @ y


def himmelblau(tree, args):
    (y, z), (c1, c2) = tree, args
    return (y**2 + z - c1) ** 2 + (y + z**2 - c2) ** 2


def matyas(tree, args):
    (y, z), (c1, c2) = tree, args
    return c1 * (y**2 + z**2) - c2 * y * z


def beale(tree, args):
    (y, z), (c1, c2, c3) = tree, args
    return (c1 - y + y * z) ** 2 + (c2 - y + y * z**2) ** 2 + (c3 - y + y * z**3) ** 2


def square_minus_one(x, args):
    return jnp.sum(jnp.square(x)) - 1.0


def problems():
    """``(name, fn, minimum, y0, args)`` as in optimistix's helpers (built under x64)."""
    bowl_init = ({"a": 0.05 * jnp.ones((2, 3, 3))}, 0.05 * jnp.ones(2))
    size = jfu.ravel_pytree(bowl_init)[0].size
    matrix = jr.normal(jr.PRNGKey(17), (size, size))
    return [
        ("bowl", bowl, 0.0, bowl_init, matrix.T @ matrix),
        ("himmelblau", himmelblau, 0.0, [jnp.array(2.0), jnp.array(2.5)], (jnp.array(11.0), jnp.array(7.0))),
        ("matyas", matyas, 0.0, [jnp.array(6.0), jnp.array(6.0)], (jnp.array(0.26), jnp.array(0.48))),
        ("beale", beale, 0.0, [jnp.array(2.0), jnp.array(0.0)],
         (jnp.array(1.5), jnp.array(2.25), jnp.array(2.625))),
        ("square_minus_one", square_minus_one, -1.0, jnp.array(1.0), None),
    ]


NAMES = ["bowl", "himmelblau", "matyas", "beale", "square_minus_one"]
SOLVER = jf.NelderMead(1e-8, 1e-8)  # optimistix's helpers: NelderMead(rtol, atol) with 1e-8


def problem(name):
    return next(p for p in problems() if p[0] == name)


# --------------------------------------------------------------------- optimistix's cases
@pytest.mark.parametrize(
    "name, mode", [(n, "fwd" if i % 2 == 0 else "bwd") for i, n in enumerate(NAMES)]
)
def test_optimistix_minimise_problems_with_aux(name, mode):
    """optimistix's test_minimise (atol = rtol = 1e-4 on the minimum), with ``has_aux=True``
    (before, every such call failed: ``step`` returned ``aux=None``). optimistix runs each
    problem under both ``autodiff_mode`` options; Nelder–Mead ignores them, so one each."""
    with optimistix_settings():
        _, fn, minimum, y0, args = problem(name)

        def with_aux(y, a):
            f = fn(y, a)
            return f, (jnp.ones((2, 3)), {"smoke_aux": jnp.ones(2), "f": f})

        sol = optx.minimise(with_aux, SOLVER, y0, args, options=dict(autodiff_mode=mode),
                            has_aux=True, max_steps=10_000, throw=False)
        f_min = fn(sol.value, args)
        assert np.allclose(np.asarray(f_min), minimum, atol=1e-4, rtol=1e-4), (name, f_min)
        assert sol.result == optx.RESULTS.successful
        # The aux belongs to the returned (best) point, not to the last trial point.
        assert float(sol.aux[1]["f"]) == float(sol.state.f_simplex[0])
        np.testing.assert_allclose(float(sol.aux[1]["f"]), float(f_min), rtol=1e-9, atol=1e-15)
        # eqx.tree_equal(sol.aux[0], jnp.ones((2, 3))) in NumPy (no eager program)
        ones = np.asarray(sol.aux[0])
        assert ones.shape == (2, 3) and ones.dtype == np.float64 and np.all(ones == 1.0)
        # Pytree y0: same structure, shapes and dtypes come back.
        assert jtu.tree_structure(sol.value) == jtu.tree_structure(y0)
        for a, b in zip(jtu.tree_leaves(sol.value), jtu.tree_leaves(y0)):
            assert a.shape == b.shape and a.dtype == b.dtype == jnp.float64


@pytest.mark.parametrize("name", ["matyas"])
def test_optimistix_minimise_jvp_primal(name):
    """optimistix's test_minimise_jvp through ``eqx.filter_jvp`` with ImplicitAdjoint
    (optimistix checks only the primal for Nelder–Mead; the tangents are checked against
    hand-derived values in test_gradient_through_the_solution)."""
    with optimistix_settings():
        _, fn, minimum, y0, args = problem(name)
        dyn, static = eqx.partition(args, eqx.is_array)
        key = jr.PRNGKey(0)
        t_y0 = jtu.tree_map(lambda x: jr.normal(key, x.shape), y0)
        t_dyn = jtu.tree_map(lambda x: jr.normal(key, x.shape), dyn)

        def run(y, d):
            return optx.minimise(fn, SOLVER, y, eqx.combine(d, static), max_steps=10_000,
                                 adjoint=optx.ImplicitAdjoint(), throw=False).value

        out, t_out = eqx.filter_jit(eqx.filter_jvp)(run, (y0, dyn), (t_y0, t_dyn))
        assert np.allclose(np.asarray(fn(out, args)), minimum, atol=1e-4, rtol=1e-4)
        assert all(np.all(np.isfinite(np.asarray(t))) for t in jtu.tree_leaves(t_out))


def test_rosenbrock_pytree_least_squares():
    """optimistix's least-squares case that minimisers also run: Rosenbrock residuals on a
    14-leaf-element pytree started at 1.45 (``optx.least_squares`` with a minimiser)."""
    def residuals(tree, c):
        y, _ = jfu.ravel_pytree(tree)
        return (100 * (y[1:] - y[:-1]), c - y[:-1])

    with optimistix_settings():
        y0 = (1.45 * jnp.ones((2, 4)), {"a": 1.45 * jnp.ones((2, 3, 2))}, ())
        sol = optx.least_squares(residuals, SOLVER, y0, jnp.array(1.0), max_steps=10_000, throw=False)
        # the residuals' sum of squares in NumPy (leaves in ravel_pytree's order)
        y = np.concatenate([np.ravel(np.asarray(x)) for x in jtu.tree_leaves(sol.value)])
        assert y.size == sum(np.size(x) for x in jtu.tree_leaves(y0))
        assert np.sum((100 * (y[1:] - y[:-1])) ** 2) + np.sum((1.0 - y[:-1]) ** 2) < 1e-4


# ------------------------------------------------------------------------ beyond those
def test_rank_promotion_raise_in_float32_with_bounds():
    """Bounds as a pytree of the y0 structure, float32, rank promotion raising."""
    with jax.numpy_rank_promotion("raise"), jax.numpy_dtype_promotion("strict"):
        y0 = {"a": jnp.full((2, 2), 0.5, jnp.float32), "b": jnp.array([0.3], jnp.float32)}
        lo = jtu.tree_map(lambda x: jnp.full_like(x, 0.2), y0)
        hi = jtu.tree_map(lambda x: jnp.full_like(x, 2.0), y0)
        fn = lambda y, _: jnp.sum((jfu.ravel_pytree(y)[0] - 0.7) ** 2)  # noqa: E731
        sol = optx.minimise(fn, jf.NelderMead(rtol=0.0, atol=1e-7), y0, options={"lower": lo, "upper": hi},
                            max_steps=5000, throw=False)
        flat = jfu.ravel_pytree(sol.value)[0]
        assert flat.dtype == jnp.float32
        np.testing.assert_allclose(np.asarray(flat), 0.7, atol=1e-3)
        S = np.asarray(sol.state.simplex)
        assert S.min() >= 0.2 and S.max() <= 2.0


def test_throw_raises_only_when_asked():
    fn = lambda y, _: F.rosenbrock(y)  # noqa: E731
    y0 = jnp.zeros(4)
    sol = optx.minimise(fn, jf.NelderMead(), y0, max_steps=3, throw=False)
    assert sol.result == optx.RESULTS.nonlinear_max_steps_reached
    with pytest.raises(Exception, match="maximum number of"):
        jax.block_until_ready(optx.minimise(fn, jf.NelderMead(), y0, max_steps=3, throw=True).value)


def shifted(y, a):
    return jnp.sum((y - a) ** 2 * jnp.arange(1.0, 1.0 + y.shape[0], dtype=y.dtype))


@pytest.mark.slow
def test_jit_and_vmap_match_single_runs():
    with jax.enable_x64(True):
        solver = jf.NelderMead(rtol=0.0, atol=1e-10)
        shifts = jnp.asarray(np.random.default_rng(0).uniform(-1, 1, (3, 4)))

        def run(a):
            return optx.minimise(shifted, solver, jnp.zeros(4), a, max_steps=5000, throw=False)

        singles = [run(a) for a in shifts]
        batched = jax.jit(jax.vmap(run))(shifts)
        for i, s in enumerate(singles):
            np.testing.assert_allclose(np.asarray(s.value), np.asarray(shifts[i]), atol=1e-5)
            # vmap runs the same steps: finished members stay put while others go on.
            np.testing.assert_allclose(np.asarray(batched.value[i]), np.asarray(s.value), rtol=1e-12, atol=1e-14)
            assert int(batched.stats["num_evals"][i]) == int(s.stats["num_evals"])


@pytest.mark.slow
def test_gradient_through_the_solution():
    """y*(a) = argmin Σ(y−a)² + c(Σy)²  ⇒  y* = a − c·Σa/(1 + n c)·1, so
    ∂y*_i/∂a_j = δ_ij − c/(1 + n c): reverse mode (jax.grad) and forward mode (jvp)
    through optx.minimise with the implicit-function-theorem adjoint."""
    c, n = 0.7, 3

    def fn(y, a):
        return jnp.sum((y - a) ** 2) + c * jnp.sum(y) ** 2

    with jax.enable_x64(True):
        solver = jf.NelderMead(rtol=0.0, atol=1e-12)

        def y_star(a):
            return optx.minimise(fn, solver, jnp.zeros(n), a, max_steps=20_000,
                                 adjoint=optx.ImplicitAdjoint(), throw=False).value

        a = jnp.array([0.3, -1.2, 2.0])
        expected = np.eye(n) - c / (1 + n * c)
        np.testing.assert_allclose(np.asarray(y_star(a)), np.asarray(a) - c * float(a.sum()) / (1 + n * c), atol=1e-6)
        np.testing.assert_allclose(np.asarray(jax.jacrev(y_star)(a)), expected, atol=1e-6)
        np.testing.assert_allclose(np.asarray(jax.jacfwd(y_star)(a)), expected, atol=1e-6)


def counted(counter, fn):
    """``counter.wrap`` for float64 runs: the host callback answers in float32 (its
    arguments reach the host thread without the x64 context), cast back here."""
    def wrapped(y, args):
        zero = jax.pure_callback(counter._record, jax.ShapeDtypeStruct((), jnp.float32),
                                 y.astype(jnp.float32), vmap_method="expand_dims")
        return fn(y, args) + zero.astype(y.dtype)

    return wrapped


def test_batched_trials_move_the_simplex_exactly_as_the_sequential_rule(counter):
    """Same steps and same final simplex; the evaluation count is exact for both
    (n + 1 to start, then 1–2 per sequential step or 4 per batched step, n per shrink)."""
    with jax.enable_x64(True):
        fn = lambda y, _: F.rosenbrock(y)  # noqa: E731
        y0 = jnp.asarray([-1.2, 1.0, 0.5, -0.3])
        runs = {}
        for batched in (False, True):
            counter.points.clear()
            solver = jf.NelderMead(rtol=0.0, atol=1e-9, batched_trials=batched)
            sol = optx.minimise(counted(counter, fn), solver, y0, max_steps=3000, throw=False)
            st = sol.state
            steps = int(sol.stats["num_steps"])
            assert int(st.num_evals) == counter.count
            moves = (int(st.num_reflections) + int(st.num_expansions) + int(st.num_contractions)
                     + int(st.num_shrinks))
            assert moves == steps
            runs[batched] = (np.asarray(st.simplex), steps, int(st.num_evals), int(st.num_shrinks))
        (s0, steps0, ev0, sh0), (s1, steps1, ev1, sh1) = runs[False], runs[True]
        assert steps0 == steps1 and sh0 == sh1
        np.testing.assert_array_equal(s0, s1)
        assert ev1 == 5 + 4 * steps1 + 4 * sh1
        assert 5 + steps0 + 4 * sh0 < ev0 <= 5 + 2 * steps0 + 4 * sh0
        assert float(F.rosenbrock(jnp.asarray(s0[0]))) < 1e-12


def test_restarts_count_exactly(counter):
    """Each restart re-evaluates n fresh vertices around the best: counted exactly."""
    with jax.enable_x64(True):
        fn = lambda y, _: F.rosenbrock(y)  # noqa: E731
        solver = jf.NelderMead(rtol=1e-4, atol=1e-4, restarts=2)
        sol = optx.minimise(counted(counter, fn), solver, jnp.asarray([-1.0, 1.5, 0.5, 2.0]),
                            max_steps=5000, throw=False)
        assert int(sol.state.num_evals) == counter.count
        assert int(sol.state.num_restarts) >= 1
        assert sol.result == optx.RESULTS.successful


@pytest.mark.slow
def test_restarts_finish_what_a_collapsed_simplex_leaves():
    """16-D Rosenbrock with the standard coefficients, 6 random starts: plain runs stall
    at f > 1 on some (the simplex collapses); restarts from their own result finish
    them and never make a run worse."""
    with jax.enable_x64(True):
        fn = lambda y, _: F.rosenbrock(y)  # noqa: E731
        y0s = jnp.asarray(np.random.default_rng(3).uniform(-2, 2, (6, 16)))
        out = {}
        for k in (0, 3):
            solver = jf.NelderMead(adaptive=False, restarts=k)
            run = jax.jit(jax.vmap(lambda y0: optx.minimise(fn, solver, y0, max_steps=200_000, throw=False)))
            sol = run(y0s)
            assert np.all(np.asarray(sol.result._value) == optx.RESULTS.successful._value)
            out[k] = (np.asarray(sol.state.f_simplex[:, 0]), np.asarray(sol.state.num_restarts))
        (f0, r0), (f3, r3) = out[0], out[3]
        assert np.all(r0 == 0) and np.all((r3 >= 1) & (r3 <= 3))
        assert np.all(f3 <= f0 + 1e-12)
        assert np.sum(f0 > 1.0) >= 2 and np.sum(f3 < 1e-10) >= 5
