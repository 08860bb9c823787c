"""One-shot entry points: :func:`minimise` and :func:`minimise_many`.

Both validate everything the user gave *before* tracing, flatten pytree bounds to
one vector, and run the solver as a single jitted computation. Data travel in
``args`` (never closures), so new data of the same shapes do not recompile.
"""

from __future__ import annotations

import contextlib
from typing import Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .. import _xla
from ._base import AbstractSolver, Solution, check_positive_int
from .progress import ProgressHook, TqdmProgress, register
from .sharding import Layout, resolve_devices, shard_keys


class _Flat(eqx.Module):
    """``fn`` seen through a flat parameter vector (hashable, so jit caches it)."""

    fn: Callable = eqx.field(static=True)
    treedef: Any = eqx.field(static=True)
    shapes: tuple = eqx.field(static=True)
    layout: Layout | None = None

    def unravel(self, x):
        sizes = [int(np.prod(s)) for s in self.shapes]
        parts = jnp.split(x, np.cumsum(sizes)[:-1]) if len(sizes) > 1 else [x]
        leaves = [p.reshape(s) for p, s in zip(parts, self.shapes)]
        return jtu.tree_unflatten(self.treedef, leaves)

    def __call__(self, x, args):
        return self.fn(self.unravel(x), args)


def _as_float_leaves(tree, name, dtype=None):
    leaves, treedef = jtu.tree_flatten(tree)
    if not leaves:
        raise ValueError(f"{name} is empty")
    out = []
    for leaf in leaves:
        try:
            a = np.asarray(leaf)
        except Exception as e:  # pragma: no cover - exotic leaves
            raise ValueError(f"{name} must contain arrays or numbers: {e}") from None
        if a.dtype == object or not (
            np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)
        ):
            raise ValueError(f"{name} must be numeric, got dtype {a.dtype}")
        out.append(a)
    return out, treedef


def prepare_bounds(bounds, dtype=None):
    """Validate ``bounds = (lower, upper)`` and flatten them.

    Returns ``(lower_flat, upper_flat, treedef, shapes)``. Raises ``ValueError``
    naming the problem: wrong shape of ``bounds``, mismatched structures or shapes,
    non-finite values, ``lower >= upper``, or no parameters at all.
    """
    if not isinstance(bounds, (tuple, list)) or len(bounds) != 2:
        raise ValueError("bounds must be a pair (lower, upper)")
    lo_leaves, lo_def = _as_float_leaves(bounds[0], "lower bound")
    hi_leaves, hi_def = _as_float_leaves(bounds[1], "upper bound")
    if lo_def != hi_def:
        raise ValueError(
            f"lower and upper bounds have different structures: {lo_def} vs {hi_def}"
        )
    shapes = []
    for i, (lo, hi) in enumerate(zip(lo_leaves, hi_leaves)):
        if lo.shape != hi.shape:
            raise ValueError(
                f"lower and upper bounds have different shapes: {lo.shape} vs {hi.shape}"
                + (f" (leaf {i})" if len(lo_leaves) > 1 else "")
            )
        shapes.append(lo.shape)
    lower = np.concatenate([a.ravel() for a in lo_leaves])
    upper = np.concatenate([a.ravel() for a in hi_leaves])
    if lower.size == 0:
        raise ValueError("bounds describe zero parameters")
    if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper))):
        raise ValueError("bounds must be finite (found NaN or inf)")
    bad = np.nonzero(~(lower < upper))[0]
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"every lower bound must be < its upper bound; parameter {i} has "
            f"lower={float(lower[i])!r} >= upper={float(upper[i])!r} ({bad.size} such parameter(s))"
        )
    if dtype is None:
        dtype = np.result_type(*[a.dtype for a in lo_leaves + hi_leaves])
        if not np.issubdtype(dtype, np.floating):
            dtype = np.float64
    else:
        try:
            given = np.dtype(dtype)
        except TypeError:
            raise ValueError(f"dtype must be a floating dtype, got {dtype!r}") from None
        if not np.issubdtype(given, np.floating):
            raise ValueError(f"dtype must be a floating dtype, got {given}")
    # float64 bounds search in float32 unless the caller enabled x64 (JAX's rule).
    dtype = jax.dtypes.canonicalize_dtype(dtype)
    # The box must survive the cast to the search dtype: no zero widths, no overflow.
    lo_c, hi_c = lower.astype(dtype), upper.astype(dtype)
    with np.errstate(over="ignore", invalid="ignore"):
        width = hi_c - lo_c
    bad = np.nonzero(~(lo_c < hi_c))[0]
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"every lower bound must be < its upper bound in the search dtype {dtype}; "
            f"parameter {i} has lower={float(lower[i])!r}, upper={float(upper[i])!r}, "
            f"which are equal in {dtype} (rescale the parameter or use float64)"
        )
    if not np.all(np.isfinite(width)):
        i = int(np.nonzero(~np.isfinite(width))[0][0])
        raise ValueError(
            f"upper - lower overflows the search dtype {dtype} for parameter {i} "
            f"(lower={float(lower[i])!r}, upper={float(upper[i])!r}); rescale it or use float64"
        )
    return (
        jnp.asarray(lo_c, dtype),
        jnp.asarray(hi_c, dtype),
        lo_def,
        tuple(shapes),
    )


