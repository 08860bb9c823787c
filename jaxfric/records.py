"""The velocity/friction record every entry point uses, and its checks (docs/algorithms.md §1, §11 step 2).

[`FrictionData`][jaxfric.rig.FrictionData] is the one record type: the rig loaders and pipeline
([`jaxfric.rig`][jaxfric.rig]), the EMPS loader, the synthetic data set, the command line
and [`jaxfric.identify`][jaxfric.identification.identify] all produce or accept it. Its channels are checked
float64 NumPy arrays, so the user's data are never rounded to float32 however JAX
is configured; it is still a pytree (``eqx.Module``), so it can travel in the
``args`` of a jitted function and be stacked over records of equal length.

The checks below run on concrete data *before* any computation, so a bad record
fails with a ``ValueError`` that names the channel and the problem, not deep inside
SciPy, a jitted function or minutes into an identification.
"""

from __future__ import annotations

import numbers
from typing import Optional

import equinox as eqx
import numpy as np

#: The paper's split: the first 1600 of 2000 samples for estimation (§1).
DEFAULT_TRAIN_FRACTION = 0.8
#: Shortest validation window `jaxfric.identify` accepts. A window of one or two
#: samples has (almost) no variance, so its normalised MSE (§6, divided by the window's
#: variance) reads 1e5 % and means nothing; ten samples also cover the start-up
#: transient of the §7 pipeline's order-4 Butterworth filter at its edge.
MIN_VALID_SAMPLES = 10


def as_channel(name: str, values, n: int | None = None, *, label: str | None = None,
               allow_empty: bool = False) -> np.ndarray:
    """``values`` as a 1-D float64 array of finite numbers (length ``n`` if given).

    Messages call the channel ``label`` (default ``channel '<name>'``); a caller that
    reports the record's length itself (``allow_empty``) lets an empty channel through.
    """
    label = f"channel '{name}'" if label is None else label
    if np.iscomplexobj(values):
        raise ValueError(f"{label} holds complex numbers; pass the real-valued signal "
                         "(the imaginary part would otherwise be dropped silently)")
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{label} is not numeric: {err}") from None
    if arr.ndim != 1:
        raise ValueError(f"{label} must be a 1-D time series, got shape {arr.shape}")
    if arr.shape[0] == 0 and not allow_empty:
        raise ValueError(f"{label} is empty (no samples)")
    if n is not None and arr.shape[0] != n:
        raise ValueError(f"{label} has {arr.shape[0]} samples, expected {n}")
    bad = ~np.isfinite(arr)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        kind = "NaN" if np.isnan(arr[first]) else "inf"
        raise ValueError(f"{label} has {int(bad.sum())} non-finite samples ({kind} first at index {first}); "
                         "remove or interpolate them")
    return arr


def check_increasing(t: np.ndarray, name: str = "t") -> None:
    """Time stamps must be strictly increasing (no duplicates, no reordering)."""
    if t.size < 2:
        raise ValueError(f"channel '{name}' needs at least 2 samples, got {t.size}")
    d = np.diff(t)
    if np.any(d == 0):
        i = int(np.flatnonzero(d == 0)[0])
        raise ValueError(f"duplicate time stamps in '{name}': t[{i}] == t[{i + 1}] == {float(t[i])!r}")
    if np.any(d < 0):
        i = int(np.flatnonzero(d < 0)[0])
        raise ValueError(f"time stamps in '{name}' are not sorted: t[{i}] = {float(t[i])!r} > "
                         f"t[{i + 1}] = {float(t[i + 1])!r}")


def is_uniform(t: np.ndarray, rtol: float = 1e-3) -> bool:
    """True when every step is within ``rtol`` of the median step."""
    d = np.diff(t)
    med = np.median(d)
    return bool(np.all(np.abs(d - med) <= rtol * med))


