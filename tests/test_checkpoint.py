"""A checkpointed, killed and resumed run equals the uninterrupted one (same key)."""

import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfric as jf
from jaxfric import functions as F

def identical(a, b):
    """``eqx.tree_equal(a, b)`` checked in NumPy: the same tree structure, and every leaf
    the same (arrays of one shape and dtype with equal elements, NaN unequal to NaN;
    other leaves equal). Comparing in NumPy compiles nothing: ``eqx.tree_equal`` runs an
    eager comparison, a compiled program, for every leaf shape of a Solution."""
    leaves_a, tree_a = jax.tree_util.tree_flatten(a)
    leaves_b, tree_b = jax.tree_util.tree_flatten(b)
    if tree_a != tree_b:
        return False
    for x, y in zip(leaves_a, leaves_b):
        if isinstance(x, (jax.Array, np.ndarray)) != isinstance(y, (jax.Array, np.ndarray)):
            return False
        if isinstance(x, (jax.Array, np.ndarray)):
            if x.shape != y.shape or x.dtype != y.dtype:
                return False
            if jnp.issubdtype(x.dtype, jax.dtypes.prng_key):
                x, y = jax.random.key_data(x), jax.random.key_data(y)
            if not np.array_equal(np.asarray(x), np.asarray(y)):
                return False
        elif x != y:
            return False
    return True


BOUNDS = F.get("rosenbrock").bounds(6, np.float32)
OBJ = F.objective("rosenbrock")
SOLVERS = {
    "pso": jf.PSO(num_particles=16, num_generations=40),
    "nm": jf.NelderMead(max_steps=60),
    "chain_pso_nm": jf.chain(jf.PSO(num_particles=9, num_generations=12), jf.NelderMead(max_steps=40),
                             num_starts=2),
    "hybrid": jf.mapso_nmds(lattice_size=3, num_generations=40, sl_generations=2, nm_max_steps=60),
}


@pytest.mark.parametrize("name", sorted(SOLVERS))
def test_chunked_run_equals_uninterrupted(name, tmp_path):
    solver = SOLVERS[name]
    full = jf.minimise(OBJ, solver, BOUNDS, key=jax.random.key(11))
    chunked = jf.minimise(OBJ, solver, BOUNDS, key=jax.random.key(11),
                          checkpoint=tmp_path / "run.npz", checkpoint_every=7)
    assert identical(full, chunked), (full.f, chunked.f)
    # resuming a finished checkpoint returns the same result without new generations
    again = jf.minimise(OBJ, solver, BOUNDS, key=jax.random.key(11),
                        checkpoint=tmp_path / "run.npz", checkpoint_every=7)
    assert identical(full, again)


KILLED = textwrap.dedent(
    """
    import os, sys, jax, numpy as np
    import jaxfric as jf
    from jaxfric import functions as F
    path = sys.argv[1]
    solver = jf.mapso_nmds(lattice_size=3, num_generations=40, sl_generations=2, nm_max_steps=60)

    def die_midway(phase, step, evals, f):
        if phase == 0 and step >= 23:   # after the chunks ending at 7, 14, 21 were saved
            os._exit(17)                # like kill -9: no cleanup at all

    jf.minimise(F.objective("rosenbrock"), solver, F.get("rosenbrock").bounds(6, np.float32),
                key=jax.random.key(11), checkpoint=path, checkpoint_every=7, progress=die_midway)
    """
)


def test_killed_and_resumed_run_equals_uninterrupted(tmp_path, subprocess_slot):
    path = tmp_path / "killed.npz"
    proc = subprocess.run([sys.executable, "-c", KILLED, str(path)], capture_output=True, text=True,
                          timeout=600, env=dict(os.environ, JAX_PLATFORMS="cpu"))
    assert proc.returncode == 17, proc.stderr[-2000:]
    assert path.exists()
    assert not list(tmp_path.glob("*tmp")), "a temporary file was left behind"  # .tmp, .jaxfric-tmp
    from jaxfric.optim.checkpoint import read_meta

    assert read_meta(path)["steps_done"] == 21
    solver = SOLVERS["hybrid"]
    resumed = jf.minimise(OBJ, solver, BOUNDS, key=jax.random.key(11), checkpoint=path, checkpoint_every=7)
    full = jf.minimise(OBJ, solver, BOUNDS, key=jax.random.key(11))
    assert identical(full, resumed)


def test_checkpoint_refuses_other_runs_and_corruption(tmp_path):
    path = tmp_path / "c.npz"
    jf.minimise(OBJ, SOLVERS["pso"], BOUNDS, key=jax.random.key(1), checkpoint=path, checkpoint_every=20)
    with pytest.raises(ValueError, match="different run"):
        jf.minimise(OBJ, SOLVERS["pso"], BOUNDS, key=jax.random.key(2), checkpoint=path)
    path.write_bytes(path.read_bytes()[:100])
    with pytest.raises(ValueError, match="unreadable or corrupted"):
        jf.minimise(OBJ, SOLVERS["pso"], BOUNDS, key=jax.random.key(1), checkpoint=path)
    with pytest.raises(ValueError, match="checkpoint_every"):
        jf.minimise(OBJ, SOLVERS["pso"], BOUNDS, key=jax.random.key(1), checkpoint=tmp_path / "x.npz",
                    checkpoint_every=0)


def _shifted(y, shift):
    return jnp.sum((y - shift) ** 2)


def _other(y, shift):
    return jnp.sum(jnp.abs(y - shift))


@pytest.mark.parametrize("change", ["objective", "args", "bounds", "solver", "dtype"])
def test_resume_for_another_problem_is_refused(change, tmp_path):
    """Issue 15 item 2 / issue 20 item 1: a checkpoint is refused, naming what differs,
    for another objective, other args, other bounds, another solver or dtype."""
    path = tmp_path / "c.ckpt"
    lo, hi = np.full(3, -2.0, np.float32), np.full(3, 2.0, np.float32)
    shift = jnp.array([0.1, 0.2, 0.3], jnp.float32)
    pso = jf.PSO(num_particles=4, num_generations=6)
    jf.minimise(_shifted, pso, (lo, hi), args=shift, key=jax.random.key(0), checkpoint=path,
                checkpoint_every=2)
    kw = dict(fn=_shifted, solver=pso, bounds=(lo, hi), args=shift, dtype=None)
    kw.update({"objective": dict(fn=_other), "args": dict(args=shift + 1.0),
               "bounds": dict(bounds=(lo, hi + 1.0)), "solver": dict(solver=jf.PSO(num_particles=4, num_generations=7)),
               "dtype": dict(bounds=(lo.astype(np.float64), hi.astype(np.float64)))}[change])
    with jax.enable_x64(change == "dtype"):
        with pytest.raises(ValueError, match=f"different run: the {change} changed"):
            jf.minimise(kw["fn"], kw["solver"], kw["bounds"], args=kw["args"], key=jax.random.key(0),
                        checkpoint=path, dtype=kw["dtype"])


def test_checkpoint_has_the_users_permissions_and_no_temporary_file(tmp_path):
    old = os.umask(0o022)
    try:
        path = tmp_path / "p.ckpt"
        jf.minimise(OBJ, SOLVERS["pso"], BOUNDS, key=jax.random.key(1), checkpoint=path, checkpoint_every=20)
    finally:
        os.umask(old)
    assert (path.stat().st_mode & 0o777) == 0o644
    assert not list(tmp_path.glob("*.tmp"))