#: Signatures (objective, search vector, shapes and dtypes of ``args``) whose output
#: was already checked: the check traces ``fn`` (about 2 ms), which would otherwise
#: be paid by every call of :func:`minimise`.
_CHECKED: dict = {}
_CHECKED_MAX = 256


def _signature(flat, lower, args):
    """A hashable key for the output check, or ``None`` when ``args`` holds leaves
    that are neither arrays nor Python scalars (then the check is not cached)."""
    leaves, treedef = jtu.tree_flatten(args)
    sig = []
    for leaf in leaves:
        if hasattr(leaf, "shape") and hasattr(leaf, "dtype"):
            sig.append((tuple(leaf.shape), str(leaf.dtype), getattr(leaf, "weak_type", None)))
        elif isinstance(leaf, (bool, int, float, complex)):
            sig.append(type(leaf))  # traced by eval_shape: only the type matters
        else:
            return None
    try:
        key = (flat, lower.shape, str(lower.dtype), treedef, tuple(sig))
        hash(key)
    except TypeError:
        return None
    return key


def _check_output(flat, lower, args):
    """``fn(y, args)`` must return a floating scalar: checked by tracing (eval_shape)
    once per signature, before any compilation."""
    key = _signature(flat, lower, args)
    if key is not None and key in _CHECKED:
        return
    try:
        out = jax.eval_shape(flat, jax.ShapeDtypeStruct(lower.shape, lower.dtype), args)
    except Exception as e:
        raise ValueError(f"calling fn(y, args) on the bounds' shape failed: {e}") from e
    if not (
        isinstance(out, jax.ShapeDtypeStruct)
        and out.shape == ()
        and jnp.issubdtype(out.dtype, jnp.floating)
    ):
        desc = getattr(out, "shape", type(out).__name__)
        raise ValueError(
            f"fn(y, args) must return a floating-point scalar, got {desc} "
            f"{getattr(out, 'dtype', '')}".rstrip()
        )
    if key is not None:
        if len(_CHECKED) >= _CHECKED_MAX:
            _CHECKED.pop(next(iter(_CHECKED)))
        _CHECKED[key] = True


def _prepare(fn, solver, bounds, args, y0, dtype):
    if not callable(fn):
        raise ValueError(f"fn must be callable fn(y, args), got {type(fn).__name__}")
    if not isinstance(solver, AbstractSolver):
        raise ValueError(
            f"solver must be a jaxfric solver (PSO, MAPSO, NelderMead, MAPSONMDS, ...), "
            f"got {type(solver).__name__}"
        )
    solver.check()
    lower, upper, treedef, shapes = prepare_bounds(bounds, dtype)
    flat = _Flat(fn, treedef, shapes)
    _check_output(flat, lower, args)
    x0 = None
    if y0 is not None:
        y_leaves, y_def = _as_float_leaves(y0, "y0")
        if y_def != treedef or [a.shape for a in y_leaves] != list(shapes):
            raise ValueError("y0 must have the same structure and shapes as the bounds")
        x0 = jnp.asarray(np.concatenate([a.ravel() for a in y_leaves]), lower.dtype)
        if not bool(jnp.all(jnp.isfinite(x0))):
            raise ValueError("y0 must be finite (found NaN or inf)")
        outside = np.nonzero(np.asarray((x0 < lower) | (x0 > upper)))[0]
        if outside.size:
            i = int(outside[0])
            raise ValueError(
                f"y0 lies outside the bounds at {outside.size} parameter(s), first at flat "
                f"index {i}: {float(x0[i])!r} not in [{float(lower[i])!r}, {float(upper[i])!r}]; "
                "a start is used as given, never clipped"
            )
    return flat, lower, upper, x0


