"""Checkpoint and resume for long swarm runs (PSO, MAPSO, MAPSO–NMDS).

The global phase advances in chunks of ``every`` generations, each chunk one
jitted call; after each chunk the swarm state and the history so far are written
to one ``.npz`` file atomically (a temporary file, then ``os.replace``), so an
interrupt never leaves a half-written checkpoint. Calling
:func:`jaxfric.minimise` again with the same ``checkpoint`` path resumes from the
last completed chunk and returns exactly what the uninterrupted run returns for
the same key: a chunked run performs the same operations in the same order.

A checkpoint records what it belongs to (solver, bounds, key, dtype); resuming it
with anything else raises ``ValueError`` instead of silently mixing runs.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .. import _xla
from ._base import Solution
from .hybrid import MAPSONMDS
from .pso import AbstractSwarm, SwarmState

FORMAT = "jaxfric-checkpoint"
VERSION = 2  # 2: swarms draw counter-based numbers per generation (0.2.0)


def _swarm_of(solver):
    if isinstance(solver, AbstractSwarm):
        return solver
    if isinstance(solver, MAPSONMDS):
        return solver.mapso
    raise ValueError(
        "checkpoint works with swarm solvers (PSO, MAPSO, MAPSONMDS), "
        f"not {type(solver).__name__}"
    )


def _fingerprint(solver, lower, upper, key) -> str:
    h = hashlib.sha256()
    h.update(repr(solver).encode())
    h.update(np.asarray(lower).tobytes() + np.asarray(upper).tobytes())
    h.update(str(np.asarray(lower).dtype).encode())
    h.update(np.asarray(jax.random.key_data(key)).tobytes())
    return h.hexdigest()


def _init(swarm, flat, lower, upper, args, key, x0):
    return swarm.init_state(flat, lower, upper, args, key, x0)


def _advance(swarm, flat, lower, upper, args, state, start, length, hook):
    return swarm.advance(state, flat, lower, upper, args, start, length, hook)


def _finish(solver, swarm, flat, lower, upper, args, key, state, evals, f_best, hook):
    sol = swarm.finish(state, evals, f_best)
    if isinstance(solver, MAPSONMDS):
        k_local = jax.random.split(key)[1]
        sol = solver.local_phase(flat, lower, upper, args, k_local, sol, state, hook)
    return sol


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _save(path: Path, fingerprint: str, done: int, state: SwarmState, evals, f_best, impl):
    leaves = {
        "x": state.x, "v": state.v, "f": state.f, "pbest": state.pbest,
        "pbest_f": state.pbest_f, "gbest": state.gbest, "gbest_f": state.gbest_f,
        "num_evals": state.num_evals, "key": jax.random.key_data(state.key),
        "hist_evals": evals, "hist_f": f_best,
    }
    meta = dict(format=FORMAT, version=VERSION, fingerprint=fingerprint,
                generations_done=int(done), key_impl=impl)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, __meta__=np.frombuffer(json.dumps(meta).encode(), np.uint8),
                     **{k: np.asarray(v) for k, v in leaves.items()})
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp creates 0600; give the usual mode
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _load(path: Path, fingerprint: str, dtype):
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(bytes(z["__meta__"]).decode())
            data = {k: z[k] for k in z.files if k != "__meta__"}
    except Exception as e:
        raise ValueError(f"checkpoint {path} is unreadable or corrupted: {e}") from None
    if meta.get("format") != FORMAT:
        raise ValueError(f"{path} is not a jaxfric checkpoint")
    if meta.get("version") != VERSION:
        raise ValueError(
            f"checkpoint {path} has format version {meta.get('version')}, "
            f"this jaxfric reads version {VERSION}"
        )
    if meta.get("fingerprint") != fingerprint:
        raise ValueError(
            f"checkpoint {path} belongs to a different run (solver, bounds, key or dtype "
            "differ); delete it or choose another path"
        )
    key = jax.random.wrap_key_data(jnp.asarray(data["key"]), impl=meta["key_impl"])
    state = SwarmState(
        x=jnp.asarray(data["x"], dtype), v=jnp.asarray(data["v"], dtype),
        f=jnp.asarray(data["f"], dtype), pbest=jnp.asarray(data["pbest"], dtype),
        pbest_f=jnp.asarray(data["pbest_f"], dtype), gbest=jnp.asarray(data["gbest"], dtype),
        gbest_f=jnp.asarray(data["gbest_f"], dtype),
        num_evals=jnp.asarray(data["num_evals"], jnp.int32), key=key,
    )
    return int(meta["generations_done"]), state, jnp.asarray(data["hist_evals"]), jnp.asarray(
        data["hist_f"], dtype
    )


def run_checkpointed(solver, flat, lower, upper, args, key, x0, hook, path, every: int,
                     options=()) -> Solution:
    """Drive ``solver`` in chunks of ``every`` generations, checkpointing to ``path``."""
    swarm = _swarm_of(solver)
    if isinstance(solver, MAPSONMDS):
        k_global = jax.random.split(key)[0]
    else:
        k_global = key
    path = Path(path)
    fp = _fingerprint(solver, lower, upper, key)
    impl = str(jax.random.key_impl(key))
    if path.exists():
        done, state, evals, f_best = _load(path, fp, lower.dtype)
    else:
        state = _xla.filter_jit(_init, options)(swarm, flat, lower, upper, args, k_global, x0)
        done, evals, f_best = 0, state.num_evals[None], state.gbest_f[None]
        _save(path, fp, done, state, evals, f_best, impl)
    total = swarm.num_generations
    while done < total:
        length = min(every, total - done)
        state, (ev, fb) = _xla.filter_jit(_advance, options)(
            swarm, flat, lower, upper, args, state, jnp.asarray(done, jnp.int32), length, hook
        )
        evals = jnp.concatenate([evals, ev])
        f_best = jnp.concatenate([f_best, fb])
        done += length
        _save(path, fp, done, state, evals, f_best, impl)
    finish = _xla.filter_jit(_finish, options)
    return finish(solver, swarm, flat, lower, upper, args, key, state, evals, f_best, hook)
