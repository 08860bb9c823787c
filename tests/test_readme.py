"""The README is a user's page that works as written: every Python block runs (those that
need the real data run on the local copies in ../shared/data and are skipped without them),
the set-up commands are the ones CI runs, every link resolves, and every number of the
results table is in the results file its row links to."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from processes import jax_subprocess

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
SHARED_DATA = ROOT.parent / "shared" / "data"
HAVE_DATA = (SHARED_DATA / "emps" / "DATA_EMPS.mat").is_file()


def blocks(language: str) -> list[str]:
    return re.findall(rf"^```{language}\n(.*?)^```", README, re.S | re.M)


def _python_params():
    out = []
    for i, code in enumerate(blocks("python")):
        marks = [pytest.mark.slow]
        if "jf.datasets" in code:
            marks.append(pytest.mark.skipif(not HAVE_DATA, reason="no local copy of the data in ../shared/data"))
        out.append(pytest.param(code, id=f"block{i}", marks=marks))
    return out


def test_readme_has_its_examples():
    assert len(blocks("python")) >= 3
    assert any("progress=True" in b for b in blocks("python")), "the quick start shows its progress"


@pytest.mark.parametrize("code", _python_params())
def test_every_python_block_runs_as_written(code, tmp_path):
    # the data sets are read from the local copy; the network is never needed here
    env = dict(os.environ, PYTHONPATH=str(ROOT), JAXFRIC_DATA=str(SHARED_DATA),
               XDG_CACHE_HOME=str(tmp_path / "cache"))
    with jax_subprocess():
        proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True,
                              text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    if "print(fit.summary())" in code and "elman" in code:
        # the quick start prints what the README shows: the same table layout and stages
        shown = blocks("text")[0].splitlines()
        printed = proc.stdout.splitlines()
        assert printed[0] == shown[0]
        for row in ("window      MSE %", "train ", "valid ", "all ", "stages: mapso J=", "time [s]: compile"):
            assert any(line.startswith(row) for line in printed), row
        assert "jaxfric" in proc.stderr or "gen/s" in proc.stderr, "no progress bar"
    if "validation MSE" in code:
        shown = re.search(r"# (\d+\.\d+) %; least squares", code).group(1)
        assert f"validation MSE {shown} %" in proc.stdout


def test_the_two_set_up_commands():
    """Command 1 installs and runs the main job; command 2 is exactly what .ci/run runs."""
    bash = "\n".join(blocks("bash"))
    assert "pip install -e . && jaxfric demo" in bash
    ci = [ln.strip() for ln in (ROOT / ".ci" / "run").read_text().splitlines()]
    install = next(ln for ln in ci if "pip install" in ln)
    test = next(ln for ln in ci if ln.startswith("python -m pytest"))
    assert f"{install} && {test}" in bash.splitlines()


def test_links_resolve():
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", README):
        if target.startswith("http"):
            continue
        assert (ROOT / target).exists(), target


def test_results_table_numbers_come_from_the_linked_files():
    table = [ln for ln in README.split("## Results", 1)[1].splitlines() if ln.startswith("| ")][2:]
    assert len(table) >= 3
    for row in table:
        files = re.findall(r"\((benchmarks/results/[^)]+\.md)\)", row)
        assert files, row
        text = "".join((ROOT / f).read_text(encoding="utf-8") for f in files)
        cells = row.split("|")[1:-2]  # every cell but the last (the file and the command)
        for cell in cells[1:]:
            for number in re.findall(r"\d+\.\d+", cell):
                assert _rounds_from(number, text), (number, files)
        assert "python benchmarks/" in row.split("|")[-2]
        command = re.search(r"`(python benchmarks/[^`]+)`", row).group(1)
        assert command.split()[1] in text or command in text, command


def _rounds_from(number: str, text: str) -> bool:
    """``number`` (as printed, d decimals) is a number of ``text`` rounded to d decimals."""
    d = len(number.split(".")[1])
    return any(len(y.split(".")[1]) >= d and f"{float(y):.{d}f}" == number
               for y in re.findall(r"\d+\.\d+", text))


def test_readme_is_a_users_page():
    lines = README.splitlines()
    assert len(lines) <= 230
    for word in ("session", "issue ", "round "):
        assert word not in README.lower(), word
    assert not re.search(r"\b\d+\.\d+\.\d+\b", README), "version narration belongs in CHANGELOG.md"
    for section in ("## Install", "## Quick start", "## Command line", "## Results", "## Known limitations",
                    "## Citing jaxfric", "## Licence"):
        assert section in README, section
    assert (ROOT / "LICENSE").read_text().count("Apache License") >= 1
    assert "cff-version" in (ROOT / "CITATION.cff").read_text()
