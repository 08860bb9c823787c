"""Every notebook in notebooks/ is built from its plain-text source and runs top to bottom
with the small budget.

The sources are jupytext percent-format files (``notebooks/01_test_functions.py`` ...);
edit those, then rebuild the committed notebooks without outputs::

    jupytext --to ipynb notebooks/0*.py

Kernels get ``JAXFRIC_NOTEBOOK_BUDGET=small``, import jaxfric from this checkout, and
share the test session's persistent compilation cache (tests/conftest.py sets it as an
environment variable, which the kernels inherit), so programs other tests compiled are
not compiled again.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from processes import jax_subprocess

nbformat = pytest.importorskip("nbformat", reason="needs nbformat (pip install jaxfric[test])")
nbclient = pytest.importorskip("nbclient", reason="needs nbclient (pip install jaxfric[test])")
pytest.importorskip("ipykernel", reason="needs ipykernel for the python3 kernel (pip install jaxfric[test])")

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


def test_there_are_four_notebooks_without_outputs():
    assert [p.name for p in NOTEBOOKS] == ["01_test_functions.ipynb", "02_friction_identification.ipynb",
                                           "03_real_recordings.ipynb", "04_motion_and_compensation.ipynb"]
    for path in NOTEBOOKS:
        nb = nbformat.read(path, as_version=4)
        for cell in nb.cells:
            if cell.cell_type == "code":
                assert not cell.outputs and cell.execution_count is None, f"{path.name} is committed with outputs"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_is_built_from_its_percent_source(path):
    jupytext = pytest.importorskip("jupytext", reason="needs jupytext (pip install jaxfric[test])")
    source = path.with_suffix(".py")
    assert source.is_file(), f"{source.name} (the notebook's source) is missing"
    built = jupytext.read(source)
    committed = nbformat.read(path, as_version=4)
    cells = [(c.cell_type, c.source) for c in committed.cells]
    assert cells == [(c.cell_type, c.source) for c in built.cells], (
        f"{path.name} differs from {source.name}: run 'jupytext --to ipynb notebooks/{source.name}'")


@pytest.fixture
def kernel_env(monkeypatch):
    """The kernels' environment: the small budget, and this checkout first on the path
    (whatever an editable install elsewhere points at)."""
    monkeypatch.setenv("JAXFRIC_NOTEBOOK_BUDGET", "small")
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    return monkeypatch


#: figures each notebook draws at least under the small budget (01: the Table 1 chart and
#: the convergence of its one function)
MIN_FIGURES = {"01_test_functions": 2}


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs_with_the_small_budget(path, kernel_env):
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(nb, kernel_name="python3", timeout=600,
                                     resources={"metadata": {"path": str(path.parent)}})
    with jax_subprocess(notebook=True):  # the largest subprocess runs alone
        client.execute()  # raises CellExecutionError with the failing cell's traceback
    text = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.outputs)
    assert "budget: small" in text
    images = sum("image/png" in o.get("data", {}) for c in nb.cells if c.cell_type == "code" for o in c.outputs)
    if "SKIPPED" not in text:
        assert images >= MIN_FIGURES.get(path.stem, 3), f"{path.name} drew {images} figures"


def test_real_recordings_notebook_skips_without_data(tmp_path, monkeypatch, capsys):
    """Without the data every cell of the committed notebook runs and says what it skipped.
    The cells run in this process (a kernel adds nothing to the skip path, and
    test_notebook_runs_with_the_small_budget runs the notebook in a kernel)."""
    import matplotlib

    matplotlib.use("Agg")
    monkeypatch.setenv("JAXFRIC_NOTEBOOK_BUDGET", "small")
    monkeypatch.setenv("JAXFRIC_PNEUMATIC_DATA", str(tmp_path / "absent"))
    monkeypatch.setenv("JAXFRIC_EMPS", str(tmp_path / "absent" / "DATA_EMPS.mat"))
    path = ROOT / "notebooks" / "03_real_recordings.ipynb"
    monkeypatch.chdir(path.parent)  # the notebook's default data paths are relative to it
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
