"""Parameter uncertainty (jaxfric.uncertainty): estimators against independent
references, calibration over noisy replicates on the rig simulator's velocity, an
unidentifiable parameter that must not look confident, and the Fit API / file round trip."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from jaxfric import Fit, load_fit, models
from jaxfric.uncertainty import (ParameterUncertainty, andrews_bandwidth, block_bootstrap_covariance,
                                 hac_covariance, jacobian_covariance, parameter_uncertainty,
                                 prediction_interval)

FC, SIGMA2 = 300.0, 1.5e4          # true Coulomb level [N] and viscous coefficient [N s/m]
NOISE = 20.0                       # measurement noise [N]
REPLICATES = 400


@pytest.fixture(scope="module")
def rig_velocity(rig_record):
    return np.asarray(rig_record.velocity, np.float64)


def _fit(model, theta, v, dt, n_train=None, **kw):
    n = v.size
    return Fit(model=model, theta=np.asarray(theta, np.float64), velocity_scaler=None, friction_scaler=None,
               dt=dt, n_train=n if n_train is None else n_train, n_samples=n, metrics={}, **kw)


@functools.partial(jax.jit, static_argnums=(1, 2, 3))
def _ar1(key, shape, rho, sd):
    """AR(1) noise of marginal standard deviation ``sd`` along the last axis (one
    compiled program per shape, not one per eager operation)."""
    e = jax.random.normal(key, shape) * sd * np.sqrt(1 - rho**2)

    def step(prev, x):
        cur = rho * prev + x
        return cur, cur

    first = jax.random.normal(jax.random.fold_in(key, 1), shape[:-1]) * sd
    _, out = jax.lax.scan(step, first, jnp.moveaxis(e, -1, 0))
    return jnp.moveaxis(out, 0, -1)


# ------------------------------------------------------------------- references
def test_jacobian_covariance_is_ols_covariance_for_a_linear_model(rig_velocity):
    """Coulomb+viscous is linear in (Fc, sigma2): the physical covariance must equal the
    textbook OLS s²(XᵀX)⁻¹, whatever the log10 search coordinate in between."""
    with jax.enable_x64(True):
        model = models.Coulomb()
        v = rig_velocity
        rng = np.random.default_rng(0)
        f = FC * np.tanh(v / model.v_eps) + SIGMA2 * v + NOISE * rng.standard_normal(v.size)
        ls = model.fit_least_squares(v, f)
        theta = model.from_physical(**ls)
        fit = _fit(model, theta, v, 1 / 128)
        u = parameter_uncertainty(fit, (v, f, 1 / 128), method="jacobian")
    x = np.stack([np.tanh(v / model.v_eps), v], axis=1)
    beta = np.linalg.lstsq(x, f, rcond=None)[0]
    r = f - x @ beta
    ref = r @ r / (v.size - 2) * np.linalg.inv(x.T @ x)
    np.testing.assert_allclose(u.estimate, beta, rtol=1e-10)
    np.testing.assert_allclose(u.cov["jacobian"], ref, rtol=1e-6)
    lo, hi = u.intervals(0.95, "jacobian")["Fc"]
    t = stats.t.ppf(0.975, v.size - 2)
    np.testing.assert_allclose([lo, hi], beta[0] + np.array([-1, 1]) * t * np.sqrt(ref[0, 0]), rtol=1e-8)


def test_hac_matches_the_newey_west_definition():
    """FFT lag sums against the definition written out as a loop over lags."""
    rng = np.random.default_rng(1)
    n, p, L = 300, 3, 7.0
    jac = rng.standard_normal((n, p))
    r = np.convolve(rng.standard_normal(n + 10), np.ones(5) / 5, "same")[:n]
    def long_run(g):
        omega = g.T @ g
        for lag in range(1, int(L) + 1):
            gam = g[lag:].T @ g[:-lag]
            omega += (1 - lag / (L + 1)) * (gam + gam.T)
        return omega

    g = jac * r[:, None]
    a = np.linalg.inv(jac.T @ jac)
    ref = a @ long_run(g) @ a * n / (n - p)
    np.testing.assert_allclose(hac_covariance(jac, r, L), ref, rtol=1e-9)
    # two independent records: no lag crosses the boundary
    ref2 = a @ (long_run(g[:100]) + long_run(g[100:])) @ a * n / (n - p)
    np.testing.assert_allclose(hac_covariance(jac, r, L, segments=(100, 200)), ref2, rtol=1e-9)


def test_bandwidth_grows_with_correlation_and_bootstrap_is_keyed():
    rng = np.random.default_rng(2)
    n = 2000
    jac = np.ones((n, 1))
    white = rng.standard_normal(n)
    ar = np.asarray(_ar1(jax.random.key(0), (n,), 0.9, 1.0))
    assert andrews_bandwidth(jac, white) < 3 < 10 < andrews_bandwidth(jac, ar)
    c1 = block_bootstrap_covariance(jac, ar, 0, 20, replicates=200)
    c2 = block_bootstrap_covariance(jac, ar, 0, 20, replicates=200)
    np.testing.assert_array_equal(c1, c2)
    # The moving-block bootstrap of a mean of AR(1) noise with blocks of b samples has
    # variance ≈ [1 + 2 Σ_{l<b} (1 - l/b) ρ^l] σ²/n: for ρ = 0.9, b = 20 that is 0.584 of
    # the long-run (1+ρ)/(1-ρ) σ²/n (blocks shorter than the correlation time see only part
    # of it). One series' estimate scatters by tens of percent (about n (1-ρ)/(1+ρ) ≈ 105
    # effective samples), so the mean over 24 NumPy-drawn series is checked against it
    # (NumPy: the same series whatever JAX's x64 setting).
    expected = (1 + 2 * sum((1 - lag / 20) * 0.9**lag for lag in range(1, 20))) / 19.0
    ratios = []
    for i in range(24):
        e = rng.standard_normal(n) * np.sqrt(1 - 0.9**2)
        series = np.empty(n)
        series[0] = rng.standard_normal()
        for t in range(1, n):
            series[t] = 0.9 * series[t - 1] + e[t]
        ratios.append(block_bootstrap_covariance(jac, series, i, 20, replicates=200)[0, 0] / (19.0 / n))
    assert abs(np.mean(ratios) / expected - 1) < 0.1, (expected, ratios)


# ------------------------------------------------------------------- calibration
def _coulomb_replicates(v, noise):
    """Least-squares fits of Coulomb+viscous on ``REPLICATES`` noisy records (vmapped),
    returning (theta (R, 2), residuals (R, n), Jacobians (R, n, 2))."""
    model = models.Coulomb()
    theta, r, jac = _replicate_arrays(model, v, noise)
    return model, np.asarray(theta), np.asarray(r), np.asarray(jac)


@functools.partial(jax.jit, static_argnums=0)
def _replicate_arrays(model, v, noise):
    """The arrays of :func:`_coulomb_replicates` as one compiled program (eager, each
    operation compiled on its own)."""
    f_true = FC * jnp.tanh(v / model.v_eps) + SIGMA2 * v
    x = jnp.stack([jnp.tanh(v / model.v_eps), v], axis=1)
    beta = jnp.linalg.lstsq(x, (f_true[None, :] + noise).T)[0].T          # (R, 2) physical
    theta = jax.vmap(lambda b: model.from_physical(Fc=b[0], sigma2=b[1]))(beta)

    def resid(th, y):
        return model.simulate(th, v) - y

    y = f_true[None, :] + noise
    r = jax.vmap(resid)(theta, y)
    jac = jax.vmap(jax.jacfwd(resid))(theta, y)
    return theta, r, jac


def _coverage(model, theta, r, jac, method, truth):
    """Fraction of replicates whose 95 % interval holds the truth, per search coordinate."""
    n, p = jac.shape[1:]
    t = stats.t.ppf(0.975, n - p)
    hits = np.zeros(p)
    for th, ri, ji in zip(theta, r, jac):
        if method == "jacobian":
            cov = jacobian_covariance(ji, ri)[0]
        else:
            cov = hac_covariance(ji, ri, andrews_bandwidth(ji, ri))
        se = np.sqrt(np.diag(cov))
        hits += np.abs(th - truth) <= t * se
    return hits / len(theta)


def test_intervals_cover_the_truth_with_white_noise(rig_velocity):
    with jax.enable_x64(True):
        v = jnp.asarray(rig_velocity)
        noise = NOISE * jax.random.normal(jax.random.key(3), (REPLICATES, v.size))
        model, theta, r, jac = _coulomb_replicates(v, noise)
        truth = np.asarray(model.from_physical(Fc=FC, sigma2=SIGMA2))
    for method in ("jacobian", "hac"):
        cov = _coverage(model, theta, r, jac, method, truth)
        assert np.all((0.85 <= cov) & (cov <= 0.99)), (method, cov)


def test_correlated_noise_needs_the_newey_west_intervals(rig_velocity):
    """AR(1) noise (ρ = 0.9): the independent-residual intervals are far too narrow,
    Newey–West's hold 85–99 % of the truths."""
    with jax.enable_x64(True):
        v = jnp.asarray(rig_velocity)
        noise = _ar1(jax.random.key(4), (REPLICATES, v.size), 0.9, NOISE)
        model, theta, r, jac = _coulomb_replicates(v, noise)
        truth = np.asarray(model.from_physical(Fc=FC, sigma2=SIGMA2))
    naive = _coverage(model, theta, r, jac, "jacobian", truth)
    hac = _coverage(model, theta, r, jac, "hac", truth)
    assert np.all(naive < 0.75), naive
    assert np.all((0.85 <= hac) & (hac <= 0.99)), hac