def _check_key(key, name="key", batch=False):
    """A single key (``batch=False``) or a non-empty batch of keys, else ``ValueError``."""
    if key is None:
        raise ValueError(f"{name} is required: pass jax.random.key(seed)")
    k = jnp.asarray(key)
    typed = jnp.issubdtype(k.dtype, jax.dtypes.prng_key)
    if not (typed or k.dtype == jnp.uint32):
        raise ValueError(f"{name} must be a JAX PRNG key, got dtype {k.dtype}")
    key_ndim = k.ndim if typed else k.ndim - 1  # raw uint32 keys carry a trailing axis
    if not batch and key_ndim != 0:
        raise ValueError(
            f"{name} must be one key, got a batch of shape {k.shape}; "
            "for several runs use minimise_many"
        )
    if batch:
        if key_ndim != 1:
            raise ValueError("keys must be a batch of keys, e.g. jax.random.split(key, 30)")
        if k.shape[0] == 0:
            raise ValueError("keys is empty: pass at least one key")
    return key


def _progress(progress, solver):
    """``(context manager yielding a hook or None)`` for ``progress=``."""
    if progress is None or progress is False:
        return contextlib.nullcontext(None)
    total, local_total = solver.progress_totals()
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


def _run(solver, flat, lower, upper, args, key, x0, hook):
    return solver.run(flat, lower, upper, args, key, x0, hook)


@_xla.no_single_kernel  # batched, the loop gained nothing and outgrew one CPU kernel
def _run_many(solver, flat, lower, upper, args, keys, x0, hook):
    return jax.vmap(lambda k: solver.run(flat, lower, upper, args, k, x0, hook))(keys)


def _run_many_map(solver, flat, lower, upper, args, keys, x0, hook):
    return jax.lax.map(lambda k: solver.run(flat, lower, upper, args, k, x0, hook), keys)


BATCHING = ("auto", "vmap", "map")


def _batching(batching, solver, layout: Layout | None) -> str:
    """``"vmap"`` or ``"map"`` for :func:`minimise_many` (see its docstring)."""
    if batching not in BATCHING:
        raise ValueError(f"batching must be one of {BATCHING}, got {batching!r}")
    if batching == "map" and layout is not None:
        raise ValueError(
            "batching='map' runs the keys one after another on one device; with several "
            "devices pass devices=False, or batching='vmap' to lay the runs out over them"
        )
    if batching == "auto":
        # A vmapped Nelder-Mead computes both sides of every branch (the shrink's n
        # evaluations each step); on one CPU running the keys in turn is faster
        # (peers.md §1). Swarms batch their evaluations well, so they keep vmap.
        from .nelder_mead import NelderMead

        one_cpu = layout is None and _platform(layout) == "cpu"
        return "map" if one_cpu and isinstance(solver, NelderMead) else "vmap"
    return batching


def _platform(layout: Layout | None) -> str:
    return layout.devices[0].platform if layout is not None else jax.default_backend()


def _unravel_solution(sol: Solution, flat: _Flat, batched: bool) -> Solution:
    if batched:
        value = jax.vmap(flat.unravel)(sol.value)
    else:
        value = flat.unravel(sol.value)
    return eqx.tree_at(lambda s: s.value, sol, value)