def check_int(name: str, value, least: int = 1, most: int | None = None, unit: str = "") -> int:
    """``value`` as an int in ``[least, most]`` (a bool is not an int); ``unit`` names it in the message."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not (
            least <= value and (most is None or value <= most)):
        span = f">= {least}" if most is None else f"in [{least}, {most}]"
        raise ValueError(f"{name} must be a whole number {span}{unit}, got {value!r}")
    return int(value)


def check_positive(name: str, value, allow_zero: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    ok = np.isfinite(v) and (v >= 0.0 if allow_zero else v > 0.0)
    if not ok:
        raise ValueError(f"{name} must be {'non-negative' if allow_zero else 'positive'} and finite, got {v!r}")
    return v


#: Two sample times within this relative difference are the same sample time: 1 kHz
#: recordings whose float32 time stamps round differently (0.0010000080 s against
#: 0.0009999840 s) are one rate, not a resampling problem.
SAMPLE_TIME_RTOL = 1e-4


def same_sample_time(a: float, b: float) -> bool:
    """``|a - b| <= SAMPLE_TIME_RTOL * b``: the same sample time (see [`SAMPLE_TIME_RTOL`][jaxfric.records.SAMPLE_TIME_RTOL])."""
    return abs(float(a) - float(b)) <= SAMPLE_TIME_RTOL * abs(float(b))


_STAMPS_HINT = "for time stamps build the record with jaxfric.rig.FrictionData.from_arrays(v, F, t)"


def check_sample_time(dt, *, stamps_hint: str = _STAMPS_HINT) -> float:
    """A scalar, positive, finite sample time [s]; ``stamps_hint`` says what to do with
    time stamps instead (default: [`FrictionData.from_arrays`][jaxfric.rig.FrictionData.from_arrays] takes them)."""
    arr = np.asarray(dt)
    if arr.ndim != 0:
        raise ValueError(f"dt must be a scalar sample time in seconds, got shape {arr.shape}; {stamps_hint}")
    try:
        value = float(arr)
    except (TypeError, ValueError):
        raise ValueError(f"dt must be a number (seconds), got {dt!r}") from None
    if not (np.isfinite(value) and value > 0.0):
        raise ValueError(f"dt must be a positive, finite sample time in seconds, got {value!r}")
    return value


def split_count(n: int, train, *, whole: bool = True, name: str = "train",
                fraction_name: str = "a train fraction") -> int:
    """The split rule of every record (§1): how many of the ``n`` samples, from the
    first, form the training window.

    ``train`` is a sample count (int) or a fraction (float, ``round(train * n)``
    samples: 0.8 of 2000 is the paper's 1600). ``whole`` allows all ``n`` samples
    (a record used wholly for training); without it the validation window must keep
    at least one sample. ``name`` and ``fraction_name`` are the caller's argument
    names in the messages.
    """
    closing = "]" if whole else ")"
    if isinstance(train, bool) or not isinstance(train, numbers.Real):
        raise ValueError(f"{name} must be a sample count (int) or a fraction in (0, 1{closing}, got {train!r}")
    if isinstance(train, numbers.Integral):
        count = int(train)
        if count > n:
            raise ValueError(f"the record ({n} samples) is shorter than the training split ({count} samples)")
    else:
        frac = float(train)
        if not (0.0 < frac < 1.0 or (whole and frac == 1.0)):
            raise ValueError(f"{fraction_name} must lie in (0, 1{closing}, got {frac!r}")
        count = int(round(frac * n))
    if not whole and count >= n:
        raise ValueError(f"the validation window is empty: all {n} samples are used for training "
                         f"({name}={count}); keep some samples for validation")
    if count < 1:
        raise ValueError(f"{name} must leave at least 1 training sample of {n}, got {count}")
    return count


def _given_split(n: int, train_fraction, n_train) -> int:
    """[`split_count`][jaxfric.records.split_count] for the ``train_fraction`` / ``n_train`` pair of [`FrictionData`][jaxfric.rig.FrictionData]."""
    if n_train is not None:
        return split_count(n, int(n_train), name="n_train")
    if isinstance(train_fraction, bool) or not isinstance(train_fraction, numbers.Real):
        raise ValueError(f"train_fraction must be a fraction in (0, 1], got {train_fraction!r}")
    train_fraction = float(train_fraction)  # train_fraction=1 means all samples, not one
    return split_count(n, train_fraction, name="train_fraction", fraction_name="train_fraction")


class FrictionData(eqx.Module):
    """Velocity/friction record on a uniform grid, ready for identification.

    Fields (float64 NumPy arrays, SI): ``t`` [s], ``velocity`` [m/s], ``friction`` [N]
    (positive when opposing +x), ``acceleration`` [m/s^2] and chamber pressures
    ``p1``, ``p2`` [Pa] (``None`` when unknown), ``dt`` [s] (a float).
    ``n_train`` (static int): the first ``n_train`` samples are the training
    window, the rest the validation window (§1: 1600 / 400). A ``train()`` view
    (or a record used wholly for training) has ``n_train == n``; a ``valid()`` view
    ``n_train == 0``. ``name`` (static) labels the record in per-record metrics.

    A pytree of arrays: it can travel in ``args`` of a jitted objective and be
    stacked/vmapped over records of equal length.
    """

    t: np.ndarray
    velocity: np.ndarray
    friction: np.ndarray
    acceleration: Optional[np.ndarray]
    p1: Optional[np.ndarray]
    p2: Optional[np.ndarray]
    dt: float
    n_train: int = eqx.field(static=True)
    name: str = eqx.field(static=True, default="")

    @classmethod
    def from_arrays(cls, velocity, friction, dt_or_t, train_fraction: float = DEFAULT_TRAIN_FRACTION, *,
                    n_train: int | None = None, acceleration=None, p1=None, p2=None,
                    rtol: float = 1e-3, name: str = "") -> "FrictionData":
        """Wrap velocity [m/s] / friction [N] pairs sampled uniformly.

        ``dt_or_t``: the sample interval [s] (scalar) or the time stamps [s]
        (must be uniform within ``rtol``; resample irregular stamps with
        [`jaxfric.rig.io.resample_uniform`][jaxfric.rig.resample_uniform] first). The split is
        ``round(train_fraction * n)`` training samples unless ``n_train`` is given
        ([`split_count`][jaxfric.records.split_count]).
        """
        velocity = as_channel("velocity", velocity)
        n = velocity.shape[0]
        if n < 2:
            raise ValueError(f"a friction record needs at least 2 samples, got {n}")
        friction = as_channel("friction", friction, n)
        try:
            stamps = np.asarray(dt_or_t, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError("dt_or_t must be the sample interval [s] (a number) or the time "
                             f"stamps [s] (an array), got {dt_or_t!r}") from None
        if stamps.ndim == 0:
            dt = check_positive("dt", stamps)
            t = np.arange(n) * dt
        else:
            t = as_channel("t", stamps, n)
            check_increasing(t)
            if not is_uniform(t, rtol):
                raise ValueError("time stamps are not uniform; resample them first "
                                 "(jaxfric.rig.io.resample_uniform or on_irregular='resample')")
            dt = float(np.median(np.diff(t)))
        extra = {key: (None if arr is None else as_channel(key, arr, n))
                 for key, arr in (("acceleration", acceleration), ("p1", p1), ("p2", p2))}
        return cls(t=t, velocity=velocity, friction=friction, dt=dt,
                   n_train=_given_split(n, train_fraction, n_train), name=name, **extra)

    @property
    def n_samples(self) -> int:
        return int(np.shape(self.velocity)[-1])

    @property
    def n_valid(self) -> int:
        return self.n_samples - self.n_train

    @property
    def role(self) -> str:
        """``"train"``, ``"valid"`` or ``"split"`` (training then validation window)."""
        if self.n_train == self.n_samples:
            return "train"
        return "valid" if self.n_train == 0 else "split"

    @property
    def train_velocity(self) -> np.ndarray:
        return self.velocity[..., : self.n_train]

    @property
    def train_friction(self) -> np.ndarray:
        return self.friction[..., : self.n_train]

    def _view(self, sl: slice, n_train: int) -> "FrictionData":
        cut = lambda a: None if a is None else a[..., sl]  # noqa: E731
        return FrictionData(t=cut(self.t), velocity=cut(self.velocity), friction=cut(self.friction),
                            acceleration=cut(self.acceleration), p1=cut(self.p1), p2=cut(self.p2),
                            dt=self.dt, n_train=n_train, name=self.name)

    def train(self) -> "FrictionData":
        """The estimation window: samples ``[0, n_train)``."""
        return self._view(slice(0, self.n_train), self.n_train)

    def valid(self) -> "FrictionData":
        """The validation window: samples ``[n_train, n)`` (its own ``n_train`` is 0)."""
        return self._view(slice(self.n_train, None), 0)

    def with_split(self, train_fraction: float | None = DEFAULT_TRAIN_FRACTION, *,
                   n_train: int | None = None) -> "FrictionData":
        """Same record, another split (fraction of samples, or a count; [`split_count`][jaxfric.records.split_count])."""
        return self._view(slice(None), _given_split(self.n_samples, train_fraction, n_train))
