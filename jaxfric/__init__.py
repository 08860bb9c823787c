"""jaxfric: JAX-accelerated identification of nonlinear friction.

The public API is re-exported here; see README.md for a tour.
"""

from importlib.metadata import PackageNotFoundError, version as _version

from . import functions
from .optim import (
    MAPSO,
    MAPSONMDS,
    PSO,
    RESULTS,
    History,
    NelderMead,
    Solution,
    mapso_nmds,
    minimise,
    minimise_many,
)

try:
    __version__ = _version("jaxfric")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

__all__ = [
    "functions",
    "MAPSO",
    "MAPSONMDS",
    "PSO",
    "RESULTS",
    "History",
    "NelderMead",
    "Solution",
    "mapso_nmds",
    "minimise",
    "minimise_many",
]
