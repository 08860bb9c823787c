"""The solver's program traced once per solver and shape, each new objective filled in
(jaxfric.optim.template, issue 47): the same results to the bit as tracing the program
with the objective, the template found again for a new objective, and the usual trace
wherever the template cannot serve."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfric as jf
from jaxfric import functions as F
from jaxfric.optim import driver, template


def leaves(sol):
    return [np.asarray(x) for x in jax.tree_util.tree_leaves(
        (sol.value, sol.f, sol.stats, sol.history))]


def same(a, b):
    la, lb = leaves(a), leaves(b)
    assert len(la) == len(lb)
    for x, y in zip(la, lb):
        np.testing.assert_array_equal(x, y)


def untemplated(monkeypatch):
    """The driver's usual trace of the program with the objective in it."""
    monkeypatch.setattr(driver, "templated", lambda *a: a[5])


def spliced(fn):
    """Whether ``fn``'s programs were compiled from the template's lowered text (not
    lowered again whole)."""
    return all(isinstance(program, template._Compiled)
               for program, _, _ in template._PROGRAMS.get(fn, {}).values())


SOLVERS = {
    "mapso_nmds": lambda: jf.mapso_nmds(num_generations=6, nm_max_steps=60),
    "pso_nm": lambda: jf.chain(jf.PSO(num_generations=10), jf.NelderMead(max_steps=60)),
    "pso": lambda: jf.PSO(num_generations=10),
    "nelder_mead": lambda: jf.NelderMead(max_steps=60),
    "mapso_3_starts": lambda: jf.mapso_nmds(num_generations=6, nm_max_steps=40, num_starts=3),
}


# every solver at "auto" (level 0 here: cheap to compile); the two chains at full optimisation too
@pytest.mark.parametrize("name,options", [(name, "auto") for name in sorted(SOLVERS)]
                         + [("mapso_nmds", "full"), ("pso_nm", "full")])
def test_filled_in_objective_gives_the_traced_programs_result(name, options, monkeypatch):
    bounds = F.get("rosenbrock").bounds(3, np.float32)
    jf.minimise(lambda y, a: F.sphere(y), SOLVERS[name](), bounds, key=0,
                compiler_options=options)  # the template, traced with another objective
    before = len(template._TEMPLATES)
    fn = lambda y, a: F.rosenbrock(y)  # noqa: E731
    filled = jf.minimise(fn, SOLVERS[name](), bounds, key=1, compiler_options=options)
    assert len(template._TEMPLATES) == before  # found again, not traced again
    assert spliced(fn), "the template's lowering served this run"
    untemplated(monkeypatch)
    traced = jf.minimise(lambda y, a: F.rosenbrock(y), SOLVERS[name](), bounds, key=1,
                         compiler_options=options)
    same(filled, traced)


def test_pytree_bounds_args_and_start_in_float64(monkeypatch):
    def fn(y, a):
        return jnp.sum((y["a"] - a) ** 2) + jnp.sum(jnp.cos(y["b"]) * y["b"] ** 2)

    bounds = ({"a": -np.ones(3), "b": -np.ones((2, 2))}, {"a": np.ones(3), "b": np.ones((2, 2))})
    y0 = {"a": np.zeros(3), "b": np.full((2, 2), 0.5)}
    args = np.array([0.1, -0.2, 0.3])
    with jax.enable_x64(True):
        runs = [jf.minimise(fn, SOLVERS["mapso_nmds"](), bounds, args=args, key=2, y0=y0,
                            compiler_options="full")]
        assert template._PROGRAMS.get(fn) and spliced(fn), "the template served this run"
        untemplated(monkeypatch)
        runs.append(jf.minimise(fn, SOLVERS["mapso_nmds"](), bounds, args=args, key=2, y0=y0,
                                compiler_options="full"))
    assert runs[0].f.dtype == np.float64
    same(*runs)


