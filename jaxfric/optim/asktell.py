"""ask / tell: a run driven from Python, for an objective outside JAX (a simulator, a
NumPy model, a lab rig).

The run *is* the compiled run of [`jaxfric.minimise`][jaxfric.optim.minimise] (its start,
loop and end in one call, `jaxfric.optim.loop._run`), started in a worker thread with an
objective that answers from Python: every batch the solver evaluates goes out through
``jax.pure_callback`` and waits until [`tell`][jaxfric.optim.asktell.tell] brings its
values. So ask/tell visits the points ``minimise`` visits for the same key, with the same
evaluation counts and stage switches, for every solver that evaluates in
batches (PSO, MAPSO, Evosax, Nelder–Mead, chains of them), and compiles what
``minimise`` compiles, once per solver and problem shape::

    st = jf.ask_init(solver, lower, upper, key)
    while not jf.ask_done(st):
        X, st = jf.ask(st)                          # (k, n) points
        st = jf.tell(st, X, [simulate(x) for x in np.asarray(X)])
    solution = jf.ask_result(st)                    # what minimise returns

These are functions beside ``minimise``, not methods of the solver: the solver contract
([`AbstractSolver`][jaxfric.optim.AbstractSolver]) does not know of them.

Several seeds in one run: ``ask_init(solver, lower, upper, keys=keys)`` with a batch of ``S``
keys runs the keys side by side as ``minimise_many(..., keys=keys, batching="vmap")``
does (``vmap`` of the same run, on one device). Every ask then carries every seed's
batch, ``X`` of shape ``(S, k, n)`` (block ``s`` is seed ``s``), [`tell`][jaxfric.optim.asktell.tell] takes
values of shape ``(S, k)``, and [`ask_result`][jaxfric.optim.asktell.ask_result] is ``minimise_many``'s batched
[`Solution`][jaxfric.optim.Solution]. Under ``vmap`` every seed is asked on every step: a seed that has
finished, and the branch of a Nelder–Mead step a seed does not take (``vmap`` computes
both sides of a conditional), still has its rows asked, and their values are
discarded. Swarms (PSO, MAPSO, Evosax) batch cleanly: while no seed has finished, every
row asked is one the algorithm uses.

The same recipe without ask/tell: wrap the outside objective in ``jax.pure_callback``
and call [`jaxfric.minimise`][jaxfric.optim.minimise] (docs/solvers.md, "Objectives outside JAX").

A run left unfinished is stopped when its last state is garbage-collected. Several runs
may be open at once, but each waits for [`tell`][jaxfric.optim.asktell.tell] inside XLA: a run large enough for
XLA:CPU to run it on its thread pool holds a pool thread while it waits, and with more
such runs open than the pool has threads (about one per core) the next one never gets
its first batch out (a 25-agent PSO on 5 parameters, 4 runs, 2 cores). For several seeds
of an objective outside JAX open one run with ``keys=`` instead: one ask then carries
every seed's batch, and only one run waits in XLA.
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
from ._base import History, Solution, result_from_f
from .contract import capabilities_of
from .loop import NO_STOP, _run
from .optx_adapter import as_protocol
from .problem import _Flat, check_key, check_start, prepare_bounds, run_work

#: Open runs by token: the compiled objective finds its run through the token it gets
#: in ``args``, so every run of one solver and problem shape shares one executable.
_CHANNELS: dict[int, "_Channel"] = {}
_TOKENS = itertools.count()


class _Channel:
    """Batches from the run to Python and values back, one batch at a time. Once the run
    is abandoned every value is ``+inf``, so the run ends without waiting (a swarm runs
    out its generations, Nelder–Mead stops at once)."""

    def __init__(self, seeds: int | None = None):
        self.seeds = seeds  # S for a run of several seeds, else None
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
        return np.full(X.shape[:-1], np.inf, X.dtype)


def _answer(token, X, wide):
    """Host side of the objective: ``X`` is one point ``(n,)`` or a batch ``(k, n)``; in
    a run of ``S`` seeds, with the seeds' axis in front: ``(S, n)`` or ``(S, k, n)``,
    asked as ``(S, k, n)`` (``wide``: float64 sent as pairs of uint32, see
    `_objective`)."""
    channel = _CHANNELS[int(np.asarray(token).flat[0])]
    X = np.array(X)  # a copy of its own: asked and kept after the callback returns
    if wide:
        X = X.view(np.float64)[..., 0]
    asked = (np.atleast_2d(X) if channel.seeds is None
             else X.reshape(channel.seeds, -1, X.shape[-1]))
    f = channel.evaluate(asked).reshape(X.shape[:-1]).astype(X.dtype)
    return np.ascontiguousarray(f[..., None]).view(np.uint32) if wide else f


def _objective(x, token):
    """``fn(x, args)`` of an ask/tell run: the value comes from [`tell`][jaxfric.optim.asktell.tell]. Batched by
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
    ``None`` once the run has finished) and the number of values told so far
    (``num_told``; in a run of several seeds, per seed: ``S * num_told`` values in all,
    discarded ones included). Every [`tell`][jaxfric.optim.asktell.tell] returns a new state; the older ones are
    spent."""

    def __init__(self, run: "_Run", event, num_told: int):
        self._run, self._event, self.num_told = run, event, num_told

    @property
    def pending(self):
        return self._event[1] if self._event[0] == "ask" else None


class _Run:
    """The worker thread running the compiled run, and its channel."""

    def __init__(self, solver, lower, upper, key, x0, seeds: int | None):
        self.token = next(_TOKENS)
        self.channel = _Channel(seeds)
        self.dtype = lower.dtype
        self.seeds = seeds
        # best row told so far (per seed in a run of several seeds)
        if seeds is None:
            self.best_x, self.best_f = np.asarray(lower), np.inf
        else:
            self.best_x = np.broadcast_to(np.asarray(lower), (seeds,) + lower.shape).copy()
            self.best_f = np.full(seeds, np.inf, lower.dtype)
        self.num_evals = 0
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


def _run_seeds(proto, flat, lower, upper, tokens, keys, x0):
    """The runs of ``minimise_many(..., batching="vmap")``: ``vmap`` of minimise's run
    over the keys. The token travels batched (one copy per seed) so that every callback
    is batched over the seeds and carries their axis in front, even for points that do
    not depend on the key (a Nelder–Mead simplex around a shared ``x0``)."""
    run = lambda t, k: _run(proto, flat, lower, upper, t, k, x0)[1]  # noqa: E731
    return jax.vmap(run)(tokens, keys)


def _work(solver, lower, upper, key, x0, token, channel: _Channel, x64: bool):
    try:
        with jax.enable_x64(x64):
            lo, hi, treedef, shapes = prepare_bounds((lower, upper), lower.dtype)
            flat = _Flat(_objective, treedef, shapes)
            if channel.seeds is None:
                args = (solver, flat, lo, hi, jnp.asarray(token, jnp.int32), key, x0,
                        None, None, jnp.asarray(NO_STOP, jnp.int32))
                _, sol = _executable(_run, args)(*args)
            else:
                args = (solver, flat, lo, hi, jnp.full(channel.seeds, token, jnp.int32),
                        key, x0)
                sol = _executable(_run_seeds, args)(*args)
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


def _executable(fn, args):
    solver, flat, lo, _, _, key, x0 = args[:7]
    leaves = jax.tree_util.tree_leaves((lo, key, x0))
    sig = (fn, solver, flat, tuple((a.shape, str(a.dtype)) for a in leaves))
    try:
        hash(sig)
    except TypeError:
        sig = None
    if sig is None or sig not in _EXECUTABLES:
        # "auto"'s rule on the run's work without an objective (its values come from
        # Python), so a cheap JAX objective's minimise compiles alike (the same bits)
        options = _xla.resolve("auto", "solver", work=run_work(solver, lo.shape[-1], 0.0))
        compiled = _xla.filter_jit(fn, options).lower(*args).compile()
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


def ask_init(solver, lower, upper, key=None, x0=None, *, keys=None) -> AskTellState:
    """Start a run of ``solver`` driven from Python (a jaxfric solver, or an optimistix
    minimiser as [`jaxfric.minimise`][jaxfric.optim.minimise] takes it, which ask/tell refuses:
    it evaluates by itself). ``lower`` / ``upper``: 1-D bounds (their dtype is the
    search dtype, as in [`jaxfric.minimise`][jaxfric.optim.minimise]); ``key``: a PRNG key or an
    int seed; ``x0``: an optional start (swarms: or an initial population).

    ``keys`` instead of ``key``: a batch of ``S`` PRNG keys, as
    [`jaxfric.minimise_many`][jaxfric.optim.minimise_many] takes them. The seeds then run side by side in one
    run (``minimise_many``'s ``batching="vmap"``): every ask carries every seed's
    batch, so one host call evaluates them all. Exactly one of ``key`` and ``keys``."""
    solver = as_protocol(solver)
    solver.check()
    if key is not None and keys is not None:
        raise ValueError("ask_init takes key= (one seed) or keys= (a batch of keys, "
                         "several seeds in one run), not both")
    if key is None and keys is None:
        raise ValueError("ask_init needs key= (one seed: jax.random.key(seed) or an int) "
                         "or keys= (several seeds: jax.random.split(key, S))")
    lower, upper = jnp.asarray(lower), jnp.asarray(upper)
    if lower.ndim != 1 or lower.shape != upper.shape or lower.shape[0] == 0:
        raise ValueError(f"ask_init needs 1-D lower and upper bounds of one length, got "
                         f"shapes {lower.shape} and {upper.shape}")
    if not jnp.issubdtype(lower.dtype, jnp.floating):
        lower = lower.astype(float)
    lo, hi, treedef, shapes = prepare_bounds((np.asarray(lower), np.asarray(upper)), lower.dtype)
    if keys is None:
        key, seeds = check_key(key), None
    else:
        key = check_key(keys, "keys", batch=True)
        seeds = int(key.shape[0])
    caps = capabilities_of(solver, int(lo.shape[0]))
    if caps.ask_tell_refused is not None:
        raise ValueError(caps.ask_tell_refused)
    if x0 is not None:
        x0 = check_start(np.asarray(x0), treedef, shapes, lo, hi, caps.population_size)
    run = _Run(solver, lo, hi, key, x0, seeds)
    return AskTellState(run, run.next_event(), 0)


def ask(st: AskTellState):
    """``(X, st)``: the points (rows) whose values [`tell`][jaxfric.optim.asktell.tell] needs next: ``(k, n)``,
    or ``(S, k, n)`` in a run of ``S`` seeds (block ``s`` is seed ``s``'s)."""
    if st.pending is None:
        raise ValueError("the run has finished (ask_done is True): read ask_result")
    return st.pending, st


def tell(st: AskTellState, X, f) -> AskTellState:
    """Give the values ``f`` of the rows ``X`` that [`ask`][jaxfric.optim.asktell.ask] returned (NaN and inf count
    as the worst value): shape ``(k,)``, or ``(S, k)`` in a run of ``S`` seeds. Returns
    the state asking for the next batch."""
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
    if f.shape != pending.shape[:-1]:
        per = (f"{pending.shape[1]} candidates of each of {pending.shape[0]} seeds, shape "
               f"{pending.shape[:-1]}" if run.seeds else f"{pending.shape[0]} candidates")
        raise ValueError(f"tell needs one fitness value per candidate: got shape "
                         f"{f.shape} for {per}")
    f = np.where(np.isfinite(f), f, np.inf).astype(run.dtype)
    _keep_best(run, pending, f)
    run.num_evals += f.shape[-1]
    run.channel.back.put(f)
    return AskTellState(run, run.next_event(), run.num_evals)


def _keep_best(run: "_Run", X, f):
    """Update the best row told so far, of the run or of each seed."""
    if run.seeds is None:
        i = int(np.argmin(f))
        if f[i] < run.best_f:
            run.best_x, run.best_f = np.array(X[i]), f[i]
        return
    i = np.argmin(f, axis=1)
    seeds = np.arange(run.seeds)
    better = f[seeds, i] < run.best_f
    run.best_x[better] = X[seeds, i][better]
    run.best_f[better] = f[seeds, i][better]


def ask_done(st: AskTellState) -> bool:
    """Whether the run has finished (by the rule the compiled run stops on)."""
    return st._event[0] == "done"


def ask_result(st: AskTellState) -> Solution:
    """The run's [`Solution`][jaxfric.optim.Solution] (flat ``value``) once it has finished, as
    [`jaxfric.minimise`][jaxfric.optim.minimise] gives it (a run of several seeds: as
    ``minimise_many(..., batching="vmap")`` gives it, every field with a leading axis
    of the seeds). Before, the best row told so far, per seed in a run of several seeds;
    there, rows whose values the run later discards count too, so it may be better than
    the final ``f``, and ``stats["num_evals"]`` is the values told per seed."""
    if ask_done(st):
        return st._event[1]
    run = st._run
    if run.num_evals == 0:
        raise ValueError("no result before the first batch has been told")
    f = jnp.asarray(run.best_f, run.dtype)
    evals = jnp.full(f.shape, run.num_evals)
    if run.seeds is None:
        history, status = History.from_arrays(evals[None], f[None]), result_from_f(f)
    else:
        history = jax.vmap(History.from_arrays)(evals[:, None], f[:, None])
        status = jax.vmap(result_from_f)(f)
    return Solution(value=jnp.asarray(run.best_x), f=f, result=status,
                    stats={"num_evals": evals}, history=history)


__all__ = ["AskTellState", "ask", "ask_done", "ask_init", "ask_result", "tell"]
