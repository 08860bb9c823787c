"""The synthetic stand-in data set of docs/algorithms.md §7 in one call: simulate, then measure."""

from __future__ import annotations

import jax

from .data import FrictionData
from .params import Rig
from .pipeline import estimate_friction
from .simulator import simulate


def synthetic_friction_data(key: jax.Array, rig: Rig | None = None, *, cutoff: float = 5.0,
                            train_fraction: float = 0.8, n_train: int | None = None,
                            **simulate_kwargs) -> FrictionData:
    """Simulate ``rig`` (default [`Rig`][jaxfric.rig.Rig]) with ``key`` and run the §7 pipeline on its measurements.

    Defaults give the paper's layout: 2000 samples at 128 Hz, 5 Hz Butterworth,
    1600 training / 400 validation samples. ``simulate_kwargs`` go to
    [`simulate`][jaxfric.rig.simulate] (``n_samples``, ``fs``, ``sensors``, ...). Use
    [`simulate`][jaxfric.rig.simulate] directly when you also need the ground truth.
    """
    rig = Rig() if rig is None else rig
    record = simulate(rig, key, **simulate_kwargs)
    return estimate_friction(record.measurements(), rig.cylinder, cutoff=cutoff,
                             train_fraction=train_fraction, n_train=n_train)
