"""Derivative-free optimisers: PSO, MAPSO, Nelder–Mead, two-stage chains (MAPSO–NMDS),
one driver (``minimise``, ``minimise_many``) and the step protocol they share."""

from ._base import RESULTS, History, Solution
from .chained import AbstractChain, Chain, ChainState, chain
from .driver import minimise, minimise_many
from .evosax_adapter import Evosax, EvosaxState, cmaes_nm
from .hybrid import MAPSONMDS, mapso_nmds
from .mapso import MAPSO
from .nelder_mead import NelderMead, NelderMeadState
from .optx_adapter import OptxMinimiser, OptxState
from .progress import RecordingProgress, TqdmProgress
from .pso import PSO
from .asktell import AskTellState
from .contract import AbstractGenerational, AbstractSolver
from .rounds import Batch, Scan
from .swarm import AbstractSwarm, SwarmState

__all__ = [
    "RESULTS",
    "AbstractChain",
    "AbstractGenerational",
    "AbstractSolver",
    "AbstractSwarm",
    "AskTellState",
    "Batch",
    "Chain",
    "Evosax",
    "EvosaxState",
    "ChainState",
    "History",
    "Solution",
    "MAPSO",
    "MAPSONMDS",
    "mapso_nmds",
    "NelderMead",
    "NelderMeadState",
    "OptxMinimiser",
    "OptxState",
    "PSO",
    "Scan",
    "RecordingProgress",
    "TqdmProgress",
    "SwarmState",
    "chain",
    "cmaes_nm",
    "minimise",
    "minimise_many",
]