def test_the_public_path_gives_the_replicate_intervals(rig_velocity):
    """parameter_uncertainty(fit, data) on one replicate equals the estimators above."""
    with jax.enable_x64(True):
        v = jnp.asarray(rig_velocity)
        # the replicates' shape (its compiled programs reused); replicate 0 is checked
        noise = _ar1(jax.random.key(5), (REPLICATES, v.size), 0.9, NOISE)
        model, theta, r, jac = _coulomb_replicates(v, noise)
        f = np.asarray(model.simulate(jnp.asarray(theta[0]), v)) - r[0]   # r = prediction - data
        fit = _fit(model, theta[0], rig_velocity, 1 / 128)
        u = parameter_uncertainty(fit, (rig_velocity, f, 1 / 128), method=("hac", "jacobian"))
    bw = andrews_bandwidth(jac[0], r[0])
    np.testing.assert_allclose(u.cov_theta["hac"], hac_covariance(jac[0], r[0], bw), rtol=1e-8)
    np.testing.assert_allclose(u.bandwidth, bw, rtol=1e-12)
    assert u.default == "hac" and u.lag1 > 0.8


# ------------------------------------------------------------------- not identifiable
def test_stiffness_without_presliding_is_not_a_confident_number():
    """LuGre on a record that never slows down (|v| >= 5 mm/s except at sharp reversals):
    σ0 is not determined; its interval must cover the box (or be strongly correlated)."""
    with jax.enable_x64(True):
        # a float64 scalar (as a fit holds dt), not a weakly typed Python float: the reference
        # Jacobian below reuses the rollout the prediction band compiled
        dt = np.float64(1e-3)
        t = np.arange(4000) * dt
        v = 0.05 * np.sign(np.sin(2 * np.pi * 1.0 * t)) * (1 + 0.5 * np.abs(np.sin(2 * np.pi * 0.3 * t)))
        model = models.LuGre()
        box = model.search_box(None, v, 50 * np.sign(v) + 300 * v)
        theta = model.from_physical(sigma0=1e7, sigma1=300.0, sigma2=300.0, Fc=50.0, Fs=60.0, vs=0.01)
        f = np.asarray(model.simulate(theta, v, dt)) + np.random.default_rng(0).standard_normal(v.size)
        fit = _fit(model, theta, v, dt, box=box)
        u = parameter_uncertainty(fit, (v, f, dt), method=("hac", "jacobian"))
    i = u.names.index("sigma0")
    loose = set(u.covers_box()) | {a for a, b, _ in u.strongly_correlated(0.95)} \
        | {b for a, b, _ in u.strongly_correlated(0.95)}
    assert "sigma0" in loose, "\n".join(u.format())
    # and the well-excited sliding parameters are confident
    se = u.stderr()
    assert se["Fc"] < 0.05 * 50.0 and se["sigma2"] < 0.1 * 300.0, se
    assert u.estimate[i] == pytest.approx(1e7)
    # the band moves the undetermined parameters over their box, not by their linearised ±1e9:
    # on a slow sweep (where Fs and vs act) it stays within the friction levels the box allows
    fit = fit.replace(uncertainty=u)
    with jax.enable_x64(True):
        slow = np.linspace(-0.02, 0.02, 400)
        y, lo, hi = fit.prediction_interval(slow, 0.95)
        cols = np.asarray(jax.jacfwd(lambda th: model.simulate(th, slow, dt))(jnp.asarray(fit.theta)))
    raw = np.sqrt(np.einsum("ta,ab,tb->t", cols, u.cov_theta["hac"], cols))
    assert raw.max() > 1e4                      # uncapped: meaningless
    assert (hi - lo).max() / 2 < 3 * 86.96      # capped: below 3 × the box's largest Coulomb level


