"""A solver's program traced once per solver and problem shape, the objective filled in
for each new objective (issue 47).

Tracing ``_chunk`` (the solver's loop, start and report) took about a sixth of a new
objective's first ``minimise`` of a 2-D to 10-D MAPSO–NMDS run, and all of it but the
objective's own operations is the same for every objective of the same shapes. So the
driver traces it once per solver, shapes and dtypes with a stand-in objective, a
primitive (``jaxfric_objective``) that only knows the output type, and keeps that jaxpr
(the *template*). For a new objective it traces the objective alone, vmapped as each
stand-in's batch is, puts it in place of each stand-in as a ``jit`` call, and compiles
the result: the same program as tracing ``_chunk`` with the objective (the objective's
operations are those of the ``vmap`` the solver applies; XLA inlines the call), without
tracing the solver again.

Only where nothing else depends on the objective: a jaxfric solver (an optimistix
minimiser may call it in other ways), one run (`minimise`; ``minimise_many`` vmaps the
program), no device layout, an objective with a strong (not weak) output dtype, and
hashable static parts; anything else is traced as before (`templated` falls back).
"""

from __future__ import annotations

import collections
import functools
import weakref

import equinox as eqx
import jax
import jax.tree_util as jtu
import numpy as np
from jax.extend.core import ClosedJaxpr, Primitive, jaxpr_as_fun
from jax.interpreters import batching

__all__ = ["templated"]


class _Unsupported(Exception):
    """The template cannot serve this call: trace the program as usual."""


# ------------------------------------------------------------------ the stand-in
objective_p = Primitive("jaxfric_objective")
_NOT_MAPPED = getattr(batching, "not_mapped", None)  # an unbatched operand's axis


def _abstract(*avals, out_dtype, shapes, num_y):
    y0 = avals[0]
    batch = y0.shape[: y0.ndim - len(shapes[0])]
    return jax.core.ShapedArray(batch, out_dtype)


def _batched(vals, dims, *, out_dtype, shapes, num_y):
    # the solver vmaps the objective over the rows of a batch (axis 0), the data unbatched
    ys, rest = vals[:num_y], vals[num_y:]
    if any(d != 0 for d in dims[:num_y]) or any(d is not _NOT_MAPPED for d in dims[num_y:]):
        raise _Unsupported("the stand-in objective batched other than over its rows")
    return objective_p.bind(*ys, *rest, out_dtype=out_dtype, shapes=shapes, num_y=num_y), 0


objective_p.def_abstract_eval(_abstract)
batching.primitive_batchers[objective_p] = _batched


@functools.cache
def _stand_in(out_dtype, shapes):
    """``fn(y, args)`` binding `objective_p` on the leaves of ``y`` and ``args`` (one
    function per output dtype and shapes, so templates are found again)."""
    def fn(y, args):
        ys, args_leaves = jtu.tree_leaves(y), jtu.tree_leaves(args)
        return objective_p.bind(*ys, *args_leaves, out_dtype=out_dtype, shapes=shapes,
                                num_y=len(ys))

    return fn


# -------------------------------------------------------------------- filling in
def _objective_eqn(fn, y_tree, args_tree, eqn, singles):
    """A ``jit`` equation of ``fn`` vmapped as the stand-in ``eqn`` is, on its operands.
    ``singles``: the objective's jaxpr on one point, traced once per call of `templated`
    and vmapped from there for each batch shape (the operations ``vmap`` of ``fn`` binds)."""
    p = eqn.params
    num_y = p["num_y"]
    avals = [v.aval for v in eqn.invars]
    depth = avals[0].ndim - len(p["shapes"][0])
    point = [jax.ShapeDtypeStruct(a.shape[depth:] if i < num_y else a.shape, a.dtype,
                                  weak_type=a.weak_type) for i, a in enumerate(avals)]
    known = tuple((s.shape, str(s.dtype), s.weak_type) for s in point)
    if known not in singles:
        def one(*leaves):
            y = jtu.tree_unflatten(y_tree, leaves[:num_y])
            args = jtu.tree_unflatten(args_tree, leaves[num_y:])
            return fn(y, args)

        singles[known] = jax.make_jaxpr(one)(*point)
    run = jaxpr_as_fun(singles[known])

    def batched(*leaves):
        return run(*leaves)[0]

    for _ in range(depth):
        batched = jax.vmap(batched, in_axes=(0,) * num_y + (None,) * (len(avals) - num_y))
    spec = [jax.ShapeDtypeStruct(a.shape, a.dtype, weak_type=a.weak_type) for a in avals]
    closed = jax.make_jaxpr(lambda *v: jax.jit(batched, keep_unused=True)(*v))(*spec)
    if closed.consts or len(closed.jaxpr.eqns) != 1 or closed.jaxpr.effects:
        raise _Unsupported("the objective is not one pure call")
    call = closed.jaxpr.eqns[0]
    out = call.outvars[0].aval
    if (out.shape, out.dtype) != (eqn.outvars[0].aval.shape, eqn.outvars[0].aval.dtype):
        raise _Unsupported("the objective's output differs from the stand-in's")
    if list(call.invars) != list(closed.jaxpr.invars):
        raise _Unsupported("the objective's call does not take its operands as given")
    return call.replace(invars=list(eqn.invars), outvars=list(eqn.outvars))


