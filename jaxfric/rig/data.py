"""Data containers: raw rig measurements and the velocity/friction record models are fitted to.

``Measurements`` holds what a rig records (docs/algorithms.md §7: x, p1, p2, F_L
against t). ``FrictionData`` (defined in [`jaxfric.records`][jaxfric.records], the one record type
of the package) holds what identification needs (§1, §2.4, §11): velocity in,
friction out, on a uniform grid, with the train/validation split of the paper
(first 1600 of 2000 samples for estimation, last 400 for validation).
"""

from __future__ import annotations

import equinox as eqx
import numpy as np

from ..records import FrictionData, as_channel, check_increasing

__all__ = ["FrictionData", "Measurements"]


class Measurements(eqx.Module):
    """Raw rig channels in SI units (NumPy float64): time [s], piston position [m],
    cap / rod chamber pressures [Pa], external load from the force sensor [N]
    (opposing +x; see ``params`` for the sign convention)."""

    t: np.ndarray
    x: np.ndarray
    p1: np.ndarray
    p2: np.ndarray
    load: np.ndarray

    @classmethod
    def from_arrays(cls, t, x, p1, p2, load) -> "Measurements":
        """Validate and wrap the five channels (finite, equal length, strictly increasing ``t``)."""
        t = as_channel("t", t)
        check_increasing(t)
        n = t.shape[0]
        return cls(t=t, x=as_channel("x", x, n), p1=as_channel("p1", p1, n),
                   p2=as_channel("p2", p2, n), load=as_channel("load", load, n))

    @property
    def n_samples(self) -> int:
        return int(np.shape(self.t)[0])
