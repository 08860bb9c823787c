"""The one driver: [`minimise`][jaxfric.optim.minimise] and [`minimise_many`][jaxfric.optim.minimise_many] own the loop for every
solver (docs/algorithms.md §5.1 for the two-stage case).

They validate what the user gave *before* tracing, flatten pytree bounds to one vector,
and run the solver (a foreign ``optimistix`` minimiser through
[`optx_adapter`][jaxfric.optim.optx_adapter]) in the loop of [`loop`][jaxfric.optim.loop] as one
jitted computation.

In this one place, for every solver: the history of the best value against
evaluations, progress reports, checkpoint/resume ([`checkpoint`][jaxfric.optim.checkpoint]),
warm starts, the population split over devices, and ``vmap`` over seeds. Data travel
in ``args`` (never closures), so new data of the same shapes do not recompile.
"""

from __future__ import annotations

import contextlib
import functools
import weakref
from pathlib import Path
from typing import Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .. import _xla
from . import checkpoint as ckpt
from ._base import Drawn, Solution, check_positive_int, count_dtype
from .chained import AbstractChain
from .contract import AbstractStartDraws, capabilities_of, continued
from .loop import NO_STOP, _begin, _chunk, _finish, blank_carry
from .rounds import compiled_start
from .optx_adapter import OptxMinimiser, as_protocol
from .problem import _check_output, _Flat, check_budget, check_key, check_start, prepare_bounds, run_work
from .progress import Chunks, TqdmProgress
from .sharding import Layout, resolve_devices, shard_keys
from .template import templated

# ------------------------------------------------------------------ validation
def _prepare(fn, solver, bounds, args, y0, dtype):
    if not callable(fn):
        raise ValueError(f"fn must be callable fn(y, args), got {type(fn).__name__}")
    if isinstance(solver, type) or not isinstance(solver, eqx.Module):
        raise ValueError(
            "solver must be a jaxfric solver (PSO, MAPSO, NelderMead, MAPSONMDS, chain(...)) "
            f"or an optimistix minimiser, got {type(solver).__name__}"
        )
    proto = as_protocol(solver)
    proto.check()
    lower, upper, treedef, shapes = prepare_bounds(bounds, dtype)
    flat = _Flat(fn, treedef, shapes)
    _check_output(flat, lower, args)
    check_budget(proto, lower.shape[0])
    x0 = None if y0 is None else check_start(y0, treedef, shapes, lower, upper,
                                             capabilities_of(proto, lower.shape[0]).population_size)
    return proto, flat, lower, upper, x0


def _options(compiler_options, proto, flat, lower, args, layout):
    """``compiler_options`` resolved for this run (`jaxfric._xla.resolve`): ``"auto"``
    with the run's estimated work (`run_work`: one run's, so ``minimise`` and each run of
    ``minimise_many`` compile alike)."""
    work = None
    if isinstance(compiler_options, str) and compiler_options == _xla.AUTO:
        work = run_work(proto, lower.shape[0], _check_output(flat, lower, args))
    return _xla.resolve(compiler_options, "solver", _platform(layout), work)


# ---------------------------------------------------------------------- progress
def _display(progress, proto, n: int):
    """``(sink, display)`` for ``progress=`` of a run on ``n`` parameters: the host display
    (``None``: no display) and `_chunked`'s ``display`` (``(sink, Chunks)``, or ``None``)."""
    if progress is None or progress is False:
        return None, None
    total, local_total = capabilities_of(proto, n).progress_totals
    if progress is True:
        sink = TqdmProgress(total, local_total)
        return sink, (sink, Chunks(total))
    if callable(progress):
        return progress, (progress, Chunks(total))
    raise ValueError(
        "progress must be None, True (a tqdm bar) or a callable "
        f"sink(phase, step, evals, f_best), got {type(progress).__name__}"
    )


@contextlib.contextmanager
def _closing(sink):
    """``sink``, closed at the end when it has a ``close`` (a tqdm bar)."""
    try:
        yield sink
    finally:
        close = getattr(sink, "close", None)
        if close is not None:
            close()


# ------------------------------------------------------------------ the end
def _no_objective(y, args):
    raise TypeError("the solution of a run does not call the objective")