def test_singular_direction_is_regularised_not_dropped():
    """Two identical columns: a pseudo-inverse would give them a finite, confident
    variance; the regularised inverse gives a huge one and correlation −1."""
    rng = np.random.default_rng(6)
    a = rng.standard_normal(500)
    jac = np.stack([a, a, rng.standard_normal(500)], axis=1)
    cov, s2, rank = jacobian_covariance(jac, rng.standard_normal(500))
    assert rank == 2
    assert cov[0, 0] > 1e6 * cov[2, 2]
    assert cov[0, 1] / np.sqrt(cov[0, 0] * cov[1, 1]) < -0.999


# ------------------------------------------------------------------- API and files
def _assert_same_intervals(got: dict, want: dict) -> None:
    """``{name: (lo, hi)}`` equal name by name (pytest >= 9.2's approx refuses nested dicts)."""
    assert got.keys() == want.keys()
    for name, bounds in want.items():
        np.testing.assert_allclose(got[name], bounds, rtol=1e-6, err_msg=name)


def test_fit_api_summary_and_round_trip(tmp_path, rig_velocity):
    with jax.enable_x64(True):
        model = models.Coulomb()
        v = rig_velocity
        f = FC * np.tanh(v / model.v_eps) + SIGMA2 * v + NOISE * np.random.default_rng(7).standard_normal(v.size)
        fit = _fit(model, model.from_physical(**model.fit_least_squares(v, f)), v, 1 / 128, n_train=1600)
        fit = fit.replace(uncertainty=parameter_uncertainty(fit, (v, f, 1 / 128), method=(
            "hac", "jacobian", "block_bootstrap"), key=0))
        assert set(fit.stderr) == {"Fc", "sigma2"}
        iv = fit.intervals(0.95)
        assert iv["Fc"][0] < FC < iv["Fc"][1]
        assert fit.intervals(0.99)["Fc"][0] < iv["Fc"][0]
        assert fit.correlation.shape == (2, 2) and fit.correlation[0, 0] == pytest.approx(1.0)
        text = fit.summary()
        assert "uncertainty (hac" in text and "se jacobian" in text
        fit.save(tmp_path / "f.npz")
        back = load_fit(tmp_path / "f.npz")
        assert isinstance(back.uncertainty, ParameterUncertainty)
        _assert_same_intervals(back.intervals(0.9), fit.intervals(0.9))
        np.testing.assert_allclose(back.uncertainty.cov["block_bootstrap"],
                                   fit.uncertainty.cov["block_bootstrap"])
        assert back.summary() == text
        # prediction band on held-out samples (noise + parameter part)
        y, lo, hi = prediction_interval(fit, v[1600:], 0.95)
        inside = np.mean((f[1600:] >= lo) & (f[1600:] <= hi))
        assert 0.9 < inside <= 1.0
        with pytest.raises(ValueError, match="level"):
            fit.intervals(95)
        with pytest.raises(ValueError, match="no 'nope' covariance"):
            fit.intervals(0.95, "nope")


