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
SITE_PACKAGES = ("mkdocs", "material", "mkdocstrings_handlers.python", "mkdocs_jupyter")
# a Sphinx role left in a docstring: mkdocstrings prints it as text instead of a link
RAW_ROLE = re.compile(r":(?:py:)?(?:class|func|meth|data|attr|mod|exc|obj|ref|const):(?:`|<code>)")


@pytest.fixture(scope="module")
def built_site(tmp_path_factory):
    """The site, built once for this module by ``mkdocs build --strict`` (warnings are
    errors: a broken link, a missing page, a cross-reference to nothing, a docstring the
    API reference cannot render). Skipped when the ``docs`` extra is not installed."""
    import importlib.util
    import subprocess
    import sys

    for name in SITE_PACKAGES:
        if importlib.util.find_spec(name.split(".")[0]) is None or importlib.util.find_spec(name) is None:
            pytest.skip(f"{name} is not installed (pip install -e '.[docs]')")
    site = tmp_path_factory.mktemp("docs") / "site"
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
                          cwd=ROOT, capture_output=True, text=True, timeout=900,
                          env={**__import__("os").environ, "NO_MKDOCS_2_WARNING": "1"})
    assert proc.returncode == 0, proc.stdout[-5000:] + proc.stderr[-5000:]
    return site


def test_documentation_site_builds_with_warnings_as_errors(built_site):
    """``mkdocs build --strict`` passes, with every kind of page present."""
    site = built_site
    for page in ("index.html", "algorithms/index.html", "api/identification/index.html",
                 "api/index.html", "howto/identify-csv/index.html", "howto/motion/index.html",
                 "howto/gpu/index.html", "notebooks/01_test_functions/index.html",
                 "notebooks/04_motion_and_compensation/index.html"):
        assert (site / page).is_file(), page
    # the API reference holds the docstrings, not only the headings
    api = (site / "api" / "identification" / "index.html").read_text(encoding="utf-8")
    assert "Fit" in api and "search box" in api.lower()
    # the maths is typeset by the KaTeX served with the site (no network needed)
    algorithms = (site / "algorithms" / "index.html").read_text(encoding="utf-8")
    assert 'class="arithmatex"' in algorithms
    assert (site / "javascripts" / "katex" / "katex.min.js").is_file()
    assert "katex-render.js" in algorithms


def test_site_has_no_raw_sphinx_roles_and_links_jaxfric_names(built_site):
    """mkdocstrings does not resolve Sphinx roles (``:class:`Fit```): a docstring must
    write a cross-reference (``[`Fit`][jaxfric.fit.Fit]``), which the site shows as a link."""
    raw = []
    for page in sorted(built_site.rglob("*.html")):
        text = page.read_text(encoding="utf-8")
        for m in RAW_ROLE.finditer(text):
            raw.append(f"{page.relative_to(built_site)}: {text[m.start():m.start() + 60]!r}")
    assert not raw, f"{len(raw)} raw Sphinx roles in the site:\n" + "\n".join(raw[:20])
    api = (built_site / "api" / "optim" / "index.html").read_text(encoding="utf-8")
    assert api.count('class="autorefs autorefs-internal"') >= 20


def test_docstrings_use_cross_references_not_sphinx_roles():
    """The source-side twin of the test above, which runs without the docs extra: no
    Sphinx role (``:func:`x```) in jaxfric's docstrings or comments."""
    found = []
    for path in sorted((ROOT / "jaxfric").rglob("*.py")):
        for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if re.search(r":(?:class|func|meth|data|attr|mod|exc|obj):`", line):
                found.append(f"{path.relative_to(ROOT)}:{i}")
    assert not found, ("Sphinx roles; write [`name`][jaxfric.module.name] instead:\n"
                       + "\n".join(found[:30]))


