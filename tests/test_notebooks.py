"""Every notebook in notebooks/ is built from its plain-text source, runs top to bottom with
the small budget from any working directory, and tells the truth about what it ran.

The sources are jupytext percent-format files (``notebooks/01_test_functions.py`` ...);
edit those, then rebuild the committed notebooks and their outputs (full budget, with the
README's data setup)::

    jupytext --to ipynb notebooks/0*.py
    JAXFRIC_DATA=/path/to/data jupyter nbconvert --to notebook --execute --inplace notebooks/0*.ipynb

Kernels get ``JAXFRIC_NOTEBOOK_BUDGET=small``, import jaxfric from this checkout, start in a
folder outside the repository, and share the test session's persistent compilation cache
(tests/conftest.py sets it as an environment variable, which the kernels inherit), so
programs other tests compiled are not compiled again.

Each notebook writes what it claims (``JAXFRIC_NOTEBOOK_CLAIMS``): the sentences it printed
with the numbers they were made from, every comparison with its models' forms and the form
the data need, and the legend of every figure. :func:`check_claims` holds them to:

* every sentence is in the outputs, and every number in it is one of its measured values or
  a constant the notebook declares (the paper's numbers, fixed settings);
* no markdown cell quotes a percentage that is not such a constant (measured numbers are
  printed by the cells, never typed into the prose);
* every comparison includes the least-squares baseline, and every physical model in it has
  the form the data need, recomputed here from the direction-wise friction levels (the 5 %
  rule of ``jaxfric identify --form auto``); every lead quoted is recomputed from the values;
* every figure drawn for a comparison names every model of it in its legend;
* no output shows a temporary path or a kernel's file name (warnings print as one line).
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import pytest
from processes import jax_subprocess

nbformat = pytest.importorskip("nbformat", reason="needs nbformat (pip install jaxfric[test])")
nbclient = pytest.importorskip("nbclient", reason="needs nbclient (pip install jaxfric[test])")
pytest.importorskip("ipykernel", reason="needs ipykernel for the python3 kernel (pip install jaxfric[test])")

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
NAMES = ["01_test_functions", "02_friction_identification", "03_real_recordings", "04_motion_and_compensation",
         "05_your_own_csv"]

#: what a clean output never shows: a kernel's temporary file name, a temporary folder
LEAKS = re.compile(r"ipykernel_\d+|/tmp/|\\Temp\\|/var/folders/")
#: a number as the notebooks print them (not part of a word such as O-ring257 or sigma0)
NUMBER = re.compile(r"(?<![\w.])[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?(?![\w])", re.IGNORECASE)
PERCENT = re.compile(r"(?<![\w.])(\d+(?:\.\d+)?)\s?%")
#: --form auto: asymmetric when the sliding levels differ by more than this share of the level
FORM_THRESHOLD = 0.05


def _outputs(nb) -> str:
    parts = []
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        for o in cell.outputs:
            parts.append(o.get("text", ""))
            data = o.get("data", {})
            parts.append(data.get("text/markdown", ""))
            if "image/png" not in data:
                parts.append(data.get("text/plain", ""))
    return "\n".join(parts)


def _images(nb) -> int:
    return sum("image/png" in o.get("data", {}) for c in nb.cells if c.cell_type == "code" for o in c.outputs)


def _number_ok(token: str, allowed) -> bool:
    """``token`` is one of ``allowed`` as printed: rounded to the token's own precision."""
    x = float(token)
    mantissa, _, exp = token.lower().partition("e")
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    tol = 0.5 * 10.0 ** (-decimals) * (10.0 ** int(exp) if exp else 1.0)
    return any(abs(abs(float(v)) - abs(x)) <= tol * (1 + 1e-9) + 1e-12 for v in allowed)


def check_claims(nb, claims: dict) -> None:
    text = _outputs(nb)
    constants = [float(c) for c in claims["constants"]]
    # sentences: printed as recorded, made of their values
    for s in claims["sentences"]:
        assert s["text"] in text, f"sentence not in the outputs: {s['text']!r}"
        allowed = list(s["values"].values()) + constants
        for token in NUMBER.findall(s["text"]):
            assert _number_ok(token, allowed), f"{token} in {s['text']!r} is neither measured nor a constant"
    # prose: no measured percentage typed into a markdown cell
    for cell in nb.cells:
        if cell.cell_type == "markdown":
            for token in PERCENT.findall(cell.source):
                assert _number_ok(token, constants), f"markdown quotes {token} %: print it from a cell instead"
    # comparisons: fair, with the baseline, leads as measured
    names = set()
    for comp in claims["comparisons"]:
        names.add(comp["name"])
        form, models = comp["form"], comp["models"]
        if "mean_pos" in form:  # the --form auto rule, recomputed from the levels
            half = 0.5 * (form["mean_pos"] - form["mean_neg"])
            off = 0.5 * (form["mean_pos"] + form["mean_neg"])
            assert form["asymmetric"] == (abs(off) / abs(half) > FORM_THRESHOLD), comp["name"]
        assert any(m["kind"] == "baseline" for m in models), f"{comp['name']}: no least-squares baseline"
        for m in models:
            if m["kind"] == "physical":
                assert (m["asymmetric"], m["offset"]) == (form["asymmetric"], form["offset"]), (
                    f"{comp['name']}: {m['label']} is not in the form the data need ({form.get('reason')})")
        for lead in comp["leads"]:
            v = comp["values"]
            assert lead["percent"] == pytest.approx(100 * (1 - v[lead["model"]] / v[lead["over"]]), rel=1e-9)
    # figures: every model of their comparison in the legend
    for fig in claims["figures"]:
        if fig["comparison"] is None:
            continue
        assert fig["comparison"] in names, f"figure for an unknown comparison {fig['comparison']!r}"
        comp = next(c for c in claims["comparisons"] if c["name"] == fig["comparison"])
        for m in comp["models"]:
            assert any(m["label"] in label for label in fig["labels"]), (
                f"a figure of {comp['name']!r} does not show {m['label']!r}: {fig['labels']}")
    leak = LEAKS.search(text)
    assert leak is None, f"an output shows {leak.group(0)!r}: {text[max(0, leak.start() - 200):leak.end() + 100]}"


