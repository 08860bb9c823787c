"""Input checks shared by the pipeline and the loaders.

They run on concrete NumPy data *before* any computation, so a bad record fails
with a ValueError that names the channel and the problem, not deep inside
SciPy or a jitted function.
"""

from __future__ import annotations

import numpy as np


def as_channel(name: str, values, n: int | None = None) -> np.ndarray:
    """``values`` as a 1-D float64 array of finite numbers (length ``n`` if given)."""
    if np.iscomplexobj(values):
        # np.asarray(..., float64) would silently drop the imaginary part.
        raise ValueError(f"channel '{name}' holds complex numbers; give real values")
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ValueError(f"channel '{name}' is not numeric: {err}") from None
    if arr.ndim != 1:
        raise ValueError(f"channel '{name}' must be 1-D, got shape {arr.shape}")
    if arr.shape[0] == 0:
        raise ValueError(f"channel '{name}' is empty (no samples)")
    if n is not None and arr.shape[0] != n:
        raise ValueError(f"channel '{name}' has {arr.shape[0]} samples, expected {n}")
    bad = ~np.isfinite(arr)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        kind = "NaN" if np.isnan(arr[first]) else "inf"
        raise ValueError(
            f"channel '{name}' has {int(bad.sum())} non-finite samples ({kind} first at index {first})"
        )
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


def check_positive(name: str, value, allow_zero: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    ok = np.isfinite(v) and (v >= 0.0 if allow_zero else v > 0.0)
    if not ok:
        raise ValueError(f"{name} must be {'non-negative' if allow_zero else 'positive'} and finite, got {v!r}")
    return v


def filter_padlen(sos: np.ndarray) -> int:
    """The default edge padding of ``scipy.signal.sosfiltfilt`` for these sections."""
    n_sections = sos.shape[0]
    zeros = min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum()))
    return 3 * (2 * n_sections + 1 - zeros)
