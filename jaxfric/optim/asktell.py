"""ask / tell: a run driven from Python, for an objective outside JAX (a simulator, a
NumPy model, a lab rig).

The run *is* the compiled run of :func:`jaxfric.minimise` (:func:`jaxfric.optim.loop._run`),
started in a worker thread with an objective that answers from Python: every batch the
solver evaluates goes out through ``jax.pure_callback`` and waits until :func:`tell`
brings its values. So ask/tell visits the points ``minimise`` visits for the same key,
with the same evaluation counts and stage switches, for every solver that evaluates in
batches (PSO, MAPSO, Evosax, Nelder–Mead, chains of them), and compiles what
``minimise`` compiles, once per solver and problem shape::

    st = solver.ask_init(lower, upper, key)
    while not solver.ask_done(st):
        X, st = solver.ask(st)                      # (k, n) points
        st = solver.tell(st, X, [simulate(x) for x in np.asarray(X)])
    solution = solver.ask_result(st)                # what minimise returns

The same recipe without ask/tell: wrap the outside objective in ``jax.pure_callback``
and call :func:`jaxfric.minimise` (docs/solvers.md, "Objectives outside JAX").

A run left unfinished is stopped when its last state is garbage-collected. Several runs
may be open at once, but each waits for :func:`tell` inside XLA: a run large enough for
XLA:CPU to run it on its thread pool holds a pool thread while it waits, and with more
such runs open than the pool has threads (about one per core) the next one never gets
its first batch out (a 25-agent PSO on 5 parameters, 4 runs, 2 cores). For several seeds
of an objective outside JAX use the ``pure_callback`` recipe with
:func:`jaxfric.minimise_many`: one host call then carries every seed's batch.
"""

from __future__ import annotations

import atexit
import functools
import itertools
import queue
import threading
import weakref

import jax
import jax.numpy as jnp
import numpy as np

from .. import _xla
from ._base import RESULTS, History, Solution
from .loop import NO_STOP, _run
from .problem import _Flat, check_key, check_start, prepare_bounds

#: Open runs by token: the compiled objective finds its run through the token it gets
#: in ``args``, so every run of one solver and problem shape shares one executable.
_CHANNELS: dict[int, "_Channel"] = {}
_TOKENS = itertools.count()


class _Channel:
    """Batches from the run to Python and values back, one batch at a time. Once the run
    is abandoned every value is ``+inf``, so the run ends without waiting (a swarm runs
    out its generations, Nelder–Mead stops at once)."""

    def __init__(self):
        self.out: queue.Queue = queue.Queue()   # ("ask", X) | ("done", Solution) | ("error", e)
        self.back: queue.Queue = queue.Queue()  # values, or None: abandoned
        self.one_at_a_time = threading.Lock()
        self.abandoned = False
        self.thread: threading.Thread | None = None

    def evaluate(self, X):
        with self.one_at_a_time:
            if not self.abandoned:
                self.out.put(("ask", X))
                f = self.back.get()
                if f is not None:
                    return f
                self.abandoned = True
        return np.full(X.shape[:1], np.inf, X.dtype)


def _answer(token, X, wide):
    """Host side of the objective: ``X`` is one point ``(n,)`` or a batch ``(k, n)``
    (``wide``: float64 sent as pairs of uint32, see :func:`_objective`)."""
    channel = _CHANNELS[int(np.asarray(token).flat[0])]
    X = np.ascontiguousarray(X)
    if wide:
        X = X.view(np.float64)[..., 0]
    f = channel.evaluate(np.atleast_2d(X)).reshape(X.shape[:-1]).astype(X.dtype)
    return np.ascontiguousarray(f[..., None]).view(np.uint32) if wide else f


