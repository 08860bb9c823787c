"""Properties every optimiser keeps on random functions and random boxes (hypothesis),
plus the hybrid's multi-start and progress reporting.

The random functions come from one family whose parameters travel in ``args`` as float32
arrays of fixed shapes: quadratic, cosine and absolute-value terms, an exponential that
overflows float32 (``exp`` of up to ~1e4), ``0 * inf`` = NaN, a NaN half-space, a ``+inf``
or ``-inf`` half-space and a logarithm that is NaN on a slab of the box and ``-inf`` at its
edges. One
function object and one solver per optimiser means each optimiser compiles once and every
example after that is a cheap call.

For every example, with every evaluated point and value recorded on the host:

* every candidate lies inside the box (and so does the reported value);
* the evaluation count in ``stats`` equals the points actually evaluated (and, for the
  swarms, the closed form ``solver.evaluations()``);
* the reported best f is exactly the best (NaN/inf-as-worst) value ever evaluated, and it
  is the value recorded *at the reported point*: non-finite values never win;
* ``f`` is finite whenever any finite value was seen, ``+inf`` (result ``nonfinite``)
  otherwise; never NaN or ``-inf``; the value and the statistics are always finite;
* the best f in the history never increases, never goes below the reported f, and holds
  no NaN or ``-inf``; evaluation counts along it never decrease.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import jaxfric as jf
from jaxfric.optim import RecordingProgress

SOLVERS = {
    "pso": jf.PSO(num_particles=6, num_generations=5),
    "mapso": jf.MAPSO(lattice_size=3, num_generations=3, sl_generations=2),
    "nm": jf.NelderMead(max_steps=25),
    "hybrid": jf.mapso_nmds(lattice_size=2, num_generations=2, sl_generations=1, nm_max_steps=15),
}
DIM = 3
EXAMPLES = 200


def family(y, p):
    """One member of the random family; ``p`` holds its parameters (float32 arrays)."""
    z = (y - p["centre"]) / p["scale"]
    lin = jnp.dot(p["direction"], z)
    val = (
        p["w_quad"] * jnp.sum(z * z)
        + p["w_cos"] * jnp.sum(jnp.cos(p["freq"] * z))
        + p["w_abs"] * jnp.sum(jnp.abs(z))
        + p["w_exp"] * jnp.exp(p["exp_rate"] * lin)  # overflows; 0 * inf = NaN when w_exp = 0
        + jnp.where(p["w_log"] == 0, 0.0, p["w_log"] * jnp.log(p["log_shift"] + jnp.abs(z[0])))
        + p["offset"]
    )
    val = jnp.where(lin > p["nan_cut"], jnp.nan, val)
    return jnp.where(-lin > p["inf_cut"], p["inf_sign"] * jnp.inf, val)


class Recorder:
    """Every evaluated point and the objective's raw value there, as XLA computed them."""

    def __init__(self):
        self.points, self.values = [], []

    def _record(self, rows):
        rows = np.asarray(rows)
        self.points.append(rows[..., :-1].reshape(-1, rows.shape[-1] - 1).copy())
        self.values.append(rows[..., -1].reshape(-1).copy())
        return np.zeros(rows.shape[:-1], rows.dtype)

    def wrap(self, fn):
        def recorded(y, args):
            f = fn(y, args)
            # the point and its value as one row: one operand for the callback to transfer
            rows = jnp.concatenate([y, f[None].astype(y.dtype)], axis=-1)
            zero = jax.pure_callback(self._record, jax.ShapeDtypeStruct(f.shape, f.dtype), rows,
                                     vmap_method="expand_dims")
            return f + zero

        return recorded

    def clear(self):
        self.points.clear()
        self.values.clear()

    def arrays(self):
        return np.concatenate(self.points), np.concatenate(self.values)


RECORDER = Recorder()
RECORDED_FAMILY = RECORDER.wrap(family)  # one function object: no recompiles across examples

