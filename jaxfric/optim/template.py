"""A solver's program traced once per solver and problem shape, the objective filled in
for each new objective (issue 47).

Tracing ``_chunk`` (the solver's loop, start and report) is the same for every objective of
the same solver, shapes and dtypes but for the objective's own operations. So the
driver traces it once per solver, shapes and dtypes with a stand-in objective, a
primitive (``jaxfric_objective``) that only knows the output type, and keeps that jaxpr
(the *template*). For a new objective it traces the objective alone, vmapped as each
stand-in's batch is, puts it in place of each stand-in as a ``jit`` call, and compiles
the result: the same program as tracing ``_chunk`` with the objective (the objective's
operations are those of the ``vmap`` the solver applies; XLA inlines the call), without
tracing the solver again.

The template is also lowered once, with a stand-in objective that reads every operand,
and kept as text; for a new objective only the objective is lowered (one small module, a
function per stand-in batch shape) and its functions take the stand-ins' place in that
text (`_Lowering`). The program is the same text JAX would lower from the filled jaxpr
but for function names, and compiles to the same executable: the tests check the results
to the bit. Whatever the splice cannot serve (JAX's internals not as expected, an
objective whose lowering adds operands, a sharding) falls back to lowering the filled
program. What each saves: docs/solvers.md, "The solver traced once per shape" and "The
lowered template".

Only where nothing else depends on the objective: a jaxfric solver (an optimistix
minimiser may call it in other ways), one run (`minimise`; ``minimise_many`` vmaps the
program), no device layout, an objective with a strong (not weak) output dtype, and
hashable static parts; anything else is traced as before (`templated` falls back).
"""

from __future__ import annotations

import collections
import copy
import functools
import re
import weakref

import equinox as eqx
import jax
import jax.numpy as jnp
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
_SLOT = "jaxfric_objective"


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
    batched.__name__ = _SLOT  # the name of its function in the lowered program
    spec = _spec(eqn.invars)
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


# --------------------------------------------------------------------- lowering
_FUNC = re.compile(r"^  func\.func (public|private) @([\w$.-]+)\((.*)$")
_TYPE = re.compile(r"tensor<[^>]*>")


def _functions(text):
    """The top-level functions of a StableHLO module's text: ``{name: (header, body)}``
    (JAX prints each at an indent of two, closed by ``  }``), in order."""
    lines, out, i = text.splitlines(), {}, 0
    while i < len(lines):
        m = _FUNC.match(lines[i])
        if m:
            end = lines.index("  }", i)
            out[m.group(2)] = (lines[i], lines[i + 1:end])
            i = end + 1
        else:
            i += 1
    return out


def _types(header):
    """A function header's operand and result types."""
    operands, _, results = header.partition(") -> ")
    return tuple(_TYPE.findall(operands)), tuple(_TYPE.findall(results))


class _Lowering:
    """A template's program lowered once with a stand-in objective that reads all its
    operands (its functions named `_SLOT`), as text; `fill` puts a new objective's
    functions in their place and compiles."""

    def __init__(self, closed, options, y_tree, args_tree):
        self.stand_ins = {}  # signature -> one stand-in equation of it

        def keep(eqn):
            self.stand_ins.setdefault(_stand_in_signature(eqn), eqn)
            return eqn

        _fill(closed.jaxpr, keep)
        singles = {}
        out_dtype = next(iter(self.stand_ins.values())).params["out_dtype"]

        def reads_all(y, args):  # the stand-in's stand-in: every operand used, none dropped
            return sum(jnp.sum(x).astype(out_dtype) for x in jtu.tree_leaves((y, args)))

        made = {s: _objective_eqn(reads_all, y_tree, args_tree, e, singles)
                for s, e in self.stand_ins.items()}
        filled = ClosedJaxpr(_fill(closed.jaxpr, lambda e: made[_stand_in_signature(e)].replace(
            invars=list(e.invars), outvars=list(e.outvars))), closed.consts)
        self.lowered = _program(filled, options).lower(*_spec(closed.jaxpr.invars))
        self.text = self.lowered.as_text()
        self.slots = {n: _types(h) for n, (h, _) in _functions(self.text).items()
                      if re.fullmatch(_SLOT + r"(_\d+)?", n)}  # stand-in function -> its types

    def fill(self, make):
        """The compiled program with ``make(eqn)``'s objective in place of each stand-in."""
        found = _slot_functions([make(e) for e in self.stand_ins.values()])
        names = [n for n in found if n != "main"]
        rename = re.compile(r"@(" + "|".join(map(re.escape, names)) + r")\b")

        def moved(line):
            if "sdy." in line:
                raise _Unsupported("a sharding inside the objective")
            return rename.sub(lambda m: "@jaxfric_obj_" + m.group(1), line)

        bodies = {}  # the objective's function per stand-in signature, found by its types
        for k in range(len(self.stand_ins)):
            header, body = found[f"{_SLOT}_slot{k}"]
            bodies[_types(header)] = [moved(line) for line in body]
        if len(bodies) != len(self.stand_ins) or not set(self.slots.values()) <= set(bodies):
            raise _Unsupported("stand-ins the lowered program cannot tell apart, or an objective "
                               "that lowers to other operands than its stand-in")
        helpers = [moved(line) for n in names if not n.startswith(f"{_SLOT}_slot")
                   for line in (found[n][0], *found[n][1], "  }")]
        out, lines, i = [], self.text.splitlines(), 0
        while i < len(lines):
            m = _FUNC.match(lines[i])
            if m and m.group(2) in self.slots:
                end = lines.index("  }", i)
                out += [lines[i], *bodies[self.slots[m.group(2)]], "  }"]
                i = end + 1
            else:
                out.append(lines[i])
                i += 1
        if out[-1] != "}":
            raise _Unsupported("a module's text not as JAX prints it")
        text = "\n".join(out[:-1] + helpers + ["}"])
        template = self.lowered.compiler_ir("stablehlo")  # parsed in its context
        module = type(template).parse(text, context=template.context)
        lowering = copy.copy(self.lowered._lowering)
        lowering._hlo, lowering._executable = module, None
        lowered = copy.copy(self.lowered)
        object.__setattr__(lowered, "_lowering", lowering)
        if lowered.compiler_ir("stablehlo") is not module:  # JAX's lowering not as expected
            raise _Unsupported("the lowering does not compile the module it is given")
        return _Compiled(lowered.compile())


