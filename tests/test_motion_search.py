"""The default search's screening stage (jaxfric/motion/_pipeline.py): the screen's spread
returns close after a number of widenings (MotionSearch.screen_cycle); the slow-attraction
starts (MotionSearch.slow_starts, motion._baseline.slow_attraction_grid)."""

import dataclasses

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


def test_the_slow_attraction_grid_changes_only_stiffness_attraction_rate_and_peak():
    """GMS: 27 variants of the start, each coordinate log10_k*, log10_C, Fs_over_Fc on its
    grid fraction of the box, every other coordinate (and the mechanics) left as it was;
    a model without an attraction rate gets none."""
    from jaxfric import models
    from jaxfric.motion._baseline import SLOW_GRID, slow_attraction_grid

    model = models.GMS(num_elements=3)
    names = model.param_names
    n = model.num_params
    rng = np.random.default_rng(0)
    lo = np.concatenate([-rng.uniform(1, 2, n), [1.0, -5.0]])
    hi = np.concatenate([rng.uniform(1, 2, n), [2.0, 5.0]])
    start = rng.uniform(lo, hi)
    grid = np.array(slow_attraction_grid(model, start, lo, hi))
    assert grid.shape == (27, n + 2)
    k = [names.index(f"log10_k{i}") for i in (1, 2, 3)]
    c, r = names.index("log10_C"), names.index("Fs_over_Fc")
    other = [i for i in range(n + 2) if i not in (*k, c, r)]
    np.testing.assert_array_equal(grid[:, other], np.broadcast_to(start[other], (27, len(other))))
    frac = (grid - lo) / (hi - lo)
    np.testing.assert_allclose(frac[:, k], np.repeat(frac[:, k[:1]], 3, axis=1), rtol=0, atol=1e-12)
    got = {(round(a, 9), round(b, 9), round(d, 9)) for a, b, d in frac[:, [k[0], c, r]]}
    want = {(round(a, 9), round(b, 9), round(d, 9)) for a in SLOW_GRID["k"] for b in SLOW_GRID["C"]
            for d in SLOW_GRID["Fs_over_Fc"]}
    assert got == want
    for other_model in (models.LuGre(), models.Coulomb(), models.Stribeck()):
        m = other_model.num_params
        assert slow_attraction_grid(other_model, np.zeros(m + 2), -np.ones(m + 2), np.ones(m + 2)) == []
    assert slow_attraction_grid(model, None, lo, hi) == []


def test_the_slow_starts_are_the_grids_points_of_lowest_whole_cost():
    """grid_ranked ranks the grid by the cost itself (the rough bowl, recomputed in NumPy)."""
    from jaxfric.motion._pipeline import grid_ranked

    data = (jnp.array([1.0, -0.5]), 0.3, 15.0)
    pool = np.random.default_rng(4).uniform(-2, 2, (9, 2))
    ref = np.sum((pool - [1.0, -0.5]) ** 2 + 0.09 * np.sin(15.0 * pool) ** 2, axis=1)
    lo, hi = np.array([-4.0, -4.0]), np.array([4.0, 4.0])
    with jax.enable_x64(True):
        stages, clock = [], _Clock(MotionBudget())
        got = grid_ranked(MotionSearch(slow_starts=3), clock, _rough, data, list(pool), lo, hi, jnp.float64,
                          stages)
    np.testing.assert_array_equal(np.array(got), pool[np.argsort(ref)[:3]])
    assert stages[0]["stage"] == "rank_slow" and stages[0]["J"] == pytest.approx(ref.min(), rel=1e-12)
    assert clock.evals == 9


def _rough_total(y, data):
    return jnp.sum(_rough(y, data) ** 2)


def test_the_slow_starts_run_the_free_run_stages_only():
    """run_search: the swarm's and the caller's starts run every stage (shooting, then free
    run), the grid's only the free run; the winner is the lowest end of all."""
    from jaxfric.motion._pipeline import run_search, start_costs

    data = (jnp.array([1.0, -0.5]), 0.3, 15.0)
    lo, hi = np.array([-4.0, -4.0]), np.array([4.0, 4.0])
    grid = [np.array([1.0, -0.5]) + d for d in ([0.02, 0.01], [2.0, 2.0], [-3.0, 1.0])]
    search = MotionSearch(particles=6, generations=3, horizons=(300, None), steps=(5, 5), starts=2,
                          slow_starts=2)
    with jax.enable_x64(True):
        y, stages, stopped = run_search(search, MotionBudget(), _rough, _rough_total, lo, hi, global_data=data,
                                        stage_data=lambda h: data, key=jax.random.key(0), dtype=jnp.float64,
                                        extra_starts=[np.array([3.0, 3.0])], grid_starts=grid)
    assert stopped is None
    ran = {}
    for s in stages:
        if s["start"] is not None:
            ran.setdefault(s["start"], []).append(s["stage"])
    last = max(ran)
    assert [ran[i] for i in (last - 1, last)] == [["free_run"], ["free_run"]]
    assert all(ran[i] == ["shooting_300", "free_run"] for i in range(last - 1))
    assert "rank_slow" in [s["stage"] for s in stages]
    best = start_costs(stages)[0]
    assert best["start"] in (last - 1, last)  # the grid point beside the bowl's minimum wins
    assert float(np.sum(np.asarray(_rough(jnp.asarray(y), data)) ** 2)) == pytest.approx(best["J"], rel=1e-6)
    plain = dataclasses.replace(search, slow_starts=0)
    with jax.enable_x64(True):
        _, stages0, _ = run_search(plain, MotionBudget(), _rough, _rough_total, lo, hi, global_data=data,
                                   stage_data=lambda h: data, key=jax.random.key(0), dtype=jnp.float64,
                                   extra_starts=[np.array([3.0, 3.0])], grid_starts=grid)
    assert "rank_slow" not in [s["stage"] for s in stages0]
    assert max(s["start"] for s in stages0 if s["start"] is not None) == last - 2


