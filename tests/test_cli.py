"""The ``jaxfric`` command line, run as a user would: ``python -m jaxfric ...`` in a subprocess
where only a real process shows the behaviour (the demo, one-line errors, Ctrl-C), and through
``main()`` in this process (the ``in_process`` fixture) where it does not.

Compiled programs are shared between the subprocesses and this process through the
test session's persistent compilation cache (tests/conftest.py sets it as an environment
variable before JAX is imported; no JAX configuration is changed), so only the first
command pays for compiling the ENN and LuGre.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest
from processes import jax_subprocess

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def cli_env():
    """The subprocesses' environment: this checkout first, and the test session's
    compilation cache (tests/conftest.py), which this process shares, so a program the
    demo compiled is read back by the Python API's fit of the same data in here."""
    return dict(os.environ, PYTHONPATH=str(ROOT), JAXFRIC_DEBUG="")


def jaxfric(env, *args, cwd=None, timeout=600, slot=True):
    """``jaxfric ARGS`` in a subprocess; ``slot=False`` for a command that ends before it
    imports JAX (about 60 MB), which need not wait while a notebook kernel runs."""
    with jax_subprocess() if slot else contextlib.nullcontext():
        return subprocess.run([sys.executable, "-m", "jaxfric", *map(str, args)], env=env, cwd=cwd,
                              capture_output=True, text=True, timeout=timeout)


def assert_ok(proc):
    assert proc.returncode == 0, f"exit {proc.returncode}\nstdout:\n{proc.stdout}\nstderr:\n{proc.stderr}"


@pytest.fixture
def in_process(capsys):
    """``jaxfric ARGS`` run in this process through ``main()`` (the code path the command
    runs; ``--no-cache`` leaves JAX's cache settings to the test session), returned as a
    finished subprocess would be. In here it reuses the programs this module's Python-API
    fits compiled, where a subprocess would import JAX and compile them again; the
    subprocess tests above and below keep what only a real process shows (exit codes
    through the shell, one-line errors, Ctrl-C)."""
    from jaxfric.cli import main

    def run(*args):
        capsys.readouterr()
        status = main([*map(str, args), "--no-cache"])
        out, err = capsys.readouterr()
        return subprocess.CompletedProcess(["jaxfric", *map(str, args)], status, out, err)

    return run