class _Compiled:
    """A spliced program, called as the ``jit`` it stands for."""

    def __init__(self, compiled):
        self.compiled = compiled

    def __call__(self, *leaves):
        return self.compiled(*leaves)

    def _cache_size(self):  # one compilation, as a jit's cache would count it
        return 1


def _slot_functions(eqns):
    """The functions of one module that calls each ``jit`` equation of ``eqns`` (the
    ``k``-th named ``{_SLOT}_slot{k}``), by name, with the helpers they call."""
    calls = [_call(e, f"{_SLOT}_slot{k}") for k, e in enumerate(eqns)]
    specs = [_spec(e.invars) for e in eqns]

    def slots(*operands):
        out, i = [], 0
        for call, spec in zip(calls, specs):
            out.append(call(*operands[i:i + len(spec)]))
            i += len(spec)
        return out

    lowered = jax.jit(slots).lower(*(s for spec in specs for s in spec))
    if lowered._lowering.const_args:
        raise _Unsupported("the objective's lowering holds constants as operands")
    return _functions(lowered.as_text())


def _stand_in_signature(eqn):
    return tuple(v.aval for v in eqn.invars), tuple(sorted(eqn.params.items()))


def _spec(variables):
    """The abstract arguments of a jaxpr's ``variables`` (shape, dtype, weak type)."""
    return [jax.ShapeDtypeStruct(v.aval.shape, v.aval.dtype, weak_type=v.aval.weak_type)
            for v in variables]


def _call(eqn, name=_SLOT):
    """The ``jit`` call equation ``eqn`` as a function (named ``name``) of its operands."""
    run = jaxpr_as_fun(eqn.params["jaxpr"])

    def call(*operands):
        return run(*operands)[0]

    call.__name__ = name
    return jax.jit(call, keep_unused=True)


_LOWERINGS: collections.OrderedDict = collections.OrderedDict()


def _lowering(closed, key, options, y_tree, args_tree) -> _Lowering:
    """The template ``closed`` lowered once per ``key`` and options (`_Lowering`)."""
    found = _LOWERINGS.get((key, options))
    if found is None:
        try:
            found = _Lowering(closed, options, y_tree, args_tree)
        except Exception as error:  # noqa: BLE001 - kept, so the next objective is not tried again
            found = _Unsupported(f"the template could not be lowered for splicing: {error!r}")
        _LOWERINGS[(key, options)] = found
        while len(_LOWERINGS) > _TEMPLATES_MAX:
            _LOWERINGS.popitem(last=False)
    if isinstance(found, _Unsupported):
        raise found
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
            sig = _stand_in_signature(eqn)
            if sig not in made:
                made[sig] = _objective_eqn(flat.fn, flat.treedef, args_tree, eqn, singles)
            return made[sig].replace(invars=list(eqn.invars), outvars=list(eqn.outvars))

        try:
            program = _lowering(closed, key, options, flat.treedef, args_tree).fill(make)
        except Exception:  # noqa: BLE001 - anything the splice cannot serve: lower it all
            filled = ClosedJaxpr(_fill(closed.jaxpr, make), closed.consts)
            program = _program(filled, options)
        hit = (program, out_tree, out_static)
        per_fn[(key, options)] = hit
        return hit

    return call
