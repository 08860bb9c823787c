"""The search box of a physical model as data: [`SearchBox`][jaxfric.models.SearchBox] (docs/algorithms.md §8.5).

A box maps a physical parameter's name (``"Fc"``, ``"sigma0"``, ``"Fs_ratio"`` for
Fs/Fc, ``"k"`` for every GMS element stiffness, ...) to its ``(low, high)`` search
range in SI units. It is an argument of [`jaxfric.identify`][jaxfric.identification.identify], not a field of
the model, so the model (the static configuration every jitted cost is keyed on)
is the same whatever box a fit searches: a new record's data-centred box never
recompiles. Per-model defaults ([`DEFAULT_RANGES`][jaxfric.models.DEFAULT_RANGES]), data-centred entries
([`data_ranges`][jaxfric.models.data_ranges]) and the user's partial box are merged by
``AbstractPhysicalModel.search_box``.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

import numpy as np
from jaxtyping import ArrayLike

from ._base import friction_scales

__all__ = ["DEFAULT_RANGES", "RANGE_FLOORS", "SearchBox", "as_range", "data_ranges", "widened"]

DEFAULT_RANGES: dict[str, tuple[float, float]] = {
    # docs/algorithms.md §8.5 [D]: order-of-magnitude ranges for hydraulic cylinders.
    "sigma0": (1e4, 1e9),
    "sigma1": (1e1, 1e6),
    "sigma2": (1e1, 1e5),
    "Fc": (10.0, 2000.0),
    "Fs_ratio": (1.0, 3.0),
    "vs": (1e-4, 5e-2),
    "delta": (0.5, 3.0),
    # docs/algorithms.md §13.1 [D]: output offset, of the order of a Coulomb level.
    "F_off": (-200.0, 200.0),
    # docs/algorithms.md §8.4 [D]: GMS element stiffness (as sigma0) and slip rate C [N/s].
    "k": (1e4, 1e9),
    "C": (1e1, 1e7),
    # docs/algorithms.md §13.1 [D]: Simscape cylinder friction, preload [N],
    # pressure coefficient [N/Pa] (Simscape's default 1e-6) and break-away ratio [-].
    "F_pr": (0.0, 2000.0),
    "f_cfr": (0.0, 1e-4),
    "K_brk": (1.0, 3.0),
}

#: Entries searched as log10 (so their range must be positive).
LOG_RANGED = ("sigma0", "sigma1", "sigma2", "vs", "k", "C")


def as_range(value, key: str = "a search range") -> tuple[float, float]:
    """A hashable ``(low, high)`` pair of floats from any pair of numbers."""
    try:
        lo, hi = (float(x) for x in value)
    except (TypeError, ValueError):
        raise ValueError(f"search box: {key} must be a (low, high) pair of numbers, got {value!r}") from None
    return (lo, hi)


#: The least start of each entry's range (docs/algorithms.md §8.5): ``(least value,
#: whether a range may start exactly there, the rule)``. Entries not listed (``F_off``)
#: may start anywhere.
RANGE_FLOORS: dict[str, tuple[float, bool, str]] = {
    **{key: (0.0, False, "must be positive") for key in LOG_RANGED + ("Fc", "delta")},
    "Fs_ratio": (1.0, True, "must start at >= 1 so that Fs >= Fc"),
    "K_brk": (1.0, True, "must start at >= 1 (break-away >= Coulomb)"),
    "F_pr": (0.0, True, "must be non-negative"),
    "f_cfr": (0.0, True, "must be non-negative"),
}


def _check_entry(key: str, lo: float, hi: float) -> None:
    """The rules a range must keep for the search coordinates of §8.5 to exist."""
    got = f"got {(lo, hi)}"
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ValueError(f"search box: {key} range must satisfy low < high (finite), {got}")
    if key in RANGE_FLOORS:
        least, inclusive, rule = RANGE_FLOORS[key]
        if lo < least or (lo == least and not inclusive):
            raise ValueError(f"search box: {key} range {rule}, {got}")


def widened(key: str, lo: float, hi: float, side: str) -> tuple[float, float] | None:
    """``key``'s range ``(lo, hi)`` widened on ``side`` (``"lower"``/``"upper"``) to a
    range [`SearchBox`][jaxfric.models.SearchBox] accepts: ten times wider for a log10 entry, one width more
    otherwise, a start never below the entry's least (`RANGE_FLOORS`). ``None``
    when ``lo`` already is that least value (Fs/Fc at 1: the model allows no lower)."""
    log = key in LOG_RANGED
    if side == "upper":
        return (lo, hi * 10.0 if log else hi + (hi - lo))
    start = lo / 10.0 if log else lo - (hi - lo)
    if key in RANGE_FLOORS:
        least, inclusive, _ = RANGE_FLOORS[key]
        if inclusive:
            if lo <= least:
                return None
            start = max(start, least)
        elif start <= least:
            start = lo / 10.0  # positive, and below lo
    return (start, hi)


class SearchBox(Mapping):
    """An immutable, validated mapping physical-parameter name -> ``(low, high)`` [SI].

    ``SearchBox({"Fc": (5, 100), "vs": (1e-4, 1e-2)})`` or ``SearchBox(Fc=(5, 100))``.
    Names are those of [`DEFAULT_RANGES`][jaxfric.models.DEFAULT_RANGES]: ``sigma0`` [N/m], ``sigma1``, ``sigma2``
    [N s/m], ``Fc`` [N], ``Fs_ratio`` (Fs/Fc) [-], ``vs`` [m/s], ``delta`` [-],
    ``F_off`` [N], ``k`` [N/m] (every GMS element), ``C`` [N/s], ``F_pr`` [N],
    ``f_cfr`` [N/Pa], ``K_brk`` [-]. A direction-dependent parameter (``Fc_pos``,
    ``Fc_neg``) shares the range of its base name.

    Raises ``ValueError`` naming the entry for an unknown name, a range that is not
    two finite numbers with low < high, a non-positive range of a log10 coordinate
    (``sigma*``, ``vs``, ``k``, ``C``) or of ``Fc`` / ``delta``, ``Fs_ratio`` or
    ``K_brk`` starting below 1, or a negative ``F_pr`` / ``f_cfr`` range.
    ``box | other`` is ``box`` with ``other``'s entries replacing its own.
    """

    __slots__ = ("_ranges",)

    def __init__(self, ranges: Mapping | None = None, /, **entries):
        if ranges is not None and not isinstance(ranges, Mapping):
            raise ValueError(f"a search box is a mapping name -> (low, high), got {type(ranges).__name__}")
        items = {**dict(ranges or {}), **entries}
        out = {}
        for key, value in items.items():
            if key not in DEFAULT_RANGES:
                raise ValueError(f"search box: unknown parameter {key!r}; box entries are "
                                 f"{', '.join(DEFAULT_RANGES)}")
            lo, hi = as_range(value, key)
            _check_entry(key, lo, hi)
            out[key] = (lo, hi)
        object.__setattr__(self, "_ranges", MappingProxyType(out))

    def __setattr__(self, name, value):
        raise AttributeError("a SearchBox is immutable; use box | {name: (low, high)}")

    def __getitem__(self, key: str) -> tuple[float, float]:
        return self._ranges[key]

    def __iter__(self):
        return iter(self._ranges)

    def __len__(self) -> int:
        return len(self._ranges)

    def __hash__(self) -> int:
        return hash(tuple(sorted(self._ranges.items())))

    def __or__(self, other: Mapping) -> "SearchBox":
        return SearchBox({**self._ranges, **dict(other)})

    def __repr__(self) -> str:
        return f"SearchBox({dict(self._ranges)!r})"

    def __str__(self) -> str:
        """``Fc [1, 50], sigma2 [1, 1000]``: the line reports and summaries show."""
        return ", ".join(f"{k} [{lo:.4g}, {hi:.4g}]" for k, (lo, hi) in self._ranges.items())

    def to_json(self) -> dict[str, list[float]]:
        """``{name: [low, high]}`` (plain floats) for fit files and reports."""
        return {k: [lo, hi] for k, (lo, hi) in self._ranges.items()}


def data_ranges(velocity: ArrayLike, friction: ArrayLike) -> dict[str, tuple[float, float]]:
    """Search ranges centred on a record's friction level ``F`` and speed ``V``.

    With ``F`` = 95th percentile of |friction| and ``V`` = max |velocity|
    ([`friction_scales`][jaxfric.models.friction_scales]), the rules are [D]:

    - Fc in [0.05, 1.2] F (Coulomb level cannot much exceed the observed force);
    - sigma0 in [F / 1e-2, F / 1e-7] N/m (bristle deflection at Fc between
      0.1 um and 10 mm);
    - sigma1 in [1e-3, 1e2] F / V and sigma2 in [1e-3, 2] F / V N s/m
      (damping/viscous force at V between 0.1 % and 100x resp. 200 % of F);
    - vs in [1e-3, 1] V m/s.

    - F_off in [-0.5, 0.5] F (§13.1);
    - GMS element stiffness k like sigma0, slip rate C in [1e-1, 1e4] F/s
      (relaxation times 10 s to 0.1 ms at the Coulomb level);
    - cylinder preload F_pr in [0, 1.2] F.

    For F = 200 N and V = 14 mm/s these reproduce the §8.5 table to within a
    factor of about 2. Fs/Fc and delta keep their defaults.
    """
    f, v = friction_scales(velocity, friction)
    return {
        "Fc": (0.05 * f, 1.2 * f),
        "F_off": (-0.5 * f, 0.5 * f),
        "k": (f / 1e-2, f / 1e-7),
        "C": (1e-1 * f, 1e4 * f),
        "F_pr": (0.0, 1.2 * f),
        "sigma0": (f / 1e-2, f / 1e-7),
        "sigma1": (1e-3 * f / v, 1e2 * f / v),
        "sigma2": (1e-3 * f / v, 2.0 * f / v),
        "vs": (1e-3 * v, v),
    }
