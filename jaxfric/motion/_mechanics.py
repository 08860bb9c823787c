"""What a motion fit identified beside its friction model, and how (§13.2): one typed,
immutable record, [`Mechanics`][jaxfric.motion.Mechanics].

A fit file keeps it as the ``"motion"`` entry of its settings (`Mechanics.to_json`), the
layout every jaxfric version has written, so files stay readable both ways.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from ..files import jsonable

__all__ = ["Mechanics"]


def _tuple(value):
    """Lists (a JSON file's form) as tuples, nested, so the record stays immutable."""
    if isinstance(value, (list, tuple)):
        return tuple(_tuple(v) for v in value)
    return value


@dataclasses.dataclass(frozen=True)
class Mechanics:
    """The mechanics of a [`MotionFit`][jaxfric.motion.MotionFit] (``fit.mechanics``).

    Attributes:
        mass: the moving mass ``m`` of ``m dv/dt = F - F_f`` [kg] (identified, or given).
        offset: a constant force added to the friction [N] (0 unless fitted).
        v0: the initial-velocity correction of the training record's first sample [m/s].
        mass_range: ``(low, high)`` [kg] the mass was searched in; ``None`` when it was given.
        error: the training cost's signal, ``"position"``, ``"velocity"`` or ``"both"``.
        horizon: the k of a k-step cost; ``None`` for free run.
        cutoff: the velocity low-pass cutoff of the training records [Hz].
        search_names: names of the search vector's entries: the model's, then the mechanics'.
        search_bounds: ``(lower, upper)`` of the search vector.
        y: the search vector at the fit.
        stopped: the budget limit that ended the search (``"max_evals"``, ``"max_time"``), or ``None``.
        starts: one row per start of the default search (its free-run cost and stage).
        records: ``{"train": lengths, "valid": lengths}`` of a fit on whole records
            (``identify_motion(train=[...])``); ``None`` for one split record.
        init_window: samples each validation record's initial state is estimated from.
        baseline: the least-squares baseline's ``M``, ``Fc``, ``Fv``, ``offset`` on the same data.
        extra: entries of a file this version does not know, kept as read.
    """

    mass: float
    offset: float = 0.0
    v0: float = 0.0
    mass_range: tuple | None = None
    error: str | None = None
    horizon: int | None = None
    cutoff: float | None = None
    search_names: tuple = ()
    search_bounds: tuple | None = None
    y: tuple = ()
    stopped: str | None = None
    starts: tuple = ()
    records: dict | None = None
    init_window: int | None = None
    baseline: dict | None = None
    extra: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        for name in ("mass", "offset", "v0"):
            object.__setattr__(self, name, float(getattr(self, name)))
        for name in ("mass_range", "search_names", "search_bounds", "y", "starts"):
            object.__setattr__(self, name, _tuple(getattr(self, name)))

    @classmethod
    def from_json(cls, entries: dict) -> "Mechanics":
        """From a fit file's ``settings["motion"]`` (`to_json`'s form)."""
        known = {f.name for f in dataclasses.fields(cls)} - {"extra"}
        if "mass" not in entries:
            raise ValueError(f"a motion fit's mechanics need a mass; the entries are {sorted(entries)}")
        return cls(**{k: v for k, v in entries.items() if k in known},
                   extra={k: v for k, v in entries.items() if k not in known})

    def to_json(self) -> dict[str, Any]:
        """The entries a fit file keeps (``settings["motion"]``, JSON types): `from_json` reads them back."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "extra"}
        return jsonable({**out, **self.extra})

    def replace(self, **changes) -> "Mechanics":
        """A copy with ``changes``."""
        return dataclasses.replace(self, **changes)
