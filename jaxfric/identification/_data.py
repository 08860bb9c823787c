"""Turn what the user passes as data into checked records (docs/algorithms.md §1, §11 step 2).

:func:`as_record` (one record, split into a training and a validation window) and
:func:`as_records` (several records, each wholly for training or for validation)
accept

* a ``FrictionData`` (``jaxfric.rig``) or any object with ``.velocity``,
  ``.friction``, ``.dt`` and a training count ``.n_train``;
* a tuple ``(velocity, friction, dt)``.

A :class:`RecordSet` holds the checked records of one identification; the cost pools
the squared errors of every training sample over the training records, each rolled
out from its own initial state (no model state is carried across a record boundary).

Every problem is reported as a ``ValueError`` here, on NumPy data, before any
tracing or optimisation starts: an identification run is long, and a bad record
should not fail minutes into it (or, worse, silently fit NaNs).
"""

from __future__ import annotations

import dataclasses
import numbers
from collections.abc import Mapping

import numpy as np

#: The paper's split: the first 1600 of 2000 samples for estimation (§1).
DEFAULT_TRAIN_FRACTION = 0.8
#: Shortest validation window :func:`jaxfric.identify` accepts. A window of one or two
#: samples has (almost) no variance, so its normalised MSE (§6, divided by the window's
#: variance) reads 1e5 % and means nothing; ten samples also cover the start-up
#: transient of the §7 pipeline's order-4 Butterworth filter at its edge.
MIN_VALID_SAMPLES = 10


@dataclasses.dataclass(frozen=True)
class Record:
    """A checked velocity/friction record: float64 NumPy arrays, SI units.

    ``velocity`` [m/s] and ``friction`` [N] have the same length ``n``; ``dt`` [s]
    is the sample time; the first ``n_train`` samples are the training window and
    the remaining ``n - n_train`` the validation window. A record used wholly for
    training has ``n_train == n``, one used wholly for validation ``n_train == 0``.
    ``name`` labels the record in per-record metrics.
    """

    velocity: np.ndarray
    friction: np.ndarray
    dt: float
    n_train: int
    #: Chamber pressures [Pa] when the data carry them (docs/algorithms.md §13.1).
    p1: np.ndarray | None = None
    p2: np.ndarray | None = None
    name: str = ""

    @property
    def role(self) -> str:
        """``"train"``, ``"valid"`` or ``"split"`` (training then validation window)."""
        if self.n_train == self.n_samples:
            return "train"
        return "valid" if self.n_train == 0 else "split"

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


