"""jaxfric: JAX-accelerated identification of nonlinear friction.

Optimisers (``minimise``, ``PSO``, ``MAPSO``, ``NelderMead``, ``MAPSONMDS``), test
functions (``functions``), friction models (``models``: ``Elman``, ``LuGre``, ...),
the hydraulic rig simulator and measurement pipeline (``rig``), identification
(``identify`` → ``Fit``, ``load_fit``) and metrics (``metrics``). See README.md.
"""

from importlib.metadata import PackageNotFoundError, version as _version

try:
    __version__ = _version("jaxfric")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

import importlib as _importlib

# Names are imported on first use (PEP 562), so ``import jaxfric`` -- and with it
# ``jaxfric --help`` -- does not pay for importing JAX (about 2 s) before it is needed.
# name -> module that defines it ("" = the name is a submodule of its own)
_LAZY = {
    "functions": "", "metrics": "", "models": "", "rig": "", "files": "",
    "compensation": "", "export": "", "motion": "", "datasets": "",
    "MotionData": ".motion", "MotionFit": ".motion", "identify_motion": ".motion",
    "load_motion_fit": ".motion", "compare_motion": ".motion",
    "compiler_options": "._xla",
    "sweep": ".sweeps", "sweeps": "",
    "Fit": ".fit", "load_fit": ".fit",
    "GradientRefinement": ".identification", "identify": ".identification",
    "friction_metrics": ".metrics",
    "Coulomb": ".models", "Dahl": ".models", "Elman": ".models", "ElmanFull": ".models",
    "LuGre": ".models", "Stribeck": ".models",
    "MAPSO": ".optim", "MAPSONMDS": ".optim", "PSO": ".optim", "RESULTS": ".optim",
    "History": ".optim", "NelderMead": ".optim", "Solution": ".optim", "mapso_nmds": ".optim",
    "minimise": ".optim", "minimise_many": ".optim", "chain": ".optim",
    "ask_init": ".optim", "ask": ".optim", "tell": ".optim", "ask_done": ".optim",
    "ask_result": ".optim",
    "Evosax": ".optim", "cmaes_nm": ".optim",
    "FrictionData": ".rig",
}


def __getattr__(name: str):
    try:
        where = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'jaxfric' has no attribute {name!r}") from None
    if where == "":
        value = _importlib.import_module(f".{name}", __name__)
    else:
        value = getattr(_importlib.import_module(where, __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


__all__ = [
    "Coulomb",
    "Dahl",
    "Elman",
    "Evosax",
    "ElmanFull",
    "Fit",
    "GradientRefinement",
    "FrictionData",
    "History",
    "LuGre",
    "MAPSO",
    "MotionData",
    "MotionFit",
    "MAPSONMDS",
    "NelderMead",
    "PSO",
    "RESULTS",
    "Solution",
    "Stribeck",
    "ask",
    "ask_done",
    "ask_init",
    "ask_result",
    "chain",
    "compensation",
    "compare_motion",
    "cmaes_nm",
    "compiler_options",
    "datasets",
    "export",
    "friction_metrics",
    "files",
    "functions",
    "identify",
    "identify_motion",
    "load_fit",
    "load_motion_fit",
    "mapso_nmds",
    "metrics",
    "minimise",
    "minimise_many",
    "models",
    "motion",
    "rig",
    "sweep",
    "sweeps",
    "tell",
]
