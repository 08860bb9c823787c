"""compare_motion's judges (docs/motion.md "Choosing a model"): the short-runs judge against
a NumPy free run written here from §13.2, its checks, and the default judge being the one
benchmarks/results/motion_judge.md measured best on new excitation."""

import csv
import functools
import inspect
import re
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfric import models
from jaxfric.motion import MotionData, MotionSearch, compare_motion, friction_step, simulate_motion
from jaxfric.motion._compare import JUDGES, short_runs_score

QUICK = MotionSearch(particles=4, generations=2, horizons=(None,), steps=(4,))
MASS, OFFSET, EPS = 2.5, 3.0, 1e-3
RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results" / "motion_judge.md"


def _record(n=1200, dt=1e-3):
    """Noise-free motion of a Coulomb + viscous axis (2.5 kg, offset 3 N) under two tones."""
    model = models.Coulomb(v_eps=EPS)
    t = np.arange(n) * dt
    u = 30 * np.sin(2 * np.pi * 1.3 * t) + 12 * np.sin(2 * np.pi * 3.1 * t + 1.0)
    with jax.enable_x64(True):
        out = simulate_motion(friction_step(model), jnp.asarray(model.from_physical(Fc=12.0, sigma2=60.0)),
                              MASS, u - OFFSET, dt, 0.0, 0.0)
    return MotionData.from_arrays(u, np.asarray(out["x"]), dt)


def _numpy_window_errors(position, force, dt, Fc, Fv, eps, mass, offset, init=20):
    """Squared position errors of one window: the state from a quadratic through its first
    ``init`` positions (value and slope at sample init-1), then §13.2's step written out:
    v' = v + (h/m)(u - F(v)) / (1 + (h/m) F'(v)), x' = x + h (v + v')/2, F = Fc tanh(v/eps) + Fv v."""
    tau = (np.arange(init) - (init - 1)) * dt
    c = np.polyfit(tau, position[:init], 2)
    x, v = c[2], c[1]
    errs = []
    for k in range(init - 1, position.size - 1):
        th = np.tanh(v / eps)
        f, slope = Fc * th + Fv * v, Fc * (1 - th ** 2) / eps + Fv
        r = dt / mass
        v_new = v + r * (force[k] - offset - f) / (1 + r * max(slope, 0.0))
        x, v = x + 0.5 * dt * (v + v_new), v_new
        errs.append((position[k + 1] - x) ** 2)
    return errs


def _numpy_short_score(rec, window, **params):
    errs = []
    for a in range(0, rec.n_samples - window + 1, window):
        errs += _numpy_window_errors(rec.position[a:a + window], rec.net_force[a:a + window], rec.dt, **params)
    return 1e3 * np.sqrt(np.mean(errs))


@functools.lru_cache(maxsize=None)
def _short_comparison():
    """``(record, comparison)``: compare_motion's short judge on 1300 samples of ``_record``,
    run once; the next test checks its scores and the baseline case of
    test_short_runs_score_equals_a_loop_of_score_calls scores its fit's baseline."""
    rec = _record(1300)
    with jax.enable_x64(True), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return rec, compare_motion(["coulomb"], rec, key=0, mass=(0.5, 10.0), fit_offset=True, search=QUICK,
                                   dtype=jnp.float64, model_options={"v_eps": EPS}, judge="short", window=300)


@pytest.mark.slow
def test_short_judge_pools_windows_each_simulated_from_its_own_first_samples():
    """The short-runs scores of the fit and of the baseline equal a NumPy free run of every
    300-sample window from a quadratic through its own first 20 positions (the last 100
    samples of 1200 + 100 make no whole window and are dropped)."""
    rec, cmp = _short_comparison()
    fit = cmp.fits["coulomb"]
    p = fit.params
    ref = _numpy_short_score(rec, 300, Fc=float(p["Fc"]), Fv=float(p["sigma2"]), eps=EPS, mass=fit.mass,
                             offset=fit.offset)
    assert cmp.judge == "short"
    assert cmp.scores["coulomb"] == pytest.approx(ref, rel=1e-7)
    b = fit.mechanics.baseline
    base = _numpy_short_score(rec, 300, Fc=max(b["Fc"], 0.0), Fv=b["Fv"], eps=1e-4, mass=b["M"], offset=b["offset"])
    assert cmp.baseline_score == pytest.approx(base, rel=1e-7)
    rows = cmp.rows()
    assert rows[0]["judge_rmse_mm"] == cmp.scores["coulomb"] and rows[-1]["judge_rmse_mm"] == cmp.baseline_score
    assert "short RMSE [mm]" in cmp.table()
    # one long free run per record scores differently: the windows matter
    assert short_runs_score(fit, [rec], 1300) != pytest.approx(cmp.scores["coulomb"], rel=1e-3)