def test_every_document_a_docstring_cites_is_shipped():
    """A docstring that cites ``docs/solvers.md``, ``benchmarks/results/motion.md`` or
    ``README.md`` sends the reader to a file of this repository; an unshipped one (a design
    note outside it) sends them nowhere. Bare lower-case names (``report.md``) are files
    jaxfric writes, not citations."""
    cited = set()
    for path in sorted((ROOT / "jaxfric").rglob("*.py")):
        for name in re.findall(r"(?<![\w./-])((?:[\w-]+/)+[\w.-]+\.md|[A-Z][A-Z_]+\.md)\b",
                               path.read_text(encoding="utf-8")):
            cited.add((name, str(path.relative_to(ROOT))))
    missing = sorted(f"{where}: {name}" for name, where in cited if not (ROOT / name).is_file())
    assert not missing, "citations of files the project does not ship:\n" + "\n".join(missing)
    assert any(name == "docs/algorithms.md" for name, _ in cited)


# every public name of these modules has an entry in the API reference (docs/api/*.md)
API_MODULES_SKIPPED = {"jaxfric.cli"}  # the command line, documented by ``jaxfric --help``


def _griffe_package():
    griffe = pytest.importorskip("griffe")
    return griffe.load("jaxfric", search_paths=[str(ROOT)], resolve_aliases=True, resolve_implicit=True)


def _lookup(pkg, path: str):
    """The griffe object at ``path``, through aliases and jaxfric's lazy top-level names."""
    import jaxfric

    parts = path.split(".")[1:]
    if parts and parts[0] in jaxfric._LAZY:  # ``jaxfric.identify`` is ``jaxfric.identification.identify``
        where = jaxfric._LAZY[parts[0]]
        parts = (where.strip(".").split(".") if where else []) + parts
    obj = pkg
    for part in parts:
        obj = obj.all_members[part] if obj.is_class else obj.members[part]
        if obj.is_alias:
            obj = obj.final_target
    return obj


def _documented(pkg) -> set[str]:
    """Canonical paths of everything ``docs/api/*.md`` documents: each ``::: identifier``
    and, for a module, the members it lists (``members: [...]``), or its ``__all__``."""
    import yaml

    out = set()
    for page in sorted((ROOT / "docs" / "api").glob("*.md")):
        lines = page.read_text(encoding="utf-8").splitlines()
        for i, line in enumerate(lines):
            m = re.match(r"^::: ([\w.]+)\s*$", line)
            if not m:
                continue
            block = []
            for follow in lines[i + 1:]:
                if follow.startswith("    ") or not follow.strip():
                    block.append(follow[4:])
                else:
                    break
            options = (yaml.safe_load("\n".join(block)) or {}).get("options", {}) if block else {}
            obj = _lookup(pkg, m.group(1))
            out.add(obj.canonical_path)
            if obj.is_module:
                members = options.get("members", None)
                if members is None:
                    members = (obj.exports if obj.exports is not None else
                               [n for n, o in obj.members.items() if not n.startswith("_") and not o.is_alias])
                for name in members or []:
                    out.add(_lookup(pkg, f"{obj.path}.{name}").canonical_path)
    return out


def test_every_public_name_has_an_api_entry():
    """Each name in ``jaxfric.__all__`` and in the ``__all__`` of each public subpackage
    (``jaxfric.motion``, ``jaxfric.optim``, ``jaxfric.models``, ...) is documented in
    ``docs/api/*.md``: a ``::: identifier`` line, or a member listed under one. A name
    re-exported in several places is documented once, in any of them."""
    pkg = _griffe_package()
    documented = _documented(pkg)
    modules = ["jaxfric"] + sorted(
        m.path for m in pkg.modules.values()
        if not m.is_alias and not m.name.startswith("_") and m.exports is not None and m.path not in API_MODULES_SKIPPED)
    assert {"jaxfric.motion", "jaxfric.optim", "jaxfric.models", "jaxfric.rig", "jaxfric.uncertainty",
            "jaxfric.sweeps", "jaxfric.datasets", "jaxfric.plausibility"} <= set(modules)
    missing = []
    for module in modules:
        names = __import__("importlib").import_module(module).__all__
        for name in names:
            if _lookup(pkg, f"{module}.{name}").canonical_path not in documented:
                missing.append(f"{module}.{name}")
    assert not missing, "public names without an entry in docs/api/*.md: " + ", ".join(missing)


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
    # the tutorials are the committed notebooks, added to the site by docs/hooks/notebooks.py
    missing = [p for p in listed if not (ROOT / ("" if p.startswith("notebooks/") else "docs") / p).is_file()]
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