def _fill(jaxpr, make):
    """``jaxpr`` with every stand-in equation replaced by ``make(eqn)`` (inside loops,
    branches and calls too); the same object where it holds none."""
    eqns, changed = [], False
    for eqn in jaxpr.eqns:
        if eqn.primitive is objective_p:
            eqns.append(make(eqn))
            changed = True
            continue
        params, touched = {}, False
        for name, value in eqn.params.items():
            new = _fill_param(value, make)
            touched |= new is not value
            params[name] = new
        if touched:
            eqn = eqn.replace(params=params)
            changed = True
        eqns.append(eqn)
    return jaxpr.replace(eqns=eqns) if changed else jaxpr


def _fill_param(value, make):
    if isinstance(value, ClosedJaxpr):
        inner = _fill(value.jaxpr, make)
        return value if inner is value.jaxpr else ClosedJaxpr(inner, value.consts)
    if isinstance(value, jax.extend.core.Jaxpr):
        return _fill(value, make)
    if isinstance(value, tuple) and any(isinstance(v, (ClosedJaxpr, jax.extend.core.Jaxpr))
                                        for v in value):
        new = tuple(_fill_param(v, make) for v in value)
        return value if all(a is b for a, b in zip(new, value)) else new
    return value


# ----------------------------------------------------------------------- caches
def _signature(tree):
    """``tree``'s structure with its arrays as (shape, dtype, weak type) and the rest by
    value: what a trace of it depends on."""
    leaves, treedef = jtu.tree_flatten(tree)
    sig = tuple((tuple(x.shape), str(x.dtype), bool(getattr(x, "weak_type", False)))
                if eqx.is_array(x) else x for x in leaves)
    key = (treedef, sig)
    hash(key)  # TypeError: not cacheable
    return key


_TEMPLATES: collections.OrderedDict = collections.OrderedDict()
_TEMPLATES_MAX = 16
#: ``fn -> {(template key, options): compiled program}``, weakly held per objective
_PROGRAMS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _template(chunk, operands, key):
    """``(closed jaxpr, output treedef, static output)`` of ``chunk(*operands)`` with the
    stand-in objective, traced once per ``key``."""
    found = _TEMPLATES.get(key)
    if found is None:
        closed, out_struct, out_static = eqx.filter_make_jaxpr(chunk)(*operands)
        found = (closed, jtu.tree_structure(out_struct), out_static)
        _TEMPLATES[key] = found
        while len(_TEMPLATES) > _TEMPLATES_MAX:
            _TEMPLATES.popitem(last=False)
    return found


def _program(closed, options):
    fun = jaxpr_as_fun(closed)

    def _chunk(*leaves):  # named as the program it is, for JAX's compile events
        return fun(*leaves)

    return jax.jit(_chunk, compiler_options=dict(options) or None)


def templated(chunk, free: bool, flat, out_type, options, fallback, traced):
    """``call(*operands)`` for the driver's ``_chunk`` program: through the template where
    `jaxfric.optim.template` allows (``free``: no part of the solver keeps more of the
    objective than its values; ``out_type``: the objective's output type), else
    ``fallback(*operands)`` (the program traced as usual; always for operands that
    ``traced(operands)`` finds traced, a call under the caller's own transformation).
    ``operands`` are ``_chunk``'s arguments with ``flat`` (the objective) second."""
    if (not free or flat.layout is not None or getattr(out_type, "weak_type", False)
            or getattr(out_type, "shape", None) != ()):
        return fallback
    shapes = tuple(tuple(s) for s in flat.shapes)
    stand_in = type(flat)(_stand_in(np.dtype(out_type.dtype), shapes), flat.treedef,
                          flat.shapes, flat.layout)
    state = {"mode": None}

    def call(*operands):
        if state["mode"] is fallback or traced(operands):
            return fallback(*operands)
        if state["mode"] is None:
            try:
                state["mode"] = _prepared(operands)
            except Exception:  # noqa: BLE001 - _Unsupported, unhashable parts, a
                # transformation the stand-in lacks: the usual trace (which raises any
                # error of the objective's own) decides
                state["mode"] = fallback
                return fallback(*operands)
        program, out_tree, out_static = state["mode"]
        leaves = [x for x in jtu.tree_leaves(operands) if eqx.is_array(x)]
        out = program(*leaves)
        return eqx.combine(jtu.tree_unflatten(out_tree, out), out_static)

    def _prepared(operands):
        swapped = (operands[0], stand_in, *operands[2:])
        key = (chunk, _signature(swapped))
        per_fn = _PROGRAMS.setdefault(flat.fn, {})
        hit = per_fn.get((key, options))
        if hit is not None:
            return hit
        closed, out_tree, out_static = _template(chunk, swapped, key)
        args_leaves, args_tree = jtu.tree_flatten(operands[4])
        if not all(eqx.is_array(a) for a in args_leaves):
            raise _Unsupported("args holds values that are not arrays (static in a trace)")

        made, singles = {}, {}

        def make(eqn):  # one equation per batch shape
            sig = (tuple(v.aval for v in eqn.invars), tuple(sorted(eqn.params.items())))
            if sig not in made:
                made[sig] = _objective_eqn(flat.fn, flat.treedef, args_tree, eqn, singles)
            return made[sig].replace(invars=list(eqn.invars), outvars=list(eqn.outvars))

        filled = ClosedJaxpr(_fill(closed.jaxpr, make), closed.consts)
        hit = (_program(filled, options), out_tree, out_static)
        per_fn[(key, options)] = hit
        return hit

    return call