def objective_free(proto, flat, args):
    """``(flat, args)`` for `_finish`: the objective and its data left out where no part
    of ``proto`` evaluates it in its ``solution`` (an optimistix minimiser may), so one
    compiled `_finish` serves every objective of the same shapes."""
    def free(p):
        if isinstance(p, AbstractChain):
            return free(p._global) and free(p._local)
        return not isinstance(p, OptxMinimiser)

    if not free(proto):
        return flat, args
    return type(flat)(_no_objective, flat.treedef, flat.shapes, flat.layout), None


def _finisher(proto, flat, lower, upper, args, options, batched: bool):
    """``carry -> Solution`` (a batch of carries when ``batched``): `_finish`, compiled
    apart from the objective where `objective_free` allows."""
    flat, args = objective_free(proto, flat, args)
    program = _xla.filter_jit(_finish_many if batched else _finish, options)
    return lambda carry: program(proto, flat, lower, upper, args, carry)


def _finish_many(proto, flat, lower, upper, args, carries):
    return jax.vmap(lambda c: _finish(proto, flat, lower, upper, args, c))(carries)


# ---------------------------------------------------------------- the start's draws
def _start_draws(proto, lower, upper, key):
    return proto.start_draws(lower, upper, key)


def _start_draws_many(proto, lower, upper, keys):
    return jax.vmap(lambda k: proto.start_draws(lower, upper, k))(keys)


def _drawn(proto, lower, upper, key, options, batched: bool = False):
    """``key`` as a ``Drawn`` key (a batch of them when ``batched``) where
    ``proto`` is an ``AbstractStartDraws``: its start's random numbers made by a program of their
    own, which does not depend on the objective, so a new objective's program leaves them
    out (issue 47); else ``key`` as it is."""
    if not isinstance(proto, AbstractStartDraws):
        return key
    program = _xla.filter_jit(_start_draws_many if batched else _start_draws, options)
    return Drawn(key, program(proto, lower, upper, key))


# ------------------------------------------------------------------ the chunks
class _Signature:
    """The arguments of `_begin` compared by structure, shapes and dtypes (what its
    result's shapes depend on), so a blank carry is built once per problem shape."""

    def __init__(self, args):
        leaves, treedef = jtu.tree_flatten(args)
        self.args = args
        self.key = (treedef, tuple(
            (tuple(x.shape), str(x.dtype), bool(getattr(x, "weak_type", False)))
            if hasattr(x, "shape") and hasattr(x, "dtype") else x for x in leaves))
        hash(self.key)  # TypeError for an unhashable leaf: the caller builds it uncached

    def __hash__(self):
        return hash(self.key)

    def __eq__(self, other):
        return isinstance(other, _Signature) and self.key == other.key


def _blank_of(like, impl, batch):
    if batch is not None:
        like = jtu.tree_map(lambda x: jax.ShapeDtypeStruct((batch, *x.shape), x.dtype)
                            if isinstance(x, jax.ShapeDtypeStruct) else x, like)
    return blank_carry(like, impl)


@functools.lru_cache(maxsize=32)
def _cached_blank(sig: _Signature, impl, batch, counts: str):
    # JAX arrays are immutable and the chunk does not donate its carry, so one blank
    # serves every call of the same signature: putting its ~20 zero arrays on the device
    # took about a third of a short run's time outside XLA (issue 47). ``counts``, the
    # counters' dtype (int64 under jax.enable_x64), is part of the key: the signature's
    # arrays are the same in both modes, the carry's counters are not
    return _blank_of(eqx.filter_eval_shape(_begin, *sig.args), impl, batch)


@functools.lru_cache(maxsize=None)
def _stand_in(dtype: str):
    """An objective returning a ``dtype`` zero: the shapes of a run's carry follow from
    the objective's output type alone."""
    def stand_in(y, args):
        return jnp.zeros((), dtype)

    return stand_in


#: ``fn -> {signature: output type}``: what `_output_type` found, per objective (weakly
#: held, so a dropped objective takes its entries with it)
_OUTPUT_TYPES: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _output_key(flat, lower, args):
    """What ``flat``'s output type depends on besides its function: the parameters'
    structure, the search vector's shape and dtype, ``args``' structure, shapes and dtypes
    (Python scalars by type) and JAX's float width; ``None`` where a leaf of ``args`` is
    neither (then nothing is cached)."""
    leaves, treedef = jtu.tree_flatten(args)
    sig = []
    for leaf in leaves:
        if hasattr(leaf, "shape") and hasattr(leaf, "dtype"):
            sig.append((tuple(leaf.shape), str(leaf.dtype), bool(getattr(leaf, "weak_type", False))))
        elif isinstance(leaf, (bool, int, float, complex)):
            sig.append(type(leaf))  # traced by eval_shape: only the type matters
        else:
            return None
    key = (flat.treedef, flat.shapes, tuple(lower.shape), str(lower.dtype), treedef,
           tuple(sig), str(jax.dtypes.canonicalize_dtype(np.float64)))
    try:
        hash(key)
    except TypeError:
        return None
    return key


