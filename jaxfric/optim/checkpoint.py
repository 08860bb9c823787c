"""Checkpoint files: a pytree (the driver's loop carry) written after a JSON header.

The pytree is written with equinox's serialisation (``eqx.tree_serialise_leaves``)
after a one-line JSON header, through [`jaxfric.files.atomic_write`][jaxfric.files.atomic_write] (a temporary
file that then replaces the checkpoint with ``os.replace``), so an interrupt never
leaves a half-written file. Files get the user's usual permissions (``0o666 & ~umask``).
The driver ([`jaxfric.optim.driver`][jaxfric.optim.driver]) runs in chunks and calls [`save`][jaxfric.optim.checkpoint.save] after
each; this module knows nothing of solvers or runs.

The header records a fingerprint of the problem, checked on resume, each part with its
own message: the objective (qualified name and a hash of its code, constants and
closure values), the bounds, the ``args`` (tree structure and a hash of every value),
the solver (its repr: every hyperparameter), the key and the search dtype.
"""

from __future__ import annotations

import functools
import hashlib
import json
import types
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from ..files import atomic_write

FORMAT = "jaxfric-checkpoint"
VERSION = 4  # the version of the carry's layout: older files are refused by name
MAGIC = b"JAXFRIC-CHECKPOINT\n"


# ------------------------------------------------------------------ fingerprint
def _hash_value(h, x, depth=0):
    """Feed ``x`` into ``h``: arrays by dtype, shape and bytes; code by its bytecode,
    constants and names; containers recursively; anything else by type and repr."""
    if depth > 6:
        h.update(type(x).__qualname__.encode())
        return
    if isinstance(x, types.CodeType):
        h.update(x.co_code)
        h.update(repr(x.co_names).encode())
        for c in x.co_consts:
            _hash_value(h, c, depth + 1)
    elif isinstance(x, (types.FunctionType, types.MethodType)):
        f = getattr(x, "__func__", x)
        h.update(f"{f.__module__}.{f.__qualname__}".encode())
        _hash_value(h, f.__code__, depth + 1)
        for cell in f.__closure__ or ():
            try:
                _hash_value(h, cell.cell_contents, depth + 1)
            except ValueError:  # an empty cell
                pass
        _hash_value(h, f.__defaults__, depth + 1)
    elif isinstance(x, functools.partial):
        _hash_value(h, (x.func, x.args, x.keywords), depth + 1)
    elif isinstance(x, (tuple, list)):
        h.update(f"{type(x).__name__}{len(x)}".encode())
        for v in x:
            _hash_value(h, v, depth + 1)
    elif isinstance(x, dict):
        for k in sorted(x, key=repr):
            h.update(repr(k).encode())
            _hash_value(h, x[k], depth + 1)
    elif isinstance(x, eqx.Module):
        leaves, treedef = jtu.tree_flatten(x)
        h.update(str(treedef).encode())
        for v in leaves:
            _hash_value(h, v, depth + 1)
        call = getattr(type(x), "__call__", None)
        if isinstance(call, types.FunctionType):
            _hash_value(h, call, depth + 1)
    elif hasattr(x, "shape") and hasattr(x, "dtype"):
        if jnp.issubdtype(x.dtype, jax.dtypes.prng_key):
            x = jax.random.key_data(x)
        a = np.asarray(x)
        h.update(f"{a.dtype}{a.shape}".encode())
        h.update(a.tobytes())
    elif callable(x) and not isinstance(x, type):
        h.update(type(x).__qualname__.encode())
        _hash_value(h, getattr(type(x), "__call__", None), depth + 1)
        _hash_value(h, getattr(x, "__dict__", {}), depth + 1)
    else:
        h.update(f"{type(x).__qualname__}:{x!r}".encode())


def _digest(x) -> str:
    h = hashlib.sha256()
    _hash_value(h, x)
    return h.hexdigest()


def fingerprint(fn, structure, solver, lower, upper, args, key) -> dict:
    """What a checkpoint belongs to, part by part (hex digests and readable names):
    the objective ``fn``, the parameters' ``structure`` (any hashable description),
    the ``solver``, the box, ``args`` and the ``key``."""
    name = getattr(fn, "__qualname__", type(fn).__qualname__)
    return {
        "objective": _digest(fn),
        "objective_name": f"{getattr(fn, '__module__', '?')}.{name}",
        "parameter structure": _digest(structure),
        "bounds": _digest((np.asarray(lower), np.asarray(upper))),
        "args": _digest((str(jtu.tree_structure(args)), jtu.tree_leaves(args))),
        "solver": _digest(repr(solver)),
        "key": _digest(key),
        "dtype": str(np.asarray(lower).dtype),
    }


