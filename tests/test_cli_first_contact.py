"""What a new user meets first: fast --help, smoke runs that keep the committed
results, and a command line that passes its arguments to the library without copying
the library's defaults (issue 20.9, 20.11; issue 19.4)."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest
from processes import jax_subprocess

ROOT = Path(__file__).resolve().parents[1]


def _python(code: str) -> subprocess.CompletedProcess:
    """``code`` run by a fresh interpreter importing this checkout; it must succeed."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    with jax_subprocess():
        proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return proc


# ------------------------------------------------------------------ 20.11: --help
@pytest.mark.parametrize("command", [[], ["demo"], ["identify"], ["predict"], ["bench"]])
def test_help_answers_without_importing_jax(command):
    code = ("import sys\n"
            "from jaxfric.cli import main\n"
            f"status = main({command!r} + ['--help'])\n"
            "assert status == 0, status\n"
            "print('JAX_IMPORTED' if 'jax' in sys.modules else 'NO_JAX')\n")
    proc = _python(code)
    assert "usage: jaxfric" in proc.stdout
    assert proc.stdout.strip().endswith("NO_JAX"), [m for m in proc.stdout.splitlines()[-1:]]


def test_warning_categories_load_without_jax():
    """pytest-xdist's controller rebuilds every warning a worker records by importing the
    category's module: jaxfric's must not pull in JAX (issue 20.14: the controller grew to
    188 MB), and each stays importable where it is documented."""
    from jaxfric import fit, identification, rig

    categories = [fit.ExtrapolationWarning, fit.ResamplingWarning, identification.BoundWarning,
                  rig.IrregularSamplingWarning]
    code = ("import importlib, sys\n"
            f"for module, name in {[(c.__module__, c.__name__) for c in categories]!r}:\n"
            "    assert issubclass(getattr(importlib.import_module(module), name), UserWarning)\n"
            "print('JAX_IMPORTED' if 'jax' in sys.modules else 'NO_JAX')\n")
    assert _python(code).stdout.strip() == "NO_JAX"


def test_lazy_package_keeps_public_names():
    import jaxfric as jf

    for name in jf.__all__:
        assert getattr(jf, name) is not None, name
    import jaxfric.identification  # noqa: F401 - the subpackage import must not shadow the function

    assert callable(jf.identify) and jf.identify.__name__ == "identify"
    with pytest.raises(AttributeError, match="no attribute 'nonsense'"):
        jf.nonsense  # noqa: B018


# ---------------------------------------------------- 20.9: quick runs write elsewhere
FAKE_BENCH = '''
import argparse
from pathlib import Path

def main(argv):
    p = argparse.ArgumentParser()
    p.add_argument("--quick", action="store_true")
    p.add_argument("--out", default=str(Path(__file__).parent / "results"))
    a = p.parse_args(argv)
    Path(a.out).mkdir(parents=True, exist_ok=True)
    (Path(a.out) / "table1.md").write_text("quick" if a.quick else "full")
    return 0
'''


def test_bench_quick_never_overwrites_committed_results(tmp_path, monkeypatch):
    from jaxfric.cli import main

    bench = tmp_path / "benchmarks"
    (bench / "results").mkdir(parents=True)
    (bench / "table1.py").write_text(FAKE_BENCH)
    committed = bench / "results" / "table1.md"
    committed.write_text("committed full-run numbers")
    monkeypatch.setenv("JAXFRIC_BENCHMARKS", str(bench))
    assert main(["bench", "table1", "--quick"]) == 0
    assert committed.read_text() == "committed full-run numbers"
    assert (bench / "results" / "quick" / "table1.md").read_text() == "quick"
    # an explicit --out is the user's choice
    assert main(["bench", "table1", "--quick", "--out", str(tmp_path / "mine")]) == 0
    assert (tmp_path / "mine" / "table1.md").read_text() == "quick"
    assert committed.read_text() == "committed full-run numbers"


def test_harness_results_dir_rule(tmp_path):
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import _harness
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    assert _harness.results_dir(tmp_path / "x") == tmp_path / "x"
    assert _harness.QUICK_RESULTS.parent == _harness.RESULTS
    assert _harness.RESULTS.name == "results" and _harness.QUICK_RESULTS.name == "quick"
    ignored = (ROOT / ".gitignore").read_text().splitlines()
    assert "/benchmarks/results/quick/" in ignored