def _objective(x, token):
    """``fn(x, args)`` of an ask/tell run: the value comes from :func:`tell`. Batched by
    ``vmap`` it is one callback per batch (``vmap_method="broadcast_all"``).

    A float64 run sends its points and receives its values as uint32 pairs: XLA may run
    the callback on a thread of its own, where ``jax.enable_x64``'s thread-local setting
    is off and JAX would round float64 operands and results to float32."""
    wide = x.dtype == jnp.float64
    shape = jax.ShapeDtypeStruct(x.shape[:-1] + ((2,) if wide else ()),
                                 jnp.uint32 if wide else x.dtype)
    send = jax.lax.bitcast_convert_type(x, jnp.uint32) if wide else x
    f = jax.pure_callback(functools.partial(_answer, wide=wide), shape, token, send,
                          vmap_method="broadcast_all")
    return jax.lax.bitcast_convert_type(f, jnp.float64) if wide else f


class AskTellState:
    """Where a run driven by ask/tell stands: the batch waiting for values (``pending``,
    ``None`` once the run has finished) and the number of values told so far. Every
    :func:`tell` returns a new state; the older ones are spent."""

    def __init__(self, run: "_Run", event, num_told: int):
        self._run, self._event, self.num_told = run, event, num_told

    @property
    def pending(self):
        return self._event[1] if self._event[0] == "ask" else None


class _Run:
    """The worker thread running the compiled run, and its channel."""

    def __init__(self, solver, lower, upper, key, x0):
        self.token = next(_TOKENS)
        self.channel = _Channel()
        self.dtype = lower.dtype
        self.best_x, self.best_f, self.num_evals = lower, np.inf, 0
        _CHANNELS[self.token] = self.channel
        x64 = bool(jax.config.jax_enable_x64)  # a thread-local setting: pass it on
        args = (solver, lower, upper, key, x0, self.token, self.channel, x64)
        self.thread = threading.Thread(target=_work, args=args, daemon=True,
                                       name=f"jaxfric-ask-tell-{self.token}")
        self.channel.thread = self.thread
        self.thread.start()
        # at interpreter exit _abandon_all stops every open run instead
        weakref.finalize(self, _abandon, self.token, self.channel).atexit = False

    def next_event(self):
        kind, payload = self.channel.out.get()
        if kind != "ask":
            # the worker has left the compiled run: let it finish before the caller goes
            # on, so no thread of ours is inside XLA when the interpreter shuts down
            self.thread.join()
        if kind == "error":
            raise payload
        return kind, payload


def _work(solver, lower, upper, key, x0, token, channel: _Channel, x64: bool):
    try:
        with jax.enable_x64(x64):
            lo, hi, treedef, shapes = prepare_bounds((lower, upper), lower.dtype)
            flat = _Flat(_objective, treedef, shapes)
            args = (solver, flat, lo, hi, jnp.asarray(token, jnp.int32), key, x0, None, None,
                    None, jnp.asarray(NO_STOP, jnp.int32))
            _, sol = _executable(args)(*args)
            channel.out.put(("done", jax.block_until_ready(sol)))
    except Exception as e:  # noqa: BLE001  (handed to the caller of ask/tell)
        channel.out.put(("error", e))
    finally:
        _CHANNELS.pop(token, None)


#: Compiled ask/tell runs by solver and problem shape. Each run calls its executable
#: directly: a call through ``jit`` would wait while another run of the same program is
#: still in its first call (whose objective waits for ``tell``), so two open runs would
#: block each other.
_EXECUTABLES: dict = {}
_EXECUTABLES_MAX = 32


def _executable(args):
    solver, flat, lo, _, _, key, x0 = args[:7]
    leaves = jax.tree_util.tree_leaves((lo, key, x0))
    sig = (solver, flat, tuple((a.shape, str(a.dtype)) for a in leaves))
    try:
        hash(sig)
    except TypeError:
        sig = None
    if sig is None or sig not in _EXECUTABLES:
        compiled = _xla.filter_jit(_run, _xla.resolve("auto", "solver")).lower(*args).compile()
        if sig is None:
            return compiled
        if len(_EXECUTABLES) >= _EXECUTABLES_MAX:
            _EXECUTABLES.pop(next(iter(_EXECUTABLES)))
        _EXECUTABLES[sig] = compiled
    return _EXECUTABLES[sig]


def _abandon(token, channel: _Channel):
    if token in _CHANNELS:
        channel.back.put(None)


