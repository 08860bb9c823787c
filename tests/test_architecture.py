"""The README's architecture holds: imports go down the layers (issue 19), checked on the
source with ``ast`` (module-level and function-level imports alike)."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "jaxfric"

#: docs/architecture.md's order: cli → report, plot, sweeps → identification, motion,
#: compensation, parallel_scan, uncertainty → fit → export, datasets, covariance → optim,
#: models, rig, metrics, functions → records, files, plausibility, styles → compiler helpers and
#: the warning categories.
LAYER = {"cli": 8, "report": 7, "plot": 7, "sweeps": 7, "identification": 6, "motion": 6, "compensation": 6,
         "parallel_scan": 6, "uncertainty": 6,
         "fit": 5, "export": 4, "datasets": 4, "covariance": 4, "optim": 3, "models": 3, "rig": 3, "metrics": 3, "functions": 3,
         "records": 2, "files": 2, "plausibility": 2, "styles": 2, "_xla": 1, "_timing": 1, "_warnings": 1}


def _imported_subpackages(path: Path):
    """``(line, first component under jaxfric)`` of every jaxfric import in ``path``;
    ``None`` for the package root."""
    pkg = path.relative_to(ROOT).parent.parts
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            base = list(pkg)[: len(pkg) - (node.level - 1)]
            full = base + (node.module.split(".") if node.module else [])
            if full:
                yield node.lineno, full[0]
            else:
                for a in node.names:
                    yield node.lineno, a.name
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("jaxfric"):
            parts = node.module.split(".")
            yield node.lineno, parts[1] if len(parts) > 1 else None
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("jaxfric."):
                    yield node.lineno, a.name.split(".")[1]


def test_every_module_is_in_a_layer():
    tops = {p.relative_to(ROOT).with_suffix("").parts[0] for p in ROOT.rglob("*.py")}
    assert tops - {"__init__", "__main__"} <= set(LAYER), sorted(tops - set(LAYER))


def test_imports_go_down():
    upward = []
    for path in ROOT.rglob("*.py"):
        me = path.relative_to(ROOT).with_suffix("").parts[0]
        if me in ("__init__", "__main__"):
            continue
        for line, target in _imported_subpackages(path):
            if target is None:  # the package root re-exports every layer: only the CLI may use it
                if me != "cli":
                    upward.append(f"{path.relative_to(ROOT)}:{line} imports the package root")
            elif LAYER.get(target, 0) > LAYER[me]:
                upward.append(f"{path.relative_to(ROOT)}:{line} ({me}) imports {target}")
    assert not upward, upward


#: Inside ``jaxfric.optim`` a module imports only modules listed before it (module-level
#: and function-level imports alike), so the package has no import circle: the pieces
#: every solver shares, the checks of a problem, the evaluation rounds and the loop that
#: compiles them, ask/tell over that loop, the solver contract, the solvers, the chains,
#: then the one driver that runs them all.
OPTIM_ORDER = ["rng", "progress", "sharding", "checkpoint", "_base", "problem", "rounds",
               "loop", "asktell", "contract",
               "swarm", "nelder_mead", "pso", "mapso", "optx_adapter", "chained", "hybrid",
               "evosax_adapter", "driver", "__init__"]


def _imported_modules(path: Path, package: str):
    """``(line, module)`` of every import of a sibling module of ``path`` inside
    ``jaxfric.<package>``, at module level or inside a function."""
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            if node.module:
                yield node.lineno, node.module.split(".")[0]
            else:
                for a in node.names:
                    yield node.lineno, a.name
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith(
                f"jaxfric.{package}."):
            yield node.lineno, node.module.split(".")[2]
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith(f"jaxfric.{package}."):
                    yield node.lineno, a.name.split(".")[2]


def test_optim_modules_import_only_earlier_ones():
    folder = ROOT / "optim"
    modules = {p.stem for p in folder.glob("*.py")}
    assert modules == set(OPTIM_ORDER), ("place every optim module in OPTIM_ORDER",
                                         sorted(modules ^ set(OPTIM_ORDER)))
    later = []
    for path in folder.glob("*.py"):
        rank = OPTIM_ORDER.index(path.stem)
        for line, target in _imported_modules(path, "optim"):
            if target in modules and OPTIM_ORDER.index(target) >= rank:
                later.append(f"optim/{path.name}:{line} imports {target}")
    assert not later, later


def _cycle(graph: dict) -> list | None:
    """A cycle of ``graph`` (module -> imported modules), or ``None``."""
    state: dict = {}

    def visit(node, trail):
        state[node] = "open"
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == "open":
                return trail[trail.index(nxt):] + [nxt] if nxt in trail else [node, nxt]
            if nxt not in state:
                found = visit(nxt, trail + [nxt])
                if found:
                    return found
        state[node] = "done"
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node, [node])
            if found:
                return found
    return None


def test_the_cycle_finder_finds_a_cycle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set(), "c": {"a"}}) is None


def test_no_import_circle_inside_the_optimisers_or_the_command_line():
    for package in ("optim", "cli"):
        folder = ROOT / package
        modules = {p.stem for p in folder.glob("*.py")} - {"__init__"}
        graph = {p.stem: {t for _, t in _imported_modules(p, package) if t in modules}
                 for p in folder.glob("*.py") if p.stem in modules}
        assert _cycle(graph) is None, (package, _cycle(graph))


def _layer_graph() -> dict:
    """jaxfric's top-level modules and packages -> those they import, module-level and
    function-level imports alike (the package root left out: only the CLI imports it)."""
    graph: dict = {}
    for path in ROOT.rglob("*.py"):
        me = path.relative_to(ROOT).with_suffix("").parts[0]
        if me not in ("__init__", "__main__"):
            graph.setdefault(me, set()).update(
                t for _, t in _imported_subpackages(path) if t not in (None, me))
    return graph


def test_no_import_circle_anywhere():
    """The layer rule lets modules of one layer import each other, and an import inside a
    function hides a circle from Python until it runs: there is none between top-level
    modules, nor between the modules of any package."""
    assert _cycle(_layer_graph()) is None, _cycle(_layer_graph())
    for folder in (p for p in ROOT.iterdir() if (p / "__init__.py").exists()):
        modules = {p.stem for p in folder.glob("*.py")} - {"__init__"}
        graph = {p.stem: {t for _, t in _imported_modules(p, folder.name) if t in modules}
                 for p in folder.glob("*.py") if p.stem in modules}
        assert _cycle(graph) is None, (folder.name, _cycle(graph))