def test_bad_requests_fail_clearly(rig_velocity):
    model = models.Coulomb()
    fit = _fit(model, [100.0, 3.0], rig_velocity, 1 / 128)
    data = (rig_velocity, np.ones_like(rig_velocity), 1 / 128)
    with pytest.raises(ValueError, match="method must be"):
        parameter_uncertainty(fit, data, method="bayes")
    with pytest.raises(ValueError, match="needs key"):
        parameter_uncertainty(fit, data, method="block_bootstrap")
    with pytest.raises(ValueError, match="no parameter uncertainty"):
        fit.stderr
    elman = Fit(model=models.Elman(neurons=2), theta=np.zeros(models.Elman(neurons=2).num_params),
                velocity_scaler=models.Scaler(lo=-1.0, hi=1.0), friction_scaler=models.Scaler(lo=-1.0, hi=1.0),
                dt=0.01, n_train=10, n_samples=20, metrics={})
    with pytest.raises(ValueError, match="black-box"):
        parameter_uncertainty(elman, data)


def test_identify_attaches_uncertainty_and_plausibility(rig_velocity, tmp_path):
    """The hook: a physical identify returns a fit with intervals (computed on first
    use), the plausibility diagnostics, and both in the saved file."""
    from jaxfric import identify
    from jaxfric.optim import MAPSO, MAPSONMDS, NelderMead

    with jax.enable_x64(True):
        model = models.Coulomb()
        v = rig_velocity
        f = FC * np.tanh(v / model.v_eps) + SIGMA2 * v + NOISE * np.random.default_rng(8).standard_normal(v.size)
        solver = MAPSONMDS(mapso=MAPSO(lattice_size=3, num_generations=5),
                           nelder_mead=NelderMead(max_steps=200, max_evals=200))
        fit = identify(model, (v, f, 1 / 128), key=0, solver=solver)
        assert fit.diagnostics["implausible"] == []
        assert fit._uncertainty.pending          # not computed until asked
        iv = fit.intervals()
        assert iv["Fc"][0] < FC < iv["Fc"][1]
        fit.save(tmp_path / "f.npz")
        _assert_same_intervals(load_fit(tmp_path / "f.npz").intervals(), iv)