def test_second_call_of_an_objective_compiles_nothing():
    compiled = []

    def listen(event, duration, **kw):
        if event == "/jax/core/compile/backend_compile_duration":
            compiled.append(kw.get("fun_name"))

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        bounds = F.get("rastrigin").bounds(2, np.float32)
        fn = lambda y, a: F.rastrigin(y)
        first = jf.minimise(fn, SOLVERS["pso_nm"](), bounds, key=0)
        n = len(compiled)
        again = jf.minimise(fn, SOLVERS["pso_nm"](), bounds, key=0)
        assert len(compiled) == n
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
    same(first, again)


def test_where_the_template_cannot_serve_the_usual_trace_runs():
    bounds = F.get("sphere").bounds(2, np.float32)
    # a Python number in args (static in a trace), and a weakly typed output
    scaled = jf.minimise(lambda y, a: a * F.sphere(y), SOLVERS["pso"](), bounds, args=2.0, key=0)
    weak = jf.minimise(lambda y, a: 1.0, SOLVERS["pso"](), bounds, key=0)
    np.testing.assert_allclose(float(scaled.f), 2.0 * float(F.sphere(scaled.value)), rtol=1e-6)
    assert float(weak.f) == 1.0


def test_objectives_with_their_own_functions_constants_and_unused_data(monkeypatch):
    """The lowered template takes objectives whose own lowering holds functions of theirs
    (``jnp.where``, ``clip``: named as some of the solver's are), constants, data they
    read and data they ignore; each run equals the traced program's to the bit."""
    table = np.linspace(0.5, 2.0, 7)

    def helpers(y, a):
        return jnp.sum(jnp.where(y > 0, y, -2.0 * y)) + jnp.max(jnp.clip(y, -0.5, 0.5))

    def constants(y, a):
        return jnp.sum(table[: y.shape[0]] * y ** 2) + jnp.sum(a * y)

    def ignores(y, a):
        return jnp.sum(y ** 2)

    args = np.array([0.3, -0.1, 0.2])
    cases = [(helpers, None), (constants, args), (ignores, args)]
    bounds = F.get("sphere").bounds(3, np.float32)
    runs = [jf.minimise(fn, SOLVERS["mapso_nmds"](), bounds, args=a, key=5) for fn, a in cases]
    assert spliced(helpers) and spliced(constants)
    untemplated(monkeypatch)
    for (fn, a), run in zip(cases, runs):
        same(run, jf.minimise(fn, SOLVERS["mapso_nmds"](), bounds, args=a, key=5))


def test_a_template_whose_lowering_cannot_be_spliced_is_lowered_whole(monkeypatch):
    """Where the lowered text cannot serve, the filled program is lowered whole: the
    same result as before, by the other path."""
    bounds = F.get("sphere").bounds(2, np.float32)
    fn = lambda y, a: F.rastrigin(y)  # noqa: E731
    monkeypatch.setattr(template, "_slot_functions", lambda eqns: {})  # nothing found
    whole = jf.minimise(fn, SOLVERS["pso_nm"](), bounds, key=3)
    assert template._PROGRAMS.get(fn) and not spliced(fn)
    monkeypatch.undo()
    untemplated(monkeypatch)
    same(whole, jf.minimise(fn, SOLVERS["pso_nm"](), bounds, key=3))


def test_a_template_that_cannot_be_lowered_for_splicing_is_tried_once(monkeypatch):
    """A template whose lowering fails is remembered: later objectives of the same shape
    go straight to lowering the filled program (the same results as the usual trace)."""
    tries = []

    def refuse(self, *a):
        tries.append(1)
        raise RuntimeError("no")

    monkeypatch.setattr(template._Lowering, "__init__", refuse)
    monkeypatch.setattr(template, "_LOWERINGS", type(template._LOWERINGS)())
    bounds = F.get("sphere").bounds(4, np.float32)
    fns = [lambda y, a: F.sphere(y), lambda y, a: F.rastrigin(y)]
    runs = [jf.minimise(fn, SOLVERS["pso"](), bounds, key=2) for fn in fns]
    assert len(tries) == 1 and not any(spliced(fn) for fn in fns)
    monkeypatch.undo()
    untemplated(monkeypatch)
    for fn, run in zip(fns, runs):
        same(run, jf.minimise(fn, SOLVERS["pso"](), bounds, key=2))
