"""Reproducibility: the same key and inputs give bit-identical results, through the API
(``minimise``, ``minimise_many``, ``identify``) and the command line (``jaxfric identify``
twice on the same CSV with the same ``--seed``; the second run loads its programs from the
persistent compilation cache, the first compiled them).

What is *not* promised (README, "Reproducibility"): bitwise equality across machines,
XLA/JAX versions or devices, or between float32 and float64 searches; a vmapped run
(``minimise_many``) matches the single run with the same key up to floating-point
reassociation, which for an objective without reductions that could be reordered means
exactly. Sharded against unsharded runs: tests/test_sharding.py.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfric as jf
from jaxfric import functions as F
from jaxfric import rig

ROOT = Path(__file__).resolve().parents[1]
SOLVERS = {
    "pso": jf.PSO(num_particles=9, num_generations=15),
    "mapso": jf.MAPSO(lattice_size=3, num_generations=6, sl_generations=3),
    "nm": jf.NelderMead(max_steps=60),
    "hybrid": jf.mapso_nmds(lattice_size=3, num_generations=4, sl_generations=2, nm_max_steps=40),
}
BOUNDS = (np.full(4, -5.12, np.float32), np.full(4, 5.12, np.float32))
SHIFT = jnp.full(4, 0.3, jnp.float32)


def rastrigin(y, shift):
    return F.rastrigin(y - shift)


def _bits(tree):
    """Every leaf as raw bytes, so 'equal' means bit-identical (NaN payloads and -0 included)."""
    leaves = jax.tree_util.tree_leaves(tree)
    return [np.asarray(x).tobytes() for x in leaves]


@pytest.mark.parametrize("name", sorted(SOLVERS))
def test_minimise_same_key_bit_identical(name):
    solver = SOLVERS[name]
    a = jf.minimise(rastrigin, solver, BOUNDS, args=SHIFT, key=jax.random.key(11))
    b = jf.minimise(rastrigin, solver, BOUNDS, args=SHIFT, key=jax.random.key(11))
    assert _bits(a) == _bits(b)
    assert bool(eqx.tree_equal(a, b))
    d = jf.minimise(rastrigin, solver, BOUNDS, args=SHIFT, key=jax.random.key(12))
    assert not np.array_equal(np.asarray(a.value), np.asarray(d.value))


def test_a_fresh_compilation_gives_the_same_bits():
    solver = SOLVERS["hybrid"]  # MAPSO and Nelder-Mead in one program
    a = jf.minimise(rastrigin, solver, BOUNDS, args=SHIFT, key=jax.random.key(11))
    # a new function object is a new jit cache entry: compiled afresh
    c = jf.minimise(lambda y, s: F.rastrigin(y - s), solver, BOUNDS, args=SHIFT, key=jax.random.key(11))
    assert _bits(a) == _bits(c)


def separable(y, target):
    """One addition of two squares: nothing in the objective for XLA to reassociate."""
    d = y - target
    return d[0] * d[0] + 10.0 * (d[1] * d[1])


@pytest.mark.parametrize("name", ["pso", "mapso", "nm"])
def test_minimise_many_is_reproducible_and_matches_single_runs(name):
    solver = SOLVERS[name]
    bounds = (np.array([-2.0, -1.0], np.float32), np.array([3.0, 1.0], np.float32))
    target = jnp.array([0.4, -0.7], jnp.float32)
    keys = jax.random.split(jax.random.key(5), 3)
    many = jf.minimise_many(separable, solver, bounds, args=target, keys=keys)
    again = jf.minimise_many(separable, solver, bounds, args=target, keys=keys)
    assert _bits(many) == _bits(again)
    for i in range(len(keys)):
        one = jf.minimise(separable, solver, bounds, args=target, key=keys[i])
        row = jax.tree_util.tree_map(lambda x: x[i], many)
        if name in ("pso", "mapso"):
            # the swarms reduce nothing across agents but argmin: the same bits
            assert _bits(one) == _bits(row), (name, i)
        else:
            # Nelder-Mead's centroid is a sum over vertices that XLA may reassociate
            # under vmap: the history differs in the last bit, the result agrees
            np.testing.assert_allclose(np.asarray(one.value), np.asarray(row.value), atol=1e-3)
            np.testing.assert_allclose(float(one.f), float(row.f), atol=1e-5)


def test_float32_and_float64_are_each_reproducible_but_differ():
    solver = SOLVERS["pso"]
    b64 = tuple(np.asarray(b, np.float64) for b in BOUNDS)
    a32 = jf.minimise(rastrigin, solver, BOUNDS, args=SHIFT, key=jax.random.key(3))
    with jax.enable_x64(True):
        s64 = jnp.asarray(SHIFT, jnp.float64)
        a64 = jf.minimise(rastrigin, solver, b64, args=s64, key=jax.random.key(3))
        b64_run = jf.minimise(rastrigin, solver, b64, args=s64, key=jax.random.key(3))
        assert a64.value.dtype == jnp.float64
        assert _bits(a64) == _bits(b64_run)
    assert a32.value.dtype == jnp.float32
    assert np.asarray(a32.value, np.float64).tobytes() != np.asarray(a64.value).tobytes()


# --------------------------------------------------------------------------- identify
def _record(n=400, fs=128.0):
    t = np.arange(n) / fs
    v = 0.010 * np.sin(2 * np.pi * 0.2 * t) + 0.004 * np.sin(2 * np.pi * 0.53 * t)
    theta = jf.LuGre().from_physical(sigma0=1e7, sigma1=3e3, sigma2=4e3, Fc=200.0, Fs=300.0, vs=2e-3)
    f = np.asarray(jf.LuGre().simulate(theta, v, 1 / fs), np.float64)
    f = f + np.random.default_rng(0).normal(0.0, 2.0, n)
    return t, v, f


# The command line's --quick budget for LuGre, so the API and the command share programs.
QUICK_LUGRE = jf.mapso_nmds(lattice_size=5, num_generations=3, nm_max_evals=200)


def _fit_bits(fit):
    d = fit.to_dict()
    d.pop("timings")
    return np.asarray(fit.theta).tobytes(), json.dumps(d, sort_keys=True)


def test_identify_same_key_bit_identical():
    t, v, f = _record()
    data = rig.FrictionData.from_arrays(v, f, t)
    a = jf.identify("lugre", data, solver=QUICK_LUGRE, key=jax.random.key(4))
    b = jf.identify("lugre", data, solver=QUICK_LUGRE, key=jax.random.key(4))
    c = jf.identify("lugre", data, solver=QUICK_LUGRE, key=4)  # an int seed is jax.random.key(seed)
    assert _fit_bits(a) == _fit_bits(b)
    assert np.asarray(a.theta).tobytes() == np.asarray(c.theta).tobytes() and a.metrics == c.metrics
    assert _bits(a.solution) == _bits(b.solution)
    other = jf.identify("lugre", data, solver=QUICK_LUGRE, key=jax.random.key(5))
    assert np.asarray(other.theta).tobytes() != np.asarray(a.theta).tobytes()


# ------------------------------------------------------------------------ command line
def _results(out: Path) -> dict:
    """results.json without what legitimately changes between runs (clock, timings, paths)."""
    r = json.loads((out / "results.json").read_text())
    for k in ("created", "command", "environment", "title"):
        r.pop(k, None)
    for m in r["models"].values():
        m.pop("seconds", None)
        m["fit"].pop("timings", None)
    return r


def test_cli_identify_twice_with_the_same_seed_is_bit_identical(tmp_path, subprocess_slot):
    t, v, f = _record()
    csv = tmp_path / "pairs.csv"
    csv.write_text("t,v,F\n" + "\n".join(f"{float(a)!r},{float(b)!r},{float(c)!r}" for a, b, c in zip(t, v, f))
                   + "\n")
    env = dict(os.environ, PYTHONPATH=str(ROOT), JAXFRIC_DEBUG="",
               JAX_COMPILATION_CACHE_DIR=str(tmp_path / "cache"))
    # Cache every program, however quick to compile, so the second run really loads them.
    env["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"
    env["JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES"] = "0"
    outs = []
    for run in ("first", "second"):
        out = tmp_path / run
        proc = subprocess.run(
            [sys.executable, "-m", "jaxfric", "identify", str(csv), "--velocity-col", "v", "--friction-col",
             "F", "--time-col", "t", "--model", "lugre", "--quick", "--seed", "7", "--quiet", "--out", str(out)],
            env=env, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr
        outs.append(out)
    assert any((tmp_path / "cache").iterdir()), "the first run should have filled the compilation cache"
    first, second = _results(outs[0]), _results(outs[1])
    assert first == second
    assert (outs[0] / "models" / "lugre.npz").read_bytes() != b""
    fa, fb = jf.load_fit(outs[0] / "models" / "lugre.npz"), jf.load_fit(outs[1] / "models" / "lugre.npz")
    assert np.asarray(fa.theta).tobytes() == np.asarray(fb.theta).tobytes()
    assert fa.metrics == fb.metrics

    # ... and it is the Python API's fit, to the bit.
    data = rig.load_friction_pairs(csv, {"t": "t", "velocity": "v", "friction": "F"})
    api = jf.identify("lugre", data, solver=QUICK_LUGRE, key=jax.random.key(7))
    assert np.asarray(api.theta).tobytes() == np.asarray(fa.theta).tobytes()
    expect = {w: api.metrics[w] for w in ("train", "valid", "all")}
    assert first["models"]["lugre"]["metrics"] == json.loads(json.dumps(expect))
