"""Properties every optimiser must keep, on random boxes (hypothesis), plus the
hybrid's multi-start and progress reporting."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxfric as jf
from jaxfric.optim import RecordingProgress
from jaxfric.optim.minimise import _run

SOLVERS = {
    "pso": jf.PSO(num_particles=6, num_generations=5),
    "mapso": jf.MAPSO(lattice_size=3, num_generations=3, sl_generations=2),
    "nm": jf.NelderMead(max_steps=25),
    "hybrid": jf.mapso_nmds(lattice_size=2, num_generations=2, sl_generations=1, nm_max_steps=15),
}
DIM = 3


def bumpy(y, args):
    centre, scale = args
    z = (y - centre) / scale
    return jnp.sum(z**2) + 0.3 * jnp.sum(jnp.cos(3.0 * z))


from conftest import CallCounter

COUNTER = CallCounter()
COUNTED_BUMPY = COUNTER.wrap(bumpy)  # one function object: no recompiles across examples

boxes = st.tuples(
    st.lists(st.floats(-1e3, 1e3), min_size=DIM, max_size=DIM),
    st.lists(st.floats(1e-3, 1e3), min_size=DIM, max_size=DIM),
    st.lists(st.floats(-2.0, 2.0), min_size=DIM, max_size=DIM),
    st.integers(0, 2**31 - 1),
)


@pytest.mark.parametrize("name", sorted(SOLVERS))
@settings(max_examples=25, deadline=None)
@given(box=boxes)
def test_candidates_in_bounds_history_monotone_best_consistent(name, box):
    counter = COUNTER
    lo_list, width_list, centre_u, seed = box
    lo = np.asarray(lo_list, np.float32)
    hi = (lo + np.asarray(width_list, np.float32)).astype(np.float32)
    hi = np.where(hi > lo, hi, np.nextafter(lo, np.float32(np.inf)))
    centre = lo + (hi - lo) * (0.5 + 0.4 * np.asarray(centre_u, np.float32) / 2)
    args = (jnp.asarray(centre), jnp.asarray(np.maximum(hi - lo, 1e-3) / 4))
    counter.points.clear()
    sol = jf.minimise(COUNTED_BUMPY, SOLVERS[name], (lo, hi), args=args, key=jax.random.key(seed))
    jax.block_until_ready(sol)
    pts = counter.all_points()
    assert np.all(pts >= lo) and np.all(pts <= hi), "a candidate left the box"
    assert int(sol.stats["num_evals"]) == counter.count
    n = int(sol.history.length)
    f_hist = np.asarray(sol.history.f)[:n]
    assert np.all(np.diff(f_hist) <= 0)
    assert np.isfinite(float(sol.f))
    np.testing.assert_allclose(float(bumpy(sol.value, args)), float(sol.f), rtol=1e-5, atol=1e-5)
    assert np.all(np.asarray(sol.value) >= lo) and np.all(np.asarray(sol.value) <= hi)


def test_hybrid_refines_global_phase_and_multistart_counts(counter):
    def rastrigin_shift(y, args):
        z = y - 0.3
        return 10 * z.size + jnp.sum(z**2 - 10 * jnp.cos(2 * jnp.pi * z))

    bounds = (-5.12 * np.ones(4), 5.12 * np.ones(4))
    hyb = jf.mapso_nmds(lattice_size=3, num_generations=10, nm_max_steps=200, num_starts=3)
    sol = jf.minimise(counter.wrap(rastrigin_shift), hyb, bounds, key=jax.random.key(0))
    jax.block_until_ready(sol)
    assert float(sol.f) <= float(sol.stats["f_global"])
    assert int(sol.stats["num_evals"]) == counter.count
    assert int(sol.stats["num_evals"]) > int(sol.stats["num_evals_global"])
    single = jf.minimise(rastrigin_shift, jf.mapso_nmds(lattice_size=3, num_generations=10, nm_max_steps=200),
                         bounds, key=jax.random.key(0))
    # same global phase (same key), more refined starts can only help
    assert float(sol.f) <= float(single.f) + 1e-6


def test_progress_reports_from_inside_the_run_without_recompiling():
    bounds = (-np.ones(3), np.ones(3))
    solver = jf.mapso_nmds(lattice_size=2, num_generations=200, sl_generations=1, nm_max_steps=120)
    fn = lambda y, a: jnp.sum((y - 0.2) ** 2)
    first = RecordingProgress()
    sol = jf.minimise(fn, solver, bounds, key=jax.random.key(0), progress=first)
    phases = [r[0] for r in first.reports]
    assert "global" in phases and "local" in phases
    glob = [r for r in first.reports if r[0] == "global"]
    assert [r[1] for r in glob] == list(range(2, 201, 2))  # every 1 % of 200 generations
    assert all(np.diff([r[3] for r in glob]) <= 0)
    size = _run._cached._cache_size() if hasattr(_run, "_cached") else None
    second = RecordingProgress()
    sol2 = jf.minimise(fn, solver, bounds, key=jax.random.key(0), progress=second)
    assert first.reports == second.reports
    assert float(sol.f) == float(sol2.f)
    if size is not None:
        assert _run._cached._cache_size() == size
    with pytest.raises(ValueError, match="progress must be"):
        jf.minimise(fn, solver, bounds, key=jax.random.key(0), progress="yes")
