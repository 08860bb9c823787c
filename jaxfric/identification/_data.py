"""Turn what the user passes as data into checked records (docs/algorithms.md §1, §11 step 2).

[`as_record`][jaxfric.identification.as_record] (one record, split into a training and a validation window) and
[`as_records`][jaxfric.identification.as_records] (several records, each wholly for training or for validation)
accept

* a [`FrictionData`][jaxfric.rig.FrictionData] ([`jaxfric.FrictionData`][jaxfric.rig.FrictionData], what every
  loader of [`jaxfric.rig`][jaxfric.rig] returns), its split ``n_train`` used unless ``train=``
  overrides it;
* a tuple ``(velocity, friction, dt)``.

Both become the same checked [`FrictionData`][jaxfric.rig.FrictionData] (``Record`` is
that class under the name this module used to give it), split by the one rule
[`jaxfric.records.split_count`][jaxfric.records.split_count].

A [`RecordSet`][jaxfric.identification.RecordSet] holds the checked records of one identification; the cost pools
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

from ..problem import TrainingRecords
from ..records import (DEFAULT_TRAIN_FRACTION, MIN_VALID_SAMPLES, FrictionData, as_channel,
                       check_sample_time, split_count)
from ..rig.simulator import RigRecord

#: The one record type; identification code calls it a record.
Record = FrictionData


def _train_count(n: int, train, data_count) -> int:
    """Resolve the split: ``train`` (count or fraction) beats the data's own count;
    identification needs two training samples and a non-empty validation window."""
    if train is None:
        train = data_count if data_count is not None else DEFAULT_TRAIN_FRACTION
    if isinstance(train, numbers.Integral) and not isinstance(train, bool) and int(train) < 2:
        raise ValueError(f"train must be at least 2 samples, got {int(train)}")
    count = split_count(n, train, whole=False)
    if count < 2:
        raise ValueError(f"the training window has {count} sample(s); need at least 2")
    return count


def _unpack(data):
    if isinstance(data, (tuple, list)):
        if len(data) != 3:
            raise ValueError(f"data as a tuple must be (velocity, friction, dt), got {len(data)} items")
        v, f, dt = data
        return v, f, dt, None
    if isinstance(data, RigRecord):
        raise ValueError("data is a RigRecord (the simulator's true states and raw sensor channels), not "
                         "a friction record: identify what the rig measures, "
                         "jaxfric.rig.estimate_friction(record.measurements(), rig.cylinder), or simulate "
                         "and measure in one call with jaxfric.rig.synthetic_friction_data(key)")
    if not isinstance(data, FrictionData):
        raise ValueError("data must be a FrictionData (not merely a FrictionData-like object: build one with "
                         "jaxfric.FrictionData.from_arrays or a loader of jaxfric.rig) or a tuple "
                         f"(velocity, friction, dt), got {type(data).__name__}")
    # A validation-only view (n_train 0) carries no split of its own.
    return data.velocity, data.friction, data.dt, (data.n_train or None)


def as_record(data, train=None, *, min_valid: int = 1) -> Record:
    """Check ``data`` and split it (§1, §11 step 2); see the module docstring.

    Args:
        data: a [`FrictionData`][jaxfric.rig.FrictionData] or ``(velocity, friction, dt)``.
        train: training samples (int) or fraction (float in (0, 1)); default the
            data's own ``n_train``, else 0.8 (the paper's 1600 of 2000).
        min_valid: fewest validation samples accepted ([`jaxfric.identify`][jaxfric.identification.identify] asks
            for [`MIN_VALID_SAMPLES`][jaxfric.identification.MIN_VALID_SAMPLES]).

    Raises:
        ValueError: mismatched lengths, NaN/inf, a non-positive ``dt``, a record
            shorter than the split, an empty validation window, or friction with
            zero variance over the training window (the cost and MSE % would
            divide by zero) or constant velocity (nothing to identify from).
    """
    v, f, dt, data_count = _unpack(data)
    velocity = as_channel("velocity", v, label="velocity", allow_empty=True)
    friction = as_channel("friction", f, label="friction", allow_empty=True)
    if velocity.shape != friction.shape:
        raise ValueError(f"velocity and friction must have the same length, got {velocity.shape[0]} "
                         f"and {friction.shape[0]} samples")
    n = velocity.shape[0]
    if n < 3:
        raise ValueError(f"the record has {n} sample{'' if n == 1 else 's'}; identification needs at "
                         "least 3 (2 to train, 1 to validate)")
    dt = check_sample_time(dt)
    n_train = _train_count(n, train, data_count)
    if n - n_train < min_valid:
        raise ValueError(f"the validation window has {n - n_train} sample(s) (train={n_train} of {n}); "
                         f"need at least {min_valid} for a meaningful validation error: use a smaller "
                         "train fraction, or train on whole records with train=[...] and valid=[...]")
    f_train = friction[:n_train]
    if not np.ptp(f_train) > 0.0:
        raise ValueError("friction has zero variance over the training window (a constant signal); "
                         "the cost and MSE % are undefined")
    if not np.ptp(velocity[:n_train]) > 0.0:
        raise ValueError("velocity is constant over the training window; a friction model cannot be "
                         "identified from it")
    return FrictionData(t=np.arange(n) * dt, velocity=velocity, friction=friction, acceleration=None,
                        dt=dt, n_train=n_train, **_pressures(data))


def _pressures(data) -> dict:
    """A [`FrictionData`][jaxfric.rig.FrictionData]'s chamber pressures ``p1``, ``p2`` as float64 arrays (``None``
    where absent or for ``(v, F, dt)`` tuples). Checked by the model that uses them
    ([`inputs_from`][jaxfric.models.AbstractFrictionModel.inputs_from]), so a bad channel no model
    needs does not stop the run."""
    given = (data.p1, data.p2) if isinstance(data, FrictionData) else (None, None)
    return {name: None if p is None else np.asarray(p, dtype=np.float64) for name, p in zip(("p1", "p2"), given)}


def _checked_whole(data, role: str, name: str) -> Record:
    """One record used whole for training (``n_train = n``) or validation (``0``)."""
    v, f, dt, _ = _unpack(data)
    velocity = as_channel("velocity", v, label=f"{name}: velocity", allow_empty=True)
    friction = as_channel("friction", f, label=f"{name}: friction", allow_empty=True)
    if velocity.shape != friction.shape:
        raise ValueError(f"{name}: velocity and friction must have the same length, got "
                         f"{velocity.shape[0]} and {friction.shape[0]} samples")
    n = velocity.shape[0]
    need = 2 if role == "train" else MIN_VALID_SAMPLES
    if n < need:
        raise ValueError(f"{name} has {n} sample(s); a {role} record needs at least {need}")
    dt = check_sample_time(dt)
    if role == "train" and not np.ptp(velocity) > 0.0:
        raise ValueError(f"{name}: velocity is constant; a friction model cannot be identified from it")
    return FrictionData(t=np.arange(n) * dt, velocity=velocity, friction=friction, acceleration=None,
                        dt=dt, n_train=n if role == "train" else 0, name=name, **_pressures(data))


def _record_list(x, what: str) -> list[tuple[str, object]]:
    """``x`` as ``[(name, record), ...]``: one record (object or ``(v, F, dt)``), a
    sequence of them (named ``what[i]``) or a mapping name -> record (e.g. file names)."""
    if x is None:
        return []
    if isinstance(x, FrictionData):
        return [(f"{what}[0]", x)]
    if isinstance(x, tuple) and len(x) == 3 and np.ndim(x[2]) == 0 and np.ndim(x[0]) == 1:
        return [(f"{what}[0]", x)]
    if isinstance(x, Mapping):
        items = [(str(k), v) for k, v in x.items()]
    elif isinstance(x, (list, tuple)):
        items = [(f"{what}[{i}]", v) for i, v in enumerate(x)]
    else:
        raise ValueError(f"{what} must be a record (FrictionData or (velocity, friction, dt)), a list of "
                         f"records or a mapping name -> record, got {type(x).__name__}")
    if not items:
        raise ValueError(f"{what} holds no records")
    return items


@dataclasses.dataclass(frozen=True)
class RecordSet(TrainingRecords):
    """The checked records of one identification (see the module docstring): a
    [`jaxfric.problem.TrainingRecords`][jaxfric.problem.TrainingRecords].

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
        """The records with training samples (the first ``n_train`` of each)."""
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
    """Check the data of one [`jaxfric.identify`][jaxfric.identification.identify] call.

    * ``data`` given: one record split by ``train`` (count or fraction, see
      [`as_record`][jaxfric.identification.as_record]); ``valid`` must be ``None``.
    * ``data`` ``None``: ``train`` is one record or a list of records, each used
      whole for training, and ``valid`` one record, a list or ``None``; a mapping
      name -> record names the records in the per-record metrics (then the
      fit has training metrics only).

    Raises:
        ValueError: everything [`as_record`][jaxfric.identification.as_record] raises; training or validation
            records with different sample times (resample them first); a training
            set whose friction has zero variance; ambiguous arguments.
    """
    if data is not None:
        if valid is not None:
            raise ValueError("valid= needs the training records as train=[record, ...] (each used whole); "
                             "with data= the one record is split by train= (a count or a fraction)")
        if train is not None and not isinstance(train, numbers.Real):
            raise ValueError("with data=, train= is the split (a sample count or a fraction); to train on "
                             "whole records call identify(model, train=[record, ...], valid=...)")
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
        raise ValueError(f"the records have different sample times ({detail}); resample them onto one "
                         "grid first (jaxfric.rig.resample_uniform)")
    rs = RecordSet(tuple(records))
    if not np.ptp(rs.train_friction) > 0.0:
        raise ValueError("friction has zero variance over the training records (a constant signal); "
                         "the cost and MSE % are undefined")
    return rs