def test_short_judge_checks_its_window_before_fitting():
    rec = _record(400)
    with pytest.raises(ValueError, match="window must be an integer >= init_window \\+ 2"):
        compare_motion(["coulomb"], rec, key=0, mass=2.5, judge="short", window=21)
    with pytest.raises(ValueError, match="a record of at least window=500 samples"):
        compare_motion(["coulomb"], rec, key=0, mass=2.5, judge="short", window=500)
    with pytest.raises(ValueError, match="judge must be one of"):
        compare_motion(["coulomb"], rec, key=0, mass=2.5, judge="oracle")


def test_the_default_judge_is_the_one_measured_best_on_new_excitation():
    """benchmarks/results/motion_judge.md counts, per criterion, the keys where its choice
    predicted the unseen excitation families within 10 % of the best candidate and no worse
    than the baseline; compare_motion's default judge is the criterion with the most."""
    if not RESULTS.exists():
        pytest.skip("benchmarks/results/motion_judge.md not written yet")
    counts = {}
    for line in RESULTS.read_text().splitlines():
        m = re.match(r"\| (\w+) \| (\d+) \| (\d+) \| (\d+) \|", line)
        if m and m.group(1) in JUDGES:
            counts[m.group(1)] = (int(m.group(3)), int(m.group(4)))
    assert set(counts) == set(JUDGES)
    default = inspect.signature(compare_motion).parameters["judge"].default
    assert counts[default] == max(counts.values())


def test_the_judge_table_counts_the_measured_rows():
    """The committed criteria table follows from the committed rows: per key, a criterion's
    pick (lowest, the baseline included) counts when its unseen RMSE is at most 1.1 x the
    best candidate's and not above the baseline's; and the ensemble rows' ratios."""
    rows_path = RESULTS.with_suffix(".csv")
    if not rows_path.exists():
        pytest.skip("benchmarks/results/motion_judge.csv not written yet")
    rows = list(csv.DictReader(rows_path.open()))
    keys = sorted({r["key"] for r in rows})
    for k in keys:  # the gated judge: the short score where blocked cross-validation beats the baseline's;
        rs = [r for r in rows if r["key"] == k]  # the baseline only where no model does
        b = next(float(r["blocked"]) for r in rs if r["model"] == "baseline")
        passed = any(float(r["blocked"]) < b for r in rs if r["model"] != "baseline")
        for r in rs:
            gate = not passed if r["model"] == "baseline" else float(r["blocked"]) < b
            r["gated"] = r["short"] if gate else "inf"
    table = {m.group(1): (int(m.group(2)), int(m.group(3)), int(m.group(4)))
             for m in re.finditer(r"^\| (\w+) \| (\d+) \| (\d+) \| (\d+) \|$", RESULTS.read_text(), re.M)}
    assert {"tail", "blocked", "short", "spread", "bic"} <= set(table)
    for crit, (n, wins, fair) in table.items():
        if crit.startswith("avg_"):  # averaged free runs: the baseline row holds their unseen RMSE
            base = [r for r in rows if r["model"] == "baseline"]
            best = {k: min(float(r["unseen"]) for r in rows if r["key"] == k) for k in keys}
            ok = [float(b[f"unseen_{crit}"]) <= float(b["unseen"]) for b in base]
            assert (n, fair) == (len(keys), sum(ok)), crit
            assert wins == sum(o and float(b[f"unseen_{crit}"]) <= 1.1 * best[b["key"]] for o, b in zip(ok, base))
            continue
        got_wins = got_fair = 0
        for k in keys:
            rs = [r for r in rows if r["key"] == k]
            pick = min(rs, key=lambda r: float(r[crit]))
            unseen = float(pick["unseen"])
            base = next(float(r["unseen"]) for r in rs if r["model"] == "baseline")
            best = min(float(r["unseen"]) for r in rs)
            got_fair += unseen <= base
            got_wins += unseen <= base and unseen <= 1.1 * best
        assert (n, wins, fair) == (len(keys), got_wins, got_fair), crit
    ens = [r for r in rows if r["model"] != "baseline"]
    better = sum(float(r["unseen_ensemble"]) < 0.99 * float(r["unseen"]) for r in ens)
    assert f"| chosen member | {len(ens)} | {better} |" in RESULTS.read_text()


