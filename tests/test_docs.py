"""Every citation of the maths resolves to a section of ``docs/algorithms.md``.

Docstrings, benchmark scripts and the CLI help cite ``docs/algorithms.md §N`` (the
project's own copy of the equations). A citation whose section does not exist sends the
reader nowhere, so each one is checked against the file's headings.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "algorithms.md"
SEARCHED = ("jaxfric", "benchmarks", "notebooks")

# "algorithms.md §8.1-8.3", "ALGORITHMS.md §3.3 / §10", "algorithms.md §1, §11 step 2"
CITATION = re.compile(r"algorithms\.md((?:[\s,/;]*(?:and\s+)?§\s*\d+(?:\.\d+)?(?:\s*[-–]\s*\d+(?:\.\d+)?)?(?:\s+[a-z]+\s+\d+)?)+)", re.I)
SECTION = re.compile(r"§\s*(\d+(?:\.\d+)?)(?:\s*[-–]\s*(\d+(?:\.\d+)?))?")


def headings() -> set[str]:
    found = set()
    for line in DOC.read_text(encoding="utf-8").splitlines():
        m = re.match(r"^#{2,4} (\d+(?:\.\d+)*)[. ]", line)
        if m:
            found.add(m.group(1).rstrip("."))
    return found


def cited_sections(text: str) -> list[str]:
    out = []
    for m in CITATION.finditer(text):
        for s in SECTION.finditer(m.group(1)):
            out.extend(x for x in s.groups() if x)
    return out


def source_texts():
    for folder in SEARCHED:
        for path in sorted((ROOT / folder).rglob("*.py")):
            yield str(path.relative_to(ROOT)), path.read_text(encoding="utf-8")


def cli_help_texts():
    """The help of ``jaxfric`` and of each sub-command, as a user sees it."""
    from jaxfric.cli.parser import build_parser

    parser = build_parser()
    yield "jaxfric --help", parser.format_help()
    for action in parser._subparsers._group_actions:  # argparse keeps sub-parsers here
        for name, sub in action.choices.items():
            yield f"jaxfric {name} --help", sub.format_help()


def test_the_parser_reads_every_citation_form():
    text = ("(ALGORITHMS.md §8.1-8.3) docs/algorithms.md §3.3 / §10; algorithms.md §1, §11 step 2 "
            "and algorithms.md §2.4 last bullet")
    assert cited_sections(text) == ["8.1", "8.3", "3.3", "10", "1", "11", "2.4"]


def test_doc_keeps_the_spec_section_numbers():
    # §0–§13 map one to one onto the specification; §14 adds this release, §15 references
    have = headings()
    expected = {str(i) for i in range(16)} | {
        "2.1", "2.2", "2.3", "2.4", "3.1", "3.2", "3.3", "3.4", "3.5", "5.1",
        "8.1", "8.2", "8.3", "8.4", "8.5", "13.1", "13.2", "13.3",
        "14.1", "14.2", "14.3", "14.4", "14.5", "14.6",
    }
    assert expected <= have, sorted(expected - have)


def test_doc_states_a_default_for_design_choices():
    text = DOC.read_text(encoding="utf-8")
    for tag in ("[P]", "[S]", "[R]", "[D]", "[?]"):
        assert tag in text
    assert text.count("**jaxfric default.**") >= 15
    for ref in ("Zhao", "Shi, Y., Eberhart", "Lagarias", "Gao, F., Han", "Canudas de Wit",
                "Al-Bender", "Elman, J. L.", "Janot", "Karnopp"):
        assert ref in text, ref


def test_every_citation_in_code_resolves():
    have = headings()
    missing = []
    for where, text in list(source_texts()) + list(cli_help_texts()):
        for section in cited_sections(text):
            if section not in have:
                missing.append(f"{where}: §{section}")
    assert not missing, "citations of missing sections:\n" + "\n".join(missing)


def test_citations_point_at_the_shipped_file():
    # ALGORITHMS.md is the specification outside the repository; a reader can only open
    # docs/algorithms.md.
    stale = []
    for where, text in list(source_texts()) + list(cli_help_texts()):
        for i, line in enumerate(text.splitlines(), 1):
            if "ALGORITHMS.md" in line:
                stale.append(f"{where}:{i}")
    assert not stale, "citations of the specification outside the repository: " + ", ".join(stale[:10])


# ------------------------------------------------------------------ the documentation site
def test_documentation_site_builds_with_warnings_as_errors(tmp_path):
    """``mkdocs build --strict``: every page, link, nav entry and API reference (the
    docstrings through mkdocstrings) builds without a warning. mkdocs comes with the
    ``test`` extra, so CI always builds the site."""
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                          cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    site = tmp_path / "site"
    for page in ("index.html", "algorithms/index.html", "api/identification/index.html",
                 "howto/identify-csv/index.html", "howto/gpu/index.html"):
        assert (site / page).is_file(), page
    # the API reference holds the docstrings, not only the headings
    api = (site / "api" / "identification" / "index.html").read_text(encoding="utf-8")
    assert "Fit" in api and "search box" in api.lower()


def test_every_nav_page_exists_or_is_an_optional_guide():
    """The nav lists real pages; the only entries the build may leave out are the guides of
    the hook's OPTIONAL set (pages other parts of the project add)."""
    import importlib.util

    import yaml

    spec = importlib.util.spec_from_file_location("optional_pages", ROOT / "docs" / "hooks" / "optional_pages.py")
    hook = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hook)
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))

    def pages(items):
        for item in items:
            value = next(iter(item.values())) if isinstance(item, dict) else item
            if isinstance(value, list):
                yield from pages(value)
            else:
                yield value

    listed = list(pages(config["nav"]))
    missing = [p for p in listed if not (ROOT / "docs" / p).is_file()]
    assert set(missing) <= hook.OPTIONAL, missing
    # and the hook keeps a present page while dropping an absent optional one
    kept = hook._prune([{"a": "index.md"}, {"b": "scale.md"}], str(ROOT / "docs"))
    assert {"a": "index.md"} in kept
    assert ({"b": "scale.md"} in kept) == (ROOT / "docs" / "scale.md").is_file()


def test_documentation_code_names_exist():
    """Every Python block of the site compiles, and every ``jf.NAME`` (and ``jf.rig.NAME``,
    ``jf.datasets.NAME``, ...) it uses exists: the how-to pages cannot drift from the API
    without this failing. (The README's blocks are run by test_readme.py.)"""
    import jaxfric as jf

    checked = 0
    for path in sorted((ROOT / "docs").rglob("*.md")):
        text = path.read_text(encoding="utf-8")
        for block in re.findall(r"^```python\n(.*?)^```", text, re.S | re.M):
            compile(block, str(path), "exec")
            for sub, name in re.findall(r"\bjf\.(?:(\w+)\.)?(\w+)", block):
                owner = getattr(jf, sub) if sub else jf  # a submodule (jf.rig) or a class (jf.MotionData)
                assert hasattr(owner, name), f"{path.name}: jf.{sub + '.' if sub else ''}{name}"
                checked += 1
    assert checked >= 15
