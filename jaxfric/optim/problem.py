"""What a problem is made of, checked before anything is traced: bounds (pytrees, or
scipy's sequence of ``(lo, hi)`` pairs / ``scipy.optimize.Bounds``), the objective's
output, starts, keys and the evaluation budget. The one home of these checks: the
driver ([`jaxfric.optim.driver`][jaxfric.optim.driver]) and ask/tell call them."""

from __future__ import annotations

import functools
import math
import numbers
from typing import Any, Callable

import equinox as eqx
import jax
import jax.extend.core
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from ._base import count_dtype
from .contract import AbstractLocal, AbstractStaged, capabilities_of
from .sharding import Layout


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


def _is_number(x) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool) or (
        isinstance(x, np.ndarray) and x.ndim == 0)


def _is_pair(p) -> bool:
    return isinstance(p, (tuple, list)) and len(p) == 2 and all(_is_number(v) for v in p)


def _scipy_bounds(bounds):
    """``((lower, upper), read_from_pairs)``. SciPy's forms: ``scipy.optimize.Bounds``, or
    a list or tuple whose every item is a ``(lo, hi)`` pair of numbers, one pair per
    parameter whatever their number (SciPy's rule: Branin's ``[(-5, 10), (0, 15)]`` is
    two parameters). Anything else comes back as given: the ``(lower, upper)`` form,
    whose two sides are arrays or pytrees of arrays."""
    if type(bounds).__name__ == "Bounds" and hasattr(bounds, "lb") and hasattr(bounds, "ub"):
        lb, ub = np.broadcast_arrays(np.asarray(bounds.lb, float), np.asarray(bounds.ub, float))
        return (np.array(lb), np.array(ub)), False
    if isinstance(bounds, (tuple, list)) and bounds and all(_is_pair(p) for p in bounds):
        pairs = np.asarray(bounds, dtype=float)
        return (pairs[:, 0], pairs[:, 1]), True
    return bounds, False


def _refuse_first(ok, message):
    """``ValueError(message(i, count))`` for the first parameter ``i`` where ``ok`` fails
    (``count`` of them fail)."""
    bad = np.nonzero(~np.asarray(ok))[0]
    if bad.size:
        raise ValueError(message(int(bad[0]), bad.size))


def prepare_bounds(bounds, dtype=None):
    """Validate ``bounds`` and flatten them. A list or tuple of ``(lo, hi)`` pairs of
    numbers is read as SciPy reads it, one pair per parameter; any other pair is
    ``(lower, upper)``, each side an array or a pytree of arrays; or
    ``scipy.optimize.Bounds``.

    Returns ``(lower_flat, upper_flat, treedef, shapes)``. Raises ``ValueError``
    naming the problem: wrong shape of ``bounds``, mismatched structures or shapes,
    non-finite values, ``lower >= upper``, or no parameters at all.
    """
    bounds, pairs = _scipy_bounds(bounds)
    if not isinstance(bounds, (tuple, list)) or len(bounds) != 2:
        raise ValueError(
            "bounds must be a pair (lower, upper), a sequence of (lo, hi) pairs, one per "
            "parameter, or scipy.optimize.Bounds"
        )
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
    read_as = (" (bounds read as SciPy's (lo, hi) pairs, one per parameter; for vectors "
               "of lower and upper bounds pass arrays: (np.array(lower), np.array(upper)))"
               if pairs else "")
    _refuse_first(lower < upper, lambda i, count: (
        f"every lower bound must be < its upper bound; parameter {i} has "
        f"lower={float(lower[i])!r} >= upper={float(upper[i])!r} ({count} such parameter(s))"
        + read_as))
    if dtype is None:
        dtype = np.result_type(*[a.dtype for a in lo_leaves + hi_leaves])
        if not np.issubdtype(dtype, np.floating):
            dtype = np.float64
        elif np.dtype(dtype).itemsize < 4:
            # float16 bounds: search in float32 (in float16 the velocities and
            # random draws overflow and the swarm stalls without a word)
            dtype = np.float32
    else:
        try:
            given = np.dtype(dtype)
        except TypeError:
            raise ValueError(f"dtype must be a floating dtype, got {dtype!r}") from None
        if not np.issubdtype(given, np.floating):
            raise ValueError(f"dtype must be a floating dtype, got {given}")
        if given.itemsize < 4:
            raise ValueError(
                f"dtype {given} is too narrow for the search (its range and 11-bit precision "
                "overflow the swarm's velocities and random draws): use float32 or float64"
            )
    # float64 bounds search in float32 unless the caller enabled x64 (JAX's rule).
    dtype = jax.dtypes.canonicalize_dtype(dtype)
    # The box must survive the cast to the search dtype: no zero widths, no overflow.
    lo_c, hi_c = lower.astype(dtype), upper.astype(dtype)
    with np.errstate(over="ignore", invalid="ignore"):
        width = hi_c - lo_c
    _refuse_first(lo_c < hi_c, lambda i, _: (
        f"every lower bound must be < its upper bound in the search dtype {dtype}; "
        f"parameter {i} has lower={float(lower[i])!r}, upper={float(upper[i])!r}, "
        f"which are equal in {dtype} (rescale the parameter or use float64)"))
    _refuse_first(np.isfinite(width), lambda i, _: (
        f"upper - lower overflows the search dtype {dtype} for parameter {i} "
        f"(lower={float(lower[i])!r}, upper={float(upper[i])!r}); rescale it or use float64"))
    return (
        jnp.asarray(lo_c, dtype),
        jnp.asarray(hi_c, dtype),
        lo_def,
        tuple(shapes),
    )