@pytest.mark.slow
@pytest.mark.parametrize("model, params", [
    (models.Dahl(), dict(sigma0=2e4, Fc=40.0)),
    (models.GMS(), dict(k1=3e4, k2=1e4, k3=3e3, alpha1=0.5, alpha2=0.3, alpha3=0.2, C=50.0, Fc=40.0,
                        Fs=55.0, vs=0.01, sigma2=200.0)),
    (models.Cylinder(), dict(F_pr=10.0, f_cfr=5e-5, K_brk=1.5, vs=0.01, sigma2=200.0)),
    (models.Stribeck(asymmetric=True, offset=True),
     dict(Fc_pos=40.0, Fc_neg=35.0, Fs_pos=50.0, Fs_neg=45.0, vs=0.01, sigma2_pos=200.0,
          sigma2_neg=220.0, F_off=2.0)),
], ids=lambda x: type(x).__name__ if isinstance(x, models.AbstractFrictionModel) else "")
def test_every_physical_model_gets_finite_intervals_from_a_frictiondata(model, params):
    """Each physical family through the public path, from a FrictionData (the Cylinder
    reads its chamber pressures from it), fitted at the truth of a lightly noisy record:
    positive finite standard errors and finite intervals around the estimate."""
    from jaxfric import FrictionData

    with jax.enable_x64(True):
        dt, n = 2e-3, 1500
        t = np.arange(n) * dt
        v = 0.05 * np.sin(2 * np.pi * 0.8 * t) + 0.02 * np.sin(2 * np.pi * 2.1 * t)
        p1, p2 = 3e5 + 1e5 * np.sin(2 * np.pi * 0.3 * t), 2e5 + 5e4 * np.cos(2 * np.pi * 0.5 * t)
        theta = model.from_physical(**params)
        x = model.inputs_from(FrictionData.from_arrays(v, v, dt, p1=p1, p2=p2), n)
        f = np.asarray(model.simulate(theta, v, dt, x)) + 0.5 * np.random.default_rng(9).standard_normal(n)
        data = FrictionData.from_arrays(v, f, dt, n_train=1200, p1=p1, p2=p2)
        fit = _fit(model, theta, v, dt, n_train=1200)
        u = parameter_uncertainty(fit, data, method=("hac", "jacobian"))
    assert u.n == 1200 and len(u.names) == model.num_params
    se = np.array(list(u.stderr("jacobian").values()))
    assert np.all(np.isfinite(se)) and np.all(se > 0)
    est = dict(zip(u.names, u.estimate))
    for k, (lo, hi) in u.intervals(0.95, "jacobian").items():
        assert np.isfinite(lo) and np.isfinite(hi) and lo < est[k] < hi, k