def test_the_short_judges_window_is_a_duration():
    """The default window is SHORT_WINDOW_S = 2 s of samples at any rate (256 at the rig
    proxy's 128 Hz, where it was measured; 2 000 at EMPS's 1 kHz); a given window is a
    number of samples, checked."""
    from jaxfric.motion._compare import SHORT_WINDOW_S, short_window

    assert SHORT_WINDOW_S == 2.0
    assert short_window(1 / 128) == 256 and short_window(1e-3) == 2000
    assert short_window(0.5) == 22  # never shorter than the initial-state window + 2
    assert short_window(1e-3, 300) == 300
    for bad in (21, 2.5, True):
        with pytest.raises(ValueError, match="window must be an integer"):
            short_window(1e-3, bad)


def _loop_window_scores(fit, records, window, init=20):
    """The reference: one ``fit.score`` call per consecutive window (the judge's protocol
    written as the per-window loop it replaced)."""
    return [fit.score(r.window(a, a + window), init) for r in records
            for a in range(0, r.n_samples - window + 1, window)]


def _given(name):
    from jaxfric.motion import MotionFit

    params = {"lugre": dict(sigma0=1e5, sigma1=300.0, sigma2=60.0, Fc=12.0, Fs=15.0, vs=0.01),
              "gms": dict(k1=1e5, k2=2e5, k3=4e5, alpha1=0.3, alpha2=0.3, alpha3=0.4, C=20.0, Fc=12.0,
                          Fs=15.0, vs=0.01, sigma2=60.0)}[name]
    return MotionFit.given(models.get(name), params, mass=2.4, offset=2.5, dt=1e-3)


@pytest.mark.parametrize("name", ["lugre", "gms", "baseline"])
def test_short_runs_score_equals_a_loop_of_score_calls(name):
    """All windows in one vmapped free run give what one ``fit.score`` per window gives:
    the same initial state from each window's first 20 positions, the same dynamics, per
    window and pooled, across records of different lengths (rests dropped)."""
    from jaxfric.motion._compare import _pooled_rmse, baseline_fit, window_scores

    with jax.enable_x64(True), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        recs = [_record(700), _record(950).window(50)]  # 2 + 3 windows of 300, rests of 100 and 0
        # the baseline of a fitted comparison (the short-judge test's, run once for both)
        fit = baseline_fit(_short_comparison()[1].best) if name == "baseline" else _given(name)
        got = window_scores(fit, recs, 300)
        ref = _loop_window_scores(fit, recs, 300)
        assert len(got) == len(ref) == 5
        for g, r in zip(got, ref):
            assert g["n"] == 280
            for k in ("rmse_mm", "fit_percent", "max_abs_mm"):
                assert g[k] == pytest.approx(r[k], rel=1e-9, abs=1e-12)
        pooled = np.sqrt(np.mean([r["rmse_mm"] ** 2 for r in ref]))
        assert short_runs_score(fit, recs, 300) == pytest.approx(pooled, rel=1e-9)
        assert _pooled_rmse(got) == pytest.approx(pooled, rel=1e-9)


def test_a_window_whose_run_is_not_finite_makes_the_short_score_inf():
    """Opposite force spikes of 1e300 N in the second of five windows on a mass of 1e-300
    kg (past MotionData's checks): that window's run is not finite, as in the loop of
    ``fit.score`` calls, the other windows are unchanged, and the judge says inf."""
    import dataclasses

    from jaxfric.motion._compare import window_scores

    with jax.enable_x64(True), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        recs = [_record(700), _record(950).window(50)]
        fit = _given("lugre")
        fit = fit.replace(mechanics=fit.mechanics.replace(mass=1e-300))
        force = recs[0].force.copy()
        force[450:452] = [1e300, -1e300]
        broken = [dataclasses.replace(recs[0], force=force), recs[1]]
        got = window_scores(fit, broken, 300)
        ref = _loop_window_scores(fit, broken, 300)
        assert [np.isfinite(g["rmse_mm"]) for g in got] == [np.isfinite(r["rmse_mm"]) for r in ref] \
            == [True, False, True, True, True]
        assert [g["rmse_mm"] for i, g in enumerate(got) if i != 1] == \
            pytest.approx([r["rmse_mm"] for i, r in enumerate(ref) if i != 1], rel=1e-9)
        assert short_runs_score(fit, broken, 300) == np.inf
        assert np.isfinite(short_runs_score(fit, recs, 300))


