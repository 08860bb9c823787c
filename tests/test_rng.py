"""The swarms' counter-based random numbers (``jaxfric.optim.rng.counter_uniform``).

Checked against scipy's distribution tests, not against stored values: uniform on
[0, 1), no correlation between neighbouring counters, generations, streams or keys,
full float64 resolution, and vmap-consistent.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.stats

from jaxfric.optim.rng import counter_seed, counter_uniform

# Every draw is N numbers (or N laid out as (N // 5, 5)). ``draw`` is one compiled program
# per dtype and number of words (key and words are its arguments), as the hash runs in the
# swarms' programs; the eager, op-by-op hash is checked against it in
# test_same_inputs_same_numbers_and_vmap_agrees.
N = 200_000


@functools.partial(jax.jit, static_argnames=("n", "dtype"))
def _draw(key, words, n, dtype):
    return counter_uniform(counter_seed(jax.random.key(key), *words), (n,), dtype)


def draw(key=0, *words, n=N, dtype=jnp.float32):
    return np.asarray(_draw(key, words, n=n, dtype=jnp.dtype(dtype)))


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_uniform_on_unit_interval(dtype):
    with jax.enable_x64(dtype == "float64"):
        u = draw(3, 7, dtype=jnp.dtype(dtype))
    assert u.dtype == np.dtype(dtype)
    assert u.min() >= 0.0 and u.max() < 1.0
    # Kolmogorov–Smirnov against U(0, 1) and a 256-bucket chi-square.
    assert scipy.stats.kstest(u, "uniform").pvalue > 1e-3
    counts = np.bincount((u * 256).astype(int), minlength=256)
    assert scipy.stats.chisquare(counts).pvalue > 1e-3
    assert abs(u.mean() - 0.5) < 5 * np.sqrt(1 / 12 / N)


def test_float64_has_more_than_float32_resolution():
    with jax.enable_x64(True):
        u = draw(0, 1, dtype=jnp.float64)
    # 24-bit numbers are multiples of 2^-24; 53-bit ones almost never are.
    assert np.mean(np.mod(u * 2.0**24, 1.0) != 0.0) > 0.99
    u32 = draw(0, 1)
    assert np.all(np.mod(u32.astype(np.float64) * 2.0**24, 1.0) == 0.0)


def test_no_correlation_between_neighbours_generations_streams_and_keys():
    bound = 5 / np.sqrt(N)  # five standard errors of a correlation coefficient
    a = draw(0, 10, 0)
    pairs = {
        "lag 1": (a[:-1], a[1:]),
        "lag 2": (a[:-2], a[2:]),
        "next generation": (a, draw(0, 11, 0)),
        "other stream": (a, draw(0, 10, 1)),
        "other key": (a, draw(1, 10, 0)),
    }
    for name, (x, y) in pairs.items():
        r = np.corrcoef(x, y)[0, 1]
        assert abs(r) < bound, f"{name}: correlation {r:.4f}"
    # Pairs of neighbours fill the unit square evenly (a 16×16 chi-square).
    grid = np.histogram2d(a[0::2], a[1::2], bins=16, range=[[0, 1], [0, 1]])[0]
    assert scipy.stats.chisquare(grid.ravel()).pvalue > 1e-3


def test_same_inputs_same_numbers_and_vmap_agrees():
    # the compiled draw and the eager, op-by-op hash (which runs the Python again)
    eager = counter_uniform(counter_seed(jax.random.key(5), 2, 1), (N,), jnp.float32)
    np.testing.assert_array_equal(draw(5, 2, 1), eager)
    assert not np.array_equal(draw(5, 2, 1)[:64], draw(5, 3, 1)[:64])
    keys = jax.random.split(jax.random.key(9), 4)
    shape = (N // 5, 5)
    # vmapped as in the swarms' programs, against each key's eager numbers
    batched = jax.jit(jax.vmap(
        lambda k: counter_uniform(counter_seed(k, 4), shape, jnp.float32)))(keys)
    for b, k in zip(batched, keys):
        np.testing.assert_array_equal(b, counter_uniform(counter_seed(k, 4), shape, jnp.float32))


def test_generation_words_are_traceable():
    """The generation index is a traced integer inside the swarm's scan."""
    key = jax.random.key(0)
    f = jax.jit(lambda i: counter_uniform(counter_seed(key, i, 2), (N,), jnp.float32))
    # against the words as Python integers (constants of the program, not arguments)
    concrete = jax.jit(lambda: counter_uniform(counter_seed(key, 6, 2), (N,), jnp.float32))
    np.testing.assert_array_equal(f(jnp.int32(6)), concrete())


# every shape once and the swarm's (16, 6) in both precisions (each case compiles
# threefry three times: the flat one jitted and eager, the shaped one eager)
@pytest.mark.parametrize("shape, x64", [((16, 6), False), ((16, 6), True), ((9, 30), True),
                                        ((2, 3, 4), False), ((5,), True)])
def test_uniform_in_box_draws_what_jax_random_draws_for_the_shape(shape, x64):
    """The solvers' starting points are drawn flat (XLA compiles a 1-D threefry faster)
    and are exactly ``jax.random.uniform`` of the shape, scaled to the box, also under
    jit and vmap over keys."""
    from jaxfric.optim._base import uniform_in_box

    with jax.enable_x64(x64):
        dt = jnp.float64 if x64 else jnp.float32
        lo, hi = jnp.full(shape[-1], -2.0, dt), jnp.full(shape[-1], 3.0, dt)
        keys = jax.random.split(jax.random.key(7), 3)
        def scale(u):
            return lo + u * (hi - lo)

        # jax.random's numbers for the shape, key by key (eager)
        drawn = [jax.random.uniform(k, shape, dt) for k in keys]
        # compared program against program (a fused multiply-add rounds the scaling
        # differently from eager, op-by-op arithmetic): jax.random's numbers are scaled
        # by a program of their own
        got = jax.jit(jax.vmap(lambda k: uniform_in_box(k, shape, lo, hi)))(keys)
        assert got.shape == (3,) + shape and got.dtype == dt
        np.testing.assert_array_equal(got, jax.jit(scale)(jnp.stack(drawn)))
        for k, u in zip(keys, drawn):
            np.testing.assert_array_equal(uniform_in_box(k, shape, lo, hi), scale(u))