f32 = np.float32


def _floats(lo, hi):
    """float32 values in [lo, hi] (hypothesis wants bounds exactly representable)."""
    return st.floats(float(f32(lo)), float(f32(hi)), allow_nan=False, width=32).filter(
        lambda x: lo <= x <= hi)


def _log_uniform(lo_exp, hi_exp):
    return _floats(lo_exp, hi_exp).map(lambda e: float(10.0**e))


def _maybe(strategy, off):
    """``strategy``, or the value ``off`` that disables the term (about a third of the time)."""
    return st.one_of(st.just(off), strategy, strategy)


def _sometimes(strategy, off):
    """``strategy`` about a third of the time, else ``off`` (for the terms that can make
    the whole box non-finite, so that most examples still have finite values to find)."""
    return st.one_of(st.just(off), st.just(off), strategy)


vec = lambda s: st.lists(s, min_size=DIM, max_size=DIM)  # noqa: E731


# The strategies are built once, not on every draw: hypothesis validates a new strategy
# object on its first use, which cost about as much as a solver run per example.
_BOX = (vec(_floats(-1e6, 1e6)), vec(_log_uniform(-3, 6)))
_CENTRE, _SCALE = vec(_floats(-0.5, 1.5)), vec(_log_uniform(-2, 1))
_TERMS = {  # drawn in this order
    "direction": vec(_floats(-1, 1)),
    "w_quad": _maybe(_log_uniform(-3, 3), 0.0),
    "w_cos": _maybe(_floats(0, 10), 0.0),
    "freq": _floats(0, 20),
    "w_abs": _maybe(_floats(0, 10), 0.0),
    "w_exp": st.one_of(st.just(0.0), _log_uniform(-3, 3)),
    "exp_rate": st.one_of(st.just(0.0), _floats(0, 2), _floats(0, 2), _floats(0, 300)),
    "w_log": _maybe(_floats(0.1, 10), 0.0),
    "log_shift": _floats(-1, 1),
    "offset": _floats(-1e6, 1e6),
    "nan_cut": _sometimes(_floats(-3, 3), 1e30),
    "inf_cut": _sometimes(_floats(-3, 3), 1e30),
    "inf_sign": st.sampled_from([1.0, -1.0]),
}
_SEED = st.integers(0, 2**31 - 1)


@st.composite
def problems(draw):
    """A random box inside the float32 range and a random member of the family."""
    lo = np.asarray(draw(_BOX[0]), f32)
    width = np.asarray(draw(_BOX[1]), f32)
    hi = (lo + width).astype(f32)
    hi = np.where(hi > lo, hi, np.nextafter(lo, f32(np.inf))).astype(f32)
    width = (hi - lo).astype(f32)
    # The centre may lie outside the box: the optimum is then on the boundary.
    centre = lo + width * np.asarray(draw(_CENTRE), f32)
    scale = width * np.asarray(draw(_SCALE), f32)
    p = {"centre": centre, "scale": np.maximum(scale, f32(1e-30))}
    p.update((name, draw(strategy)) for name, strategy in _TERMS.items())
    args = {k: jnp.asarray(np.asarray(v, f32)) for k, v in p.items()}
    return lo, hi, args, draw(_SEED)


def _safe(f):
    return np.where(np.isfinite(f), f, np.inf)


def _flush_subnormals(a):
    """XLA on CPU flushes float32 subnormals to zero (FTZ/DAZ), so a bound of 1e-45 acts
    as 0 in its comparisons and arithmetic."""
    a = np.asarray(a, f32)
    return np.where(np.abs(a) < np.finfo(f32).tiny, f32(0), a)