def _output_type(flat, lower, args):
    """``jax.eval_shape`` of the objective on the search vector, memoised per objective and
    `_output_key`: tracing it took about 2 000 Python calls of every warm ``minimise``
    (issue 47). An objective that cannot be weakly referenced or hashed (an ``eqx.Module``
    holding arrays, say) is traced every time."""
    key, known = _output_key(flat, lower, args), None
    try:
        known = None if key is None else _OUTPUT_TYPES.get(flat.fn)
    except TypeError:  # unhashable, or no weak reference to it
        key = None
    if known is not None and key in known:
        return known[key]
    out = jax.eval_shape(flat, jax.ShapeDtypeStruct(lower.shape, lower.dtype), args)
    if key is not None:
        try:
            _OUTPUT_TYPES.setdefault(flat.fn, {})[key] = out
        except TypeError:
            pass
    return out


def _shapes_only(proto, flat, lower, args):
    """``(flat, args)`` for `_blank`: the objective replaced by a stand-in of the same
    output type (and no ``args``) where no part of ``proto`` keeps more of it than
    its values (`objective_free`), so a new objective of the same shapes finds its blank
    carry made (tracing the start again for it cost a fifth of a chain's first call,
    issue 47)."""
    if objective_free(proto, flat, args)[0] is flat:
        return flat, args
    out = _output_type(flat, lower, args)
    if getattr(out, "weak_type", False):
        return flat, args
    return type(flat)(_stand_in(str(out.dtype)), flat.treedef, flat.shapes, flat.layout), None


def _blank(proto, flat, lower, upper, args, key, x0, warm, batch: int | None = None):
    """The unused carry of a chunk that starts the run (`blank_carry`), with a leading
    axis of ``batch`` runs when given; ``key`` is one run's key."""
    flat, args = _shapes_only(proto, flat, lower, args)
    begin_args = (proto, flat, lower, upper, args, key, x0, warm)
    impl = jax.random.key_impl(key)
    try:
        sig = _Signature(begin_args)
        hash(impl)
    except TypeError:
        return _blank_of(eqx.filter_eval_shape(_begin, *begin_args), impl, batch)
    return _cached_blank(sig, impl, batch, str(count_dtype()))


def _chunked(call, finish, blank, display=None, checkpoint=None):
    """Run ``call(carry, fresh, stop_at) -> (carry, report)`` (the compiled `_chunk`, or
    its batch over keys) to the end and return ``finish(carry)``, the solution.

    Without a display or a checkpoint that is one call. With a display the run goes in
    chunks of ``Chunks`` steps and the host reports each
    chunk's end (each run's, for a batch; ``display = (sink, chunks)``); with ``checkpoint = (path, every, meta,
    resumed)`` it saves the carry after every ``every`` steps, and starts from
    ``resumed = (carry, steps_done)`` when that is not ``None``. Every call runs the same
    program, and a chunk takes exactly the steps the whole run takes there, so the
    solution is the same to the bit whatever the chunks.
    """
    sink, chunks = display if display is not None else (None, None)
    path, every, meta, resumed = checkpoint if checkpoint is not None else (None, None, None, None)
    carry, done, fresh = blank, 0, True
    if resumed is not None:
        (carry, done), fresh = resumed, False
    saved, next_save = done, None if path is None else done + every
    phases = None
    while True:
        stop = NO_STOP
        if chunks is not None:
            lengths = [chunks.length(p) for p in phases] if phases is not None else [
                chunks.length(chunks.first_phase)]
            stop = min(stop, done + min(lengths))
        if next_save is not None:
            stop = min(stop, next_save)
        carry, rep = call(carry, np.asarray(fresh), np.asarray(stop, np.int32))
        fresh = False
        rep = jax.device_get(rep)
        finished = bool(np.all(rep.done))
        running = ~np.atleast_1d(rep.done)
        if sink is not None:
            for i in range(np.size(rep.phase)):
                sink(int(np.ravel(rep.phase)[i]), int(np.ravel(rep.step)[i]),
                     int(np.ravel(rep.evals)[i]), float(np.ravel(rep.f_best)[i]))
            phases = [int(p) for p in np.atleast_1d(rep.phase)[running]] or None
        if path is not None and (finished or stop >= next_save):
            steps = int(np.max(carry.steps))
            if steps != saved or not path.exists():
                ckpt.save(path, {**meta, "steps_done": steps}, carry)
                saved = steps
            next_save = steps + every
        if finished or stop == NO_STOP:
            return finish(carry)
        done = stop


