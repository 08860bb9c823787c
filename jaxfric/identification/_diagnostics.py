"""What a fit cannot tell by its error alone: parameters on a bound, unidentifiable ones.

A physical parameter that ends on the edge of its search box (docs/algorithms.md §8.5)
was stopped by the box, not by the data: its value is an artefact of the range, and
the optimum may lie outside. :func:`on_bound` finds those parameters and says which
range to widen; :func:`jaxfric.identify` warns with :class:`BoundWarning` and
records them in ``Fit.diagnostics`` (shown by ``Fit.summary()``, ``results.json`` and
``report.md``).

The networks' weights are left alone: their box is a regulariser (the context-weight
bound keeps the free run stable, ``NAMED_MODEL_DEFAULTS``), and a weight on it is
expected rather than a sign of a wrong range.
"""

from __future__ import annotations

import numpy as np

from .._warnings import BoundWarning
from ..models import AbstractFrictionModel, AbstractPhysicalModel

#: A parameter within this fraction of its box width of a bound counts as on it (the
#: swarms clip to the box, so a stopped parameter sits exactly there).
BOUND_TOLERANCE = 1e-3


def _coordinates(model: AbstractFrictionModel):
    """``(search name, physical name, kind, box entry)`` per entry of ``theta`` (no
    entry for a range the model fixes, e.g. GMS's splits, nor for the networks)."""
    if isinstance(model, AbstractPhysicalModel):
        for search, phys, kind in model._coords:
            key = model._range_key(phys, kind)
            yield search, phys, kind, key if key in model.box_keys else None
    else:
        for name in model.param_names:
            yield name, name, "linear", None


def on_bound(model: AbstractFrictionModel, theta, box=None, tol: float = BOUND_TOLERANCE) -> list[dict]:
    """Parameters of ``theta`` (search coordinates) within ``tol`` box widths of a bound
    of ``box`` (the fit's :class:`jaxfric.models.SearchBox`; ``None``: the defaults).

    Returns one dict per such parameter: ``name`` (physical), ``search_name``,
    ``side`` (``"lower"``/``"upper"``), ``value`` and ``range`` in physical units
    (for LuGre's ``Fs`` the ratio Fs/Fc, whose box entry is ``Fs_ratio``),
    ``box_key`` (the box entry that sets the range, e.g. ``"vs"``), ``option`` (what
    to pass, e.g. ``"box['vs']"``) and a one-line ``message`` naming all of it. Empty
    for models fitted on scaled data.
    """
    if model.needs_scaling:
        return []
    theta = np.asarray(theta, np.float64)
    lower, upper = model.bounds(box)
    out = []
    for i, (search, name, kind, key) in enumerate(_coordinates(model)):
        option = None if key is None else f"box[{key!r}]"
        width = upper[i] - lower[i]
        side = ("lower" if theta[i] <= lower[i] + tol * width
                else "upper" if theta[i] >= upper[i] - tol * width else None)
        if side is None:
            continue
        phys = (lambda x: 10.0 ** x) if kind == "log10" else (lambda x: x)
        value, lo, hi = float(phys(theta[i])), float(phys(lower[i])), float(phys(upper[i]))
        widen = (f"pass box={{{key!r}: ({lo / 10 if kind == 'log10' else lo - width:.4g}, {hi:.4g})}}"
                 if side == "lower"
                 else f"pass box={{{key!r}: ({lo:.4g}, {hi * 10 if kind == 'log10' else hi + width:.4g})}}")
        if key is None:
            widen = "widen the search box"
        shown = f"{name}/Fc" if kind == "ratio" else name
        out.append({
            "name": name, "search_name": search, "side": side, "value": value, "range": [lo, hi],
            "box_key": key, "option": option,
            "message": (f"{shown} = {value:.4g} ended on the {side} bound of its search range "
                        f"[{lo:.4g}, {hi:.4g}]: the box, not the data, fixed it; widen the range "
                        f"({widen}) and fit again"),
        })
    return out


def unidentifiable(model: AbstractFrictionModel, velocity) -> tuple[str, ...]:
    """Parameters the training velocity cannot determine, as ``"name: reason"`` strings.

    Asks ``model.unidentifiable(velocity)`` (the models' hook: a record or a velocity
    array in, reasons out; e.g. LuGre's σ0, σ1 when the record holds no pre-sliding)
    when the model's class defines it; ``()`` otherwise. For several training records
    ``velocity`` is their samples together.
    """
    method = getattr(type(model), "unidentifiable", None)
    if not callable(method):
        return ()
    # "name: reason" (one JSON-friendly string each; the name is what precedes the
    # first ": "), so Fit.summary(), results.json and report.md say why, not only which
    return tuple(f"{m}: {m.reason}" if getattr(m, "reason", None) else str(m)
                 for m in method(model, np.asarray(velocity, np.float64)))
