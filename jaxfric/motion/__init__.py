"""Friction inside the mechanics: simulation-error identification (docs/algorithms.md §13.2).

* [`friction_step`][jaxfric.motion.friction_step] — any jaxfric friction model one sample at a time;
* [`simulate_motion`][jaxfric.motion.simulate_motion] — ``m dv/dt = F_act - F_f - F_load``, ``dx/dt = v`` in one ``lax.scan``;
* [`k_step_positions`][jaxfric.motion.k_step_positions], [`track_states`][jaxfric.motion.track_states] — k-step-ahead prediction from measured states;
* [`identify_motion`][jaxfric.motion.identify_motion] → [`MotionFit`][jaxfric.motion.MotionFit] (``simulate``, ``simulate(record, init_window=N)``,
  metrics in mm and FIT %, the identified [`Mechanics`][jaxfric.motion.Mechanics], save / [`load_motion_fit`][jaxfric.motion.load_motion_fit]), from [`MotionData`][jaxfric.motion.MotionData] (force and
  position, no friction signal), one record split or several (``train=[...]``, ``valid=[...]``);
  the default search ([`MotionSearch`][jaxfric.motion.MotionSearch]) with a budget (``max_evals``, ``max_time``);
* [`compare_motion`][jaxfric.motion.compare_motion] → [`MotionComparison`][jaxfric.motion.MotionComparison]: several models ranked by validation error,
  with an [`OverfitWarning`][jaxfric.motion.OverfitWarning] when a richer model validates worse than a simpler one,
  the least-squares baseline as a row, and a judge (by default ``"gated"``: many short free runs,
  [`short_runs_score`][jaxfric.motion.short_runs_score] over windows of [`SHORT_WINDOW_S`][jaxfric.motion.SHORT_WINDOW_S], for the models whose
  blocked folds beat least squares', [`gated_scores`][jaxfric.motion.gated_scores]; or the short runs alone, the held-back tail, or blocked folds);
* [`MotionProblem`][jaxfric.motion.MotionProblem] — the motion problem of [`jaxfric.problem`][jaxfric.problem] (a motion fit's
  search coordinates, training records, residuals and score);
* [`BaselineWarning`][jaxfric.motion.BaselineWarning] — a fit worse than the least-squares Coulomb + viscous + offset
  baseline on its own training data; [`NarrowGateWarning`][jaxfric.motion.NarrowGateWarning] — the gated judge's choice beats
  least squares' blocked folds by less than [`NARROW_GATE`][jaxfric.motion.NARROW_GATE].
"""

from .._warnings import BaselineWarning, NarrowGateWarning
from ._api import (ATTRACTION_TIME_S, DEFAULT_INIT_WINDOW, EXTRAPOLATION_MARGIN, EXTRAPOLATION_SHARE, MotionData,
                   MotionFit, MotionProblem, baseline_motion_fit, identify_motion, load_motion_fit, motion_metrics)
from ._compare import (NARROW_GATE, SHORT_WINDOW_S, MotionComparison, OverfitWarning, baseline_fit, blocked_score, blocked_scores, compare_motion,
                       gated_scores, rank_fits, short_judge, short_runs_score, short_window)
from ._mechanics import Mechanics
from ._pipeline import MotionBudget, MotionSearch, default_search
from ._forward import advance_motion, k_step_positions, motion_start, simulate_motion, track_states
from ._step import (BristleStep, ElmanFullStep, ElmanStep, FrictionStep, GMSStep, StaticStep,
                    friction_step)

__all__ = [
    "ATTRACTION_TIME_S",
    "BaselineWarning",
    "DEFAULT_INIT_WINDOW",
    "EXTRAPOLATION_MARGIN",
    "EXTRAPOLATION_SHARE",
    "Mechanics",
    "MotionBudget",
    "MotionComparison",
    "MotionSearch",
    "NARROW_GATE",
    "NarrowGateWarning",
    "OverfitWarning",
    "compare_motion",
    "rank_fits",
    "SHORT_WINDOW_S",
    "baseline_fit",
    "blocked_score",
    "blocked_scores",
    "gated_scores",
    "short_judge",
    "short_runs_score",
    "short_window",
    "advance_motion",
    "motion_start",
    "default_search",
    "BristleStep",
    "ElmanFullStep",
    "ElmanStep",
    "FrictionStep",
    "GMSStep",
    "MotionData",
    "MotionFit",
    "MotionProblem",
    "baseline_motion_fit",
    "StaticStep",
    "friction_step",
    "identify_motion",
    "k_step_positions",
    "load_motion_fit",
    "motion_metrics",
    "simulate_motion",
    "track_states",
]