def test_box_capping_keeps_a_determined_combination():
    """Two nearly collinear parameters: their sum is determined, each alone is not. The
    band's covariance shrinks the free direction to the box and keeps the sum's variance."""
    rng = np.random.default_rng(10)
    a = rng.standard_normal(400)
    jac = np.stack([a, a + 1e-7 * rng.standard_normal(400), rng.standard_normal(400)], axis=1)
    r = 0.1 * rng.standard_normal(400)
    cov = jacobian_covariance(jac, r)[0]
    u = ParameterUncertainty(names=("a", "b", "c"), kinds=("linear",) * 3, estimate=np.zeros(3),
                             theta=np.zeros(3), lower=-np.ones(3), upper=np.ones(3),
                             cov_theta={"jacobian": cov}, cov={"jacobian": cov}, n=400, dof=397,
                             s2=0.01, rank=2, bandwidth=0.0, default="jacobian")
    capped = u.box_capped()
    t = u.t_quantile(0.95)
    assert cov[0, 0] * t**2 > 1e6 and capped[0, 0] * t**2 <= 1.01
    s = np.array([1.0, 1.0, 0.0])
    assert s @ capped @ s == pytest.approx(s @ cov @ s, rel=1e-3)   # vs 1e6 times for a marginal cap
    np.testing.assert_allclose(capped[2, 2], cov[2, 2], rtol=1e-3)


def test_a_parameter_the_data_do_not_touch_is_undetermined_by_every_method():
    """A Jacobian whose third column is zero (a stiffness the record never excites) and
    AR(1) residuals: the Newey–West and block-bootstrap standard errors of that parameter
    are the Jacobian covariance's regularised one (huge), not the ~0 their vanishing
    scores alone give, and the two determined parameters keep their sandwich values."""
    rng = np.random.default_rng(13)
    n = 2000
    jac = np.stack([rng.standard_normal(n), np.sin(np.arange(n) * 0.01), np.zeros(n)], axis=1)
    e = rng.standard_normal(n)
    r = np.empty(n)
    r[0] = e[0]
    for i in range(1, n):
        r[i] = 0.8 * r[i - 1] + e[i]
    cov_j = jacobian_covariance(jac, r)[0]
    cov_h = hac_covariance(jac, r, 20.0)
    cov_b = block_bootstrap_covariance(jac, r, 0, 21, replicates=100)
    assert cov_j[2, 2] > 1e9
    for cov in (cov_h, cov_b):
        assert cov[2, 2] == pytest.approx(cov_j[2, 2], rel=1e-6)
    ref = hac_covariance(jac[:, :2], r, 20.0) * (n - 2) / (n - 3)  # the determined pair alone (p = 2)
    np.testing.assert_allclose(cov_h[:2, :2], ref, rtol=1e-6)