def as_record(data, train=None, *, min_valid: int = 1) -> Record:
    """Check ``data`` and split it (§1, §11 step 2); see the module docstring.

    Args:
        data: a FrictionData-like object or ``(velocity, friction, dt)``.
        train: training samples (int) or fraction (float in (0, 1)); default the
            data's own ``n_train``, else 0.8 (the paper's 1600 of 2000).
        min_valid: fewest validation samples accepted (:func:`jaxfric.identify` asks
            for :data:`MIN_VALID_SAMPLES`).

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
    if n - n_train < min_valid:
        raise ValueError(
            f"the validation window has {n - n_train} sample(s) (train={n_train} of {n}); "
            f"need at least {min_valid} for a meaningful validation error: use a smaller "
            "train fraction, or train on whole records with train=[...] and valid=[...]"
        )
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


def _checked_whole(data, role: str, name: str) -> Record:
    """One record used whole for training (``n_train = n``) or validation (``0``)."""
    v, f, dt, _ = _unpack(data)
    velocity = _channel(f"{name}: velocity", v)
    friction = _channel(f"{name}: friction", f)
    if velocity.shape != friction.shape:
        raise ValueError(
            f"{name}: velocity and friction must have the same length, got "
            f"{velocity.shape[0]} and {friction.shape[0]} samples"
        )
    n = velocity.shape[0]
    need = 2 if role == "train" else MIN_VALID_SAMPLES
    if n < need:
        raise ValueError(f"{name} has {n} sample(s); a {role} record needs at least {need}")
    dt = _sample_time(dt)
    if role == "train" and not np.ptp(velocity) > 0.0:
        raise ValueError(f"{name}: velocity is constant; a friction model cannot be identified from it")
    return Record(velocity=velocity, friction=friction, dt=dt,
                  n_train=n if role == "train" else 0, name=name)


def _record_list(x, what: str) -> list[tuple[str, object]]:
    """``x`` as ``[(name, record), ...]``: one record (object or ``(v, F, dt)``), a
    sequence of them (named ``what[i]``) or a mapping name -> record (e.g. file names)."""
    if x is None:
        return []
    if hasattr(x, "velocity"):
        return [(f"{what}[0]", x)]
    if isinstance(x, tuple) and len(x) == 3 and np.ndim(x[2]) == 0 and np.ndim(x[0]) == 1:
        return [(f"{what}[0]", x)]
    if isinstance(x, Mapping):
        items = [(str(k), v) for k, v in x.items()]
    elif isinstance(x, (list, tuple)):
        items = [(f"{what}[{i}]", v) for i, v in enumerate(x)]
    else:
        raise ValueError(
            f"{what} must be a record (FrictionData or (velocity, friction, dt)), a list of "
            f"records or a mapping name -> record, got {type(x).__name__}"
        )
    if not items:
        raise ValueError(f"{what} holds no records")
    return items


@dataclasses.dataclass(frozen=True)
class RecordSet:
    """The checked records of one identification (see the module docstring).

    ``records`` are in the order given: the training records first, then the
    validation records (or one ``"split"`` record). All share one sample time.
    """

    records: tuple[Record, ...]

    @property
    def single(self) -> Record | None:
        """The one split record of the classic call ``identify(model, data)``, else ``None``."""
        if len(self.records) == 1 and self.records[0].role == "split":
            return self.records[0]
        return None

    @property
    def train_records(self) -> tuple[Record, ...]:
        return tuple(r for r in self.records if r.n_train > 0)

    @property
    def dt(self) -> float:
        return self.records[0].dt

    @property
    def train_velocity(self) -> np.ndarray:
        """Training samples of every training record, concatenated (for scalers and boxes)."""
        return np.concatenate([r.train_velocity for r in self.train_records])

    @property
    def train_friction(self) -> np.ndarray:
        return np.concatenate([r.train_friction for r in self.train_records])

    @property
    def n_train(self) -> int:
        return int(sum(r.n_train for r in self.records))

    @property
    def n_samples(self) -> int:
        return int(sum(r.n_samples for r in self.records))


def as_records(data=None, train=None, valid=None) -> RecordSet:
    """Check the data of one :func:`jaxfric.identify` call.

    * ``data`` given: one record split by ``train`` (count or fraction, see
      :func:`as_record`); ``valid`` must be ``None``.
    * ``data`` ``None``: ``train`` is one record or a list of records, each used
      whole for training, and ``valid`` one record, a list or ``None``; a mapping
      name -> record names the records in the per-record metrics (then the
      fit has training metrics only).

    Raises:
        ValueError: everything :func:`as_record` raises; training or validation
            records with different sample times (resample them first); a training
            set whose friction has zero variance; ambiguous arguments.
    """
    if data is not None:
        if valid is not None:
            raise ValueError(
                "valid= needs the training records as train=[record, ...] (each used whole); "
                "with data= the one record is split by train= (a count or a fraction)"
            )
        if train is not None and not isinstance(train, numbers.Real):
            raise ValueError(
                "with data=, train= is the split (a sample count or a fraction); to train on "
                "whole records call identify(model, train=[record, ...], valid=...)"
            )
        return RecordSet((as_record(data, train, min_valid=MIN_VALID_SAMPLES),))
    if train is None:
        raise ValueError("no data: pass a record as data=, or train=[record, ...] (and valid=...)")
    if isinstance(train, numbers.Real):
        raise ValueError(f"train={train!r} is a split of data=, but no data= was given")
    train_list = _record_list(train, "train")
    valid_list = _record_list(valid, "valid")
    records = [_checked_whole(d, "train", name) for name, d in train_list]
    records += [_checked_whole(d, "valid", name) for name, d in valid_list]
    names = [r.name for r in records]
    if len(set(names)) != len(names):
        raise ValueError(f"record names must be unique, got {names}")
    dts = sorted({r.dt for r in records})
    if not np.allclose(dts, dts[0], rtol=1e-6, atol=0.0):
        detail = ", ".join(f"{r.name} {r.dt:.6g} s" for r in records)
        raise ValueError(
            f"the records have different sample times ({detail}); resample them onto one "
            "grid first (jaxfric.rig.resample_uniform)"
        )
    rs = RecordSet(tuple(records))
    if not np.ptp(rs.train_friction) > 0.0:
        raise ValueError(
            "friction has zero variance over the training records (a constant signal); "
            "the cost and MSE % are undefined"
        )
    return rs
