"""Progress without a host callback in the compiled program (issue 47, item 2).

A run with a progress display goes in chunks of its one compiled program and the host
updates the display between chunks, so:

* the result is the same to the bit with the display on or off, for one run and for a
  batch of runs (``minimise_many``), with and without a checkpoint;
* a display recompiles nothing;
* the program reaches JAX's persistent compilation cache: a second, identical
  ``identify`` with progress in a new process compiles none of the solver's programs.
"""

from __future__ import annotations

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
from jaxfric.optim import RecordingProgress

BOUNDS = F.get("rosenbrock").bounds(4, np.float32)
OBJ = F.objective("rosenbrock")


def leaves(tree):
    """Every leaf as a NumPy array (PRNG keys as their words)."""
    def raw(x):
        if hasattr(x, "dtype") and jnp.issubdtype(x.dtype, jax.dtypes.prng_key):
            return np.asarray(jax.random.key_data(x))
        return np.asarray(x)

    return [raw(x) for x in jax.tree_util.tree_leaves(tree)]


def identical(a, b):
    la, lb = leaves(a), leaves(b)
    return (jax.tree_util.tree_structure(a) == jax.tree_util.tree_structure(b)
            and all(x.dtype == y.dtype and np.array_equal(x, y) for x, y in zip(la, lb)))


SOLVERS = {
    "pso": jf.PSO(num_particles=10, num_generations=150),
    "nm": jf.NelderMead(max_steps=260),
    "mapso_nm": jf.mapso_nmds(lattice_size=3, num_generations=30, sl_generations=2,
                              nm_max_steps=200),
}


@pytest.mark.parametrize("name", sorted(SOLVERS))
def test_progress_on_or_off_gives_the_same_bits(name, run_cache_size):
    solver = SOLVERS[name]
    off = jf.minimise(OBJ, solver, BOUNDS, key=jax.random.key(5))
    size = run_cache_size()
    seen = RecordingProgress()
    on = jf.minimise(OBJ, solver, BOUNDS, key=jax.random.key(5), progress=seen)
    assert run_cache_size() == size, "a progress display recompiled the run"
    assert identical(off, on)
    assert len(seen.reports) > 3, seen.reports  # it did report, chunk by chunk
    last = seen.reports[-1]
    assert last[2] == int(off.stats["num_evals"]) and last[3] == float(off.f)


def test_progress_with_a_checkpoint_gives_the_same_bits(tmp_path):
    solver = SOLVERS["mapso_nm"]
    off = jf.minimise(OBJ, solver, BOUNDS, key=jax.random.key(6))
    seen = RecordingProgress()
    on = jf.minimise(OBJ, solver, BOUNDS, key=jax.random.key(6), progress=seen,
                     checkpoint=tmp_path / "c.ckpt", checkpoint_every=9)
    assert identical(off, on)
    assert {r[0] for r in seen.reports} == {"global", "local"}


@pytest.mark.parametrize("batching", ["vmap", "map"])
def test_progress_of_many_runs_gives_the_same_bits(batching):
    keys = jax.random.split(jax.random.key(7), 3)
    solver = SOLVERS["mapso_nm"]
    off = jf.minimise_many(OBJ, solver, BOUNDS, keys=keys, batching=batching)
    seen = RecordingProgress()
    on = jf.minimise_many(OBJ, solver, BOUNDS, keys=keys, batching=batching, progress=seen)
    assert identical(off, on)
    # every run's last report is its result
    finals = {r[3] for r in seen.reports[-3:]}
    assert finals == {float(f) for f in np.asarray(off.f)}


SECOND_PROCESS = textwrap.dedent(
    """
    import sys, jax
    jax.config.update("jax_compilation_cache_dir", sys.argv[1])
    # every program is written, however fast it compiled (the default skips < 1 s)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    import numpy as np
    import jaxfric
    from jaxfric.models import LuGre

    t = np.arange(600) / 128.0
    v = 0.010 * np.sin(2 * np.pi * 0.2 * t) + 0.004 * np.sin(2 * np.pi * 0.53 * t)
    f = 250.0 * np.tanh(v / 1e-3) + 3e3 * v
    reports = []
    fit = jaxfric.identify(LuGre(), (v, f, 1 / 128.0), key=0, progress=lambda *r: reports.append(r),
                           solver=jaxfric.mapso_nmds(lattice_size=3, num_generations=8,
                                                     sl_generations=1, nm_max_steps=60))
    assert reports, "no progress was reported"
    print("theta", [float(x) for x in fit.theta])
    """
)


def test_a_second_identify_with_progress_compiles_no_solver_program(tmp_path, subprocess_slot):
    """The cache holds the solver's program after the first process (a program with a
    host callback would never be written), and the second process writes nothing new:
    it compiled nothing, and found the same fit."""
    cache = tmp_path / "cache"
    env = dict(os.environ, JAX_PLATFORMS="cpu")

    def run():
        proc = subprocess.run([sys.executable, "-c", SECOND_PROCESS, str(cache)], env=env,
                              capture_output=True, text=True, timeout=900)
        assert proc.returncode == 0, proc.stderr[-3000:]
        return proc.stdout.strip().splitlines()[-1], set(os.listdir(cache))

    first_theta, first = run()
    assert any(name.startswith("jit__chunk") for name in first), sorted(first)
    second_theta, second = run()
    assert second == first, f"the second process compiled: {sorted(second - first)}"
    assert second_theta == first_theta