@pytest.fixture(scope="module")
def demo(cli_env, tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "report"
    proc = jaxfric(cli_env, "demo", "--quick", "--quiet", "--out", out)
    assert_ok(proc)
    return out, proc


# ------------------------------------------------------------------------ demo
def test_demo_quick_writes_the_report(demo):
    from jaxfric.report import FIGURES

    out, proc = demo
    figures = list(FIGURES) + ["fit_elman.png", "fit_lugre.png"]
    for name in ["report.md", "results.json", *figures, "models/elman.npz", "models/lugre.npz",
                 "rig_measurements.csv", "friction_data.csv"]:
        assert (out / name).is_file(), name
    for name in figures:
        assert (out / name).stat().st_size > 10_000, name
        img = mpimg.imread(out / name)
        assert img.shape[0] > 300 and img.shape[1] > 500
        assert img[..., :3].std() > 0.05, f"{name} looks blank"
    assert not [p for p in out.rglob(".*")], "temporary files left behind"


def test_demo_report_holds_the_compensation_table(demo):
    """docs/algorithms.md §13.3 in the demo's report: no, each fit's and the ideal feed-forward."""
    import re

    out, _ = demo
    text = (out / "report.md").read_text()
    assert "## Friction compensation" in text
    section = text.split("## Friction compensation", 1)[1].split("\n## ", 1)[0]
    assert "| compensation | tracking RMS [mm] | max error [mm] |" in section
    rows = {m.group(1): [float(x) for x in m.group(2, 3, 4)] for m in re.finditer(
        r"^\| ([^|]+?) \| ([-\d.e+]+) \| ([-\d.e+]+) \| ([-\d.e+]+) \|$", section, re.M)}
    # the models are named as in the comparison table: the demo fits LuGre in the asymmetric
    # form the rig's friction needs, and the report says why
    assert set(rows) == {"none", "ENN (30 neurons)", "LuGre (asymmetric + offset)", "ideal (true friction)"}, rows
    assert "stick-slip column measures each fit's friction" in section
    assert "| physical models' form | the training data's sliding friction averages" in text
    assert "| elman: pipeline | MAPSO (8x8 agents, G = 3) -> Nelder-Mead (<= 200 evaluations) -> BFGS" in text
    assert all(np.isfinite(v).all() and min(v) >= 0 for v in rows.values()), rows
    # the true friction fed forward tracks better than no compensation
    assert rows["ideal (true friction)"][0] < rows["none"][0]
    assert (out / "compensation.png").stat().st_size > 10_000
    assert "Friction compensation" in json.loads((out / "results.json").read_text())["sections"]


def test_demo_prints_the_comparison_table(demo):
    out, proc = demo
    lines = proc.stdout.splitlines()
    header = lines[0]
    for col in ("model", "#params", "MSE % train", "MSE % valid", "MAX [N] valid", "FIT % valid", "time [s]"):
        assert col in header
    assert lines[2].startswith("ENN (30 neurons)") and lines[2].split()[3] == "180"
    assert lines[3].startswith("LuGre (asymmetric + offset)") and lines[3].split()[4] == "10"
    # --quiet: no progress or stage messages (warnings from identify would still show)
    assert all(line.startswith("jaxfric: warning: ") for line in proc.stderr.splitlines()), proc.stderr
    results = json.loads((out / "results.json").read_text())
    assert set(results["models"]) == {"elman", "lugre"}
    assert results["data"]["n_samples"] == 2000 and results["data"]["n_train"] == 1600
    mse = results["models"]["elman"]["metrics"]["valid"]["mse_percent"]
    assert f"{mse:.4g}" in lines[2]


def test_demo_report_lists_every_figure_and_reproduces_in_the_public_api(demo):
    """results.json names every figure of the folder (the compensation study's too) and the
    command says how many; the report's Python block uses only jaxfric's public API and,
    run as printed, repeats the demo's LuGre fit."""
    import re

    from jaxfric import load_fit

    out, proc = demo
    results = json.loads((out / "results.json").read_text())
    pngs = {p.name for p in out.glob("*.png")}
    assert set(results["figures"]) == pngs and "compensation.png" in pngs
    assert f"{len(pngs)} figures" in proc.stdout
    block = re.search(r"In Python:\n\n```python\n(.*?)```", (out / "report.md").read_text(), re.S).group(1)
    assert "jaxfric.cli" not in block and "FitSpec" not in block and "import jaxfric as jf" in block
    assert re.search(r"^fit_lugre = jf\.identify\('lugre', data, key=fit_key, model_options=", block, re.M)
    namespace = {}
    exec("\n".join(ln for ln in block.splitlines() if not ln.startswith("fit_elman")), namespace)
    saved = load_fit(out / "models" / "lugre.npz")
    np.testing.assert_allclose(namespace["fit_lugre"].theta, saved.theta, rtol=1e-6)
    assert namespace["fit_lugre"].metrics["valid"]["mse_percent"] == pytest.approx(
        saved.metrics["valid"]["mse_percent"], rel=1e-6)


def test_stage_lines_name_the_samples_the_global_stage_sees():
    """The ENN's MAPSO searches on the first GLOBAL_STAGE_SAMPLES (2000) training samples:
    the demo's 1600 training samples all, a longer record's first 2000."""
    import jaxfric as jf
    from jaxfric.cli.fitting import describe_solver

    enn = jf.Elman()
    assert "G = 50) on the 1600 training samples -> BFGS" in describe_solver(None, enn, n_train=1600)
    assert "on the first 2000 of the 5000 training samples" in describe_solver(None, enn, n_train=5000)
    assert "samples" not in describe_solver(None, enn)  # several records, used whole


def test_help_says_what_the_demo_runs_and_every_model_name():
    """The demo runs jaxfric's pipeline (the paper's only with --paper), and every --model
    help lists the names the commands accept (the registry's, tests/test_cli_first_contact.py)."""
    from jaxfric.cli.checks import MODEL_NAMES
    from jaxfric.cli.parser import build_parser

    parser = build_parser()
    top = parser.format_help()
    assert "jaxfric's" in top.split("identify ")[0] and "paper end to end" not in top
    sub = parser._subparsers._group_actions[0].choices
    demo = sub["demo"].format_help()
    assert "first 2000 samples" not in demo and "on the 1600 training samples" in demo
    for command in ("demo", "identify", "sweep"):
        text = " ".join(sub[command].format_help().split())
        assert f"friction models: {', '.join(MODEL_NAMES)}" in text or \
            f"friction models ({', '.join(MODEL_NAMES)})" in text, command


# -------------------------------------------------- identify and predict vs Python
@pytest.fixture(scope="module")
def python_fit(demo):
    """The Python API on the demo's friction_data.csv, with the CLI's quick budget and seed 5."""
    import jax

    import jaxfric as jf
    from jaxfric import rig
    from jaxfric.identification import identify

    csv = demo[0] / "friction_data.csv"
    data = rig.load_friction_pairs(csv, {"t": "t", "velocity": "velocity", "friction": "friction"})
    solver = jf.mapso_nmds(lattice_size=8, num_generations=3, nm_max_evals=200)
    fit = identify("elman", data, solver=solver, key=jax.random.key(5), model_options={"neurons": 30})
    return csv, data, fit


def test_identify_csv_reproduces_the_python_api(in_process, python_fit, tmp_path):
    csv, _, fit = python_fit
    out = tmp_path / "rep"
    proc = in_process("identify", csv, "--velocity-col", "velocity", "--friction-col", "friction",
                   "--time-col", "t", "--model", "elman", "--neurons", "30", "--quick", "--seed", "5",
                   "--quiet", "--out", out)
    assert_ok(proc)
    got = json.loads((out / "results.json").read_text())["models"]["elman"]["metrics"]
    for window in ("train", "valid", "all"):
        for key, value in fit.metrics[window].items():
            assert got[window][key] == pytest.approx(value, rel=1e-6, abs=1e-9), (window, key)
    assert "ENN (30 neurons)" in proc.stdout


def test_saved_fit_predicts_the_same_through_the_cli(in_process, python_fit, tmp_path):
    csv, data, fit = python_fit
    model_file = tmp_path / "elman.npz"
    fit.save(model_file)
    pred_csv = tmp_path / "pred.csv"
    proc = in_process("predict", model_file, csv, "--velocity-col", "velocity", "--time-col", "t",
                   "--friction-col", "friction", "--out", pred_csv)
    assert_ok(proc)
    assert "MSE %" in proc.stdout
    table = np.genfromtxt(pred_csv, delimiter=",", names=True)
    expect = np.asarray(fit.predict(data.velocity, data.dt), dtype=np.float64)
    np.testing.assert_allclose(table["friction_predicted"], expect, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(table["velocity"], np.asarray(data.velocity), rtol=0, atol=0)
    np.testing.assert_allclose(table["error"], table["friction_measured"] - table["friction_predicted"])


def test_identify_raw_rig_channels_runs_the_pipeline(in_process, demo, tmp_path):
    out_demo, _ = demo
    out = tmp_path / "raw"
    proc = in_process("identify", out_demo / "rig_measurements.csv", "--time-col", "t", "--x-col", "x",
                   "--p1-col", "p1", "--p2-col", "p2", "--load-col", "load", "--bore", "0.1", "--rod", "0.07",
                   "--mass", "120", "--model", "lugre", "--quick", "--quiet", "--out", out)
    assert_ok(proc)
    raw = json.loads((out / "results.json").read_text())["data"]
    pairs = json.loads((out_demo / "results.json").read_text())["data"]
    assert raw["n_samples"] == pairs["n_samples"] and raw["n_train"] == pairs["n_train"]
    np.testing.assert_allclose(raw["friction_range_N"], pairs["friction_range_N"], rtol=1e-4)
    assert (out / "fit_lugre.png").is_file()


# --------------------------------------------------------------- user errors
@pytest.fixture(scope="module")
def small_csv(tmp_path_factory):
    p = tmp_path_factory.mktemp("csv") / "pairs.csv"
    t = np.arange(300) / 100.0
    v = 0.01 * np.sin(2 * np.pi * 0.5 * t)
    p.write_text("t,v,F\n" + "\n".join(f"{a},{b},{c}" for a, b, c in zip(t, v, 100 * np.tanh(v / 1e-3))))
    return p


# The four kinds the brief names run as real subprocesses (stderr must hold one line and no
# traceback); the other cases run in-process through main(), which is the same code path.
SUBPROCESS_ERRORS = [
    (["identify", "no-such-file.csv", "--velocity-col", "v", "--friction-col", "F", "--dt", "0.01"],
     "file not found: no-such-file.csv"),
    (["identify", "{csv}", "--velocity-col", "speed", "--friction-col", "F", "--time-col", "t"],
     "--velocity-col: no column 'speed' in"),
    (["identify", "{csv}", "--velocity-col", "v", "--friction-col", "F", "--dt", "fast"],
     "argument --dt: not a number: 'fast'"),
    (["identify", "{csv}", "--velocity-col", "v", "--friction-col", "F", "--dt", "0.01", "--model", "lugre,magic"],
     "unknown model 'magic'"),
]
IN_PROCESS_ERRORS = [
    (["identify", "{csv}", "--velocity-col", "v", "--friction-col", "F", "--time-col", "t", "--velocity-unit", "furlong"],
     "unknown velocity unit 'furlong'"),
    (["identify", "{csv}", "--x-col", "v", "--p1-col", "F", "--p2-col", "F", "--load-col", "F", "--time-col", "t"],
     "needs the cylinder geometry: --bore --rod --mass"),
    (["identify", "{csv}", "--velocity-col", "v", "--friction-col", "F"], "give --time-col COL or --dt"),
    (["identify", "{csv}", "--velocity-col", "v", "--friction-col", "F", "--dt", "0.01", "--train-fraction", "1"],
     "argument --train-fraction: must lie strictly between 0 and 1"),
    (["identify", "{csv}", "--velocity-col", "v", "--friction-col", "F", "--time-col", "t", "--delimiter", ";"],
     "only one column found with --delimiter ';'; the lines look ','-separated"),
    (["demo", "--neurons", "0"], "argument --neurons: must be >= 1"),
    (["demo", "--model", ""], "argument --model/--models: give at least one model"),
    (["predict", "missing.npz", "{csv}"], "model file not found: missing.npz"),
    (["predict", "{csv}", "{csv}", "--velocity-col", "v", "--time-col", "t"], "cannot load the fit"),
    (["bench", "nonsense"], "argument name: invalid choice"),
    (["predict", "{csv}", "{csv}", "--velocity-col", "v", "--time-col", "t", "--out", "."],
     "--out . is a folder; give a file name"),
    (["identify", "{csv}", "--velocity-col", "v", "--friction-col", "F", "--dt", "0.01", "--box", "Fc=10,1"],
     "argument --box: Fc range must satisfy low < high"),
    (["identify", "{csv}", "--velocity-col", "v", "--friction-col", "F", "--dt", "0.01", "--box", "Fc"],
     "argument --box: give NAME=LO,HI"),
    (["identify", "{csv}", "--velocity-col", "v", "--friction-col", "F", "--dt", "0.01", "--model", "coulomb",
      "--box", "sigma0=1e4,1e6"], "--box sigma0: none of the models coulomb has this parameter"),
]


def _fill(args, csv):
    return [a.replace("{csv}", str(csv)) for a in args]


def _assert_one_line(stderr, message):
    assert "Traceback" not in stderr
    lines = [line for line in stderr.strip().splitlines() if line.strip()]
    assert len(lines) == 1, stderr
    assert lines[0].startswith("jaxfric: error: ") and message in lines[0], lines[0]


@pytest.mark.parametrize("args, message", SUBPROCESS_ERRORS)
def test_user_errors_are_one_line_without_traceback(cli_env, small_csv, tmp_path, args, message):
    # each error is found before JAX is imported (test_user_errors_come_before_jax), so the
    # subprocess needs no slot: it waited 13-19 s while a notebook kernel held the lock
    proc = jaxfric(cli_env, *_fill(args, small_csv), cwd=tmp_path, slot=False)
    assert proc.returncode == 2
    _assert_one_line(proc.stderr, message)
    assert proc.stdout == "" and not list(tmp_path.iterdir())  # nothing written


def test_user_errors_come_before_jax(small_csv, tmp_path):
    """The subprocess errors above are found before JAX is imported: in a fresh
    interpreter, each ``main(args)`` returns 2 and ``jax`` is still not in ``sys.modules``."""
    cases = [_fill(args, small_csv) for args, _ in SUBPROCESS_ERRORS]
    code = ("import sys\n"
            "from jaxfric.cli import main\n"
            f"for args in {cases!r}:\n"
            "    assert main(args) == 2, args\n"
            "    assert 'jax' not in sys.modules, args\n"
            "print('NO_JAX')\n")
    proc = subprocess.run([sys.executable, "-c", code], env=dict(os.environ, PYTHONPATH=str(ROOT)), cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "NO_JAX"


@pytest.mark.parametrize("args, message", IN_PROCESS_ERRORS)
def test_more_user_errors(small_csv, tmp_path, monkeypatch, capsys, args, message):
    from jaxfric.cli import main

    monkeypatch.chdir(tmp_path)
    assert main([*_fill(args, small_csv), "--no-cache"] if args[0] != "bench" else _fill(args, small_csv)) == 2
    _assert_one_line(capsys.readouterr().err, message)
    assert not list(tmp_path.iterdir())


def test_bad_data_fail_before_any_stage_message_or_bar(tmp_path, monkeypatch, capsys):
    """Without --quiet: identify's record checks run before 'identifying ...' and the bar."""
    from jaxfric.cli import main

    p = tmp_path / "constant.csv"
    p.write_text("t,v,F\n" + "\n".join(f"{k / 100},{0.01 * np.sin(k / 9)},5.0" for k in range(100)))
    monkeypatch.chdir(tmp_path)
    status = main(["identify", str(p), "--velocity-col", "v", "--friction-col", "F", "--time-col", "t",
                   "--model", "coulomb", "--quick", "--no-cache"])
    assert status == 2
    err = capsys.readouterr().err
    assert err.splitlines()[-1].startswith("jaxfric: error: friction has zero variance"), err
    assert "identifying" not in err and "%|" not in err
    assert sorted(x.name for x in tmp_path.iterdir()) == ["constant.csv"]


def test_box_option_reaches_the_fit_and_the_reproduce_line(small_csv, tmp_path, monkeypatch, capsys):
    """``--box NAME=LO,HI`` goes into the FitSpec (its repr is the report's Reproduce line)
    and from there to identify(box=...): the saved fit searched that box. Fc (truth 100 N)
    then ends on the upper end of (1, 50), and the warning gives the wider range as this
    command takes it."""
    from jaxfric.cli import main
    from jaxfric.fit import load_fit

    monkeypatch.chdir(tmp_path)
    out = tmp_path / "report"
    assert main(["identify", str(small_csv), "--velocity-col", "v", "--friction-col", "F", "--time-col", "t",
                 "--model", "coulomb", "--box", "Fc=1,50", "--box", "sigma2=1,1000", "--quick", "--quiet",
                 "--no-cache", "--out", str(out)]) == 0
    fit = load_fit(out / "models" / "coulomb.npz")
    assert fit.box["Fc"] == (1.0, 50.0) and fit.box["sigma2"] == (1.0, 1000.0)
    assert "box={'Fc': (1.0, 50.0), 'sigma2': (1.0, 1000.0)}" in (out / "report.md").read_text()
    err = capsys.readouterr().err
    assert "jaxfric: warning: Coulomb: Fc = 50 ended on the upper bound" in err
    assert "(pass --box Fc=1,99) and fit again" in err and "box={" not in err


def test_pairs_with_chamber_pressures_fit_a_pressure_dependent_model(tmp_path, monkeypatch, capsys):
    """--p1-col/--p2-col beside --velocity-col/--friction-col reach Cylinder (in --pressure-unit);
    one of them alone is refused, and Cylinder without them names the missing channels."""
    from jaxfric.cli import main
    from jaxfric.fit import load_fit
    from jaxfric.metrics import friction_metrics

    monkeypatch.chdir(tmp_path)
    t = np.arange(400) / 100.0
    v = 0.01 * np.sin(2 * np.pi * 0.5 * t) + 0.003 * np.sin(2 * np.pi * 1.3 * t)
    p1 = 3.0 + np.sin(2 * np.pi * 0.3 * t)  # bar
    p2 = 2.0 + 0.5 * np.cos(2 * np.pi * 0.7 * t)
    f = np.tanh(v / 1e-4) * (20.0 + 4e-5 * 1e5 * (p1 + p2)) + 800.0 * v
    csv = tmp_path / "pressures.csv"
    csv.write_text("t,v,F,p1,p2\n" + "\n".join(",".join(f"{x:.17g}" for x in row) for row in zip(t, v, f, p1, p2)))
    base = ["identify", str(csv), "--velocity-col", "v", "--friction-col", "F", "--time-col", "t",
            "--model", "cylinder", "--quick", "--quiet", "--no-cache"]
    out = tmp_path / "report"
    assert main([*base, "--p1-col", "p1", "--p2-col", "p2", "--pressure-unit", "bar",
                 "--out", str(out)]) == 0
    fit = load_fit(out / "models" / "cylinder.npz")
    own = fit.predict(v, inputs=np.stack([p1, p2]) * 1e5)  # the fit saw pascals
    assert fit.metrics["valid"]["mse_percent"] == pytest.approx(
        friction_metrics(f[320:], np.asarray(own)[320:])["mse_percent"], rel=1e-5, abs=1e-9)
    assert fit.metrics["valid"]["mse_percent"] < 1.0
    assert "pressures 'p1' and 'p2'" in (out / "report.md").read_text()
    capsys.readouterr()
    assert main([*base, "--p1-col", "p1", "--out", str(tmp_path / "one")]) == 2
    assert "need both --p1-col and --p2-col" in capsys.readouterr().err
    assert main([*base, "--out", str(tmp_path / "none")]) == 2
    assert "Cylinder needs the measured channel(s) p1, p2" in capsys.readouterr().err


# -------------------------------------------------------------------- Ctrl-C
def test_ctrl_c_exits_130_and_says_what_was_kept(cli_env, demo, tmp_path, interruptible, subprocess_slot):
    out = tmp_path / "interrupted"
    proc = subprocess.Popen(
        [sys.executable, "-m", "jaxfric", "identify", str(demo[0] / "friction_data.csv"), "--velocity-col",
         "velocity", "--friction-col", "friction", "--time-col", "t", "--model", "coulomb,elman", "--quick",
         # 3000 generations: the static Coulomb model finishes in seconds, while the 7-neuron
         # ENN (not in the demo's compilation cache) is still compiling or running when
         # Ctrl-C comes, however fast compilation gets.
         "--generations", "3000", "--neurons", "7", "--quiet", "--out", str(out)],
        env=cli_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **interruptible)
    deadline = time.monotonic() + 300
    while not (out / "models" / "coulomb.npz").exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr
    lines = [line for line in stderr.strip().splitlines() if line.strip()]
    # the finished fit may have said something (e.g. a parameter on its bound) before the interrupt
    assert all(line.startswith("jaxfric: warning: ") for line in lines[:-1]), stderr
    assert lines[-1] == f"jaxfric: interrupted; kept 1 finished file(s) in {out / 'models'}: coulomb.npz"
    assert (out / "models" / "coulomb.npz").is_file()
    assert not (out / "report.md").exists()
    assert not [p for p in out.rglob(".*")]


# ---------------------------------------------------------------- help, bench
@pytest.mark.parametrize("command", [[], ["demo"], ["identify"], ["predict"], ["bench"]])
def test_help_has_examples(command, capsys):
    from jaxfric.cli import main

    assert main([*command, "--help"]) == 0
    text = capsys.readouterr().out
    assert text.startswith("usage: jaxfric")
    assert "examples:" in text


def test_bench_passes_arguments_through(cli_env):
    proc = jaxfric(cli_env, "bench", "table1", "--help")
    assert_ok(proc)
    assert "--quick" in proc.stdout and "jaxfric bench table1" in proc.stdout


def test_bench_reports_a_missing_script(cli_env, tmp_path):
    env = dict(cli_env, JAXFRIC_BENCHMARKS=str(tmp_path))
    proc = jaxfric(env, "bench", "table1")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.startswith("jaxfric: error: benchmark script not found")


# ------------------------------------------------------------- unit helpers
def test_read_table_and_units(tmp_path):
    from jaxfric.cli.data import read_table
    from jaxfric.cli.errors import UserError
    from jaxfric.cli.units import unit_factor

    p = tmp_path / "a.txt"
    p.write_text("# comment\n1 2 3\n4 5 6\n")
    t = read_table(str(p), delimiter="whitespace")
    assert t.header == [] and t.column("2", "--x").tolist() == [3.0, 6.0]
    with pytest.raises(UserError, match="out of range"):
        t.column("3", "--x")
    p.write_text("a,b\n1,2\n3,x\n")
    with pytest.raises(UserError, match="non-number 'x'"):
        read_table(str(p))
    assert unit_factor("pressure", "bar", "--p") == 1e5
    assert unit_factor("force", "-1", "--load-unit") == -1.0
    with pytest.raises(UserError, match="non-zero"):
        unit_factor("force", "0", "--load-unit")


# ------------------------------------------------------ predict: honest; --valid
def test_predict_keeps_one_row_per_input_row_and_warns_even_when_quiet(cli_env, tmp_path):
    """Irregular time stamps: one prediction per input row (not per resampled row), equal to
    Fit.predict_at, and the resampling is one 'jaxfric: warning:' line despite --quiet."""
    from jaxfric.fit import Fit
    from jaxfric.models import LuGre

    model = LuGre()
    theta = np.asarray(model.from_physical(sigma0=1e5, sigma1=300.0, sigma2=800.0, Fc=40.0, Fs=60.0,
                                           vs=3e-3), np.float32)
    fit = Fit(model=model, theta=theta, velocity_scaler=None, friction_scaler=None, dt=0.01,
              n_train=80, n_samples=100, metrics={}, velocity_range=(-0.03, 0.03), box={"Fc": (5.0, 100.0)})
    fit.save(tmp_path / "lugre.npz")
    t = np.cumsum(np.r_[0.0, np.random.default_rng(0).uniform(0.5, 1.5, 59)]) * 0.01
    v = 0.02 * np.sin(2 * np.pi * 0.5 * t)
    (tmp_path / "irregular.csv").write_text("t,v\n" + "\n".join(f"{a:.17g},{b:.17g}" for a, b in zip(t, v)) + "\n")
    proc = jaxfric(cli_env, "predict", tmp_path / "lugre.npz", tmp_path / "irregular.csv", "--velocity-col", "v",
                   "--time-col", "t", "--quiet", "--out", tmp_path / "pred.csv")
    assert_ok(proc)
    warnings_ = [ln for ln in proc.stderr.splitlines() if ln.startswith("jaxfric: warning:")]
    assert len(warnings_) == 1 and "differs from the fit's" in warnings_[0], proc.stderr
    table = np.genfromtxt(tmp_path / "pred.csv", delimiter=",", names=True)
    assert table.shape == (60,)
    np.testing.assert_array_equal(table["t"], t)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        expect = np.asarray(fit.predict_at(t, v), np.float64)
    np.testing.assert_allclose(table["friction_predicted"], expect, rtol=1e-6, atol=1e-6)


def test_identify_with_valid_files_trains_on_the_whole_file_and_reports_each_record(in_process, tmp_path):
    import jax

    import jaxfric as jf
    from jaxfric import rig
    from jaxfric.identification import identify

    def write(name, phase, n):
        t = np.arange(n) * 0.01
        v = 0.02 * np.sin(2 * np.pi * 0.5 * t + phase) + 0.005 * np.sin(2 * np.pi * 1.3 * t)
        f = 40.0 * np.tanh(v / 1e-3) + 800.0 * v + np.cos(7.0 * t)
        p = tmp_path / name
        p.write_text("t,v,F\n" + "\n".join(f"{a:.17g},{b:.17g},{c:.17g}" for a, b, c in zip(t, v, f)) + "\n")
        return p

    a, b = write("a.csv", 0.0, 300), write("b.csv", 1.0, 200)
    out = tmp_path / "rep"
    proc = in_process("identify", a, "--valid", b, "--velocity-col", "v", "--friction-col", "F",
                   "--time-col", "t", "--model", "coulomb", "--quick", "--seed", "3", "--quiet", "--out", out)
    assert_ok(proc)
    res = json.loads((out / "results.json").read_text())
    assert res["data"]["n_train"] == 300 and res["data"]["n_valid"] == 0
    recs = res["models"]["coulomb"]["records"]
    assert [(r["name"], r["role"], r["n_samples"]) for r in recs] == [(str(a), "train", 300), (str(b), "valid", 200)]
    cols = {"t": "t", "velocity": "v", "friction": "F"}
    fit = identify("coulomb", train={str(a): rig.load_friction_pairs(a, cols)},
                   valid={str(b): rig.load_friction_pairs(b, cols)}, key=jax.random.key(3),
                   solver=jf.mapso_nmds(lattice_size=5, num_generations=3, nm_max_evals=200))
    for got, want in zip(recs, fit.metrics["records"]):
        assert got["all"]["mse_percent"] == pytest.approx(want["all"]["mse_percent"], rel=1e-6)
    text = (out / "report.md").read_text()
    assert "| record | role | samples |" in text and "Validation record" in text
    assert any(p.name.startswith("fit_coulomb_") and "b_csv" in p.name for p in out.iterdir())
