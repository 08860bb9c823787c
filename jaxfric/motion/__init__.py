"""Friction inside the mechanics: simulation-error identification (docs/algorithms.md §13.2).

* :func:`friction_step` — any jaxfric friction model one sample at a time;
* :func:`simulate_motion` — ``m dv/dt = F_act - F_f - F_load``, ``dx/dt = v`` in one ``lax.scan``;
* :func:`k_step_positions`, :func:`track_states` — k-step-ahead prediction from measured states;
* :func:`identify_motion` → :class:`MotionFit` (``simulate``, metrics in mm and FIT %, save /
  :func:`load_motion_fit`), from :class:`MotionData` (force and position, no friction signal).
"""

from ._api import MotionData, MotionFit, identify_motion, load_motion_fit, motion_metrics
from ._forward import k_step_positions, simulate_motion, track_states
from ._step import (BristleStep, ElmanFullStep, ElmanStep, FrictionStep, GMSStep, StaticStep,
                    friction_step)

__all__ = [
    "BristleStep",
    "ElmanFullStep",
    "ElmanStep",
    "FrictionStep",
    "GMSStep",
    "MotionData",
    "MotionFit",
    "StaticStep",
    "friction_step",
    "identify_motion",
    "k_step_positions",
    "load_motion_fit",
    "motion_metrics",
    "simulate_motion",
    "track_states",
]
