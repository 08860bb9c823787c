"""Turn what the user passes as ``data`` into one checked record (ALGORITHMS.md §1, §11 step 2).

:func:`as_record` accepts

* a ``FrictionData`` (``jaxfric.rig``) or any object with ``.velocity``,
  ``.friction``, ``.dt`` and a training count ``.n_train``;
* a tuple ``(velocity, friction, dt)``.

Every problem is reported as a ``ValueError`` here, on NumPy data, before any
tracing or optimisation starts: an identification run is long, and a bad record
should not fail minutes into it (or, worse, silently fit NaNs).
"""

from __future__ import annotations

import dataclasses
import numbers

import numpy as np

#: The paper's split: the first 1600 of 2000 samples for estimation (§1).
DEFAULT_TRAIN_FRACTION = 0.8


@dataclasses.dataclass(frozen=True)
class Record:
    """A checked velocity/friction record: float64 NumPy arrays, SI units.

    ``velocity`` [m/s] and ``friction`` [N] have the same length ``n``; ``dt`` [s]
    is the sample time; the first ``n_train`` samples are the training window and
    the remaining ``n - n_train >= 1`` the validation window.
    """

    velocity: np.ndarray
    friction: np.ndarray
    dt: float
    n_train: int
    #: Chamber pressures [Pa] when the data carry them (docs/algorithms.md §13.1).
    p1: np.ndarray | None = None
    p2: np.ndarray | None = None

    @property
    def n_samples(self) -> int:
        return int(self.velocity.shape[0])

    @property
    def n_valid(self) -> int:
        return self.n_samples - self.n_train

    @property
    def train_velocity(self) -> np.ndarray:
        return self.velocity[: self.n_train]

    @property
    def train_friction(self) -> np.ndarray:
        return self.friction[: self.n_train]


def _channel(name: str, values) -> np.ndarray:
    if np.iscomplexobj(values):
        raise ValueError(
            f"{name} holds complex numbers; pass the real-valued signal "
            "(the imaginary part would otherwise be dropped silently)"
        )
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{name} is not numeric: {err}") from None
    if arr.ndim != 1:
        raise ValueError(f"{name} must be a 1-D time series, got shape {arr.shape}")
    bad = ~np.isfinite(arr)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        kind = "NaN" if np.isnan(arr[first]) else "inf"
        raise ValueError(
            f"{name} holds {int(bad.sum())} non-finite samples ({kind} first at index {first}); "
            "remove or interpolate them before identification"
        )
    return arr


def _sample_time(dt) -> float:
    arr = np.asarray(dt)
    if arr.ndim != 0:
        raise ValueError(
            f"dt must be a scalar sample time in seconds, got shape {arr.shape}; for time "
            "stamps build the record with jaxfric.rig.FrictionData.from_arrays(v, F, t)"
        )
    try:
        value = float(arr)
    except (TypeError, ValueError):
        raise ValueError(f"dt must be a number (seconds), got {dt!r}") from None
    if not (np.isfinite(value) and value > 0.0):
        raise ValueError(f"dt must be a positive, finite sample time in seconds, got {value!r}")
    return value


def _train_count(n: int, train, data_count) -> int:
    """Resolve the split: ``train`` (count or fraction) beats the data's own count."""
    if train is None:
        train = data_count if data_count is not None else DEFAULT_TRAIN_FRACTION
    if isinstance(train, bool) or not isinstance(train, numbers.Real):
        raise ValueError(f"train must be a sample count (int) or a fraction in (0, 1), got {train!r}")
    if isinstance(train, numbers.Integral):
        count = int(train)
        if count < 2:
            raise ValueError(f"train must be at least 2 samples, got {count}")
        if count > n:
            raise ValueError(
                f"the record ({n} samples) is shorter than the training split ({count} samples)"
            )
    else:
        frac = float(train)
        if not 0.0 < frac < 1.0:
            raise ValueError(f"a train fraction must lie in (0, 1), got {frac!r}")
        count = int(round(frac * n))
    if count >= n:
        raise ValueError(
            f"the validation window is empty: all {n} samples are used for training "
            f"(train={count}); keep some samples for validation"
        )
    if count < 2:
        raise ValueError(f"the training window has {count} sample(s); need at least 2")
    return count


def _unpack(data):
    if isinstance(data, (tuple, list)):
        if len(data) != 3:
            raise ValueError(
                f"data as a tuple must be (velocity, friction, dt), got {len(data)} items"
            )
        v, f, dt = data
        return v, f, dt, None
    missing = [a for a in ("velocity", "friction", "dt") if not hasattr(data, a)]
    if missing:
        raise ValueError(
            "data must be a FrictionData-like object (with .velocity, .friction, .dt and "
            f".n_train) or a tuple (velocity, friction, dt); {type(data).__name__} has no "
            f"{', '.join('.' + m for m in missing)}"
        )
    count = getattr(data, "n_train", None)
    if count is not None:
        count = int(count)
        if count == 0:
            count = None  # a validation-only view carries no split of its own
    return data.velocity, data.friction, data.dt, count


def as_record(data, train=None) -> Record:
    """Check ``data`` and split it (§1, §11 step 2); see the module docstring.

    Args:
        data: a FrictionData-like object or ``(velocity, friction, dt)``.
        train: training samples (int) or fraction (float in (0, 1)); default the
            data's own ``n_train``, else 0.8 (the paper's 1600 of 2000).

    Raises:
        ValueError: mismatched lengths, NaN/inf, a non-positive ``dt``, a record
            shorter than the split, an empty validation window, or friction with
            zero variance over the training window (the cost and MSE % would
            divide by zero) or constant velocity (nothing to identify from).
    """
    v, f, dt, data_count = _unpack(data)
    velocity = _channel("velocity", v)
    friction = _channel("friction", f)
    if velocity.shape != friction.shape:
        raise ValueError(
            f"velocity and friction must have the same length, got {velocity.shape[0]} "
            f"and {friction.shape[0]} samples"
        )
    n = velocity.shape[0]
    if n < 3:
        raise ValueError(
            f"the record has {n} sample{'' if n == 1 else 's'}; identification needs at "
            "least 3 (2 to train, 1 to validate)"
        )
    dt = _sample_time(dt)
    n_train = _train_count(n, train, data_count)
    f_train = friction[:n_train]
    if not np.ptp(f_train) > 0.0:
        raise ValueError(
            "friction has zero variance over the training window (a constant signal); "
            "the cost and MSE % are undefined"
        )
    if not np.ptp(velocity[:n_train]) > 0.0:
        raise ValueError(
            "velocity is constant over the training window; a friction model cannot be "
            "identified from it"
        )
    # Checked by the model that uses them (AbstractFrictionModel.inputs_from), so a bad
    # channel no model needs does not stop the run.
    pressures = {name: np.asarray(getattr(data, name), dtype=np.float64) for name in ("p1", "p2")
                 if getattr(data, name, None) is not None}
    return Record(velocity=velocity, friction=friction, dt=dt, n_train=n_train, **pressures)
