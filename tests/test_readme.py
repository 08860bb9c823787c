"""The README is a user's page that works as written: every Python block runs (those that
need the real data run on the local copies in ../shared/data and are skipped without them)
and prints what the output block after it shows, the set-up commands are the ones CI runs,
every link resolves, and every number of the results table is in the results file its row
links to.

What the output blocks show and the tests compare exactly: sample and parameter counts,
evaluation and step counts of fixed budgets, the table layout, and the EMPS recipe's MSE and
warning (a least-squares optimum, the same on every CPU). Machine-dependent, not compared:
every time, and the quick start's MSE, MAX, FIT, R2 and J values (float32 rounding differs
between CPUs and the network's free run amplifies it; docs/reproducibility.md)."""

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


def code_and_output() -> list[tuple[str, str | None]]:
    """Each Python block with the ``text`` block that follows it before the next code block
    (what it prints), or ``None``."""
    out = []
    for m in re.finditer(r"^```(\w+)\n(.*?)^```", README, re.S | re.M):
        if m.group(1) == "python":
            out.append([m.group(2), None])
        elif m.group(1) == "text" and out and out[-1][1] is None:
            out[-1][1] = m.group(2)
        elif m.group(1) != "text" and out and out[-1][1] is None:
            out[-1][1] = ""  # another code block first: this one shows no output
    return [(code, shown or None) for code, shown in out]


def _python_params():
    out = []
    for i, (code, shown) in enumerate(code_and_output()):
        marks = [pytest.mark.slow]
        if "jf.datasets" in code:
            marks.append(pytest.mark.skipif(not HAVE_DATA, reason="no local copy of the data in ../shared/data"))
        out.append(pytest.param(code, shown, id=f"block{i}", marks=marks))
    return out


def _masked(line: str) -> str:
    """``line`` of the quick start's summary with its machine-dependent numbers replaced by
    ``#``: all of a metrics or time row, the J values of the stage line; the sample,
    evaluation and step counts stay."""
    number = r"-?\d+(\.\d+)?(e[-+]?\d+)?" if line.startswith(("train", "valid", "all", "time")) \
        else r"-?\d+\.\d+(e[-+]?\d+)?"
    return " ".join(re.sub(number, "#", line).split())


def test_readme_has_its_examples():
    assert len(blocks("python")) >= 3
    assert any("progress=True" in b for b in blocks("python")), "the quick start shows its progress"


def test_every_print_shows_its_output():
    """A block that prints is followed by the output it prints."""
    for code, shown in code_and_output():
        if "print(" in code and "cmp.table()" not in code:  # the motion block's table: docs/motion.md
            assert shown, code[:200]


@pytest.mark.parametrize("code, shown", _python_params())
def test_every_python_block_runs_as_written(code, shown, tmp_path):
    # the data sets are read from the local copy; the network is never needed here
    env = dict(os.environ, PYTHONPATH=str(ROOT), JAXFRIC_DATA=str(SHARED_DATA),
               XDG_CACHE_HOME=str(tmp_path / "cache"))
    with jax_subprocess():
        proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True,
                              text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    if "print(fit.summary())" in code and "elman" in code:
        # the quick start: the same lines, counts and budgets; its decimals are machine-dependent
        shown_lines, printed = shown.splitlines(), proc.stdout.splitlines()
        assert printed[0] == shown_lines[0]  # model, parameter and sample counts
        assert [_masked(x) for x in printed] == [_masked(x) for x in shown_lines]
        valid = next(x for x in printed if x.startswith("valid "))
        assert float(valid.split()[1]) < 1.0  # an excellent fit on any CPU (MSE % below 1)
        assert "jaxfric" in proc.stderr or "gen/s" in proc.stderr, "no progress bar"
    if "validation MSE" in code:
        # the EMPS recipe: its MSE and its warning, on stdout and stderr, exactly as shown
        lines = shown.splitlines()
        assert proc.stdout.splitlines() == lines[:1]
        for line in lines[1:]:
            assert line in " ".join(proc.stderr.split()), line


def test_the_two_set_up_commands():
    """Command 1 installs and runs the main job; command 2 is exactly what .ci/run runs."""
    bash = "\n".join(blocks("bash"))
    assert "pip install -e . && jaxfric demo" in bash
    ci = [ln.strip() for ln in (ROOT / ".ci" / "run").read_text().splitlines()]
    install = next(ln for ln in ci if "pip install -e" in ln)
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
    assert len(lines) <= 220
    for word in ("session", "issue ", "round "):
        assert word not in README.lower(), word
    assert not re.search(r"\b\d+\.\d+\.\d+\b", README), "version narration belongs in CHANGELOG.md"
    for section in ("## Install", "## Quick start", "## Command line", "## Results", "## Known limitations",
                    "## Citing jaxfric", "## Licence"):
        assert section in README, section
    assert (ROOT / "LICENSE").read_text().count("Apache License") >= 1
    assert "cff-version" in (ROOT / "CITATION.cff").read_text()