def _run_many(proto, flat, lower, upper, args, keys, x0, carries, fresh, stop_at,
              batching="vmap"):
    """`_chunk` for every key: ``(carries, reports)`` with a leading axis."""
    def run(key, carry):
        return _chunk(proto, flat, lower, upper, args, key, x0, None, carry, fresh, stop_at)

    if batching == "map":
        return jax.lax.map(lambda kc: run(*kc), (keys, carries))
    return jax.vmap(run)(keys, carries)


BATCHING = ("auto", "vmap", "map")


def _batching(batching, proto, layout: Layout | None, n: int) -> str:
    """``"vmap"`` or ``"map"`` for [`minimise_many`][jaxfric.optim.minimise_many] (see its docstring)."""
    if batching not in BATCHING:
        raise ValueError(f"batching must be one of {BATCHING}, got {batching!r}")
    proto = as_protocol(proto)
    if batching == "map" and layout is not None:
        raise ValueError(
            "batching='map' runs the keys one after another on one device; with several "
            "devices pass devices=False, or batching='vmap' to lay the runs out over them"
        )
    if batching == "auto":
        # A vmapped solver with conditional batches (Nelder-Mead) computes both sides of
        # every branch; on one CPU running the keys in turn is faster (docs/solvers.md).
        # Swarms batch their evaluations well, so they keep vmap.
        one_cpu = layout is None and _platform(layout) == "cpu"
        return "map" if one_cpu and not capabilities_of(proto, n).batches_runs else "vmap"
    return batching


def _platform(layout: Layout | None) -> str:
    return layout.devices[0].platform if layout is not None else jax.default_backend()


def _unravel_solution(sol: Solution, flat: _Flat, batched: bool) -> Solution:
    if flat.shapes == (tuple(sol.value.shape[-1:]),) and jtu.treedef_is_leaf(flat.treedef):
        return sol  # bounds of one vector: the value is already in their shape
    value = jax.vmap(flat.unravel)(sol.value) if batched else flat.unravel(sol.value)
    return eqx.tree_at(lambda s: s.value, sol, value)


def _warm_state(warm_start, proto, flat, lower, upper, args, key, x0):
    """The state a warm start continues from, checked against what ``init`` builds."""
    if not isinstance(warm_start, Solution) or warm_start.state is None:
        raise ValueError("warm_start must be a Solution returned by jaxfric.minimise")
    state = warm_start.state
    expect = eqx.filter_eval_shape(compiled_start, proto, flat, lower, upper, args, key, x0)
    shape = lambda t: [(tuple(a.shape), str(a.dtype)) for a in jtu.tree_leaves(t)]  # noqa: E731
    if jtu.tree_structure(state) != jtu.tree_structure(expect) or shape(state) != shape(expect):
        raise ValueError(
            "warm_start's state does not fit this solver and problem (a different solver "
            "type, population size, number of parameters or dtype); continue a run with the "
            "same kind of solver, only a larger budget"
        )
    return continued(proto, state)


def _resume(proto, flat, lower, upper, args, key, x0, warm, path: Path, every: int):
    """``checkpoint`` for `_chunked`: the file's header, and the stored carry and its
    steps when ``path`` exists (after checking it belongs to this problem)."""
    fp = ckpt.fingerprint(flat.fn, (str(flat.treedef), flat.shapes), proto, lower,
                          upper, args, key)
    meta = ckpt.header(fp, key)
    resumed = None
    if path.exists():
        like = eqx.filter_eval_shape(_begin, proto, flat, lower, upper, args, key, x0, warm)
        stored, carry = ckpt.load(path, fp, like)
        done = int(stored["steps_done"])
        carry = eqx.tree_at(lambda c: c.steps, carry, jnp.asarray(done, jnp.int32))
        resumed = (carry, done)
    return path, every, meta, resumed


