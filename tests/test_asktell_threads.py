"""ask/tell's worker threads never outlive what they are for: a thread still inside the
compiled run (in a ``pure_callback``) when the interpreter finalises is unwound through
XLA's frames, and the process aborts."""

import jax
import numpy as np

import jaxfric as jf
from jaxfric.optim import asktell


def _sphere(x):
    return float(np.sum(np.asarray(x) ** 2))


def _solver():
    return jf.PSO(num_particles=4, num_generations=3)


def test_a_finished_run_has_joined_its_thread():
    st = jf.ask_init(_solver(), np.full(2, -1.0), np.full(2, 1.0), jax.random.key(0))
    run = st._run
    while not jf.ask_done(st):
        X, st = jf.ask(st)
        st = jf.tell(st, X, [_sphere(x) for x in np.asarray(X)])
    assert not run.thread.is_alive()
    assert run.token not in asktell._CHANNELS


def test_interpreter_exit_stops_an_open_run():
    st = jf.ask_init(_solver(), np.full(2, -1.0), np.full(2, 1.0), jax.random.key(1))
    X, st = jf.ask(st)
    run = st._run
    assert run.thread.is_alive() and run.token in asktell._CHANNELS
    asktell._abandon_all()          # what atexit runs
    assert not run.thread.is_alive()
    assert run.token not in asktell._CHANNELS


def test_a_float64_run_keeps_float64_on_xla_callback_threads():
    """Under ``jax.enable_x64`` (a thread-local setting) XLA may answer the callback on a
    thread of its own, where JAX rounded float64 operands to float32 and refused the
    values told (in 2 runs of 3 with three asks of a 25 × 5 population). The points stay float64 and the run equals
    minimise's."""
    solver = jf.PSO(num_particles=25, num_generations=10)
    lo, hi = np.full(5, -2.0), np.full(5, 2.0)
    shift = 0.1234567890123

    def fn(y, args):
        return jax.numpy.sum((y - shift) ** 2)

    with jax.enable_x64(True):
        st = jf.ask_init(solver, lo, hi, 3)
        while not jf.ask_done(st):
            X, st = jf.ask(st)
            assert X.dtype == np.float64
            st = jf.tell(st, X, np.sum((np.asarray(X) - shift) ** 2, axis=1))
        sol = jf.ask_result(st)
        ref = jf.minimise(fn, solver, (lo, hi), key=3)
    np.testing.assert_array_equal(sol.value, ref.value)
    assert int(sol.stats["num_evals"]) == int(ref.stats["num_evals"]) == 25 * 11
