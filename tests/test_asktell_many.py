"""ask/tell with several seeds in one run (``ask_init(..., keys=keys)``): every ask
carries every seed's batch, and the run is ``minimise_many(..., batching="vmap")``'s.
One PSO and one PSO -> Nelder-Mead chain on one box, so each compiles once."""

import jax
import numpy as np
import pytest

import jaxfric as jf

LO, HI = np.full(2, -2.0, np.float32), np.full(2, 3.0, np.float32)
TARGET = np.array([0.5, -0.25], np.float32)
KEYS = jax.random.split(jax.random.key(7), 3)
S = 3

PSO = jf.PSO(num_particles=4, num_generations=3)
CHAIN = jf.chain(jf.PSO(num_particles=4, num_generations=3), jf.NelderMead(max_steps=8))
SOLVERS = pytest.mark.parametrize("solver", [PSO, CHAIN], ids=["pso", "pso_nm"])


def separable_np(X):
    """A separable quadratic on the last axis of ``X``: ``(..., 2) -> (...)``."""
    d = np.asarray(X, np.float32) - TARGET
    return d[..., 0] * d[..., 0] + np.float32(10.0) * (d[..., 1] * d[..., 1])


def _drive(solver, objective=separable_np):
    """Drive ``solver`` with ``KEYS`` by ask/tell; the solution and every batch asked."""
    st = jf.ask_init(solver, LO, HI, keys=KEYS)
    asked = []
    while not jf.ask_done(st):
        X, st = jf.ask(st)
        asked.append(np.array(X))
        st = jf.tell(st, X, objective(X))
    return jf.ask_result(st), asked


_BATCHES = []  # the host batches of the latest _recipe run


def _host(X):
    X = np.asarray(X)
    _BATCHES.append(X.copy())
    return separable_np(X).astype(X.dtype)


def _recipe_objective(y, args):
    """``separable_np`` through a ``pure_callback``: one function object for the module,
    so each solver's minimise_many program compiles once for both tests that run it."""
    return jax.pure_callback(_host, jax.ShapeDtypeStruct(y.shape[:-1], y.dtype), y,
                             vmap_method="broadcast_all")


def _recipe(solver):
    """The documented recipe without ask/tell: a NumPy objective in a ``pure_callback``
    under ``minimise_many(..., batching="vmap")``; its solution and every host batch."""
    _BATCHES.clear()
    sol = jf.minimise_many(_recipe_objective, solver, (LO, HI), keys=KEYS, batching="vmap")
    return sol, list(_BATCHES)


@SOLVERS
def test_several_seeds_in_one_run_give_minimise_many(solver):
    """Each ask is ``(S, k, n)``, each seed's block; the batched solution is
    minimise_many's for the same keys (same tolerance as the single-seed tests, the
    counts exactly). minimise_many runs the recipe's objective (``separable`` in NumPy,
    through a pure_callback): the program test_an_ask_is_a_host_call... compiles too,
    so the module compiles one minimise_many program per solver."""
    ref, _ = _recipe(solver)
    sol, asked = _drive(solver)
    assert all(X.ndim == 3 and X.shape[0] == S and X.shape[2] == 2 for X in asked)
    assert np.shape(sol.value) == (S, 2) and np.shape(sol.f) == (S,)
    np.testing.assert_allclose(sol.value, ref.value, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(sol.f, ref.f, rtol=1e-5, atol=1e-7)
    assert sol.stats.keys() == ref.stats.keys()
    for name in ref.stats:
        np.testing.assert_array_equal(sol.stats[name], ref.stats[name], err_msg=name)
    np.testing.assert_array_equal(sol.result._value, ref.result._value)
    # the seeds do differ: one run of three seeds, not three copies of one
    assert len({tuple(v) for v in np.asarray(sol.value).tolist()}) == S


@SOLVERS
def test_an_ask_is_a_host_call_of_the_pure_callback_recipe(solver):
    """One ask per host call of the recipe, with the same points (both runs are told the
    same NumPy values)."""
    sol, asked = _drive(solver)
    ref, batches = _recipe(solver)
    assert len(asked) == len(batches)
    for X, B in zip(asked, batches):
        np.testing.assert_array_equal(X, B.reshape(X.shape))
    np.testing.assert_array_equal(sol.value, ref.value)


def test_best_so_far_is_per_seed():
    """Before the run ends, ask_result is each seed's best row told so far, and
    ``num_told`` counts the values told per seed."""
    st = jf.ask_init(PSO, LO, HI, keys=KEYS)
    X, st = jf.ask(st)
    f = separable_np(X)
    st = jf.tell(st, X, f)
    assert st.num_told == X.shape[1]
    part = jf.ask_result(st)
    best = np.argmin(f, axis=1)
    np.testing.assert_array_equal(part.f, f[np.arange(S), best])
    np.testing.assert_array_equal(part.value, X[np.arange(S), best])
    np.testing.assert_array_equal(part.stats["num_evals"], np.full(S, X.shape[1]))


def test_ask_init_and_tell_refuse_what_does_not_fit():
    with pytest.raises(ValueError, match="not both"):
        jf.ask_init(PSO, LO, HI, jax.random.key(0), keys=KEYS)
    with pytest.raises(ValueError, match="key= .* or keys="):
        jf.ask_init(PSO, LO, HI)
    with pytest.raises(ValueError, match="batch of keys"):
        jf.ask_init(PSO, LO, HI, keys=jax.random.key(0))
    st = jf.ask_init(PSO, LO, HI, keys=KEYS)
    X, st = jf.ask(st)
    with pytest.raises(ValueError, match="one fitness value per candidate"):
        jf.tell(st, X, separable_np(X).reshape(-1))   # (S * k,), not (S, k)
    with pytest.raises(ValueError, match="one fitness value per candidate"):
        jf.tell(st, X, separable_np(X)[0])            # one seed's values
    with pytest.raises(ValueError, match="the batch ask returned"):
        jf.tell(st, X[0], separable_np(X[0]))


def test_an_abandoned_run_of_several_seeds_ends():
    """A run of several seeds dropped half-way answers its remaining batches with +inf
    (one value per seed and row) and its worker thread leaves the compiled run."""
    import gc

    st = jf.ask_init(PSO, LO, HI, keys=KEYS)
    X, st = jf.ask(st)
    st = jf.tell(st, X, separable_np(X))
    channel = st._run.channel  # not the run: dropping that is what abandons it
    del st, X
    gc.collect()
    channel.thread.join(60)
    assert not channel.thread.is_alive()
    assert channel.out.get_nowait()[0] == "done"  # not "error"