def test_box_capping_never_gives_a_negative_variance():
    """A sandwich covariance rounded to an indefinite matrix (eigenvalues 1e-4, -1e-6 in
    box units): the capped covariance is positive semi-definite, the negative direction
    given no variance, so no band variance j Σ jᵀ is negative."""
    q, _ = np.linalg.qr(np.random.default_rng(12).standard_normal((2, 2)))
    cov = (q * np.array([1e-4, -1e-6])) @ q.T
    u = ParameterUncertainty(names=("a", "b"), kinds=("linear",) * 2, estimate=np.zeros(2),
                             theta=np.zeros(2), lower=-np.ones(2), upper=np.ones(2),
                             cov_theta={"hac": cov}, cov={"hac": cov}, n=400, dof=398,
                             s2=0.01, rank=2, bandwidth=3.0, default="hac")
    capped = u.box_capped()
    lam = np.linalg.eigvalsh(capped)
    assert lam.min() >= -1e-18 and lam.max() == pytest.approx(1e-4, rel=1e-9)
    j = q[:, 1]  # along the negative direction: the uncapped variance would be -1e-6
    assert j @ cov @ j < 0 and j @ capped @ j >= -1e-18


def test_several_training_records_pool_their_residuals():
    """A list of records: residuals of each, no Newey–West lag across the boundary, and
    the independent-residual covariance is the OLS one of the stacked samples."""
    from jaxfric import FrictionData

    with jax.enable_x64(True):
        model = models.Coulomb()
        rng = np.random.default_rng(11)
        recs, vs, fs = [], [], []
        for k in range(2):  # 2 x 1000 samples: the shapes of the rig record's tests above
            v = 0.01 * np.sin(np.arange(1000) * 0.03 + k)
            f = 30 * np.tanh(v / model.v_eps) + 500 * v + rng.standard_normal(1000)
            recs.append(FrictionData.from_arrays(v, f, 0.01, name=f"r{k}"))
            vs.append(v)
            fs.append(f)
        v, f = np.concatenate(vs), np.concatenate(fs)
        fit = _fit(model, model.from_physical(**model.fit_least_squares(v, f)), v, 0.01)
        u = parameter_uncertainty(fit, recs)
    assert u.segments == (1000, 1000) and u.n == 2000 and u.default == "hac"
    x = np.stack([np.tanh(v / model.v_eps), v], axis=1)
    r = f - x @ np.linalg.lstsq(x, f, rcond=None)[0]
    np.testing.assert_allclose(u.cov["jacobian"], r @ r / 1998 * np.linalg.inv(x.T @ x), rtol=1e-6)


def test_a_same_shaped_fit_reuses_the_compiled_linearisation():
    """The residuals, Jacobian and physical values are one compiled program whose records
    are traced inputs: a second fit of the same model on another record of the same
    length compiles nothing; a new record length compiles that one program, not one
    per operation."""
    rng = np.random.default_rng(3)
    compiles = []

    def listen(event, *args, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            compiles.append(event)

    def one(model, n, shift):
        v = np.sin(np.linspace(0.0, 12.0, n)) * 0.05
        theta = model.from_physical(Fc=20.0 + shift, sigma2=300.0)
        f = 20.0 * np.tanh(v / model.v_eps) + 300.0 * v + rng.standard_normal(n)
        before = len(compiles)
        u = parameter_uncertainty(_fit(model, theta, v, 1e-3), (v, f, 1e-3))
        return u, len(compiles) - before

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        first, _ = one(models.Coulomb(), 703, 0.0)
        second, n_second = one(models.Coulomb(), 703, 1.0)
        _, n_new = one(models.Coulomb(v_eps=2e-3), 701, 0.0)
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
    assert n_second == 0 and 1 <= n_new <= 2
    assert first.estimate[0] != second.estimate[0]  # the new record and theta were used
