"""Direction-wise friction levels of a record (Coulomb level as a half-range).

For a record that slides back and forth, the mean friction while moving
forwards (``v > v_move``) and backwards (``v < -v_move``) gives the Coulomb level
as the half-range ``(F_+ - F_-)/2`` and a constant force offset (sensor or
area mismatch) as ``(F_+ + F_-)/2``. This is the definition used for the
pneumatic seal data (``data/pneumatic_seal_friction/make_summary.py``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class CoulombLevels(NamedTuple):
    """Mean friction [N] per direction, half-range (Coulomb level) and offset [N], sample counts."""

    mean_pos: float
    mean_neg: float
    halfrange: float
    offset: float
    n_pos: int
    n_neg: int


def coulomb_levels(velocity, friction, v_move: float = 3e-3) -> CoulombLevels:
    """Coulomb level [N] of a record as the half-range of the direction-wise mean friction.

    velocity [m/s], friction [N]; samples with ``|v| <= v_move`` [m/s] (reversals,
    standstill) are left out.
    """
    v = np.asarray(velocity, dtype=np.float64)
    f = np.asarray(friction, dtype=np.float64)
    pos, neg = v > v_move, v < -v_move
    if not pos.any() or not neg.any():
        raise ValueError(f"the record must slide both ways faster than v_move = {v_move} m/s")
    f_pos, f_neg = float(f[pos].mean()), float(f[neg].mean())
    return CoulombLevels(f_pos, f_neg, 0.5 * (f_pos - f_neg), 0.5 * (f_pos + f_neg), int(pos.sum()), int(neg.sum()))