#: Signatures (objective, search vector, shapes and dtypes of ``args``) whose output
#: was already checked, with the objective's `jaxpr_work`: the check traces ``fn``
#: (about 2 ms), which would otherwise be paid by every call of `minimise`.
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


def _sub_jaxprs(param):
    if isinstance(param, jax.extend.core.ClosedJaxpr):
        yield param.jaxpr
    elif isinstance(param, jax.extend.core.Jaxpr):
        yield param
    elif isinstance(param, (tuple, list)):
        for p in param:
            yield from _sub_jaxprs(p)


def jaxpr_work(jaxpr) -> float:
    """Array elements one call of ``jaxpr`` computes, an estimate of its run time known
    before XLA runs: every equation's output size (a matrix product's times its
    contracted size), a ``scan``'s body times its length, a ``cond``'s costliest branch;
    ``inf`` with a ``while`` loop, whose trip count is unknown."""
    total = 0.0
    for eqn in jaxpr.eqns:
        name = eqn.primitive.name
        subs = [j for p in eqn.params.values() for j in _sub_jaxprs(p)]
        if name == "while":
            return math.inf
        if name == "scan":
            total += eqn.params["length"] * sum(map(jaxpr_work, subs))
        elif name == "cond":
            total += max(map(jaxpr_work, subs))
        elif subs:
            total += sum(map(jaxpr_work, subs))
        else:
            size = sum(math.prod(getattr(v.aval, "shape", ())) for v in eqn.outvars)
            if name == "dot_general":
                (contracted, _), _ = eqn.params["dimension_numbers"]
                size *= math.prod(eqn.invars[0].aval.shape[d] for d in contracted)
            total += max(size, 1)
    return total


def _local_evaluations(solver, n: int) -> int | None:
    """Evaluations a run of ``solver`` is expected to take (`run_work`): a local solver's
    two a step (Nelder–Mead's reflection and at most one more; its budget counts a
    shrink's ``n + 2`` at every step), a chain's stages added, any other's budget."""
    if isinstance(solver, AbstractStaged):  # a chain: its stages' added
        return solver.expected_evaluations(n, _local_evaluations)
    cap = capabilities_of(solver, n)
    if isinstance(solver, AbstractLocal):
        return None if cap.max_steps is None else n + 1 + 2 * cap.max_steps
    return cap.max_evaluations


def run_work(solver, n: int, per_evaluation: float) -> float | None:
    """A run's estimated work, for ``compiler_options="auto"`` (its rule in docs/solvers.md):
    its expected evaluations times (the objective's `jaxpr_work` + ``n``, the solver's own
    arithmetic per point); ``None`` where the evaluations are unknown."""
    evals = _local_evaluations(solver, n)
    return None if evals is None else evals * (per_evaluation + n)


def _check_output(flat, lower, args) -> float:
    """``fn(y, args)`` must return a floating scalar: checked by tracing (make_jaxpr)
    once per signature, before any compilation. Returns the objective's `jaxpr_work`."""
    key = _signature(flat, lower, args)
    if key is not None and key in _CHECKED:
        return _CHECKED[key]
    try:
        jaxpr, out = jax.make_jaxpr(flat, return_shape=True)(
            jax.ShapeDtypeStruct(lower.shape, lower.dtype), args)
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
    work = jaxpr_work(jaxpr.jaxpr)
    if key is not None:
        if len(_CHECKED) >= _CHECKED_MAX:
            _CHECKED.pop(next(iter(_CHECKED)))
        _CHECKED[key] = work
    return work


