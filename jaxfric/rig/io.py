"""Loaders for recorded data: raw rig channels or ready velocity/friction pairs.

Sources are a delimited text file (CSV, or whitespace-separated with
``delimiter=None``) or a mapping of NumPy arrays. The caller maps the canonical
channel names to file columns (header names or 0-based indices) and gives unit
factors to reach SI (``scale={"x": 1e-3}`` for mm, ``{"p1": 1e5}`` for bar; a
negative factor flips a sign convention). Irregular time stamps are resampled
to a uniform grid with a warning (``on_irregular="resample"``) or rejected
(``"raise"``); unsorted or duplicate stamps are always an error.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Mapping

import numpy as np

from .._warnings import IrregularSamplingWarning
from ..files import column_index, read_rows
from ..records import check_int
from ._checks import as_channel, check_increasing, check_positive, is_uniform
from .data import FrictionData, Measurements

RAW_CHANNELS = ("t", "x", "p1", "p2", "load")
PAIR_CHANNELS = ("t", "velocity", "friction")
#: Channels `load_friction_pairs` reads when ``columns`` maps them.
PAIR_EXTRA_CHANNELS = ("p1", "p2")


def resample_uniform(t, *channels, dt: float | None = None):
    """Linear interpolation of ``channels`` onto a uniform grid from ``t[0]`` to ``t[-1]``.

    ``dt`` [s] defaults to the median time step. Returns ``(t_uniform, *channels)``.
    """
    t = as_channel("t", t)
    check_increasing(t)
    step = float(np.median(np.diff(t))) if dt is None else check_positive("dt", dt)
    n = int(np.floor((t[-1] - t[0]) / step + 1e-9)) + 1
    grid = t[0] + step * np.arange(n)
    out = [np.interp(grid, t, as_channel(f"channel {i}", c, t.size)) for i, c in enumerate(channels)]
    return (grid, *out)


def uniformise(signals: dict, on_irregular: str, dt: float | None, rtol: float) -> dict:
    """``signals`` (a ``"t"`` column and channels) on a uniform time grid: as they are when
    the stamps are uniform within ``rtol`` and ``dt`` is not given, else resampled
    linearly (``on_irregular="resample"``, with an
    [`IrregularSamplingWarning`][jaxfric.rig.IrregularSamplingWarning]) or refused
    (``"raise"``)."""
    if on_irregular not in ("resample", "raise"):
        raise ValueError(f"on_irregular must be 'resample' or 'raise', got {on_irregular!r}")
    t = signals["t"]
    check_increasing(t)
    if is_uniform(t, rtol) and dt is None:
        return signals
    d = np.diff(t)
    if not is_uniform(t, rtol):
        msg = (f"time stamps are irregular (median step {np.median(d):.6g} s, min {d.min():.6g} s, "
               f"max {d.max():.6g} s)")
        if on_irregular == "raise":
            raise ValueError(msg + "; pass on_irregular='resample' to interpolate onto a uniform grid")
        warnings.warn(msg + "; resampled linearly onto a uniform grid", IrregularSamplingWarning, stacklevel=3)
    names = [k for k in signals if k != "t"]
    grid, *out = resample_uniform(t, *(signals[k] for k in names), dt=dt)
    return {"t": grid, **dict(zip(names, out))}


def _read_table(path, columns: Mapping, delimiter, skip_rows: int, comments: str) -> dict:
    """Read the requested columns of a delimited text file as float64 arrays.

    Every problem is a ValueError naming the file and, for a bad cell, its line, column
    and text: a cell that is not a number (text in a numeric column, an empty cell) is
    an error here rather than a NaN that fails later as "non-finite samples".
    """
    numbered = read_rows(path, delimiter=delimiter, comments=comments)
    by_name = any(isinstance(c, str) for c in columns.values())
    header = []
    if by_name:
        if not numbered:
            raise ValueError(f"{path}: empty file, no header to map column names")
        header = numbered[0][1]
        numbered = numbered[1:]
    rows = numbered[skip_rows:]
    if not rows:
        raise ValueError(f"{path}: no data rows")
    width = len(rows[0][1])
    for lineno, row in rows:
        if len(row) != width:
            raise ValueError(f"{path}: line {lineno} has {len(row)} columns, expected {width} "
                             "(is the delimiter right?)")
    index, names = {}, {}
    for channel, col in columns.items():
        if isinstance(col, str):
            index[channel] = column_index(header, col, path=path, what=f"for channel '{channel}'")
            names[channel] = f"column '{col}'"
        else:
            index[channel] = int(col)
            names[channel] = f"column {int(col)}"
    for channel, i in index.items():
        if not -width <= i < width:
            raise ValueError(f"{path}: column index {i} (for channel '{channel}') is missing; "
                             f"the file has {width} columns")
    out = {}
    for channel, i in index.items():
        values = np.empty(len(rows), np.float64)
        for k, (lineno, row) in enumerate(rows):
            text = row[i]
            try:
                values[k] = float(text)
            except ValueError:
                what = "is empty" if text == "" else f"holds {text!r}, not a number"
                raise ValueError(f"{path}: line {lineno}, {names[channel]} (channel '{channel}') "
                                 f"{what}") from None
        out[channel] = values
    return out


def _factor(kind: str, channel: str, value, *, allow_zero: bool) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{kind} for channel '{channel}' must be a number, got {value!r}") from None
    if not np.isfinite(v) or (v == 0.0 and not allow_zero):
        need = "a finite number" if allow_zero else "a finite, non-zero number"
        raise ValueError(f"{kind} for channel '{channel}' must be {need}, got {value!r}")
    return v


def _gather(source, columns, required, scale, fill, delimiter, skip_rows, comments,
            optional=()) -> dict:
    """The ``required`` channels (read, or filled with a constant) and those of the
    ``optional`` channels the source maps, scaled to SI, as float64 arrays of one length."""
    check_int("skip_rows", skip_rows, 0)
    scale = {ch: _factor("scale", ch, v, allow_zero=False) for ch, v in dict(scale or {}).items()}
    fill = {ch: _factor("fill", ch, v, allow_zero=True) for ch, v in dict(fill or {}).items()}
    if isinstance(source, Mapping):
        columns = (dict(columns) if columns is not None else {c: c for c in (*required, *optional) if c in source})
        missing_keys = [col for col in columns.values() if col not in source]
        if missing_keys:
            raise ValueError(f"missing column(s) {missing_keys}; the arrays given are {sorted(source)}")
        raw = {ch: np.asarray(source[col]) for ch, col in columns.items()}
        if skip_rows:
            raw = {ch: a[skip_rows:] for ch, a in raw.items()}
    else:
        if columns is None:
            raise ValueError("columns= is required for files: map each channel to a column name or index")
        raw = _read_table(os.fspath(source), columns, delimiter, skip_rows, comments)
    unknown = sorted((set(raw) | set(fill) | set(scale)) - set(required) - set(optional))
    if unknown:
        raise ValueError(f"unknown channel name(s) {unknown}; expected some of "
                         f"{list(required) + list(optional)}")
    missing = [ch for ch in required if ch not in raw and ch not in fill]
    if missing:
        raise ValueError(f"missing channel(s) {missing}: map them in columns= or give a constant in fill=")
    if not raw:
        raise ValueError("no channel read from the source: columns= maps none of them")
    n = None
    out = {}
    for ch in (*required, *optional):
        if ch in raw:
            arr = as_channel(ch, raw[ch], n)
            n = arr.shape[0]
            out[ch] = arr * float(scale.get(ch, 1.0))
    for ch in required:
        if ch not in out:
            out[ch] = np.full(n, float(fill[ch]) * float(scale.get(ch, 1.0)))
    return out


def load_measurements(source, columns: Mapping | None = None, *, scale: Mapping | None = None,
                      fill: Mapping | None = None, delimiter: str | None = ",", skip_rows: int = 0,
                      comments: str = "#", on_irregular: str = "resample", dt: float | None = None,
                      rtol: float = 1e-3) -> Measurements:
    """Raw rig channels ``t, x, p1, p2, load`` (SI after ``scale``) from a file or arrays.

    source: path of a delimited text file, or a mapping of 1-D arrays.
    columns: channel -> column name (header) or 0-based index; for a mapping of
        arrays, channel -> key (default: the channel names themselves).
    scale: channel -> factor to SI units (time to s, x to m, pressures to Pa,
        load to N; -1 flips a sign convention). fill: channel -> constant for a
        channel the source lacks (e.g. ``{"p1": 0.0}`` for a single-chamber cylinder).
    delimiter: ``","`` for CSV, ``None`` for whitespace. skip_rows: data rows to drop
        at the start (after the header). on_irregular: ``"resample"`` (linear, with
        an [`IrregularSamplingWarning`][jaxfric.rig.IrregularSamplingWarning]) or ``"raise"``; ``dt`` forces the grid step.
    """
    sig = _gather(source, columns, RAW_CHANNELS, scale, fill, delimiter, skip_rows, comments)
    sig = uniformise(sig, on_irregular, dt, rtol)
    return Measurements.from_arrays(sig["t"], sig["x"], sig["p1"], sig["p2"], sig["load"])


def load_friction_pairs(source, columns: Mapping | None = None, *, scale: Mapping | None = None,
                        delimiter: str | None = ",", skip_rows: int = 0, comments: str = "#",
                        on_irregular: str = "resample", dt: float | None = None, rtol: float = 1e-3,
                        train_fraction: float = 0.8, n_train: int | None = None) -> FrictionData:
    """Ready velocity [m/s] / friction [N] pairs against time [s] as [`FrictionData`][jaxfric.rig.FrictionData].

    Same conventions as [`load_measurements`][jaxfric.rig.load_measurements], channels ``t, velocity, friction``,
    and optionally the chamber pressures ``p1``, ``p2`` [Pa after ``scale``] for a model
    that takes them ([`Cylinder`][jaxfric.models.Cylinder]).
    """
    sig = _gather(source, columns, PAIR_CHANNELS, scale, None, delimiter, skip_rows, comments,
                  optional=PAIR_EXTRA_CHANNELS)
    sig = uniformise(sig, on_irregular, dt, rtol)
    return FrictionData.from_arrays(sig["velocity"], sig["friction"], sig["t"], train_fraction,
                                    n_train=n_train, rtol=max(rtol, 1e-6),
                                    p1=sig.get("p1"), p2=sig.get("p2"))
