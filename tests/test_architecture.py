"""The README's architecture holds: imports go down the layers (issue 19), checked on the
source with ``ast`` (module-level and function-level imports alike)."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "jaxfric"

#: docs/architecture.md's order: cli → report, plot, sweeps → identification, motion,
#: compensation, uncertainty → fit, pipeline → export, datasets, covariance, problem → optim,
#: models, rig, metrics, functions → records, files, plausibility, styles → compiler helpers and
#: the warning categories.
LAYER = {"cli": 8, "report": 7, "plot": 7, "sweeps": 7, "identification": 6, "motion": 6, "compensation": 6,
         "uncertainty": 6,
         "fit": 5, "pipeline": 5, "export": 4, "datasets": 4, "covariance": 4, "problem": 4, "optim": 3, "models": 3, "rig": 3, "metrics": 3, "functions": 3,
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
#: every solver shares, the evaluation rounds, the solver contract (which knows nothing of
#: ask/tell), the checks of a problem, the loop that compiles the rounds, the solvers,
#: ask/tell over the loop (a driver beside ``minimise``), the chains, then the one driver
#: that runs them all.
OPTIM_ORDER = ["rng", "progress", "sharding", "checkpoint", "_base", "rounds", "contract",
               "problem", "loop",
               "swarm", "nelder_mead", "pso", "mapso", "optx_adapter", "asktell", "chained",
               "hybrid", "evosax_adapter", "template", "driver", "__init__"]


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


def _jaxfric_module(path: Path) -> list[str]:
    """``path``'s dotted name under jaxfric as parts: ``motion/_api.py`` -> ``["motion", "_api"]``
    (a package's ``__init__`` is the package itself)."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return parts[:-1] if parts[-1] == "__init__" else parts


def _is_private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def _imported_paths(path: Path):
    """``(line, dotted parts under jaxfric)`` of every name ``path`` takes from jaxfric:
    ``from ..identification._api import x`` gives ``identification._api.x``, ``from
    ..motion import _compare`` gives ``motion._compare``, and an attribute read on an
    imported jaxfric module (``_api._fast_pipeline``) gives its full path too."""
    here = _jaxfric_module(path)
    package = list(path.relative_to(ROOT).parent.parts)
    tree = ast.parse(path.read_text())
    modules: dict[str, list[str]] = {}  # local name -> jaxfric path of an imported module
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
            elif (node.module or "").split(".")[0] == "jaxfric":
                base = []
            else:
                continue
            module = base + [p for p in (node.module or "").split(".") if p and p != "jaxfric"]
            if not node.level and (node.module or "").startswith("jaxfric"):
                module = node.module.split(".")[1:]
            for a in node.names:
                full = module + [a.name]
                target = ROOT.joinpath(*full)
                if target.is_dir() or target.with_suffix(".py").exists():
                    modules[a.asname or a.name] = full
                yield node.lineno, full
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("jaxfric."):
                    full = a.name.split(".")[1:]
                    if a.asname:
                        modules[a.asname] = full
                    yield node.lineno, full
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                and node.value.id in modules and modules[node.value.id] != here):
            yield node.lineno, modules[node.value.id] + [node.attr]


def private_reaches() -> list[str]:
    """Every place a jaxfric module uses a name that is private to a package it is not
    in (issue 46's packages: each subpackage, and the top-level modules together). A
    leading underscore makes a name private to the package that holds it:
    ``jaxfric.identification._api`` and ``jaxfric.rig.simulator._substep`` are their
    subpackage's, ``jaxfric.uncertainty._g`` the top-level modules'. The root's private
    modules (``_xla``, ``_timing``, ``_warnings``: the bottom layer) serve every package."""
    found = []
    for path in sorted(ROOT.rglob("*.py")):
        here = _jaxfric_module(path)
        top_level = len(here) <= 1 and not (ROOT.joinpath(*here).is_dir() and here)
        for line, full in _imported_paths(path):
            first = next((i for i, p in enumerate(full) if _is_private(p)), None)
            if first is None:
                continue
            owner = full[:first]
            while owner and not ROOT.joinpath(*owner).is_dir():  # a module: its package
                owner = owner[:-1]
            if owner:
                allowed = here[: len(owner)] == owner
            else:  # a root module (open to all) or a private name of a top-level module
                allowed = first == 0 or top_level
            if not allowed:
                found.append(f"{path.relative_to(ROOT)}:{line} uses jaxfric.{'.'.join(full)}")
    return found


