"""The swarms' bounding: the select form of clip gives jnp.clip's numbers.

MAPSO bounds with :func:`jaxfric.optim._base.clip` (two selects) because XLA:CPU
compiles it 1.2-2.2x faster inside MAPSO's generation (docs/solvers.md); that
is only allowed if it is the same function as ``jnp.clip``.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfric.optim._base import clip
from jaxfric.optim.mapso import competition
from jaxfric.optim.pso import pso_move


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_select_clip_equals_jnp_clip_including_nan_inf_and_bounds(dtype):
    with jax.enable_x64(dtype == np.float64):
        rng = np.random.default_rng(0)
        lower = rng.uniform(-3, 0, 7).astype(dtype)
        upper = (lower + rng.uniform(0.1, 4, 7)).astype(dtype)
        x = rng.uniform(-6, 6, (50, 7)).astype(dtype)
        x[0] = lower  # exactly on the bounds
        x[1] = upper
        x[2, :4] = [np.nan, np.inf, -np.inf, np.nan]
        x[3] = np.nextafter(lower, -np.inf)  # one ulp outside
        got = np.asarray(clip(jnp.asarray(x), jnp.asarray(lower), jnp.asarray(upper)))
        want = np.asarray(jnp.clip(jnp.asarray(x), jnp.asarray(lower), jnp.asarray(upper)))
        assert got.dtype == want.dtype == dtype
        np.testing.assert_array_equal(got, want)  # NaN where jnp.clip gives NaN
        assert np.isnan(got[2, 0]) and got[2, 1] == upper[1] and got[2, 2] == lower[2]
        # a scalar bound pair (the velocity clamp passes arrays, users may pass floats)
        np.testing.assert_array_equal(np.asarray(clip(jnp.asarray(x), -1.0, 1.0)),
                                      np.asarray(jnp.clip(jnp.asarray(x), -1.0, 1.0)))


def test_pso_move_and_competition_give_the_same_numbers_with_either_clip(monkeypatch):
    with jax.enable_x64(True):
        rng = np.random.default_rng(1)
        p, d = 25, 6
        lower, upper = -np.ones(d) * 2.0, np.ones(d) * 3.0
        x = rng.uniform(lower, upper, (p, d))
        v = rng.uniform(-9, 9, (p, d))
        pbest = rng.uniform(lower, upper, (p, d))
        r = rng.uniform(0, 1, (2, p, d))
        vmax = 0.8 * (upper - lower)  # some velocities clamped, some positions clipped
        args = (r, x, v, pbest, pbest[:1], 0.9, 2.0, 2.0, vmax, lower, upper)
        a = pso_move(*map(jnp.asarray, args))
        b = pso_move(*map(jnp.asarray, args), clip=clip)
        for u, w in zip(a, b):
            np.testing.assert_array_equal(np.asarray(u), np.asarray(w))
        assert np.any(np.asarray(a[0]) == upper) and np.any(np.asarray(a[0]) == lower)  # bounds hit
        assert np.any(np.abs(np.asarray(a[1])) == vmax)  # velocity clamp hit

        import jaxfric.optim.mapso as mapso

        f = rng.uniform(0, 1, p)
        u = rng.uniform(0, 1, (p, d + 3))
        with_selects = competition(jnp.asarray(u), jnp.asarray(x), jnp.asarray(f), 5,
                                   jnp.asarray(lower), jnp.asarray(upper), 0.5)
        monkeypatch.setattr(mapso, "clip", jnp.clip)
        with_jnp = competition(jnp.asarray(u), jnp.asarray(x), jnp.asarray(f), 5,
                               jnp.asarray(lower), jnp.asarray(upper), 0.5)
        for s, j in zip(with_selects, with_jnp):
            np.testing.assert_array_equal(np.asarray(s), np.asarray(j))
