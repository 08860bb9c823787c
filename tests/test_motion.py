"""Motion identification (docs/algorithms.md §13.2): per-sample friction steps, the forward
model against scipy's ODE solver, k-step prediction, and parameter recovery."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from jaxfric import models
from jaxfric.fit import predict
from jaxfric.models import Scaler
from jaxfric.motion import (MotionData, friction_step, identify_motion, k_step_positions,
                            load_motion_fit, simulate_motion, track_states)
from jaxfric.optim import MAPSO, MAPSONMDS, NelderMead


def _velocity(n=400, dt=1e-3):
    """Reversals and a 40-sample standstill (v exactly 0), where stick/slip states differ."""
    t = np.arange(n) * dt
    v = 0.02 * np.sin(2 * np.pi * 3 * t) + 0.005 * np.sin(2 * np.pi * 11 * t + 0.3)
    v[200:240] = 0.0
    return v


def _models_and_thetas():
    rng = np.random.default_rng(0)
    lugre = models.LuGre()
    el = models.Elman(neurons=5, context_weight_bound=1.0)
    elf = models.ElmanFull(neurons=4)
    out = [
        (lugre, lugre.from_physical(sigma0=1e6, sigma1=300.0, sigma2=500.0, Fc=20.0, Fs=30.0, vs=5e-3)),
        (models.Dahl(viscous=True), models.Dahl(viscous=True).from_physical(sigma0=2e5, Fc=15.0, sigma2=100.0)),
        (models.Coulomb(), models.Coulomb().from_physical(Fc=20.0, sigma2=200.0)),
        (models.Stribeck(), models.Stribeck().from_physical(Fc=20.0, Fs=35.0, vs=4e-3, sigma2=150.0)),
    ]
    # §13.1 asymmetric / offset forms and GMS (§8.4): every direction-dependent level differs
    la = models.LuGre(asymmetric=True, offset=True)
    da = models.Dahl(viscous=True, asymmetric=True, offset=True)
    do = models.Dahl(offset=True)
    g = models.GMS(num_elements=3)
    ga = models.GMS(num_elements=3, asymmetric=True, offset=True)
    gms = dict(k1=2e5, k2=6e4, k3=1e4, alpha1=0.5, alpha2=0.3, alpha3=0.2, C=30.0, vs=4e-3)
    out += [
        (la, la.from_physical(sigma0=1e6, sigma1=300.0, sigma2_pos=500.0, sigma2_neg=350.0, Fc_pos=20.0,
                              Fc_neg=14.0, Fs_pos=30.0, Fs_neg=25.0, vs=5e-3, F_off=-3.0)),
        (da, da.from_physical(sigma0=2e5, Fc_pos=15.0, Fc_neg=9.0, sigma2_pos=100.0, sigma2_neg=60.0,
                              F_off=2.5)),
        (do, do.from_physical(sigma0=2e5, Fc=15.0, F_off=-1.5)),
        (g, g.from_physical(Fc=20.0, Fs=30.0, sigma2=150.0, **gms)),
        (ga, ga.from_physical(Fc_pos=20.0, Fc_neg=13.0, Fs_pos=30.0, Fs_neg=22.0, sigma2_pos=150.0,
                              sigma2_neg=90.0, F_off=4.0, **gms)),
        (models.Coulomb(asymmetric=True, offset=True), models.Coulomb(asymmetric=True, offset=True)
         .from_physical(Fc_pos=20.0, Fc_neg=12.0, sigma2_pos=200.0, sigma2_neg=120.0, F_off=3.0)),
    ]
    for m in (el, elf):
        lo, hi = m.bounds()
        out.append((m, rng.uniform(lo, hi) * 0.5))
    return out


def _model_id(x):
    if not isinstance(x, models.AbstractFrictionModel):
        return "theta"
    flags = "".join(f"-{f}" for f in ("asymmetric", "offset") if getattr(x, f, False))
    return type(x).__name__ + flags


@pytest.mark.parametrize("model,theta", _models_and_thetas(), ids=_model_id)
def test_step_reproduces_predict(model, theta):
    """Stepping output/update sample by sample gives Fit.predict's free run (same recursion)."""
    with jax.enable_x64(True):
        v = _velocity()
        theta = jnp.asarray(theta, jnp.float64)
        scalers = (Scaler.fit(v), Scaler(lo=np.float64(-40.0), hi=np.float64(40.0))) \
            if model.needs_scaling else (None, None)
        ref = np.asarray(predict(model, theta, scalers, v, 1e-3))
        step = friction_step(model, scalers)
        s = step.init(theta, jnp.asarray(v[0]), 1e-3)
        # each sample's output and update as one compiled call (op by op, the 400 samples
        # of a GMS took 5 s)
        output, update = eqx.filter_jit(step.output), eqx.filter_jit(step.update)
        got = []
        for vk in v:
            got.append(float(output(theta, s, vk, 1e-3)))
            s = update(theta, s, vk, 1e-3)
        np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-9 * np.max(np.abs(ref)))