def test_harness_data_files_are_none_when_absent_and_never_downloaded(tmp_path, monkeypatch):
    """Benchmarks skip cleanly without the real data: no file, no download, ``None``."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import _harness
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    from jaxfric import datasets

    def no_download(*a, **k):
        raise AssertionError("a benchmark tried to download")

    monkeypatch.setattr(datasets, "_download", no_download)
    for var in ("JAXFRIC_EMPS", "JAXFRIC_PNEUMATIC_DATA"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setenv("JAXFRIC_DATA", str(tmp_path / "empty"))
    monkeypatch.setattr(_harness, "SHARED_DATA", tmp_path / "none")
    assert _harness.emps_file() is None
    assert _harness.emps_file(tmp_path / "DATA_EMPS.mat") is None
    assert _harness.pneumatic("O-ring", 3) is None
    given = tmp_path / "DATA_EMPS.mat"
    given.write_bytes(b"")
    assert _harness.emps_file(given) == given  # an explicit path is the user's choice


def _takes_quick(tree) -> bool:
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            name = getattr(node.func, "attr", getattr(node.func, "id", None))
            if name == "add_output_arguments":
                return True
            if name == "add_argument" and any(
                    isinstance(a, ast.Constant) and a.value == "--quick" for a in node.args):
                return True
    return False


def _passes_quick_to_results_dir(tree) -> bool:
    return any(isinstance(node, ast.Call) and getattr(node.func, "id", None) == "results_dir"
               and any(k.arg == "quick" for k in node.keywords) for node in ast.walk(tree))


def test_every_benchmark_with_quick_writes_quick_results_elsewhere():
    """A script that takes --quick hands it to the harness's output rule (results/quick/);
    benchmarks/motion.py wrote its smoke run over the committed motion.md and figures."""
    scripts = sorted(p for p in (ROOT / "benchmarks").glob("*.py") if not p.name.startswith("_"))
    quick = {p.name: ast.parse(p.read_text()) for p in scripts}
    quick = {name: tree for name, tree in quick.items() if _takes_quick(tree)}
    assert {"motion.py", "table1.py", "peers.py"} <= set(quick)
    assert [name for name, tree in quick.items() if not _passes_quick_to_results_dir(tree)] == []


def test_every_benchmark_script_is_listed_with_the_page_that_cites_it():
    """Every script in benchmarks/ backs a claim: docs/benchmarks.md's table lists it with
    what it writes and the page citing that, and lists no script that is gone."""
    import re

    text = (ROOT / "docs" / "benchmarks.md").read_text(encoding="utf-8")
    listed = set(re.findall(r"^\| `(\w+\.(?:py|sh))` \|", text, re.M))
    scripts = {p.name for p in (ROOT / "benchmarks").glob("*.py") if not p.name.startswith("_")}
    assert scripts - {"baselines.py"} <= listed, scripts - listed
    assert listed <= scripts | {"gpu_check.sh"}, listed - scripts


# ------------------------------------------------------ 19.4: one specification object
def _args(*argv):
    from jaxfric.cli.parser import build_parser

    return build_parser().parse_args(["demo", *argv])


def test_cli_solver_budgets_are_the_librarys():
    from jaxfric.cli.spec import FitSpec
    from jaxfric.identification import paper_solver

    for name in ("lugre", "elman"):
        spec = FitSpec.from_args(name, _args("--models", name, "--solver", "mapso"))
        model = spec.build_model()
        # LuGre with --solver mapso ran 300 generations while identify's default runs 200
        assert spec.build_solver(model) == paper_solver(model).mapso
    spec = FitSpec.from_args("lugre", _args("--models", "lugre", "--solver", "nelder-mead"))
    model = spec.build_model()
    assert spec.build_solver(model) == paper_solver(model).nelder_mead
    spec = FitSpec.from_args("lugre", _args("--models", "lugre", "--generations", "7"))
    solver = spec.build_solver(spec.build_model())
    base = paper_solver(spec.build_model())
    assert solver.mapso.num_generations == 7
    assert solver.mapso.lattice_size == base.mapso.lattice_size
    assert solver.nelder_mead == base.nelder_mead
    assert FitSpec.from_args("lugre", _args("--models", "lugre")).build_solver() is None


def test_cli_copies_no_library_default():
    import inspect

    import jaxfric as jf
    from jaxfric import rig
    from jaxfric.cli.parser import build_parser
    from jaxfric.cli.spec import FitSpec

    args = _args()
    assert args.neurons is None
    spec = FitSpec.from_args("elman", args)
    assert spec.build_model().neurons == jf.Elman().neurons
    ident = build_parser().parse_args(["identify", "f.csv"])
    for option in ("cutoff", "gravity", "train_fraction"):
        assert getattr(ident, option) is None, option
        assert option in inspect.signature(rig.estimate_friction).parameters


def test_reproduce_line_is_the_specification_in_the_public_api():
    from jaxfric.cli.commands import _python_snippet
    from jaxfric.cli.spec import FitSpec

    args = _args("--models", "lugre,elman", "--quick", "--seed", "4")
    specs = [FitSpec.from_args(n, args) for n in ("lugre", "elman")]
    for spec in specs:
        assert eval(repr(spec), {"FitSpec": FitSpec}) == spec
    text = _python_snippet(args, ["lugre", "elman"], ["data = ..."], "fit_key")
    for name, spec in zip(("lugre", "elman"), specs):
        assert f"fit_{name} = {spec.python('data', 'fit_key')}" in text
    assert "jaxfric.cli" not in text  # the public API only
    import jaxfric as jf  # the solver the line builds is the one the specification runs

    assert eval(specs[0].python().split("solver=", 1)[1][:-1], {"jf": jf}) == specs[0].build_solver()


# ------------------------------------------------------- 20.14: the quick subset
def test_slow_tests_are_marked_and_exist():
    """``-m "not slow"`` leaves out the long tests; every listed one still exists (a renamed
    test would silently fall back into the quick subset)."""
    import ast

    from conftest import SLOW_TESTS

    assert SLOW_TESTS
    for nodeid in SLOW_TESTS:
        path, name = nodeid.split("::")
        tree = ast.parse((ROOT / path).read_text())
        names = {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)}
        assert name in names, nodeid
    assert "slow:" in (ROOT / "pyproject.toml").read_text()


# ------------------------------------------------------- checks before JAX, memory, predict
def test_command_line_model_names_are_the_librarys():
    """The names refused before JAX is imported are exactly jaxfric.models.available()."""
    from jaxfric import models
    from jaxfric.cli.checks import MODEL_NAMES

    assert tuple(MODEL_NAMES) == tuple(models.available())


def test_memory_figure_is_the_dense_matrix_of_the_stage_that_runs():
    """BFGS (the networks' default gradient stage) holds an n x n matrix, Nelder-Mead an
    (n+1) x n simplex; a swarm alone holds neither. The refusal names the figures."""
    import argparse

    from jaxfric.cli.errors import UserError
    from jaxfric.cli.fitting import check_memory, memory_need
    from jaxfric.cli.spec import FitSpec

    def spec(name, **kw):
        args = argparse.Namespace(generations=None, nm_evals=None, quick=False, neurons=kw.pop("neurons", None),
                                  solver=kw.pop("solver", "mapso-nmds"), refine=kw.pop("refine", "default"),
                                  paper=kw.pop("paper", False), seed=0, box=None)
        s = FitSpec.from_args(name, args)
        return s, s.build_model()

    s, m = spec("elman", neurons=30)  # 180 parameters, MAPSO then BFGS
    assert memory_need(s, m, x64=False)[0] == 180 * 180 * 4
    assert memory_need(s, m, x64=True)[0] == 180 * 180 * 8
    s, m = spec("elman", neurons=30, paper=True)  # MAPSO-NMDS
    assert memory_need(s, m, x64=False)[0] == 181 * 180 * 4
    s, m = spec("elman", neurons=30, solver="mapso")  # a swarm alone (with identify's BFGS)
    assert memory_need(s, m, x64=False)[0] == 180 * 180 * 4
    s, m = spec("lugre", solver="pso")
    assert memory_need(s, m, x64=False) == (0, "")
    s, m = spec("elman", neurons=1000)
    with pytest.raises(UserError, match=r"6 000 parameters: BFGS's dense Hessian \(6 000 x 6 000 x 4 bytes\) "
                       r"needs 144 MB, more than the 100 MB of memory available; use fewer neurons"):
        check_memory(s, m, x64=False, available=100_000_000)
    check_memory(s, m, x64=False, available=10**12)  # fits: nothing said


def test_predict_says_and_applies_the_fits_velocity_filter(tmp_path, capsys):
    """A fit saved with the pipeline's velocity filter: predict says so, and with
    --filter-velocity its output is the fit's prediction of the low-passed velocity."""
    import numpy as np

    import jaxfric as jf
    from jaxfric.cli import main
    from jaxfric.rig.pipeline import lowpass

    t = np.arange(400) / 100.0
    rng = np.random.default_rng(0)
    v = 0.02 * np.sin(2 * np.pi * 0.5 * t) + 0.004 * rng.standard_normal(t.size)
    (tmp_path / "v.csv").write_text("t,v\n" + "\n".join(f"{float(a)!r},{float(b)!r}" for a, b in zip(t, v)) + "\n")
    fit = jf.Fit(model=jf.Coulomb(), theta=np.array([40.0, 3.0]), velocity_scaler=None, friction_scaler=None,
                 dt=0.01, n_train=300, n_samples=400, metrics={"train": None, "valid": None, "all": None},
                 settings={"velocity_filter": {"kind": "butterworth zero-phase", "order": 4, "cutoff_hz": 5.0}})
    fit.save(tmp_path / "fit.npz")
    base = ["predict", str(tmp_path / "fit.npz"), str(tmp_path / "v.csv"), "--velocity-col", "v", "--time-col", "t"]
    assert main([*base, "--out", str(tmp_path / "raw.csv"), "--no-cache"]) == 0
    err = capsys.readouterr().err
    assert "trained on velocity filtered by a zero-phase Butterworth low-pass (order 4, 5 Hz)" in err
    assert "--filter-velocity" in err
    assert main([*base, "--out", str(tmp_path / "filtered.csv"), "--filter-velocity", "--no-cache"]) == 0
    got = np.genfromtxt(tmp_path / "filtered.csv", delimiter=",", names=True)
    expected = np.asarray(fit.predict(lowpass(v, 100.0, 5.0, 4)))
    assert np.allclose(got["velocity"], lowpass(v, 100.0, 5.0, 4), rtol=0, atol=1e-12)
    assert np.allclose(got["friction_predicted"], expected, rtol=1e-5, atol=1e-4)
    raw = np.genfromtxt(tmp_path / "raw.csv", delimiter=",", names=True)
    assert np.allclose(raw["velocity"], v, rtol=0, atol=1e-12)


def test_demo_help_describes_the_pipelines_the_demo_runs():
    """--help, the stage lines and the report's settings share one description of each
    demo model's pipeline (describe_solver of the library's defaults), so they cannot drift."""
    import argparse

    from jaxfric.cli.fitting import describe_solver
    from jaxfric.cli.parser import DEMO_EPILOG
    from jaxfric.cli.spec import FitSpec

    args = argparse.Namespace(generations=None, nm_evals=None, quick=False, neurons=None, solver="mapso-nmds",
                              refine="default", paper=False, seed=0, box=None, asymmetric=True)
    for name in ("elman", "lugre"):
        spec = FitSpec.from_args(name, args)
        model = spec.build_model()
        text = describe_solver(spec.build_solver(model), model, spec.paper, spec.refine, n_train=1600)
        assert text in DEMO_EPILOG, (name, text)
        assert f"{model.num_params} parameters" in DEMO_EPILOG
    assert FitSpec.from_args("elman", args).asymmetric is False  # the networks have no such form


def test_asymmetric_models_are_those_with_the_form():
    from jaxfric import models
    from jaxfric.cli.spec import ASYMMETRIC_MODELS
    from jaxfric.identification._api import resolve_model

    for name in models.available():
        try:
            model = resolve_model(name, {"asymmetric": True, "offset": True})
        except ValueError:
            assert name not in ASYMMETRIC_MODELS, name
        else:
            assert name in ASYMMETRIC_MODELS and model.asymmetric and model.offset, name
