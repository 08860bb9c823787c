"""Unit names the command line understands, as factors to SI.

A unit option takes a name (``mm``, ``bar``, ``ms`` ...) or a plain number, the factor
that brings the column to SI; a negative factor also flips the sign convention.
"""

from __future__ import annotations

import math

from .errors import UserError

_FACTORS: dict[str, dict[str, float]] = {
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6, "min": 60.0},
    "length": {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "in": 0.0254},
    "velocity": {"m/s": 1.0, "cm/s": 1e-2, "mm/s": 1e-3, "um/s": 1e-6, "in/s": 0.0254},
    "force": {"N": 1.0, "kN": 1e3, "mN": 1e-3, "lbf": 4.4482216152605},
    "pressure": {"Pa": 1.0, "kPa": 1e3, "MPa": 1e6, "bar": 1e5, "mbar": 1e2, "psi": 6894.757293168},
}

UNITS = {kind: tuple(names) for kind, names in _FACTORS.items()}
"""Known unit names per kind (for help texts)."""


def unit_factor(kind: str, text, option: str) -> float:
    """Factor to SI for ``text`` (a unit name of ``kind`` or a number); ``option`` names
    the command-line option in the error message."""
    table = _FACTORS[kind]
    s = str(text).strip()
    for name, value in table.items():
        if s == name or s.lower() == name.lower():
            return value
    try:
        value = float(s)
    except ValueError:
        raise UserError(f"{option}: unknown {kind} unit {s!r}; use one of {', '.join(table)} "
                        "or a numeric factor to SI") from None
    if not math.isfinite(value) or value == 0.0:
        raise UserError(f"{option}: the factor must be a finite non-zero number, got {s!r}")
    return value