def test_stateful_model_without_step_is_refused():
    with pytest.raises(ValueError, match="scaled data"):
        friction_step(models.Elman(neurons=3))


def _ode_reference(force_fn, mass, p, x0, v0, t_end, n_out):
    """scipy's solve_ivp of the continuous LuGre mechanics (fine tolerance)."""
    s0, s1, s2, fc, fs, vs = p

    def rhs(t, y):
        x, v, z = y
        g = fc + (fs - fc) * np.exp(-(v / vs) ** 2)
        zd = v - s0 * abs(v) / g * z
        f = s0 * z + s1 * zd + s2 * v
        return [v, (force_fn(t) - f) / mass, zd]

    g0 = fc + (fs - fc) * np.exp(-(v0 / vs) ** 2)
    t_eval = np.linspace(0, t_end, n_out + 1)
    sol = solve_ivp(rhs, (0, t_end), [x0, v0, np.sign(v0) * g0 / s0], method="Radau",
                    rtol=1e-10, atol=1e-13, t_eval=t_eval)
    return sol.y[0], sol.y[1]


def test_forward_model_converges_to_solve_ivp():
    """The discrete forward model approaches scipy's ODE solution at first order in h,
    through stick phases and reversals (LuGre, a smooth friction model)."""
    p = (2e4, 150.0, 40.0, 10.0, 15.0, 5e-3)
    mass, t_end = 2.0, 1.0

    def force_fn(t):
        return 18.0 * np.sin(2 * np.pi * 1.5 * t)

    model = models.LuGre()
    x_ref, v_ref = _ode_reference(force_fn, mass, p, 0.0, 0.0, t_end, 50)
    errs = []
    with jax.enable_x64(True):
        theta = model.from_physical(sigma0=p[0], sigma1=p[1], sigma2=p[2], Fc=p[3], Fs=p[4], vs=p[5])
        step = friction_step(model)
        for n in (2000, 4000, 8000):
            dt = t_end / n
            t = np.arange(n + 1) * dt
            out = simulate_motion(step, theta, mass, force_fn(t), dt, 0.0, 0.0)
            x = np.asarray(out["x"])[:: n // 50]
            errs.append(np.max(np.abs(x - x_ref)))
    scale = np.ptp(x_ref)
    assert scale > 0.01  # the mass did move, through reversals
    assert errs[-1] < 2e-3 * scale
    assert errs[0] / errs[1] > 1.6 and errs[1] / errs[2] > 1.6  # first order


def test_forward_model_is_stable_for_stiff_friction():
    """Stiff bristles (sigma0 h^2 / m = 100 at h = 1 ms) and a near-hard sign: no blow-up,
    the mass sticks under a force ramped to below breakaway, and the stuck displacement
    equals that of a 100x finer step."""
    with jax.enable_x64(True):
        lugre = models.LuGre()
        theta = lugre.from_physical(sigma0=1e8, sigma1=1e4, sigma2=100.0, Fc=20.0, Fs=30.0, vs=1e-3)
        step = friction_step(lugre)

        def stuck(dt):
            n = int(round(1.0 / dt))
            force = np.minimum(np.arange(n) * dt / 0.5, 1.0) * 25.0  # below Fs = 30 N
            x = np.asarray(simulate_motion(step, theta, 1.0, force, dt, 0.0, 0.0)["x"])
            assert np.all(np.isfinite(x))
            return x[-1]

        coarse, fine = stuck(1e-3), stuck(1e-5)
        assert 0 < coarse < 1e-6  # bristle deflection ~ 25 N / sigma0, no sliding
        assert abs(coarse - fine) < 0.01 * fine
        coul = models.Coulomb(v_eps=1e-5)
        th = coul.from_physical(Fc=20.0, sigma2=10.0)
        # both runs 3 s long: one compiled program (the creep settles within milliseconds)
        out = simulate_motion(friction_step(coul), th, 1.0, np.full(3000, 10.0), 1e-3, 0.0, 0.0)
        assert np.max(np.abs(np.asarray(out["v"]))) < 1e-5  # sticks (creep below v_eps)
        out = simulate_motion(friction_step(coul), th, 1.0, np.full(3000, 30.0), 1e-3, 0.0, 0.0)
        # slides towards the viscous terminal speed (30 - 20) / 10 = 1 m/s, e-folding 0.1 s
        np.testing.assert_allclose(float(out["v"][-1]), 1.0 - np.exp(-10 * 3.0), rtol=2e-3)


def test_k_step_matches_free_run_from_each_start():
    """k-step prediction from the states of a free run reproduces that free run."""
    with jax.enable_x64(True):
        model = models.Stribeck()
        theta = model.from_physical(Fc=10.0, Fs=14.0, vs=3e-3, sigma2=50.0)
        step = friction_step(model)
        t = np.arange(600) * 1e-3
        u = 15 * np.sin(2 * np.pi * 2 * t)
        out = simulate_motion(step, theta, 1.5, u, 1e-3, 0.0, 0.0)
        states = track_states(step, theta, out["v"], 1e-3)
        xk = k_step_positions(step, theta, 1.5, u, 1e-3, out["x"], out["v"], states, 7)
        np.testing.assert_allclose(np.asarray(xk), np.asarray(out["x"])[7:], atol=1e-12)
        lugre = models.LuGre()
        th = lugre.from_physical(sigma0=1e5, sigma1=200.0, sigma2=50.0, Fc=10.0, Fs=14.0, vs=3e-3)
        st = friction_step(lugre)
        out = simulate_motion(st, th, 1.5, u, 1e-3, 0.0, 0.0)
        states = track_states(st, th, out["v"], 1e-3)
        xk = k_step_positions(st, th, 1.5, u, 1e-3, out["x"], out["v"], states, 5)
        np.testing.assert_allclose(np.asarray(xk), np.asarray(out["x"])[5:], atol=1e-12)


def _recording(model, theta, mass, n=3000, dt=1e-3, offset=0.0):
    t = np.arange(n) * dt
    u = 30 * np.sin(2 * np.pi * 1.3 * t) + 12 * np.sin(2 * np.pi * 3.1 * t + 1.0)
    out = simulate_motion(friction_step(model), jnp.asarray(theta), mass, u - offset, dt, 0.0, 0.0)
    return u, np.asarray(out["x"]), np.asarray(out["v"])


@pytest.mark.slow
def test_identify_motion_recovers_parameters(tmp_path):
    """Noise-free simulated motion: Coulomb + viscous friction, mass and offset recovered
    within 2 % from force and position alone (free-run position error)."""
    with jax.enable_x64(True):
        model = models.Coulomb(v_eps=1e-3)
        truth = dict(Fc=12.0, sigma2=60.0)
        theta = model.from_physical(**truth)
        u, x, v = _recording(model, theta, 2.5, n=2000, offset=3.0)
        data = MotionData.from_arrays(u, x, 1e-3)
        solver = MAPSONMDS(mapso=MAPSO(lattice_size=4, num_generations=30),
                           nelder_mead=NelderMead(max_steps=600, max_evals=600))
        fit = identify_motion(model, data, key=0, mass=(0.5, 10.0), solver=solver,
                              fit_offset=True, box={"Fc": (2.0, 40.0), "sigma2": (5.0, 500.0)},
                              data_bounds=False, dtype=jnp.float64)
        got = {k: float(v) for k, v in fit.params.items()}
        for k, val in truth.items():
            assert abs(got[k] - val) <= 0.02 * abs(val), (k, got[k], val)
        assert abs(fit.mass - 2.5) <= 0.05
        assert abs(fit.offset - 3.0) <= 0.06
        assert fit.metrics["valid"]["fit_percent"] > 98.0
        fit.save(tmp_path / "m.npz")
        back = load_motion_fit(tmp_path / "m.npz")
        assert back.mass == fit.mass
        np.testing.assert_array_equal(back.simulate(u[:50], 0.0, 0.0)["x"], fit.simulate(u[:50], 0.0, 0.0)["x"])


def test_identify_motion_bad_input_fails_fast():
    u = np.sin(np.arange(200) * 0.05)
    x = np.cumsum(u) * 1e-3
    with pytest.raises(ValueError, match="same length"):
        MotionData.from_arrays(u, x[:-1], 1e-3)
    bad = x.copy()
    bad[5] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        MotionData.from_arrays(u, bad, 1e-3)
    with pytest.raises(ValueError, match="mass"):
        identify_motion("coulomb", (u, x, 1e-3), key=0, mass=-1.0)
    with pytest.raises(ValueError, match="error must be"):
        identify_motion("coulomb", (u, x, 1e-3), key=0, mass=1.0, error="force")


@pytest.mark.slow
@pytest.mark.parametrize("name", ["elman"])
def test_identify_motion_runs_for_dynamic_models(name, tmp_path):
    """The Elman network (context, scalers without a friction signal) runs
    inside the mechanics, give finite metrics, and survive save/load."""
    model = models.Coulomb(v_eps=1e-3)
    theta = model.from_physical(Fc=12.0, sigma2=60.0)
    with jax.enable_x64(True):
        u, x, _ = _recording(model, theta, 2.5, n=600)
    solver = MAPSONMDS(mapso=MAPSO(lattice_size=3, num_generations=3),
                       nelder_mead=NelderMead(max_steps=20, max_evals=20))
    opts = {"neurons": 3} if name == "elman" else None
    fit = identify_motion(name, (u, x, 1e-3), key=1, mass=2.5, solver=solver, model_options=opts)
    for w in ("train", "valid", "train_kstep", "valid_kstep"):
        assert np.isfinite(fit.metrics[w]["rmse_mm"])
    fit.save(tmp_path / "f.npz")
    back = load_motion_fit(tmp_path / "f.npz")
    np.testing.assert_array_equal(back.simulate(u[:40], 0.0, 0.0)["x"], fit.simulate(u[:40], 0.0, 0.0)["x"])


@pytest.mark.slow
def test_cli_identify_motion(tmp_path):
    from jaxfric.cli import main

    model = models.Coulomb(v_eps=1e-3)
    with jax.enable_x64(True):
        u, x, _ = _recording(model, model.from_physical(Fc=12.0, sigma2=60.0), 2.5, n=600)
    path = tmp_path / "m.csv"
    np.savetxt(path, np.c_[np.arange(600) * 1e-3, u / 10, x], delimiter=",", header="t,volt,x", comments="")
    rc = main(["identify-motion", str(path), "--force-col", "volt", "--force-gain", "10", "--x-col", "x",
               "--time-col", "t", "--mass", "2.5", "--model", "coulomb", "--quick", "--quiet",
               "--window", "0.2", "--no-cache", "--out", str(tmp_path / "r")])  # 0.6 s: 3 windows
    assert rc == 0
    assert (tmp_path / "r" / "models" / "coulomb.npz").exists()
    assert "valid RMSE [mm]" in (tmp_path / "r" / "motion.md").read_text()
    assert main(["identify-motion", str(path), "--force-col", "volt", "--x-col", "x", "--time-col", "t",
                 "--quiet", "--no-cache", "--out", str(tmp_path / "r2")]) != 0  # no mass given



def test_cli_identify_motion_resamples_irregular_stamps_and_takes_a_position_unit(tmp_path, capsys):
    """Irregular time stamps (rows missing) are resampled onto a uniform grid and said even
    under --quiet (until 0.8.1 the median step was taken as if the stamps were uniform);
    --x-unit mm scales the position column (0.8.1 had no such option)."""
    from jaxfric.cli import main
    from jaxfric.motion import load_motion_fit

    model = models.Coulomb(v_eps=1e-3)
    with jax.enable_x64(True):
        u, x, _ = _recording(model, model.from_physical(Fc=12.0, sigma2=60.0), 2.5, n=600)
    keep = np.ones(600, bool)
    keep[[100, 101, 102, 350, 351]] = False  # gaps of 4 and 3 ms in a 1 ms record
    path = tmp_path / "m.csv"
    np.savetxt(path, np.c_[np.arange(600)[keep] * 1e-3, u[keep], 1e3 * x[keep]], delimiter=",",
               header="t,F,x_mm", comments="")
    capsys.readouterr()
    rc = main(["identify-motion", str(path), "--force-col", "F", "--x-col", "x_mm", "--x-unit", "mm",
               "--time-col", "t", "--mass", "2.5", "--model", "coulomb", "--quick", "--quiet",
               "--window", "0.2", "--no-cache", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert rc == 0, err
    assert "jaxfric: warning: time stamps are irregular" in err and "resampled linearly onto a uniform grid" in err
    fit = load_motion_fit(tmp_path / "r" / "models" / "coulomb.npz")
    assert fit.dt == pytest.approx(1e-3)
    assert fit.n_samples == 600  # 0 .. 599 ms on the 1 ms grid, the dropped rows interpolated
