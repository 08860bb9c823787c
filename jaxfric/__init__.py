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

from . import functions, metrics, models, rig
from ._xla import compiler_options
from .fit import Fit, load_fit
from .identify import GradientRefinement, identify
from .metrics import friction_metrics
from .models import Coulomb, Dahl, Elman, ElmanFull, LuGre, Stribeck
from .optim import (
    MAPSO,
    MAPSONMDS,
    PSO,
    Evosax,
    RESULTS,
    History,
    NelderMead,
    Solution,
    chain,
    cmaes_nm,
    mapso_nmds,
    minimise,
    minimise_many,
)
from .rig import FrictionData

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
    "MAPSONMDS",
    "NelderMead",
    "PSO",
    "RESULTS",
    "Solution",
    "Stribeck",
    "chain",
    "cmaes_nm",
    "compiler_options",
    "friction_metrics",
    "functions",
    "identify",
    "load_fit",
    "mapso_nmds",
    "metrics",
    "minimise",
    "minimise_many",
    "models",
    "rig",
]