def check_solution(name, solver, lo, hi, sol, points, values):
    """The properties listed in the module docstring."""
    # The box as the user gave it or as XLA sees it: MAPSO's select-form clip hands back
    # a subnormal bound's own bits (the user's bound, exactly), jnp.clip's max/min the
    # flushed zero.
    lo = np.minimum(np.asarray(lo, f32), _flush_subnormals(lo))
    hi = np.maximum(np.asarray(hi, f32), _flush_subnormals(hi))
    value = np.asarray(sol.value)
    f = np.asarray(sol.f)
    evals = int(sol.stats["num_evals"])
    # candidates and the reported value in the box
    assert points.dtype == np.float32 and np.all(np.isfinite(points)), "a candidate is NaN or inf"
    assert np.all(points >= lo) and np.all(points <= hi), "a candidate left the box"
    assert np.all(np.isfinite(value)) and np.all(value >= lo) and np.all(value <= hi)
    # exact evaluation counts
    assert evals == len(values), (evals, len(values))
    if hasattr(solver, "evaluations"):
        assert evals == solver.evaluations()
    for k, v in sol.stats.items():
        assert np.all(np.isfinite(np.asarray(v))) or k == "f_global", (k, v)
    # the reported f is the best value evaluated, non-finite counting as worst ...
    best = _safe(values).min()
    assert f == best, (float(f), float(best))
    # ... and it is the value recorded at the reported point
    at_value = np.all(points == value, axis=1)
    assert at_value.any(), "the reported value was never evaluated"
    assert np.any(_safe(values[at_value]) == f), "f is not the objective at the reported value"
    # finite when anything finite was seen; never NaN or -inf
    assert not np.isnan(f) and f != -np.inf
    if np.isfinite(values).any():
        assert np.isfinite(f) and not bool(sol.result == jf.RESULTS.nonfinite), (float(f), sol.result)
    else:
        assert f == np.inf and bool(sol.result == jf.RESULTS.nonfinite)
    if "f_global" in sol.stats:
        g = float(sol.stats["f_global"])
        assert not np.isnan(g) and g != -np.inf and f <= g
        assert int(sol.stats["num_evals_global"]) <= evals
    # the history
    n = int(sol.history.length)
    hist_f = np.asarray(sol.history.f)[:n]
    hist_e = np.asarray(sol.history.evals)[:n]
    assert n >= 1
    assert not np.isnan(hist_f).any() and not (hist_f == -np.inf).any()
    assert np.all(hist_f[1:] <= hist_f[:-1]), hist_f  # (np.diff of inf, inf is NaN)
    assert np.all(hist_f >= f)
    assert np.all(np.diff(hist_e) >= 0) and hist_e[-1] <= evals


@pytest.mark.parametrize("name", sorted(SOLVERS))
@settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(problem=problems())
def test_optimisers_on_random_functions_and_boxes(name, problem):
    lo, hi, args, seed = problem
    solver = SOLVERS[name]
    RECORDER.clear()
    sol = jf.minimise(RECORDED_FAMILY, solver, (lo, hi), args=args, key=jax.random.key(seed))
    jax.block_until_ready(sol)
    points, values = RECORDER.arrays()
    for label, seen in (("NaN", np.isnan(values).any()), ("+inf", (values == np.inf).any()),
                        ("-inf", (values == -np.inf).any()), ("no finite value", not np.isfinite(values).any())):
        if seen:
            event(f"evaluated {label}")
    check_solution(name, solver, lo, hi, sol, points, values)


