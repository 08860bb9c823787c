"""Derivative-free optimisers: PSO, MAPSO, Nelder–Mead, two-stage chains (MAPSO–NMDS),
one driver (``minimise``, ``minimise_many``; ask/tell from Python beside it) and the
solver contract they share."""

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
from .asktell import AskTellState, ask, ask_done, ask_init, ask_result, tell
from .contract import (
    AbstractGenerational,
    AbstractLocal,
    AbstractSolver,
    AbstractStaged,
    AbstractStartDraws,
    Capabilities,
)
from .rounds import Batch, Scan
from .swarm import AbstractSwarm, SwarmState

__all__ = [
    "RESULTS",
    "AbstractChain",
    "AbstractGenerational",
    "AbstractLocal",
    "AbstractSolver",
    "AbstractStaged",
    "AbstractStartDraws",
    "AbstractSwarm",
    "AskTellState",
    "Batch",
    "Capabilities",
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
    "ask",
    "ask_done",
    "ask_init",
    "ask_result",
    "chain",
    "cmaes_nm",
    "minimise",
    "minimise_many",
    "tell",
]