def minimise(
    fn: Callable,
    solver: AbstractSolver,
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
) -> Solution:
    """Minimise ``fn(y, args)`` over the box ``bounds`` with ``solver``, in one jitted call.

    Args:
        fn: objective ``fn(y, args) -> scalar``; ``y`` has the structure of the bounds.
            NaN or inf values count as the worst possible value.
        solver: a jaxfric solver (:class:`PSO`, :class:`MAPSO`, :class:`NelderMead`,
            :class:`MAPSONMDS`).
        bounds: ``(lower, upper)``, arrays or matching pytrees of arrays.
        args: data passed to ``fn``; arrays here do not trigger recompilation.
        key: a JAX PRNG key (``jax.random.key(0)``). Same key, same result.
        y0: optional starting point (Nelder–Mead's start; for swarms, one agent),
            inside the bounds (a start outside them is an error, not clipped).
        dtype: floating dtype of the search (default: that of the bounds, or JAX's
            default float).
        progress: ``True`` for a tqdm bar (generation or step, best f, evaluations,
            elapsed), a callable ``sink(phase, step, evals, f_best)`` (phase 0 =
            global generations, 1 = Nelder–Mead steps), or ``None`` (silent). Reports
            come from inside the compiled run about every 1 % of the generations
            and every 50 Nelder–Mead steps; a new display never recompiles. The
            report is a host callback: it costs time of its own and keeps a CPU swarm
            loop out of one kernel (a 15 ms MAPSO run, 100 agents and 253 generations,
            took 54 ms with a do-nothing sink), so leave it off for short runs.
        devices: where to evaluate the population: ``None`` (default) splits it by
            agents over every device when there are several (no effect on one);
            ``False`` keeps it on one device; or a sequence of devices.
        checkpoint: a file path. The global (swarm) phase then runs in chunks of
            ``checkpoint_every`` generations and saves its state atomically after each;
            calling ``minimise`` again with the same path resumes from the last chunk
            and returns exactly the uninterrupted run's result for the same key (swarm
            solvers and MAPSO–NMDS only; see :mod:`jaxfric.optim.checkpoint`).
        checkpoint_every: generations per chunk.
        compiler_options: XLA options for this run's executable only (never global):
            ``"auto"`` (default; on CPU, 512-bit vectors, XLA's older fusion code
            generator, and a small swarm's whole generation loop, else MAPSO's
            self-learning loop, as one kernel; measured faster for the swarms, see
            :mod:`jaxfric._xla`), ``None`` (XLA's defaults) or a dict of XLA option
            names to values (plus ``"jaxfric_single_kernel_loops": bool``).

    Returns:
        A :class:`Solution`.

    Raises:
        ValueError: before any tracing, for invalid bounds, hyperparameters, keys, or an
            objective that does not return a floating scalar.
    """
    flat, lower, upper, x0 = _prepare(fn, solver, bounds, args, y0, dtype)
    key = _check_key(key)
    layout = resolve_devices(devices)
    options = _xla.resolve(compiler_options, "solver", _platform(layout))
    if layout is not None:
        options = _xla.without_single_kernel(options)  # keep the sharded program plain
        flat = eqx.tree_at(lambda f: f.layout, flat, layout, is_leaf=lambda x: x is None)
    if checkpoint is not None:
        from .checkpoint import _swarm_of, run_checkpointed

        _swarm_of(solver)  # only swarm solvers can be chunked: fail before any work
        check_positive_int("checkpoint_every", checkpoint_every)
    with _progress(progress, solver) as hook:
        if checkpoint is None:
            run = _xla.filter_jit(_run, options)
            sol = run(solver, flat, lower, upper, args, key, x0, hook)
        else:
            sol = run_checkpointed(
                solver, flat, lower, upper, args, key, x0, hook, checkpoint, checkpoint_every,
                options,
            )
        jax.block_until_ready(sol)
    return _unravel_solution(sol, flat, batched=False)


def minimise_many(
    fn: Callable,
    solver: AbstractSolver,
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
    """Independent runs of :func:`minimise`, one per key, in one jitted call.

    ``keys`` is a batch of PRNG keys (``jax.random.split(key, n)``). Every field of
    the returned :class:`Solution` gains a leading axis of length ``n``; run ``i``
    equals ``minimise(..., key=keys[i])`` up to floating-point reassociation (bit for
    bit with ``batching="map"``).
    ``progress`` as in :func:`minimise` (reports arrive once per run and step).
    ``devices``: ``None`` (default) lays the runs out over every device when there
    are several (the batch is padded to a multiple of the device count and the
    padding dropped); ``False`` keeps them on one device; or a sequence of devices.
    ``compiler_options`` as in :func:`minimise`.

    ``batching``: ``"vmap"`` runs the keys side by side (one batched evaluation of
    every run's candidates per step; runs can be laid out over devices);
    ``"map"`` runs them one after another inside the same compiled call (``lax.map``;
    one device); ``"auto"`` (default) picks ``"map"`` for :class:`NelderMead` on a
    single CPU device and ``"vmap"`` otherwise. Under ``vmap`` Nelder–Mead's
    conditionals become selects: ``stats["num_evals"]`` still counts the evaluations
    the algorithm asked for, but XLA computes both branches (the shrink's ``n``
    evaluations every step), which made 8 vmapped runs on 30-D Rosenbrock about 1.5×
    slower than the same runs mapped (benchmarks/results/peers.md §1).
    """
    flat, lower, upper, x0 = _prepare(fn, solver, bounds, args, y0, dtype)
    keys = _check_key(keys, "keys", batch=True)
    layout = resolve_devices(devices)
    options = _xla.resolve(compiler_options, "solver", _platform(layout))
    run = _run_many_map if _batching(batching, solver, layout) == "map" else _run_many
    if layout is not None:
        options = _xla.without_single_kernel(options)
    keys, n = shard_keys(keys, layout)
    with _progress(progress, solver) as hook:
        sol = _xla.filter_jit(run, options)(solver, flat, lower, upper, args, keys, x0, hook)
        jax.block_until_ready(sol)
    if keys.shape[0] != n:
        sol = jax.tree_util.tree_map(lambda a: a[:n], sol)
    return _unravel_solution(sol, flat, batched=True)