def check_budget(solver, n: int):
    """The evaluation counter must hold the budget of ``solver``'s run on ``n`` parameters."""
    top = int(jnp.iinfo(count_dtype()).max)
    most = capabilities_of(solver, n).max_evaluations
    if most is not None and most > top:
        raise ValueError(
            f"this run may take {most:,} objective evaluations, more than the {count_dtype()} "
            f"evaluation counter holds ({top:,}); enable 64-bit counters with "
            "`with jax.enable_x64(True):` (a float32 search stays float32 with dtype=) "
            "or lower the budget"
        )


def check_start(y0, treedef, shapes, lower, upper, agents: int | None):
    """``y0`` as a flat start ``(D,)``, or for a population solver of ``agents`` agents
    an initial population ``(k, D)`` (every leaf with one more leading axis of the same
    length ``k <= agents``)."""
    y_leaves, y_def = _as_float_leaves(y0, "y0")
    if y_def != treedef:
        raise ValueError("y0 must have the same structure and shapes as the bounds")
    if [a.shape for a in y_leaves] == list(shapes):
        x0 = np.concatenate([a.ravel() for a in y_leaves])[None]
    elif all(a.ndim == len(s) + 1 and a.shape[1:] == s for a, s in zip(y_leaves, shapes)) and len(
        {a.shape[0] for a in y_leaves}
    ) == 1:
        k = y_leaves[0].shape[0]
        x0 = np.concatenate([a.reshape(k, -1) for a in y_leaves], axis=1)
        if agents is None:
            raise ValueError(
                "y0 with a leading population axis needs a swarm (PSO, MAPSO, or a chain "
                "starting with one); this solver takes one start"
            )
        if k > agents:
            raise ValueError(f"y0 holds {k} starts but the swarm has {agents} agents")
    else:
        raise ValueError("y0 must have the same structure and shapes as the bounds "
                         "(or, for swarms, one more leading axis: an initial population)")
    x0 = jnp.asarray(x0, lower.dtype)
    if not bool(jnp.all(jnp.isfinite(x0))):
        raise ValueError("y0 must be finite (found NaN or inf)")
    outside = np.nonzero(np.asarray(jnp.any((x0 < lower) | (x0 > upper), axis=0)))[0]
    if outside.size:
        i = int(outside[0])
        bad = np.asarray(x0[:, i])
        v = bad[(bad < float(lower[i])) | (bad > float(upper[i]))][0]
        raise ValueError(
            f"y0 lies outside the bounds at {outside.size} parameter(s), first at flat "
            f"index {i}: {float(v)!r} not in [{float(lower[i])!r}, {float(upper[i])!r}]; "
            "a start is used as given, never clipped"
        )
    return x0[0] if x0.shape[0] == 1 and not agents else x0


@functools.lru_cache(maxsize=256)
def _int_key(seed: int, impl: str):
    """``jax.random.key(seed)`` (JAX's default implementation ``impl``), made once per seed (an eager dispatch per call cost a
    short run about a millisecond; a key is immutable, so sharing one is safe)."""
    return jax.random.key(seed)


def check_key(key, name="key", batch=False):
    """One key (an int seed is accepted, as [`jaxfric.identify`][jaxfric.identification.identify] does) or, with
    ``batch``, a non-empty batch of keys; else ``ValueError`` naming the problem."""
    if key is None:
        raise ValueError(f"{name} is required: pass jax.random.key(seed) (or an int seed)")
    if isinstance(key, numbers.Integral) and not isinstance(key, bool):
        if batch:
            raise ValueError(f"{name} must be a batch of keys, e.g. "
                             f"jax.random.split(jax.random.key({int(key)}), 8), not an int")
        return _int_key(int(key), jax.config.jax_default_prng_impl)
    try:
        k = jnp.asarray(key)
    except TypeError:
        raise ValueError(f"{name} must be a JAX PRNG key or an int seed, got "
                         f"{type(key).__name__}") from None
    typed = jnp.issubdtype(k.dtype, jax.dtypes.prng_key)
    if not (typed or k.dtype == jnp.uint32):
        raise ValueError(f"{name} must be a JAX PRNG key (or an int seed), got dtype {k.dtype}")
    if not typed:
        if k.ndim == 0 or k.shape[-1] != 2:
            raise ValueError(
                f"{name} is a raw uint32 array of shape {k.shape}, but a raw key has 2 words "
                f"(shape (2,), or (n, 2) for a batch); pass jax.random.key(seed) or an int seed"
            )
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
