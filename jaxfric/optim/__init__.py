"""Derivative-free optimisers: PSO, MAPSO, Nelder–Mead and the MAPSO–NMDS hybrid."""

from ._base import RESULTS, AbstractSolver, History, Solution
from .hybrid import MAPSONMDS, mapso_nmds
from .mapso import MAPSO
from .minimise import minimise, minimise_many
from .nelder_mead import NelderMead, NelderMeadState
from .progress import ProgressHook, RecordingProgress, TqdmProgress
from .pso import PSO, SwarmState

__all__ = [
    "RESULTS",
    "AbstractSolver",
    "History",
    "Solution",
    "MAPSO",
    "MAPSONMDS",
    "mapso_nmds",
    "NelderMead",
    "NelderMeadState",
    "PSO",
    "ProgressHook",
    "RecordingProgress",
    "TqdmProgress",
    "SwarmState",
    "minimise",
    "minimise_many",
]
