"""One verdict per parameter (issue 44): the model's excitation rules, the plausibility
rules and the intervals are one analysis of a fit, and a parameter it finds not
identifiable never shows an interval as if it were one: not in ``Fit.summary()``, the
command line's lines, report.md, results.json, nor the saved fit file."""

import json
import re

import jax
import numpy as np
import pytest

from jaxfric import Fit, FrictionData, load_fit, models, report
from jaxfric.plausibility import PlausibilityWarning
from jaxfric.uncertainty import assess_fit, cli_lines

DT = 1e-3
#: A number in brackets: an interval, wherever it is printed.
INTERVAL = r"\[-?[\d.]+(?:e[-+]?\d+)?, -?[\d.]+(?:e[-+]?\d+)?\]"


@pytest.fixture(scope="module")
def flagged_fit():
    """An asymmetric LuGre with an offset on EMPS-like trapezoids: no pre-sliding, few
    standstill samples. The excitation rules flag sigma0, sigma1, Fs_pos, Fs_neg, vs
    and F_off, the offset rule flags F_off (a 7 N offset beside 17/23 N levels), yet a
    linearisation at the fit gives finite intervals for all ten."""
    t = np.arange(6000) * DT
    v = 0.2 * np.clip(4 * np.sin(2 * np.pi * 0.5 * t), -1, 1) * (0.6 + 0.4 * np.cos(2 * np.pi * 0.13 * t))
    model = models.LuGre(asymmetric=True, offset=True)
    with jax.enable_x64(True):
        theta = np.asarray(model.from_physical(sigma0=1e5, sigma1=300.0, sigma2_pos=170.0, sigma2_neg=240.0,
                                               Fc_pos=17.0, Fc_neg=23.0, Fs_pos=25.0, Fs_neg=30.0, vs=0.01,
                                               F_off=7.0), np.float64)
        f = np.asarray(model.simulate(theta, v, DT)) + np.random.default_rng(0).standard_normal(v.size)
        data = FrictionData.from_arrays(v, f, DT, 0.8)
        n = data.n_train
        fit = Fit(model=model, theta=theta, velocity_scaler=None, friction_scaler=None, dt=DT, n_train=n,
                  n_samples=v.size, metrics={},
                  diagnostics={"unidentifiable": [f"{m}: {m.reason}" for m in model.unidentifiable(v[:n])]})
        with pytest.warns(PlausibilityWarning, match="So F_off is not identifiable from these data"):
            fit = assess_fit(fit, data)
        assert fit.uncertainty is not None  # computed here, in float64
    return fit, data


def _flagged(fit):
    return {k for k, v in fit.verdicts().items() if not v["identifiable"]}


def _no_interval_for(text: str, names, skip=("box:", "Search box")) -> None:
    """No line of ``text`` that names a flagged parameter holds an interval (the search
    box's ranges, printed on their own line, are not intervals)."""
    for line in text.splitlines():
        if line.lstrip().startswith(skip):
            continue
        for cell in re.split(r", |\|", line):  # one parameter per cell or list item
            for name in names:
                if re.search(rf"(?<![\w]){name}(?![\w])", cell):
                    assert not re.search(INTERVAL, cell), (name, line)


def test_one_verdict_from_every_analysis(flagged_fit):
    fit, _ = flagged_fit
    verdicts = fit.verdicts()
    flagged = _flagged(fit)
    # the excitation rules and the offset rule, together
    assert {"sigma0", "sigma1", "Fs_pos", "Fs_neg", "vs", "F_off"} <= flagged
    assert {"Fc_pos", "Fc_neg"}.isdisjoint(flagged)
    assert any("plausibility rule offset_asymmetric" in r for r in verdicts["F_off"]["reasons"])
    assert any("pre-sliding" in r for r in verdicts["sigma0"]["reasons"])
    for name, v in verdicts.items():
        assert (v["interval"] is None) == (name in flagged), name
        assert v["identifiable"] == (not v["reasons"]), name
    # the linearisation alone would have given the flagged parameters finite intervals
    assert all(np.isfinite(fit.intervals()[k]).all() for k in flagged if k in fit.uncertainty.names)
    lo, hi = verdicts["Fc_pos"]["interval"]
    assert lo < 17.0 < hi


def test_summary_and_command_line_show_no_interval_for_a_flagged_parameter(flagged_fit):
    fit, _ = flagged_fit
    flagged = _flagged(fit)
    text = fit.summary()
    _no_interval_for(text, flagged)
    for name in flagged:
        assert re.search(rf"^  {name}\s.*   not identifiable$", text, re.M), name
        assert re.search(rf"{name}=\S+ \[not identifiable\]", text), name
    assert re.search(rf"^  Fc_pos\s.*{INTERVAL}$", text, re.M)
    assert "do not read them as physical properties" in text
    lines = "\n".join(cli_lines(fit))
    _no_interval_for(lines, flagged)
    assert "F_off 7" in lines and "(not identifiable)" in lines and re.search(rf"Fc_pos \S+ {INTERVAL}", lines)


def test_report_and_results_show_no_interval_for_a_flagged_parameter(flagged_fit, tmp_path):
    fit, data = flagged_fit
    flagged = _flagged(fit)
    report.write_report(tmp_path, data, {"lugre": fit}, title="flags", save_models=True)
    md = (tmp_path / "report.md").read_text()
    _no_interval_for(md.split("## Settings")[0], flagged)
    for name in flagged:
        assert re.search(rf"^\| {name} \| .* \| not identifiable \| \*\*not identifiable\*\* \|$", md, re.M), name
    # one block of reasons, each reason once
    assert md.count("pre-sliding, so this stiffness/damping is not determined") == 1
    res = json.loads((tmp_path / "results.json").read_text())["models"]["lugre"]
    rows = {r["name"]: r for r in res["uncertainty"]["table"]}
    for name in rows:
        assert rows[name]["identifiable"] == (name not in flagged), name
        assert bool(rows[name]["reasons"]) == (name in flagged), name
    assert {k for k, v in res["uncertainty"]["verdicts"].items() if not v["identifiable"]} == flagged
    for where in (res["fit"], json.loads(json.dumps(fit.to_dict(include_theta=False)))):
        assert set(where["uncertainty"]["intervals_95"]).isdisjoint(flagged)
        assert set(where["uncertainty"]["not_identifiable"]) == flagged & set(rows)
        assert {k for k, v in where["verdicts"].items() if not v["identifiable"]} == flagged
        assert all(where["verdicts"][k]["interval"] is None for k in flagged)


def test_the_saved_fit_keeps_the_verdicts(flagged_fit, tmp_path):
    fit, _ = flagged_fit
    fit.save(tmp_path / "f.npz")
    back = load_fit(tmp_path / "f.npz")
    assert back.verdicts() == fit.verdicts()
    assert back.summary() == fit.summary()
    _no_interval_for(back.summary(), _flagged(back))