#: How long interpreter exit waits for an abandoned run to answer its remaining batches
#: with +inf and leave the compiled run.
_EXIT_JOIN_S = 30.0


@atexit.register
def _abandon_all():
    """Stop the runs still open at interpreter exit. A worker thread left waiting inside
    the compiled run (in a ``pure_callback``) would be unwound through XLA's frames when
    the interpreter finalises, which aborts the process."""
    open_runs = list(_CHANNELS.items())
    for token, channel in open_runs:
        _abandon(token, channel)
    for _, channel in open_runs:
        if channel.thread is not None:
            channel.thread.join(_EXIT_JOIN_S)


def start(solver, lower, upper, key, x0=None) -> AskTellState:
    """Start a run of ``solver`` (already checked) on the 1-D box ``[lower, upper]``."""
    lower, upper = jnp.asarray(lower), jnp.asarray(upper)
    if lower.ndim != 1 or lower.shape != upper.shape or lower.shape[0] == 0:
        raise ValueError(f"ask_init needs 1-D lower and upper bounds of one length, got "
                         f"shapes {lower.shape} and {upper.shape}")
    if not jnp.issubdtype(lower.dtype, jnp.floating):
        lower = lower.astype(float)
    lo, hi, treedef, shapes = prepare_bounds((np.asarray(lower), np.asarray(upper)), lower.dtype)
    key = check_key(key)
    if x0 is not None:
        x0 = check_start(np.asarray(x0), treedef, shapes, lo, hi, solver.population_size())
    run = _Run(solver, lo, hi, key, x0)
    return AskTellState(run, run.next_event(), 0)


def ask(st: AskTellState):
    """``(X, st)``: the points (rows) whose values :func:`tell` needs next."""
    if st.pending is None:
        raise ValueError("the run has finished (ask_done is True): read ask_result")
    return st.pending, st


def tell(st: AskTellState, X, f) -> AskTellState:
    """Give the values ``f`` of the rows ``X`` that :func:`ask` returned (NaN and inf count
    as the worst value); returns the state asking for the next batch."""
    if st.pending is None:
        raise ValueError("the run has finished (ask_done is True): nothing to tell")
    run = st._run
    if st.num_told != run.num_evals:
        raise ValueError("this ask/tell state was already told; continue from the state "
                         "tell returned")
    pending = st.pending
    if tuple(np.shape(X)) != tuple(pending.shape):
        raise ValueError(f"tell needs the batch ask returned, of shape {pending.shape}, "
                         f"got shape {tuple(np.shape(X))}")
    f = np.asarray(f, run.dtype)
    if f.shape != (pending.shape[0],):
        raise ValueError(f"tell needs one fitness value per candidate: got shape "
                         f"{f.shape} for {pending.shape[0]} candidates")
    f = np.where(np.isfinite(f), f, np.inf).astype(run.dtype)
    i = int(np.argmin(f))
    if f[i] < run.best_f:
        run.best_x, run.best_f = pending[i], f[i]
    run.num_evals += f.shape[0]
    run.channel.back.put(f)
    return AskTellState(run, run.next_event(), run.num_evals)


def done(st: AskTellState) -> bool:
    """Whether the run has finished (by the rule the compiled run stops on)."""
    return st._event[0] == "done"


def result(st: AskTellState) -> Solution:
    """The run's :class:`Solution` (flat ``value``) once it has finished, as
    :func:`jaxfric.minimise` gives it; before, the best point told so far."""
    if done(st):
        return st._event[1]
    run = st._run
    if run.num_evals == 0:
        raise ValueError("no result before the first batch has been told")
    f = jnp.asarray(run.best_f, run.dtype)
    evals = jnp.asarray(run.num_evals)
    return Solution(value=jnp.asarray(run.best_x), f=f,
                    result=RESULTS.where(jnp.isfinite(f), RESULTS.successful, RESULTS.nonfinite),
                    stats={"num_evals": evals},
                    history=History.from_arrays(evals[None], f[None]))


__all__ = ["AskTellState", "ask", "done", "result", "start", "tell"]
