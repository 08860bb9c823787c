"""The default search's screening stage (jaxfric/motion/_pipeline.py): the screen's spread
returns close after a number of widenings (MotionSearch.screen_cycle)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfric.motion import MotionBudget, MotionSearch
from jaxfric.motion._pipeline import _Clock, screen_free_run


def _bowl(y, c):
    return jnp.concatenate([y - c, jnp.ones(1, y.dtype)])  # minimum J = 1 at y = c


@pytest.mark.parametrize("cycle, spreads", [(0, [0.2, 0.8, 3.2, 12.8, 51.2]), (2, [0.2, 0.8, 0.2, 0.8, 0.2]),
                                            (3, [0.2, 0.8, 3.2, 0.2, 0.8])])
def test_the_screen_returns_close_after_screen_cycle_widenings(cycle, spreads):
    """At the minimum nothing lower is found: each round widens 4x from screen_spread, and
    with screen_cycle=c every c-th widening returns to screen_spread (0: never)."""
    c = jnp.array([0.3, -0.2])
    lo, hi = np.array([-1.0, -1.0]), np.array([1.0, 1.0])
    with jax.enable_x64(True):
        stages = []
        _, f = screen_free_run(MotionSearch(screen=5, screen_size=8, screen_steps=5, screen_spread=0.2,
                                            screen_cycle=cycle),
                               _Clock(MotionBudget()), _bowl, np.asarray(c), 1.0, lo, hi, c,
                               jax.random.key(0), jnp.float64, stages)
        assert f == 1.0
        np.testing.assert_allclose([s["spread"] for s in stages], spreads, rtol=1e-12)


def _rough(y, data):
    """Residuals of Σ (y_i - c_i)² + a² sin²(w y_i): a bowl with a valley every π/w."""
    c, a, w = data
    return jnp.concatenate([y - c, a * jnp.sin(w * y)])


def test_a_round_that_finds_a_lower_point_resets_the_cycle():
    """From a local valley of the rough bowl the screen only goes down; each round's spread
    follows the rule from the rounds before it: screen_spread after a round that lowered J,
    else 4x the last one, back to screen_spread at every screen_cycle-th widening in a row."""
    data = (jnp.array([1.0, -0.5]), 0.3, 15.0)
    lo, hi = np.array([-4.0, -4.0]), np.array([4.0, 4.0])
    y0 = jnp.array([3.0, 2.5])
    with jax.enable_x64(True):
        f0 = float(jnp.sum(_rough(y0, data) ** 2))
        stages = []
        screen_free_run(MotionSearch(screen=10, screen_size=8, screen_steps=10, screen_cycle=2),
                        _Clock(MotionBudget()), _rough, np.asarray(y0), f0, lo, hi, data,
                        jax.random.key(1), jnp.float64, stages)
    best = [f0] + [s["best"] for s in stages]
    assert best == sorted(best, reverse=True) and best[-1] < f0
    expected, spread, widened = [], 0.1, 0
    for i in range(len(stages)):
        expected.append(spread)
        if best[i + 1] < best[i]:
            spread, widened = 0.1, 0
        else:
            widened += 1
            spread = 0.1 if widened % 2 == 0 else 4.0 * spread
    np.testing.assert_allclose([s["spread"] for s in stages], expected, rtol=1e-12)
    assert 0.4 in [pytest.approx(s["spread"]) for s in stages]  # it did widen at least once


def test_the_screen_cycle_setting_is_checked():
    for bad in (MotionSearch(screen_cycle=-1), MotionSearch(screen_cycle=True), MotionSearch(screen_cycle=1.5)):
        with pytest.raises(ValueError, match="MotionSearch"):
            bad.check()