# ----------------------------------------------------------------------- entries
def minimise(
    fn: Callable,
    solver,
    bounds,
    *,
    args: Any = None,
    key=None,
    y0=None,
    dtype=None,
    progress=None,
    devices=None,
    checkpoint=None,
    checkpoint_every: int = 50,
    compiler_options="auto",
    warm_start: Solution | None = None,
) -> Solution:
    """Minimise ``fn(y, args)`` over the box ``bounds`` with ``solver``, in one jitted call.

    Args:
        fn: objective ``fn(y, args) -> scalar``; ``y`` has the structure of the bounds.
            NaN or inf values count as the worst possible value.
        solver: a jaxfric solver ([`PSO`][jaxfric.optim.PSO], [`MAPSO`][jaxfric.optim.MAPSO], [`NelderMead`][jaxfric.optim.NelderMead],
            [`MAPSONMDS`][jaxfric.optim.MAPSONMDS], [`chain`][jaxfric.optim.chain]) or any ``optimistix`` minimiser.
        bounds: a list or tuple of ``(lo, hi)`` pairs of numbers, read as SciPy reads
            it: one pair per parameter, however many (``[(-5, 10), (0, 15)]`` is two
            parameters); ``(lower, upper)`` with each side an array or a matching
            pytree of arrays; or ``scipy.optimize.Bounds``.
        args: data passed to ``fn``; arrays here do not trigger recompilation.
        key: a JAX PRNG key (``jax.random.key(0)``) or an int seed (``key=0`` is
            ``jax.random.key(0)``). Same key, same result.
        y0: optional start inside the bounds (Nelder–Mead's start; for swarms, agent 0),
            or for swarms an initial population: every leaf with one more leading axis
            ``k`` (the first ``k`` agents). A start outside the bounds is an error.
        dtype: floating dtype of the search (default: that of the bounds, float16 bounds
            searching in float32, or JAX's default float). float16 is refused.
        progress: ``True`` for a tqdm bar, a callable ``sink(phase, step, evals, f_best)``
            (phase 0 = global generations, 1 = local steps), or ``None`` (silent).
            The run then goes in chunks of about 1 % of the generations and of 50 local
            steps, and the display is updated on the host between chunks (also once at
            the end). Every chunk runs the program a silent run compiles, so a display
            neither recompiles nor changes the result (the same to the bit), and the
            persistent compilation cache keeps the program. Each chunk costs a call from
            Python, about a millisecond: leave it off for runs of a few milliseconds.
        devices: where to evaluate the population: ``None`` (default) splits it by
            agents over every device when there are several; ``False`` keeps it on one
            device; or a sequence of devices.
        checkpoint: a file path. The run then goes in chunks of ``checkpoint_every``
            steps and saves its state atomically after each; calling ``minimise`` again
            with the same path resumes from the last chunk and returns exactly the
            uninterrupted run's result. Works for every solver. The file records the
            problem (objective, bounds, args, solver, key, dtype); resuming it for a
            different problem is refused (see [`jaxfric.optim.checkpoint`][jaxfric.optim.checkpoint]).
        checkpoint_every: steps (generations, simplex steps) per chunk.
        compiler_options: XLA options for this run's executable only (never global):
            ``"auto"`` (see [`jaxfric.compiler_options`][jaxfric._xla.compiler_options];
            a run whose estimated work is small, such as a new objective's short run,
            compiles with LLVM at level 0: about half the compilation, a slower run),
            ``"full"`` (the same options, always at full optimisation: for a program run
            many times), ``"fast-compile"`` (level 0 whatever the run), ``None`` (XLA's
            defaults) or a dict of XLA option names to values.
        warm_start: a [`Solution`][jaxfric.optim.Solution] of an earlier run with the same kind of solver:
            continue it (``solver`` with a larger ``num_generations``, say) instead of
            starting afresh.

    Returns:
        A [`Solution`][jaxfric.optim.Solution] (``print`` shows value, f, evaluations and result).

    Raises:
        ValueError: before any tracing, for invalid bounds, hyperparameters, keys, or an
            objective that does not return a floating scalar.
    """
    proto, flat, lower, upper, x0 = _prepare(fn, solver, bounds, args, y0, dtype)
    if warm_start is not None and key is None:
        key = 0  # unused: the warm state carries its own
    key = check_key(key)
    layout = resolve_devices(devices)
    options = _options(compiler_options, proto, flat, lower, args, layout)
    if layout is not None:
        flat = eqx.tree_at(lambda f: f.layout, flat, layout, is_leaf=lambda x: x is None)
    warm = None
    if warm_start is not None:
        warm = _warm_state(warm_start, proto, flat, lower, upper, args, key, x0)
    resume = None
    if checkpoint is not None:
        check_positive_int("checkpoint_every", checkpoint_every)
        resume = _resume(proto, flat, lower, upper, args, key, x0, warm, Path(checkpoint),
                         checkpoint_every)
    program = _xla.filter_jit(_chunk, options)
    drawn = _drawn(proto, lower, upper, key, options)
    free = objective_free(proto, flat, args)[0] is not flat
    chunk = templated(_chunk, free, flat, _output_type(flat, lower, args) if free else None,
                      options, program, lambda operands: _xla._traced(operands, {}))

    def call(carry, fresh, stop_at):
        return chunk(proto, flat, lower, upper, args, drawn, x0, warm, carry, fresh, stop_at)

    sink, display = _display(progress, proto, lower.shape[0])
    with _closing(sink):
        blank = _blank(proto, flat, lower, upper, args, key, x0, warm)
        finish = _finisher(proto, flat, lower, upper, args, options, batched=False)
        sol = jax.block_until_ready(_chunked(call, finish, blank, display, resume))
    return _unravel_solution(sol, flat, batched=False)