def _refuse(path, meta_fp: dict, fp: dict):
    for part in ("dtype", "objective", "args", "bounds", "parameter structure", "solver",
                 "key"):
        if meta_fp.get(part) != fp[part]:
            extra = ""
            if part == "objective":
                extra = (f" (written for {meta_fp.get('objective_name')}, now "
                         f"{fp['objective_name']}; an edited function counts as another)")
            if part == "dtype":
                extra = f" ({meta_fp.get('dtype')} vs {fp['dtype']})"
            raise ValueError(
                f"checkpoint {path} belongs to a different run: the {part} changed{extra}; "
                "delete it or choose another path"
            )


# ---------------------------------------------------------------- serialisation
def _is_key(x) -> bool:
    return hasattr(x, "dtype") and jnp.issubdtype(x.dtype, jax.dtypes.prng_key)


def _raw(tree):
    """Typed PRNG keys as their raw words (what a file can hold)."""
    return jtu.tree_map(lambda x: jax.random.key_data(x) if _is_key(x) else x, tree)


def _raw_like(tree):
    def one(x):
        if _is_key(x):
            return jax.eval_shape(jax.random.key_data, x)
        return jax.ShapeDtypeStruct(x.shape, x.dtype) if hasattr(x, "shape") else x

    return jtu.tree_map(one, tree)


def _typed(raw, like, impl):
    return jtu.tree_map(
        lambda r, x: jax.random.wrap_key_data(r, impl=impl) if _is_key(x) else r, raw, like)


def header(fp: dict, key) -> dict:
    """The header of a checkpoint of the run with fingerprint ``fp`` and ``key`` (its
    ``"steps_done"`` is added by the writer)."""
    impl = str(jax.random.key_impl(key)) if _is_key(jnp.asarray(key)) else "threefry2x32"
    return dict(format=FORMAT, version=VERSION, fingerprint=fp, key_impl=impl)


def save(path: Path, meta: dict, carry) -> None:
    """Write ``carry`` after a JSON header, atomically, with the user's permissions
    ([`jaxfric.files.atomic_write`][jaxfric.files.atomic_write])."""

    def write(tmp: Path):
        with open(tmp, "wb") as fh:
            fh.write(MAGIC)
            fh.write(json.dumps(meta).encode() + b"\n")
            eqx.tree_serialise_leaves(fh, _raw(carry))

    atomic_write(path, write)


def read_meta(path) -> dict:
    """The header of a checkpoint (format, version, fingerprint, steps done)."""
    with open(path, "rb") as fh:
        if fh.readline() != MAGIC:
            raise ValueError(f"{path} is not a jaxfric checkpoint (unreadable or corrupted)")
        return json.loads(fh.readline().decode())


def load(path: Path, fp: dict, like):
    """The carry stored in ``path``, after checking it belongs to this problem."""
    try:
        meta = read_meta(path)
    except ValueError as e:
        if "not a jaxfric checkpoint" in str(e):
            raise ValueError(f"checkpoint {path} is unreadable or corrupted: "
                             "not a jaxfric checkpoint") from None
        raise ValueError(f"checkpoint {path} is unreadable or corrupted: {e}") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"checkpoint {path} is unreadable or corrupted: {e}") from None
    if meta.get("format") != FORMAT:
        raise ValueError(f"{path} is not a jaxfric checkpoint")
    if meta.get("version") != VERSION:
        raise ValueError(
            f"checkpoint {path} has format version {meta.get('version')}, "
            f"this jaxfric reads version {VERSION}"
        )
    _refuse(path, meta.get("fingerprint", {}), fp)
    try:
        with open(path, "rb") as fh:
            fh.readline()
            fh.readline()
            raw = eqx.tree_deserialise_leaves(fh, _raw_like(like))
    except Exception as e:
        raise ValueError(f"checkpoint {path} is unreadable or corrupted: {e}") from None
    return meta, _typed(raw, like, meta["key_impl"])