def test_short_runs_score_checks_the_sample_time():
    from jaxfric.motion._compare import window_scores

    fit = _given("lugre")
    with pytest.raises(ValueError, match="sample time"):
        window_scores(fit, [_record(700, dt=2e-3)], 300)
    assert window_scores(fit, [_record(200)], 300) == []


def test_the_emps_blocks_are_contiguous_and_each_run_starts_from_its_own_head():
    """benchmarks/motion_judge.py --proxy emps-blocked: the 3 blocks are consecutive, equal
    (to a sample) parts of DATA_EMPS.mat that together are the whole file, and a block's
    free run depends on its own samples only: its score equals that of a record rebuilt from
    the block's force and position alone (the state from its first 20 positions), and
    differs from the whole file's free run cut at the same place. Skipped without the file."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from _harness import emps_file
    from motion_judge import emps_blocks

    from jaxfric.motion import MotionFit
    from jaxfric.rig.emps import load_emps

    path = emps_file()
    if path is None:
        pytest.skip("DATA_EMPS.mat not found (JAXFRIC_DATA, ../shared/data)")
    blocks = list(emps_blocks(path).values())
    rec = load_emps(path)
    assert len(blocks) == 3 and max(b.n_samples for b in blocks) - min(b.n_samples for b in blocks) <= 1
    np.testing.assert_array_equal(np.concatenate([b.position for b in blocks]), rec.qm)
    np.testing.assert_array_equal(np.concatenate([b.force for b in blocks]), rec.force)
    coul = models.Coulomb(v_eps=1e-4)  # the published IDIM-LS values (SOURCE.md)
    fit = MotionFit.given(coul, {"Fc": 20.39, "sigma2": 203.5}, mass=95.11, offset=-3.165, dt=rec.dt)
    with jax.enable_x64(True):
        whole = fit.simulate(MotionData.from_arrays(rec.force, rec.qm, rec.dt), init_window=20)["x"]
        start = 0
        for b in blocks:
            alone = MotionData.from_arrays(b.force, b.position, b.dt)
            assert fit.score(b, 20)["rmse_mm"] == pytest.approx(fit.score(alone, 20)["rmse_mm"], rel=1e-9)
            run = fit.simulate(b, init_window=20)["x"]
            assert abs(run[19] - b.position[19]) < 1e-4  # starts at its own 20th sample
            if start:
                assert np.max(np.abs(run[20:] - whole[start + 20:start + b.n_samples])) > 1e-4
            start += b.n_samples


def test_the_emps_blocks_fit_free_runs_at_different_force_offsets():
    """Why a fit trained on EMPS block 2 predicts blocks 0 and 1 badly (docs/motion.md, "The
    force offset decides EMPS block 2"): with the published IDIM-LS Coulomb + viscous model and
    only its force offset varied, each block's free run fits best at its own offset, block 2's
    at least 0.25 N below blocks 0 and 1's; 0.4 N away from a block's best its error at least
    doubles; and least squares on each whole block puts block 2's offset at least 0.3 N below
    the two others', while on the blocks' quarters (2 s) its offsets scatter over more than
    10 N. Skipped without the file."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from _harness import emps_file
    from motion_judge import emps_blocks

    from jaxfric.motion import MotionFit
    from jaxfric.motion._baseline import least_squares

    path = emps_file()
    if path is None:
        pytest.skip("DATA_EMPS.mat not found (JAXFRIC_DATA, ../shared/data)")
    coul = models.Coulomb(v_eps=1e-4)
    grid = np.round(np.arange(-3.9, -2.55, 0.05), 3)
    best, ls, quarters = [], [], []
    with jax.enable_x64(True):
        for b in emps_blocks(path).values():
            rmse = np.array([MotionFit.given(coul, {"Fc": 20.39, "sigma2": 203.5}, mass=95.11, offset=o,
                                             dt=b.dt).score(b, 20)["rmse_mm"] for o in grid])
            i = int(np.argmin(rmse))
            assert 0 < i < grid.size - 1  # a minimum inside the grid
            away = [rmse[j] for j in (i - 8, i + 8) if 0 <= j < grid.size]  # 0.4 N from the best
            assert away and min(away) > 2 * rmse[i], (grid[i], rmse[i], away)
            best.append(grid[i])
            ls.append(least_squares([b]).offset)
            n = b.n_samples
            quarters += [least_squares([b.window(round(q * n / 4), round((q + 1) * n / 4))]).offset for q in range(4)]
    assert best[2] <= min(best[:2]) - 0.25, best
    assert ls[2] <= min(ls[:2]) - 0.3, ls
    assert max(quarters) - min(quarters) > 10.0, quarters


def test_the_averaged_pseudo_candidates_weights_and_rmse():
    """benchmarks/motion_judge.py's averages (issue 45 item 4): each rule's weights from the
    short scores, and the RMSE of a weighted average of two free runs against a hand
    computation: past the first 2 samples, runs (1, 3) mm and (3, -1) mm average to (2, 1) mm,
    against positions (4, -2) mm an RMSE of sqrt((2^2 + 3^2) / 2) mm (run a alone: sqrt((3^2 + 5^2) / 2))."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from motion_judge import average_weights, averaged_rmse

    short = {"baseline": 2.0, "a": 1.0, "b": 3.0, "c": 1.5, "d": 4.0}
    assert average_weights(short, "avg_all") == pytest.approx(dict.fromkeys(short, 0.2))
    assert average_weights(short, "avg_beats_ls") == pytest.approx(dict.fromkeys(("baseline", "a", "c"), 1 / 3))
    assert average_weights(short, "avg_top3") == pytest.approx(dict.fromkeys(("a", "c", "baseline"), 1 / 3))
    inv = {"baseline": 1 / 4, "a": 1.0, "b": 1 / 9, "c": 1 / 2.25, "d": 1 / 16}
    assert average_weights(short, "avg_inv_var") == pytest.approx({k: v / sum(inv.values()) for k, v in inv.items()})
    runs = {"a": np.array([9.0, 9.0, 1e-3, 3e-3]), "b": np.array([-9.0, 5.0, 3e-3, -1e-3])}
    x = np.array([0.0, 0.0, 4e-3, -2e-3])
    assert averaged_rmse(x, runs, {"a": 0.5, "b": 0.5}, init=2) == pytest.approx(np.sqrt(6.5), rel=1e-12)
    assert averaged_rmse(x, runs, {"a": 1.0}, init=2) == pytest.approx(np.sqrt(17.0), rel=1e-12)
    with pytest.raises(KeyError):
        average_weights(short, "avg_median")


def test_the_narrow_gate_counts_are_the_committed_rows():
    """`NARROW_COUNTS`, which `MotionComparison.choice`'s narrow-pass warning quotes, follows
    from the committed rows of every one-fit-per-candidate judge table: per key where a model
    passes the gate, the gated pick's margin ``1 − blocked / least squares' blocked`` below
    or above `NARROW_GATE`, and whether its unseen error exceeds least squares'."""
    from jaxfric.motion._compare import NARROW_COUNTS, NARROW_GATE

    stems = ["motion_judge", *(f"motion_judge_keys{a}_{a + 4}" for a in range(5, 40, 5)), "judge_emps",
             *(f"judge_emps_keys{a}_{a + 4}" for a in range(5, 25, 5)), "judge_emps_keys25_34", "judge_emps_keys35_39",
             "judge_emps_keys40_44", "judge_pneumatic"]
    # the 70 keys the threshold was set on and the 20 measured after it (rig 30-39, EMPS 35-44)
    tables = [RESULTS.parent / f"{stem}.csv" for stem in stems]
    if not all(p.exists() for p in tables):
        pytest.skip("judge tables not written yet")
    counts = {"narrow": [0, 0], "wide": [0, 0]}
    keys = 0
    for path in tables:
        rows = list(csv.DictReader(path.open()))
        for k in sorted({r["key"] for r in rows}):
            rs = [r for r in rows if r["key"] == k]
            base = next(r for r in rs if r["model"] == "baseline")
            keys += 1
            passed = [r for r in rs if r["model"] != "baseline" and float(r["blocked"]) < float(base["blocked"])]
            if not passed:
                continue
            pick = min(passed, key=lambda r: float(r["short"]))
            side = counts["narrow" if 1 - float(pick["blocked"]) / float(base["blocked"]) < NARROW_GATE else "wide"]
            side[0] += 1
            side[1] += float(pick["unseen"]) > float(base["unseen"])
    assert keys == 90
    assert {k: tuple(v) for k, v in counts.items()} == NARROW_COUNTS
