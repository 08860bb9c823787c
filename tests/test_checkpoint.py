"""A checkpointed, killed and resumed run equals the uninterrupted one (same key)."""

import os
import subprocess
import sys
import textwrap

import equinox as eqx
import jax
import numpy as np
import pytest

import jaxfric as jf
from jaxfric import functions as F

BOUNDS = F.get("rastrigin").bounds(5, np.float32)
OBJ = F.objective("rastrigin")
SOLVERS = {
    "pso": jf.PSO(num_particles=9, num_generations=40),
    "hybrid": jf.mapso_nmds(lattice_size=3, num_generations=40, sl_generations=2, nm_max_steps=60),
}


@pytest.mark.parametrize("name", sorted(SOLVERS))
def test_chunked_run_equals_uninterrupted(name, tmp_path):
    solver = SOLVERS[name]
    full = jf.minimise(OBJ, solver, BOUNDS, key=jax.random.key(11))
    chunked = jf.minimise(OBJ, solver, BOUNDS, key=jax.random.key(11),
                          checkpoint=tmp_path / "run.npz", checkpoint_every=7)
    assert bool(eqx.tree_equal(full, chunked)), (full.f, chunked.f)
    # resuming a finished checkpoint returns the same result without new generations
    again = jf.minimise(OBJ, solver, BOUNDS, key=jax.random.key(11),
                        checkpoint=tmp_path / "run.npz", checkpoint_every=7)
    assert bool(eqx.tree_equal(full, again))


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

    jf.minimise(F.objective("rastrigin"), solver, F.get("rastrigin").bounds(5, np.float32),
                key=jax.random.key(11), checkpoint=path, checkpoint_every=7, progress=die_midway)
    """
)


def test_killed_and_resumed_run_equals_uninterrupted(tmp_path):
    path = tmp_path / "killed.npz"
    proc = subprocess.run([sys.executable, "-c", KILLED, str(path)], capture_output=True, text=True,
                          timeout=600, env=dict(os.environ, JAX_PLATFORMS="cpu"))
    assert proc.returncode == 17, proc.stderr[-2000:]
    assert path.exists()
    assert not list(tmp_path.glob("*.tmp")), "a temporary file was left behind"
    with np.load(path) as z:
        import json

        meta = json.loads(bytes(z["__meta__"]).decode())
    assert meta["generations_done"] == 21
    solver = SOLVERS["hybrid"]
    resumed = jf.minimise(OBJ, solver, BOUNDS, key=jax.random.key(11), checkpoint=path, checkpoint_every=7)
    full = jf.minimise(OBJ, solver, BOUNDS, key=jax.random.key(11))
    assert bool(eqx.tree_equal(full, resumed))


def test_checkpoint_refuses_other_runs_and_corruption(tmp_path):
    path = tmp_path / "c.npz"
    jf.minimise(OBJ, SOLVERS["pso"], BOUNDS, key=jax.random.key(1), checkpoint=path, checkpoint_every=20)
    with pytest.raises(ValueError, match="different run"):
        jf.minimise(OBJ, SOLVERS["pso"], BOUNDS, key=jax.random.key(2), checkpoint=path)
    path.write_bytes(path.read_bytes()[:100])
    with pytest.raises(ValueError, match="unreadable or corrupted"):
        jf.minimise(OBJ, SOLVERS["pso"], BOUNDS, key=jax.random.key(1), checkpoint=path)
    with pytest.raises(ValueError, match="swarm solvers"):
        jf.minimise(OBJ, jf.NelderMead(), BOUNDS, key=jax.random.key(1), checkpoint=tmp_path / "nm.npz")
    with pytest.raises(ValueError, match="checkpoint_every"):
        jf.minimise(OBJ, SOLVERS["pso"], BOUNDS, key=jax.random.key(1), checkpoint=tmp_path / "x.npz",
                    checkpoint_every=0)