def minimise_many(
    fn: Callable,
    solver,
    bounds,
    *,
    keys,
    args: Any = None,
    y0=None,
    dtype=None,
    progress=None,
    devices=None,
    compiler_options="auto",
    batching="auto",
) -> Solution:
    """Independent runs of [`minimise`][jaxfric.optim.minimise], one per key, in one jitted call.

    ``keys`` is a batch of PRNG keys (``jax.random.split(key, n)``). Every field of
    the returned [`Solution`][jaxfric.optim.Solution] gains a leading axis of length ``n``; run ``i``
    equals ``minimise(..., key=keys[i])`` up to floating-point reassociation (bit for
    bit with ``batching="map"``). Stages run in loops of their own, so a batch of
    two-stage runs never computes a global step while refining, or the reverse.
    ``progress`` as in [`minimise`][jaxfric.optim.minimise] (each chunk's end is reported once per run).
    ``devices``: ``None`` (default) lays the runs out over every device when there
    are several (the batch is padded to a multiple of the device count and the
    padding dropped); ``False`` keeps them on one device; or a sequence of devices.
    ``compiler_options`` as in [`minimise`][jaxfric.optim.minimise].

    ``batching``: ``"vmap"`` runs the keys side by side (one batched evaluation of
    every run's candidates per step; runs can be laid out over devices);
    ``"map"`` runs them one after another inside the same compiled call (``lax.map``;
    one device); ``"auto"`` (default) picks ``"map"`` for an optimistix minimiser
    ([`NelderMead`][jaxfric.optim.NelderMead]) on a single CPU device and ``"vmap"`` otherwise. Under
    ``vmap`` Nelder–Mead's conditionals become selects: ``stats["num_evals"]`` still
    counts the evaluations the algorithm asked for, but XLA computes both branches
    (slower than mapped: docs/solvers.md, "What measurements decided").
    """
    proto, flat, lower, upper, x0 = _prepare(fn, solver, bounds, args, y0, dtype)
    keys = check_key(keys, "keys", batch=True)
    layout = resolve_devices(devices)
    options = _options(compiler_options, proto, flat, lower, args, layout)
    mode = _batching(batching, proto, layout, lower.shape[0])
    keys, n = shard_keys(keys, layout)
    program = _xla.filter_jit(_run_many, options)
    drawn = _drawn(proto, lower, upper, keys, options, batched=True)

    def call(carries, fresh, stop_at):
        return program(proto, flat, lower, upper, args, drawn, x0, carries, fresh, stop_at, mode)

    sink, display = _display(progress, proto, lower.shape[0])
    with _closing(sink):
        blank = _blank(proto, flat, lower, upper, args, keys[0], x0, None, keys.shape[0])
        finish = _finisher(proto, flat, lower, upper, args, options, batched=True)
        sol = jax.block_until_ready(_chunked(call, finish, blank, display))
    if keys.shape[0] != n:
        sol = jax.tree_util.tree_map(lambda a: a[:n], sol)
    return _unravel_solution(sol, flat, batched=True)
