"""Sharded and unsharded runs give the same result for the same key.

JAX reads ``XLA_FLAGS`` once at start-up, so the check runs in a fresh Python
process with four forced host (CPU) devices."""

import json
import os
import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent(
    """
    import json, os
    import jax, jax.numpy as jnp, numpy as np
    import jaxfric as jf
    from jaxfric import functions as F
    assert jax.device_count() == 4, jax.devices()
    lo, hi = F.get("rastrigin").bounds(6, np.float32)
    obj = F.objective("rastrigin")
    out = {}
    # The hybrid covers every sharded path: swarm populations (MAPSO's lattice and
    # self-learning evaluations), Nelder-Mead, and runs laid out over devices.
    # nm_adaptive=False: Nelder-Mead's standard coefficients. Gao-Han's (the default from
    # n = 2 since 0.7.0) give float32 arithmetic that XLA compiles with different rounding
    # for one and four devices (same f, points 1e-7 apart); checked separately below.
    for name, solver in [
        ("hybrid", jf.mapso_nmds(lattice_size=3, num_generations=10, nm_max_steps=50, nm_adaptive=False)),
    ]:
        a = jf.minimise(obj, solver, (lo, hi), key=jax.random.key(0))
        b = jf.minimise(obj, solver, (lo, hi), key=jax.random.key(0), devices=False)
        keys = jax.random.split(jax.random.key(1), 7)  # not a multiple of 4: padded
        m = jf.minimise_many(obj, solver, (lo, hi), keys=keys)
        u = jf.minimise_many(obj, solver, (lo, hi), keys=keys, devices=False)
        out[name] = dict(
            population=bool(jnp.array_equal(a.value, b.value)) and float(a.f) == float(b.f),
            runs=bool(jnp.array_equal(m.value, u.value)) and bool(jnp.array_equal(m.f, u.f)),
            runs_shape=list(m.f.shape),
            expected_shape=[7],
            evals_equal=bool(jnp.array_equal(m.stats["num_evals"], u.stats["num_evals"])),
        )
    g = jf.mapso_nmds(lattice_size=3, num_generations=10, nm_max_steps=50)
    a = jf.minimise(obj, g, (lo, hi), key=jax.random.key(0))
    b = jf.minimise(obj, g, (lo, hi), key=jax.random.key(0), devices=False)
    out["gao_han_rounding"] = dict(f_equal=float(a.f) == float(b.f),
                                   max_abs=float(jnp.max(jnp.abs(a.value - b.value))))
    # Nelder-Mead: batching='auto' lays the runs out over the devices (vmap), as an
    # unsharded vmap computes them; 'map' (one device) with four devices is an error.
    nm = jf.NelderMead(max_steps=60)
    keys = jax.random.split(jax.random.key(2), 5)
    s4 = jf.minimise_many(obj, nm, (lo, hi), keys=keys)
    s1 = jf.minimise_many(obj, nm, (lo, hi), keys=keys, devices=False, batching="vmap")
    try:
        jf.minimise_many(obj, nm, (lo, hi), keys=keys, batching="map")
        map_error = ""
    except ValueError as e:
        map_error = str(e)
    out["nelder_mead"] = dict(
        runs=bool(jnp.array_equal(s4.value, s1.value)) and bool(jnp.array_equal(s4.f, s1.f)),
        runs_shape=list(s4.f.shape),
        expected_shape=[5],
        evals_equal=bool(jnp.array_equal(s4.stats["num_evals"], s1.stats["num_evals"])),
        map_error=map_error,
    )
    print("RESULT" + json.dumps(out))
    """
)


def test_sharded_equals_unsharded_on_four_host_devices(subprocess_slot):
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    proc = subprocess.run(
        [sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    line = [l for l in proc.stdout.splitlines() if l.startswith("RESULT")][0]
    out = json.loads(line[len("RESULT"):])
    gh = out.pop("gao_han_rounding")
    assert gh["f_equal"] and gh["max_abs"] <= 1e-5, gh
    for name, r in out.items():
        if "population" in r:  # Nelder-Mead has no population to split
            assert r["population"], f"{name}: population-sharded run differs"
        assert r["runs"], f"{name}: runs sharded over devices differ"
        assert r["runs_shape"] == r["expected_shape"] and r["evals_equal"], (name, r)
    assert "one device" in out["nelder_mead"]["map_error"], out["nelder_mead"]
