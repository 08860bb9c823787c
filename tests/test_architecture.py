"""The README's architecture holds: imports go down the layers (issue 19), checked on the
source with ``ast`` (module-level and function-level imports alike)."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "jaxfric"

#: The README's order: cli → report, plot → identification, motion, compensation → fit →
#: export → optim, models, rig, metrics, functions → records, files → compiler helpers and
#: the warning categories.
LAYER = {"cli": 8, "report": 7, "plot": 7, "identification": 6, "motion": 6, "compensation": 6,
         "fit": 5, "export": 4, "datasets": 4, "optim": 3, "models": 3, "rig": 3, "metrics": 3, "functions": 3,
         "records": 2, "files": 2, "_xla": 1, "_timing": 1, "_warnings": 1}


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
