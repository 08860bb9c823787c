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
    st = _solver().ask_init(np.full(2, -1.0), np.full(2, 1.0), jax.random.key(0))
    run = st._run
    while not _solver().ask_done(st):
        X, st = _solver().ask(st)
        st = _solver().tell(st, X, [_sphere(x) for x in np.asarray(X)])
    assert not run.thread.is_alive()
    assert run.token not in asktell._CHANNELS


def test_interpreter_exit_stops_an_open_run():
    st = _solver().ask_init(np.full(2, -1.0), np.full(2, 1.0), jax.random.key(1))
    X, st = _solver().ask(st)
    run = st._run
    assert run.thread.is_alive() and run.token in asktell._CHANNELS
    asktell._abandon_all()          # what atexit runs
    assert not run.thread.is_alive()
    assert run.token not in asktell._CHANNELS