def test_the_family_reaches_every_kind_of_bad_value():
    """The strategy really produces NaN, +inf, -inf and float32 overflow (else the test above
    would prove less than it says)."""
    z = np.linspace(-3, 3, 61, dtype=f32)
    z[30] = 0.0
    y = np.stack([z, np.zeros_like(z), np.zeros_like(z)], axis=1)
    batch = jax.jit(jax.vmap(family, in_axes=(0, None)))  # one program for every variant
    base = {"centre": np.zeros(3), "scale": np.ones(3), "direction": np.array([1.0, 0, 0]), "w_quad": 1.0,
            "w_cos": 0.0, "freq": 0.0, "w_abs": 0.0, "w_exp": 0.0, "exp_rate": 0.0, "w_log": 0.0,
            "log_shift": 0.0, "offset": 0.0, "nan_cut": 1e30, "inf_cut": 1e30, "inf_sign": 1.0}

    def values(**over):
        p = {k: np.asarray(v, f32) for k, v in {**base, **over}.items()}
        return np.asarray(batch(y, p))

    assert np.all(np.isfinite(values()))
    assert np.isnan(values(nan_cut=1.0)).any()
    assert (values(inf_cut=1.0) == np.inf).any() and (values(inf_cut=1.0, inf_sign=-1.0) == -np.inf).any()
    assert (values(w_exp=1.0, exp_rate=100.0) == np.inf).any()  # exp(300) overflows float32
    assert np.isnan(values(w_exp=0.0, exp_rate=100.0)).any()  # 0 * inf
    assert np.isnan(values(w_log=1.0, log_shift=-1.0)).any()  # log of a negative number
    assert (values(w_log=1.0, log_shift=0.0) == -np.inf).any()  # log(0)


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


def test_progress_reports_every_percent_without_recompiling(run_cache_size):
    bounds = (-np.ones(3), np.ones(3))
    solver = jf.mapso_nmds(lattice_size=2, num_generations=200, sl_generations=1, nm_max_steps=120)
    fn = lambda y, a: jnp.sum((y - 0.2) ** 2)  # noqa: E731
    first = RecordingProgress()
    sol = jf.minimise(fn, solver, bounds, key=jax.random.key(0), progress=first)
    phases = [r[0] for r in first.reports]
    assert "global" in phases and "local" in phases
    glob = [r for r in first.reports if r[0] == "global"]
    assert [r[1] for r in glob] == list(range(2, 201, 2))  # every 1 % of 200 generations
    assert all(np.diff([r[3] for r in glob]) <= 0)
    size = run_cache_size()
    second = RecordingProgress()
    sol2 = jf.minimise(fn, solver, bounds, key=jax.random.key(0), progress=second)
    assert first.reports == second.reports
    assert float(sol.f) == float(sol2.f)
    assert run_cache_size() == size
    with pytest.raises(ValueError, match="progress must be"):
        jf.minimise(fn, solver, bounds, key=jax.random.key(0), progress="yes")


@pytest.mark.parametrize("x64", [False, True])
@pytest.mark.parametrize("raw", [False, True])
def test_first_population_draws_what_two_separate_draws_give(x64, raw):
    """The swarms' first positions and velocities come from one threefry over both keys
    (one generator for XLA to compile instead of two): the numbers of two separate
    ``jax.random.uniform`` calls, for typed and raw keys, in float32 and float64."""
    from jaxfric.optim.swarm import first_population

    with jax.enable_x64(x64):
        dtype = jnp.float64 if x64 else jnp.float32
        key = jax.random.PRNGKey(7) if raw else jax.random.key(7)
        # the box arithmetic of the reference in NumPy (IEEE, as JAX's eager operations):
        # only the random numbers come from JAX
        np_dtype = np.dtype(dtype)
        lower, upper = np.array([-2.0, 0.0, 1.0], np_dtype), np.array([3.0, 1.0, 9.0], np_dtype)
        vmax = np_dtype.type(0.2) * (upper - lower)
        x, v, _ = first_population(key, 6, jnp.asarray(lower), jnp.asarray(upper), jnp.asarray(vmax))
        kx, kv, _ = jax.random.split(key, 3)
        ux = np.asarray(jax.random.uniform(kx, (18,), dtype)).reshape(6, 3)
        uv = np.asarray(jax.random.uniform(kv, (18,), dtype)).reshape(6, 3)
        np.testing.assert_array_equal(x, lower + ux * (upper - lower))
        np.testing.assert_array_equal(v, -vmax + uv * (vmax + vmax))
        assert x.dtype == v.dtype == dtype