def test_the_private_name_finder_finds_each_kind(tmp_path, monkeypatch):
    """The finder flags a private module, a private name and a private attribute of an
    imported module across packages, and lets a package use its own and the root's."""
    root = tmp_path / "jaxfric"
    for folder in ("a", "b"):
        (root / folder).mkdir(parents=True)
        (root / folder / "__init__.py").write_text("")
    (root / "_shared.py").write_text("")
    (root / "top.py").write_text("from .a.public import shown\n")
    (root / "other.py").write_text("from .top import _helper\n")
    (root / "a" / "_inner.py").write_text("def _hidden(): pass\ndef shown(): pass\n")
    (root / "a" / "public.py").write_text("from ._inner import _hidden\nfrom .. import _shared\n"
                                          "from .._shared import z\n")
    (root / "b" / "user.py").write_text(
        "from ..a._inner import shown\nfrom ..a import _inner\nfrom jaxfric.a.public import _hidden\n"
        "from ..a import public\nx = public._hidden\nfrom .._shared import y\n"
        "from ..top import _helper\n")
    monkeypatch.setattr(__import__(__name__), "ROOT", root)
    assert private_reaches() == ["b/user.py:1 uses jaxfric.a._inner.shown",
                                 "b/user.py:2 uses jaxfric.a._inner",
                                 "b/user.py:3 uses jaxfric.a.public._hidden",
                                 "b/user.py:7 uses jaxfric.top._helper",
                                 "b/user.py:5 uses jaxfric.a.public._hidden"]


def test_no_module_uses_another_package_private_names():
    """Issue 46: what one package needs of another is public there (its ``__init__`` or a
    public module, documented); a private name is its own package's business."""
    assert not private_reaches(), private_reaches()


#: Issue 46, one home per concept: where the Elman recurrence (a ``tanh`` of a sum,
#: ``tanh(w u + r c + b)`` §2.2 or ``tanh(w u + W_c c + b)`` §2.3) and the motion residual
#: (a difference with a simulated ``*_hat`` series in ``jaxfric.motion``, ``√w (x̂ − x̃)``
#: §13.2; the force balance's ``y_hat - y`` is another concept) may be written.
#: ``export._elman_hidden`` is the one named twin: an exported step computes without JAX
#: (its docstring; test_export holds it to ``Fit.predict``).
CONCEPT_HOMES = {"Elman recurrence": {("models/elman.py", "elman_hidden"), ("models/elman.py", "elman_full_hidden"),
                                      ("export.py", "_elman_hidden")},
                 "motion residual": {("motion/_residuals.py", "motion_residual")}}


def _is_hat(node) -> bool:
    """``x_hat`` or ``x_hat[...]``: a simulated series."""
    while isinstance(node, ast.Subscript):
        node = node.value
    return isinstance(node, ast.Name) and node.id.endswith("_hat")


def concept_places() -> dict[str, set]:
    """``concept -> {(file, enclosing function)}`` of every place the library writes an
    Elman recurrence or a motion residual (see `CONCEPT_HOMES`), found on the source."""
    found: dict[str, set] = {name: set() for name in CONCEPT_HOMES}
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()

        def visit(node, function):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                function = node.name
            if (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.BinOp)
                    and isinstance(node.args[0].op, ast.Add)
                    and getattr(node.func, "attr", getattr(node.func, "id", None)) == "tanh"):
                found["Elman recurrence"].add((rel, function))
            if rel.startswith("motion/") and isinstance(node, ast.BinOp) and isinstance(node.op, ast.Sub) and (
                    _is_hat(node.left) or _is_hat(node.right)):
                found["motion residual"].add((rel, function))
            for child in ast.iter_child_nodes(node):
                visit(child, function)

        visit(ast.parse(path.read_text()), None)
    return found


def test_the_concept_finder_finds_a_second_home(tmp_path, monkeypatch):
    """The finder flags a full-context and a diagonal recurrence and a weighted or plain
    motion residual wherever they are written, and leaves ``tanh(v / v_eps)``, metrics
    and the force balance's errors alone."""
    root = tmp_path / "jaxfric"
    (root / "motion").mkdir(parents=True)
    (root / "step.py").write_text(
        "import jax.numpy as jnp\n"
        "def full(p, u, c):\n    return jnp.tanh(p['w'] * u + p['W_c'] @ c + p['b'])\n"
        "def diag(w, u, r, c, b):\n    return np.tanh(w * u + r * c + b)\n"
        "def sign(v, v_eps):\n    return jnp.tanh(v / v_eps)\n")
    (root / "motion" / "cost.py").write_text(
        "def cost(x_hat, x, w):\n    return jnp.sqrt(w) * (x_hat[1:] - x)\n"
        "def score(x, x_hat):\n    return rmse(x, x_hat)\n")
    (root / "balance.py").write_text("def error(y_hat, y):\n    return y_hat - y\n")
    monkeypatch.setattr(__import__(__name__), "ROOT", root)
    assert concept_places() == {"Elman recurrence": {("step.py", "full"), ("step.py", "diag")},
                                "motion residual": {("motion/cost.py", "cost")}}


def test_one_home_per_concept():
    """Issue 46: the Elman recurrences and the motion residual are each written in one
    function (the export's NumPy twin named), which every rollout, step and cost calls."""
    places = concept_places()
    assert places == CONCEPT_HOMES, {k: sorted(places[k] ^ CONCEPT_HOMES[k]) for k in places}
