"""What a fit cannot tell by its error alone: parameters on a bound, unidentifiable ones.

A physical parameter that ends on the edge of its search box (docs/algorithms.md §8.5)
was stopped by the box, not by the data: its value is an artefact of the range, and
the optimum may lie outside. [`on_bound`][jaxfric.identification.on_bound] finds those parameters and says which
range to widen; [`jaxfric.identify`][jaxfric.identification.identify] warns with [`BoundWarning`][jaxfric.identification.BoundWarning] and
records them in ``Fit.diagnostics`` (shown by ``Fit.summary()``, ``results.json`` and
``report.md``).

The networks' weights are left alone: their box is a regulariser (the context-weight
bound keeps the free run stable, ``NAMED_MODEL_DEFAULTS``), and a weight on it is
expected rather than a sign of a wrong range.
"""

from __future__ import annotations

import numpy as np

from .._warnings import BoundWarning, FrictionSignWarning  # noqa: F401 (re-exported)
from ..models import RANGE_FLOORS, AbstractFrictionModel, AbstractPhysicalModel, widened

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
    of ``box`` (the fit's [`jaxfric.models.SearchBox`][jaxfric.models.SearchBox]; ``None``: the defaults).

    Returns one dict per such parameter: ``name`` (physical), ``search_name``,
    ``side`` (``"lower"``/``"upper"``), ``value`` and ``range`` in physical units
    (for LuGre's ``Fs`` the ratio Fs/Fc, whose box entry is ``Fs_ratio``),
    ``box_key`` (the box entry that sets the range, e.g. ``"vs"``), ``option`` (what
    to pass, e.g. ``"box['vs']"``), ``shown`` (the name the message uses: ``Fs/Fc``),
    ``widen_to`` (a wider range the box accepts, `jaxfric.models._box.widened`)
    or, where the range already starts at the least value the model allows (Fs/Fc at
    1), ``None`` with ``at_limit`` true, and a one-line ``message`` naming all of it
    (`bound_message`). A coordinate whose range the model fixes
    (GMS's element splits, in [0, 1]) has no box entry to widen and is left out. Empty
    for models fitted on scaled data.
    """
    if model.needs_scaling:
        return []
    theta = np.asarray(theta, np.float64)
    lower, upper = model.bounds(box)
    out = []
    for i, (search, name, kind, key) in enumerate(_coordinates(model)):
        width = upper[i] - lower[i]
        side = ("lower" if theta[i] <= lower[i] + tol * width
                else "upper" if theta[i] >= upper[i] - tol * width else None)
        if side is None or key is None:  # key None: a range the model fixes (GMS's splits)
            continue
        phys = (lambda x: 10.0 ** x) if kind == "log10" else (lambda x: x)
        value, lo, hi = float(phys(theta[i])), float(phys(lower[i])), float(phys(upper[i]))
        flag = {"name": name, "search_name": search, "side": side, "value": value, "range": [lo, hi],
                "box_key": key, "option": f"box[{key!r}]", "shown": f"{name}/Fc" if kind == "ratio" else name}
        wider = widened(key, lo, hi, side)
        flag.update(at_limit=wider is None, widen_to=None if wider is None else list(wider))
        flag["message"] = bound_message(flag)
        out.append(flag)
    return out


def bound_message(flag: dict, style: str = "python") -> str:
    """The one-line message of an [`on_bound`][jaxfric.identification.on_bound] flag; ``style="cli"`` gives the wider
    range as the command line takes it (``--box vs=1e-05,0.01``), ``"python"`` as
    [`jaxfric.identify`][jaxfric.identification.identify] does (``box={'vs': (1e-05, 0.01)}``)."""
    key, (lo, hi) = flag["box_key"], flag["range"]
    if flag.get("widen_to") is None:  # the range already starts where the model's rule allows
        advice = (f"the least the model allows ({key} range {RANGE_FLOORS[key][2]}): the data "
                  f"ask for less than the model can express")
    else:
        a, b = flag["widen_to"]
        option = f"--box {key}={a:.4g},{b:.4g}" if style == "cli" else f"box={{{key!r}: ({a:.4g}, {b:.4g})}}"
        advice = f"the box, not the data, fixed it; widen the range (pass {option}) and fit again"
    shown = flag.get("shown", flag["name"])
    return (f"{shown} = {flag['value']:.4g} ended on the {flag['side']} bound of its search range "
            f"[{lo:.4g}, {hi:.4g}]: {advice}")


#: Samples faster than this fraction of the largest speed count as moving for
#: `friction_sign`.
MOVING_FRACTION = 0.1


def friction_sign(velocity, friction) -> str | None:
    """A one-line warning when ``friction`` mostly pushes along ``velocity``, else ``None``.

    Friction dissipates: with jaxfric's convention (friction > 0 while x increases) the
    mean of ``F·sign(v)`` over the moving samples (``|v|`` above `MOVING_FRACTION`
    of its largest value) is the mean friction level, positive even with an offset when
    the record moves both ways. A negative mean means a crossed sign convention, which no
    friction model can fit (a Coulomb level then ends on the lower bound of its box).
    """
    v, f = np.asarray(velocity, np.float64).ravel(), np.asarray(friction, np.float64).ravel()
    speed = np.abs(v)
    top = float(np.max(speed)) if speed.size else 0.0
    moving = speed > MOVING_FRACTION * top
    if top <= 0.0 or not moving.any():
        return None
    level = float(np.mean(f[moving] * np.sign(v[moving])))
    if level >= 0.0:
        return None
    return (f"the friction mostly pushes along the motion (mean of F·sign(v) over the moving samples: "
            f"{level:.4g}); jaxfric's convention is friction > 0 while the velocity is positive. "
            f"Check the signs: negate the friction, or, from raw cylinder channels, the load (it "
            f"opposes +x; a scale or unit factor of -1 flips it) and which chamber is p1 (the one "
            f"pushing towards +x)")


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
