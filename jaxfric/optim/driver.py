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
from pathlib import Path
from typing import Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu

from .. import _xla
from . import checkpoint as ckpt
from ._base import Solution, check_positive_int
from .loop import NO_STOP, _begin, _run
from .rounds import compiled_start
from .optx_adapter import as_protocol
from .problem import _check_output, _Flat, check_budget, check_key, check_start, prepare_bounds
from .progress import ProgressHook, TqdmProgress, register
from .sharding import Layout, resolve_devices, shard_keys

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
                                             proto.population_size())
    return proto, flat, lower, upper, x0


# ---------------------------------------------------------------------- progress
def _progress(progress, proto):
    """``(context manager yielding a hook or None)`` for ``progress=``."""
    if progress is None or progress is False:
        return contextlib.nullcontext(None)
    total, local_total = proto.progress_totals()
    if progress is True:
        sink = TqdmProgress(total, local_total)
    elif callable(progress):
        sink = progress
    else:
        raise ValueError(
            "progress must be None, True (a tqdm bar) or a callable "
            f"sink(phase, step, evals, f_best), got {type(progress).__name__}"
        )
    every = max(1, (total or 100) // 100)

    @contextlib.contextmanager
    def ctx():
        with register(sink) as token:
            yield ProgressHook(token, every_generation=every, every_step=50)

    return ctx()


def _one(proto, flat, lower, upper, args, key, x0, hook):
    return _run(proto, flat, lower, upper, args, key, x0, hook)[1]


def _run_many(proto, flat, lower, upper, args, keys, x0, hook, batching="vmap"):
    run = lambda k: _one(proto, flat, lower, upper, args, k, x0, hook)  # noqa: E731
    if batching == "map":
        return jax.lax.map(run, keys)
    return jax.vmap(run)(keys)


BATCHING = ("auto", "vmap", "map")


def _batching(batching, proto, layout: Layout | None) -> str:
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
        return "map" if one_cpu and not proto.batches_runs() else "vmap"
    return batching


def _platform(layout: Layout | None) -> str:
    return layout.devices[0].platform if layout is not None else jax.default_backend()


def _unravel_solution(sol: Solution, flat: _Flat, batched: bool) -> Solution:
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
    return proto.continued(state)


def _run_checkpointed(run, proto, flat, lower, upper, args, key, x0, hook, warm,
                      path: Path, every: int):
    """Drive ``run`` (the compiled `_run`) in chunks of ``every`` steps, saving the
    carry to ``path`` after each; resume from ``path`` when it exists. A chunked run
    takes the same steps, in the same order, with the same compiled loop, so it returns
    exactly what the uninterrupted run returns."""
    fp = ckpt.fingerprint(flat.fn, (str(flat.treedef), flat.shapes), proto, lower,
                                upper, args, key)
    meta = ckpt.header(fp, key)
    carry, done = None, 0
    if path.exists():
        like = eqx.filter_eval_shape(_begin, proto, flat, lower, upper, args, key, x0, warm)
        stored, carry = ckpt.load(path, fp, like)
        done = int(stored["steps_done"])
        carry = eqx.tree_at(lambda c: c.steps, carry, jnp.asarray(done, jnp.int32))
    while True:
        carry, sol = run(proto, flat, lower, upper, args, key, x0, hook, carry, warm,
                         jnp.asarray(done + every, jnp.int32))
        new_done = int(carry.steps)
        finished = new_done < done + every
        if new_done != done or not path.exists():
            ckpt.save(path, {**meta, "steps_done": new_done}, carry)
        if finished:
            return sol
        done = new_done


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
            Reports come from inside the compiled run about every 1 % of the generations
            and every 50 local steps, and once when each stage ends; a new display never
            recompiles. A host callback costs time of its own: leave it off for short runs.
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
            ``"auto"`` (see [`jaxfric.compiler_options`][jaxfric._xla.compiler_options]), ``None`` (XLA's
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
    options = _xla.resolve(compiler_options, "solver", _platform(layout))
    if layout is not None:
        flat = eqx.tree_at(lambda f: f.layout, flat, layout, is_leaf=lambda x: x is None)
    warm = None
    if warm_start is not None:
        warm = _warm_state(warm_start, proto, flat, lower, upper, args, key, x0)
    if checkpoint is not None:
        check_positive_int("checkpoint_every", checkpoint_every)
    with _progress(progress, proto) as hook:
        if checkpoint is None:
            # stop_at as an array, as a checkpointed run's chunks pass it: the whole run
            # and a checkpointed run's first chunk are then one compiled program
            _, sol = _xla.filter_jit(_run, options)(
                proto, flat, lower, upper, args, key, x0, hook, None, warm,
                jnp.asarray(NO_STOP, jnp.int32))
        else:
            sol = _run_checkpointed(
                _xla.filter_jit(_run, options), proto, flat, lower, upper, args, key, x0,
                hook, warm, Path(checkpoint), checkpoint_every,
            )
        jax.block_until_ready(sol)
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
    ``progress`` as in [`minimise`][jaxfric.optim.minimise] (reports arrive once per run and step).
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
    counts the evaluations the algorithm asked for, but XLA computes both branches,
    which made 8 vmapped runs on 30-D Rosenbrock about 1.5× slower than the same runs
    mapped (docs/solvers.md, "What measurements decided").
    """
    proto, flat, lower, upper, x0 = _prepare(fn, solver, bounds, args, y0, dtype)
    keys = check_key(keys, "keys", batch=True)
    layout = resolve_devices(devices)
    options = _xla.resolve(compiler_options, "solver", _platform(layout))
    mode = _batching(batching, proto, layout)
    keys, n = shard_keys(keys, layout)
    with _progress(progress, proto) as hook:
        sol = _xla.filter_jit(_run_many, options)(
            proto, flat, lower, upper, args, keys, x0, hook, mode)
        jax.block_until_ready(sol)
    if keys.shape[0] != n:
        sol = jax.tree_util.tree_map(lambda a: a[:n], sol)
    return _unravel_solution(sol, flat, batched=True)
