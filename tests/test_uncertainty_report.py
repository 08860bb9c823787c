"""report.md / results.json show each physical fit's intervals, correlations, the
prediction band with its measured coverage, and the plausibility warnings."""

import json

import jax
import numpy as np
import pytest

from jaxfric import Fit, FrictionData, models, report
from jaxfric.plausibility import PlausibilityWarning
from jaxfric.uncertainty import assess_fit


def test_report_shows_intervals_band_coverage_and_warnings(tmp_path):
    with jax.enable_x64(True):
        dt, n = 1e-3, 3000
        t = np.arange(n) * dt
        v = 0.2 * np.clip(4 * np.sin(2 * np.pi * 0.5 * t), -1, 1)
        rng = np.random.default_rng(0)
        coul = models.Coulomb()
        f = 20 * np.tanh(v / coul.v_eps) + 200 * v + rng.standard_normal(n)
        data = FrictionData.from_arrays(v, f, dt, 0.8)
        theta = np.asarray(coul.from_physical(**coul.fit_least_squares(v[:2400], f[:2400])))
        members = theta + np.array([[0.0, 0.0], [0.05, 0.0], [-0.05, 0.001]])   # three close optima
        good = Fit(model=coul, theta=theta, velocity_scaler=None, friction_scaler=None, dt=dt, n_train=2400,
                   n_samples=n, metrics={}, ensemble={"theta": members, "J": [0.1, 0.1, 0.1], "best": 0})
        strib = models.Stribeck()
        bad = Fit(model=strib, theta=np.asarray(strib.from_physical(Fc=20.0, Fs=80.0, vs=1e-4, sigma2=200.0)),
                  velocity_scaler=None, friction_scaler=None, dt=dt, n_train=2400, n_samples=n, metrics={})
        good = assess_fit(good, data)
        with pytest.warns(PlausibilityWarning, match="Stribeck peak"):
            bad = assess_fit(bad, data)
        report.write_report(tmp_path, data, {"coulomb": good, "stribeck": bad}, title="t", save_models=False)
    md = (tmp_path / "report.md").read_text()
    res = json.loads((tmp_path / "results.json").read_text())["models"]
    assert "Parameter uncertainty (95% intervals" in md and "se (Newey–West)" in md
    assert "| | Fc | sigma2 |" in md and "| Fc | +1.00 |" in md
    band = res["coulomb"]["uncertainty"]["band"]
    assert 0.85 < band["valid"] <= 1.0 and 0.85 < band["train"] <= 1.0
    assert f"holds {band['train']:.1%} of the training samples" in md
    eb = res["coulomb"]["uncertainty"]["ensemble_band"]
    lo = np.min([coul.simulate(m, v) for m in members], axis=0)
    hi = np.max([coul.simulate(m, v) for m in members], axis=0)
    assert eb["valid"] == pytest.approx(np.mean((f[2400:] >= lo[2400:]) & (f[2400:] <= hi[2400:])))
    assert eb["valid"] < 0.3 and "3 members' min–max band" in md
    # the plausibility rule's verdict is the parameter's verdict, in its row and with its reason
    assert "| Fs | 80 |" in md and "| not identifiable | **not identifiable** |" in md
    assert "- Fs: Fs/Fc = 4: a Stribeck peak" in md and "(plausibility rule stribeck_spike)" in md
    assert res["stribeck"]["uncertainty"]["implausible"][0]["name"] == "Fs"
    assert res["coulomb"]["fit"]["uncertainty"]["names"] == ["Fc", "sigma2"]


def test_cli_prints_the_intervals(tmp_path, monkeypatch, capsys):
    from jaxfric.cli import main

    p = tmp_path / "pairs.csv"
    t = np.arange(300) / 100.0
    v = 0.01 * np.sin(2 * np.pi * 0.5 * t)
    f = 30 * np.tanh(v / 1e-4) + 500 * v + np.random.default_rng(1).standard_normal(t.size)
    p.write_text("t,v,F\n" + "\n".join(f"{a},{b},{c}" for a, b, c in zip(t, v, f)))
    monkeypatch.chdir(tmp_path)
    assert main(["identify", str(p), "--velocity-col", "v", "--friction-col", "F", "--time-col", "t",
                 "--model", "coulomb", "--quick", "--no-cache", "--out", str(tmp_path / "r")]) == 0
    out = capsys.readouterr()
    line = next(s for s in (out.out + out.err).splitlines() if "95% intervals (hac)" in s)
    assert "Fc " in line and "sigma2 " in line
    assert "Parameter uncertainty" in (tmp_path / "r" / "report.md").read_text()