def test_there_are_five_notebooks_with_full_budget_outputs():
    assert [p.stem for p in NOTEBOOKS] == NAMES
    for path in NOTEBOOKS:
        nb = nbformat.read(path, as_version=4)
        text = _outputs(nb)
        assert "budget: full" in text, f"{path.name} is not committed with the outputs of a full run"
        assert not any(o.get("output_type") == "error" for c in nb.cells if c.cell_type == "code"
                       for o in c.outputs), f"{path.name} is committed with an error"
        leak = LEAKS.search(text)
        assert leak is None, f"{path.name} shows {leak.group(0)!r}"
        if "SKIPPED" not in text:
            assert _images(nb) >= MIN_FIGURES.get(path.stem, 3), path.name


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_is_built_from_its_percent_source(path):
    jupytext = pytest.importorskip("jupytext", reason="needs jupytext (pip install jaxfric[test])")
    source = path.with_suffix(".py")
    assert source.is_file(), f"{source.name} (the notebook's source) is missing"
    built = jupytext.read(source)
    committed = nbformat.read(path, as_version=4)
    cells = [(c.cell_type, c.source) for c in committed.cells]
    assert cells == [(c.cell_type, c.source) for c in built.cells], (
        f"{path.name} differs from {source.name}: run 'jupytext --to ipynb notebooks/{source.name}' "
        "and execute it again")


@pytest.fixture
def kernel_env(monkeypatch, tmp_path):
    """The kernels' environment: the small budget, this checkout first on the path
    (whatever an editable install elsewhere points at), and a file for the claims."""
    monkeypatch.setenv("JAXFRIC_NOTEBOOK_BUDGET", "small")
    monkeypatch.setenv("JAXFRIC_NOTEBOOK_CLAIMS", str(tmp_path / "claims"))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    return monkeypatch


#: figures each notebook draws at least under the small budget (01: the Table 1 chart and
#: the convergence of its one function)
MIN_FIGURES = {"01_test_functions": 2}


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs_with_the_small_budget(path, kernel_env, tmp_path):
    nb = nbformat.read(path, as_version=4)
    for cell in nb.cells:  # run it fresh: the committed outputs must not count
        if cell.cell_type == "code":
            cell.outputs, cell.execution_count = [], None
    elsewhere = tmp_path / "cwd"  # any working directory, not notebooks/
    elsewhere.mkdir()
    client = nbclient.NotebookClient(nb, kernel_name="python3", timeout=600,
                                     resources={"metadata": {"path": str(elsewhere)}})
    with jax_subprocess(notebook=True):  # the largest subprocess runs alone
        client.execute()  # raises CellExecutionError with the failing cell's traceback
    text = _outputs(nb)
    assert "budget: small" in text
    if "SKIPPED" not in text:
        assert _images(nb) >= MIN_FIGURES.get(path.stem, 3), f"{path.name} drew {_images(nb)} figures"
    claims = json.loads((tmp_path / "claims" / f"{path.stem}.json").read_text())
    assert claims["budget"] == "small"
    check_claims(nb, claims)


def test_real_recordings_notebook_skips_without_data(tmp_path, monkeypatch, capsys):
    """Without the data (offline, nothing in $JAXFRIC_DATA or the cache) every cell of the
    notebook runs and says what it skipped. The cells run in this process (a kernel adds
    nothing to the skip path, and test_notebook_runs_with_the_small_budget runs the
    notebook in a kernel)."""
    import matplotlib

    from jaxfric import datasets

    matplotlib.use("Agg")
    monkeypatch.setenv("JAXFRIC_NOTEBOOK_BUDGET", "small")
    monkeypatch.setenv("JAXFRIC_DATA", str(tmp_path / "absent"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv("JAXFRIC_EMPS_TEST", raising=False)
    monkeypatch.delenv("JAXFRIC_NOTEBOOK_CLAIMS", raising=False)

    def offline(url, dest):
        raise OSError("offline (test)")

    monkeypatch.setattr(datasets, "_download", offline)
    monkeypatch.chdir(tmp_path)
    path = ROOT / "notebooks" / "03_real_recordings.ipynb"
    nb = nbformat.read(path, as_version=4)
    namespace = {"__name__": "__main__"}
    for cell in (c for c in nb.cells if c.cell_type == "code"):
        lines = cell.source.splitlines()
        # the one IPython magic: the kernel's figure backend (Agg here)
        assert all(ln == "%matplotlib inline" for ln in lines if ln.startswith(("%", "!"))), cell.source
        exec(compile("\n".join(ln for ln in lines if not ln.startswith("%")), str(path), "exec"), namespace)
    text = capsys.readouterr().out
    assert "budget: small" in text
    assert "SKIPPED: no pneumatic_seal_friction data" in text
    assert "SKIPPED: no EMPS file" in text
    assert "Not scored: no EMPS test recording given" in text
    assert not (tmp_path / "absent").exists(), "nothing is written when nothing can be downloaded"