def test_the_slow_starts_setting_is_checked():
    for bad in (MotionSearch(slow_starts=-1), MotionSearch(slow_starts=True), MotionSearch(slow_starts=1.5)):
        with pytest.raises(ValueError, match="MotionSearch"):
            bad.check()


def _coulomb_drive(n: int, dt: float = 1e-3):
    """A 2.5 kg drive with Coulomb + viscous friction (Fc 8 N, 20 N s/m) and a -3 N load under
    two sines, simulated in float64: n samples of force and position."""
    from jaxfric import models
    from jaxfric.motion import MotionData, friction_step, simulate_motion

    t = np.arange(n) * dt
    u = 30 * np.sin(2 * np.pi * 1.3 * t) + 12 * np.sin(2 * np.pi * 3.1 * t + 1.0)
    truth = models.Coulomb(v_eps=1e-3)
    with jax.enable_x64(True):
        out = simulate_motion(friction_step(truth), jnp.asarray(truth.from_physical(Fc=8.0, sigma2=20.0), jnp.float64),
                              2.5, u - 3.0, dt, 0.0, 0.0)
    return MotionData.from_arrays(u, np.asarray(out["x"]), dt)


#: The GMS fit of test_identify_motion_passes_the_grid_to_gms_only: its record length, search
#: and mechanics, which the attraction-rate test below reuses so that its two GMS fits run the
#: programs this one compiled (its checks are on the box, which depends on the training
#: velocity and net force only, not on the search or the mechanics identified).
GMS_DRIVE_SAMPLES = 800
GRID_SEARCH = MotionSearch(particles=4, generations=2, horizons=(200, None), steps=(3, 3), starts=1,
                           least_squares_start=True, slow_starts=2)
GRID_MECHANICS = {"mass": (1.0, 5.0), "fit_offset": True}


def test_identify_motion_passes_the_grid_to_gms_only():
    """identify_motion: a GMS fit with slow_starts=2 ranks the grid and runs 2 more starts on
    the free run only; a LuGre fit with the same search gets no grid (its search unchanged:
    the same stages and the same parameters as with slow_starts=0)."""
    import warnings

    from jaxfric.motion import identify_motion

    rec = _coulomb_drive(GMS_DRIVE_SAMPLES)
    search = GRID_SEARCH
    fits = {}
    with jax.enable_x64(True), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, s in (("gms", search), ("lugre", search), ("lugre0", dataclasses.replace(search, slow_starts=0))):
            fits[name] = identify_motion(name.rstrip("0"), rec, key=0, train=1.0, search=s, dtype=jnp.float64,
                                         **GRID_MECHANICS)
    gms = [(s["stage"], s["start"]) for s in fits["gms"].stages]
    assert ("rank_slow", None) in gms
    assert [st for st, i in gms if i in (2, 3)] == ["free_run", "free_run"]
    assert [st for st, i in gms if i in (0, 1)] == ["shooting_200", "free_run"] * 2
    assert [s["stage"] for s in fits["lugre"].stages] == [s["stage"] for s in fits["lugre0"].stages]
    assert "rank_slow" not in [s["stage"] for s in fits["lugre"].stages]
    np.testing.assert_array_equal(fits["lugre"].theta, fits["lugre0"].theta)


def test_the_default_search_has_no_slow_attraction_starts():
    """The slow-attraction starts lower GMS's training cost and raise its error on new
    excitation (docs/motion.md, "Deeper on training, worse on new motion"): off by default,
    for GMS as for every physical model; the screen stays."""
    from jaxfric import models
    from jaxfric.motion import default_search

    for model in (models.GMS(), models.LuGre(), models.Stribeck()):
        search = default_search(model)
        assert search.slow_starts == 0
        assert search.screen == 16 and search.least_squares_start


def test_a_motion_fits_attraction_rate_starts_at_the_friction_scale_per_second():
    """identify_motion's data-centred box bounds GMS's attraction rate C below by
    F / ATTRACTION_TIME_S (F = friction_scales of the training velocity and net force), not by
    the force-balance box's 0.1 F; a C the caller gives is kept; force balance is unchanged."""
    import warnings

    from jaxfric import models
    from jaxfric.models import friction_scales
    from jaxfric.motion import ATTRACTION_TIME_S, identify_motion

    rec = _coulomb_drive(GMS_DRIVE_SAMPLES)  # the grid test's GMS fit: its programs, compiled once
    f = float(friction_scales(rec.velocity, rec.net_force)[0])
    search = GRID_SEARCH
    with jax.enable_x64(True), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = identify_motion("gms", rec, key=0, train=1.0, search=search, dtype=jnp.float64, **GRID_MECHANICS)
        given = identify_motion("gms", rec, key=0, train=1.0, search=search, dtype=jnp.float64, **GRID_MECHANICS,
                                box={"C": (2.0, 3e3)})
    assert fit.box["C"] == (f / ATTRACTION_TIME_S, 1e4 * f)
    assert 10.0 ** fit.mechanics.search_bounds[0][models.GMS().param_names.index("log10_C")] \
        == pytest.approx(f / ATTRACTION_TIME_S)
    assert given.box["C"] == (2.0, 3e3)
    assert models.GMS().search_box(None, rec.velocity, rec.net_force)["C"][0] == pytest.approx(0.1 * f)
