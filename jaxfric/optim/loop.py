"""The loop every solver runs in, one compiled program (docs/algorithms.md §5.1 for the
two-stage case)::

    state = start()                            # init_rounds, evaluated in the program
    for stage in range(num_stages()):          # a chain: global, then local
        while not finished(state) and stage(state) == stage:
            state = step(state, stage)         # step_rounds, evaluated in the program
            record history; report progress

[`jaxfric.minimise`][jaxfric.optim.minimise] compiles `_run`; ask/tell ([`jaxfric.optim.asktell`][jaxfric.optim.asktell])
compiles the same function with an objective answered from Python.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from ._base import NO_STEP_CAP, History, Solution
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
def _record(proto, state, history):
    _, f = proto.best(state)
    return history.record(proto.num_evals(state), f)


def _begin(proto, flat, lower, upper, args, key, x0, warm) -> Carry:
    state = compiled_start(proto, flat, lower, upper, args, key, x0) if warm is None else warm
    cap = proto.steps_for(lower.shape[0])
    size = min((NO_STEP_CAP if cap is None else cap) + 2, HISTORY_SIZE)  # + the first entry, + room
    history = _record(proto, state, History.empty(size, lower.dtype))
    return Carry(state, history, jnp.array(0, jnp.int32))


def _loop(proto, flat, lower, upper, args, carry: Carry, stop_at, hook) -> Carry:
    """Steps until the solver terminates or ``carry.steps == stop_at``, stage by stage."""

    def report(c: Carry, force: bool):
        if hook is not None:
            phase, step = proto.progress(c.state)
            hook.emit(phase, step, proto.num_evals(c.state), proto.best(c.state)[1], force)

    for s in range(proto.num_stages()):
        def cond(c, s=s):
            done, _ = proto.finished(c.state)
            return ~done & (proto.stage(c.state) == s) & (c.steps < stop_at)

        def body(c, s=s):
            state = compiled_step(proto, flat, lower, upper, args, c.state, s)
            c = Carry(state, _record(proto, state, c.history), c.steps + 1)
            report(c, False)
            return c

        carry = jax.lax.while_loop(cond, body, carry)
    report(carry, True)
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


def _run(proto, flat, lower, upper, args, key, x0, hook, carry=None, warm=None, stop_at=None):
    """One compiled call: start (unless ``carry`` continues a chunked run), loop until
    done or ``stop_at`` steps, and the solution. Returns ``(carry, solution)``."""
    if carry is None:
        carry = _begin(proto, flat, lower, upper, args, key, x0, warm)
    stop_at = jnp.asarray(NO_STOP if stop_at is None else stop_at, jnp.int32)
    carry = _loop(proto, flat, lower, upper, args, carry, stop_at, hook)
    return carry, _end(proto, flat, lower, upper, args, carry)
