"""The loop every solver runs in, one compiled program (docs/algorithms.md §5.1 for the
two-stage case)::

    state = start()                            # init_rounds, evaluated in the program
    for stage in range(num_stages):            # a chain: global, then local
        while not finished(state) and stage(state) == stage:
            state = step(state, stage)         # step_rounds, evaluated in the program
            record history

[`jaxfric.minimise`][jaxfric.optim.minimise] compiles `_chunk`: the start (or the carry
of an earlier chunk) and the loop up to a step count. A run with a progress display or
a checkpoint calls it again and again, reporting and saving between the calls on the
host; a plain run calls it once. It is one program either way, with no host callback in
it, so JAX's persistent compilation cache keeps it like any other, and chunked and whole
runs take bit-identical steps. ask/tell ([`jaxfric.optim.asktell`][jaxfric.optim.asktell])
compiles `_run`, the whole run at once, with an objective answered from Python.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._base import NO_STEP_CAP, History, Solution
from .contract import AbstractStaged, capabilities_of, progress_of, stage_of
from .rounds import compiled_start, compiled_step


#: Most history entries kept (a longer run keeps every 2nd, 4th, ... step).
HISTORY_SIZE = 4096


class Carry(eqx.Module):
    """What the loop carries (and a checkpoint stores): the solver's state, the
    history, and the number of steps taken by this call's loop so far."""

    state: Any
    history: History
    steps: Any


# -------------------------------------------------------------------- the loop
def _history_size(proto, n: int) -> int:
    """Entries of a run's history buffer: the run's steps, its first entry and room for
    one more, at most `HISTORY_SIZE`."""
    cap = capabilities_of(proto, n).max_steps
    return min((NO_STEP_CAP if cap is None else cap) + 2, HISTORY_SIZE)


def _record(proto, state, history, fills: bool = True):
    _, f = proto.best(state)
    return history.record(proto.num_evals(state), f, fills)


def _strong(tree):
    """Every array of ``tree`` with a fixed (not weak) dtype, so a carry built on the host
    (``blank_carry``), one loaded from a checkpoint and
    one returned by `_chunk` are the same input type to it (no recompilation)."""
    return jax.tree_util.tree_map(
        lambda a: jnp.asarray(a, a.dtype) if isinstance(a, jax.Array) else a, tree)


def _begin(proto, flat, lower, upper, args, key, x0, warm) -> Carry:
    state = compiled_start(proto, flat, lower, upper, args, key, x0) if warm is None else warm
    size = _history_size(proto, lower.shape[0])
    _, f = proto.best(state)
    history = History.first(size, proto.num_evals(state), jnp.asarray(f).astype(lower.dtype))
    return _strong(Carry(state, history, jnp.array(0, jnp.int32)))


def blank_carry(like, impl):
    """A carry of zeros shaped as ``like`` (``eqx.filter_eval_shape`` of `_begin`), its
    PRNG keys of implementation ``impl``: the unused ``carry`` argument of a chunk that
    starts the run. NumPy zeros put on the device: it compiles nothing."""
    def zero(x):
        if not isinstance(x, jax.ShapeDtypeStruct):
            return x
        if jnp.issubdtype(x.dtype, jax.dtypes.prng_key):
            raw = jax.eval_shape(jax.random.key_data, x)
            return jax.random.wrap_key_data(jax.device_put(np.zeros(raw.shape, raw.dtype)),
                                            impl=impl)
        return jax.device_put(np.zeros(x.shape, x.dtype))

    return jax.tree_util.tree_map(zero, like)


def _done(proto, state):
    """Whether the run has finished (``finished``'s first half; a staged solver's own
    ``done``, which leaves the result untraced)."""
    return proto.done(state) if isinstance(proto, AbstractStaged) else proto.finished(state)[0]


def _loop(proto, flat, lower, upper, args, carry: Carry, stop_at) -> Carry:
    """Steps until the solver terminates or ``carry.steps == stop_at``, stage by stage."""
    n = lower.shape[0]
    # A buffer below HISTORY_SIZE holds the first entry and one per step of the run (at
    # most its max_steps), so it never fills: its compression stays out of the program
    fills = _history_size(proto, n) >= HISTORY_SIZE
    for s in range(capabilities_of(proto, n).num_stages):
        def cond(c, s=s):
            return ~_done(proto, c.state) & (stage_of(proto, c.state) == s) & (c.steps < stop_at)

        def body(c, s=s):
            state = compiled_step(proto, flat, lower, upper, args, c.state, s)
            return Carry(state, _record(proto, state, c.history, fills), c.steps + 1)

        carry = jax.lax.while_loop(cond, body, carry)
    return carry


def _end(proto, flat, lower, upper, args, carry: Carry) -> Solution:
    _, result = proto.finished(carry.state)
    sol = proto.solution(flat, lower, upper, args, carry.state, result)
    _, f = proto.best(carry.state)
    history = carry.history.close(proto.num_evals(carry.state), f).filled()
    return eqx.tree_at(lambda s: s.history, sol, history)


#: ``stop_at`` of a run that is not chunked (always an array: one compiled loop for
#: chunked and whole runs, so they take bit-identical steps)
NO_STOP = 2**31 - 1


class Report(eqx.Module):
    """Where a chunked run stands after a chunk, for the host: the progress phase and
    step (``contract.progress_of``), the
    evaluations, the best value, and whether the run has finished."""

    phase: Any
    step: Any
    evals: Any
    f_best: Any
    done: Any


def _report(proto, carry: Carry) -> Report:
    phase, step = progress_of(proto, carry.state)
    return Report(phase, step, proto.num_evals(carry.state), proto.best(carry.state)[1],
                  _done(proto, carry.state))


def _chunk(proto, flat, lower, upper, args, key, x0, warm, carry, fresh, stop_at):
    """[`jaxfric.minimise`][jaxfric.optim.minimise]'s program that calls the objective:
    the start when ``fresh`` (a boolean array; ``carry`` is then a ``blank_carry``),
    else ``carry``; then steps until done or ``carry.steps == stop_at``. Returns
    ``(carry, report)``; `_finish` makes the solution of the last carry."""
    carry = jax.lax.cond(
        fresh, lambda: _begin(proto, flat, lower, upper, args, key, x0, warm),
        lambda: _strong(carry))
    carry = _strong(_loop(proto, flat, lower, upper, args, carry, stop_at))
    return carry, _report(proto, carry)


def _finish(proto, flat, lower, upper, args, carry) -> Solution:
    """The solution of a run's last carry, a program of its own: it never calls the
    objective (unless an optimistix minimiser's ``postprocess`` does), so the driver
    compiles it without one (``driver.objective_free``) once per solver and problem shape, and a
    new objective compiles only `_chunk` (issue 47)."""
    return _end(proto, flat, lower, upper, args, carry)


def _run(proto, flat, lower, upper, args, key, x0, carry=None, warm=None, stop_at=None):
    """The whole run in one call (ask/tell's program): start (unless ``carry`` continues
    a run), loop until done or ``stop_at`` steps, and the solution. Returns
    ``(carry, solution)``."""
    if carry is None:
        carry = _begin(proto, flat, lower, upper, args, key, x0, warm)
    stop_at = jnp.asarray(NO_STOP if stop_at is None else stop_at, jnp.int32)
    carry = _loop(proto, flat, lower, upper, args, carry, stop_at)
    return carry, _end(proto, flat, lower, upper, args, carry)
