"""Physical plausibility of a fitted friction model (docs/uncertainty.md, "Plausibility").

A fit can minimise the cost with values that are not physics: a Stribeck peak many
times the Coulomb level that acts only inside the handful of samples near zero
velocity, a constant force offset that the data cannot tell from asymmetric Coulomb
levels, a pre-sliding stiffness whose elastic range the record barely visits. Each
rule below states where a parameter means something and, when the fit lies outside,
returns a [`Implausible`][jaxfric.plausibility.Implausible] with the reason and the evidence from the data. The
rules look at the fitted physical values and the training record only (NumPy, no
model rollout), so they run on every fit.

Rules (thresholds are module constants):

* ``stribeck_spike`` — Fs/Fc > [`STRIBECK_RATIO`][jaxfric.plausibility.STRIBECK_RATIO] while fewer than
  [`MIN_SUPPORT_FRACTION`][jaxfric.plausibility.MIN_SUPPORT_FRACTION] of the samples (of that direction) lie where the peak
  acts, 0 < |v| < vs (ln 20)^{1/δ} (the excess Fs − Fc has decayed to 5 % beyond).
  LuGre, Stribeck, GMS; Cylinder's breakaway ratio ``K_brk`` likewise.
* ``offset_asymmetric`` — an offset F_off with direction-dependent Coulomb levels,
  |F_off| > [`OFFSET_FRACTION`][jaxfric.plausibility.OFFSET_FRACTION] of their mean, while fewer than
  [`MIN_STANDSTILL_FRACTION`][jaxfric.plausibility.MIN_STANDSTILL_FRACTION] of the samples are at standstill (|v| below 2 % of
  max |v|), the only samples that separate an offset from the two levels.
* ``presliding_unvisited`` — a pre-sliding stiffness (LuGre and Dahl σ0, GMS k_i)
  whose elastic range z = Fc/σ0 (GMS: α_i Fc / k_i) holds fewer than
  [`MIN_SUPPORT_FRACTION`][jaxfric.plausibility.MIN_SUPPORT_FRACTION] of the samples and fewer than
  [`MIN_SUPPORT_SAMPLES`][jaxfric.plausibility.MIN_SUPPORT_SAMPLES] samples, counting the travel since the last velocity
  reversal (needs the sample time).
"""

from __future__ import annotations

import dataclasses
import warnings
from typing import Any

import numpy as np

__all__ = ["Implausible", "PlausibilityWarning", "check_plausibility", "travel_since_reversal"]

#: Fs/Fc (Cylinder: K_brk) above this is a Stribeck peak worth evidence [D].
STRIBECK_RATIO = 2.0
#: Fewer samples than this fraction where a parameter acts: the parameter is set by them alone.
MIN_SUPPORT_FRACTION = 0.01
#: ... and fewer than this many samples (for the pre-sliding rule, which counts samples).
MIN_SUPPORT_SAMPLES = 20
#: |F_off| above this fraction of the mean Coulomb level is a real shift of the levels [D].
OFFSET_FRACTION = 0.1
#: Standstill: |v| below this fraction of max |v| (as `jaxfric.models` LOW_SPEED).
STANDSTILL = 0.02
#: Fewer standstill samples than this fraction, and an offset is not separated from
#: asymmetric Coulomb levels [D] (measured on EMPS: docs/uncertainty.md, "Plausibility").
MIN_STANDSTILL_FRACTION = 0.05


#: What a [`PlausibilityWarning`][jaxfric.plausibility.PlausibilityWarning] means for the user, said at the end of each.
WHAT_IT_MEANS = ("So {name} is not identifiable from these data: the fit still predicts records like these, but "
                 "{name} is no physical property (fit.verdicts() gives every parameter's verdict)")


class PlausibilityWarning(UserWarning):
    """A fitted parameter lies outside the range where it means something physically
    ([`jaxfric.plausibility`][jaxfric.plausibility]): the message gives the reason and the evidence."""


@dataclasses.dataclass(frozen=True)
class Implausible:
    """One rule a fit breaks: ``name`` (the parameter), ``rule``, ``message`` (reason
    and evidence in words) and ``evidence`` (the numbers)."""

    name: str
    rule: str
    message: str
    evidence: dict

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "rule": self.rule, "message": self.message,
                "evidence": {k: float(v) if isinstance(v, (int, float, np.floating, np.integer)) else v
                             for k, v in self.evidence.items()}}


def travel_since_reversal(velocity, dt: float) -> np.ndarray:
    """|∫ v dt| since the last sign change of ``v`` (or the start) at every sample [m]:
    the displacement a bristle or Maxwell element has been loaded through."""
    v = np.asarray(velocity, np.float64)
    step = v * float(dt)
    sign = np.sign(v)
    # a new segment starts where the sign flips (zeros continue the current segment)
    last = np.maximum.accumulate(np.where(sign != 0, np.arange(sign.size), 0))
    s = sign[last]
    new = np.r_[True, s[1:] != s[:-1]]
    seg = np.cumsum(new) - 1
    csum = np.cumsum(step)
    start = csum[np.flatnonzero(new)] - step[np.flatnonzero(new)]
    return np.abs(csum - start[seg])


def _direction_sets(params: dict, base: str):
    """``[(suffix, sign)]`` for a parameter given per direction, else ``[("", 0)]``."""
    if base + "_pos" in params:
        return [("_pos", 1.0), ("_neg", -1.0)]
    return [("", 0.0)]


def _exponent(model, params) -> float:
    for attr in ("stribeck_exponent", "exponent"):
        if hasattr(model, attr):
            return float(getattr(model, attr))
    return float(params.get("delta", 2.0))


def _stribeck(model, params, v) -> list[Implausible]:
    out = []
    if "vs" not in params:
        return out
    delta = _exponent(model, params)
    reach = float(params["vs"]) * np.log(20.0) ** (1.0 / delta)
    speed = np.abs(v)
    if "K_brk" in params:
        pairs = [("K_brk", float(params["K_brk"]), 0.0)]
    elif "Fs" in params or "Fs_pos" in params:
        pairs = []
        for sfx, sign in _direction_sets(params, "Fs"):
            fc = float(params.get("Fc" + sfx, params.get("Fc", np.nan)))
            pairs.append(("Fs" + sfx, float(params["Fs" + sfx]) / fc if fc > 0 else np.inf, sign))
    else:
        return out
    for name, ratio, sign in pairs:
        if not ratio > STRIBECK_RATIO:
            continue
        side = (sign * v > 0) if sign else np.ones_like(v, bool)
        inside = side & (speed > 0) & (speed < reach)
        frac = float(np.sum(inside)) / max(int(np.sum(side)), 1)
        if frac < MIN_SUPPORT_FRACTION:
            what = "K_brk" if name == "K_brk" else f"Fs/Fc{name[2:]}"
            out.append(Implausible(name, "stribeck_spike", (
                f"{what} = {ratio:.3g}: a Stribeck peak {ratio:.3g}× the Coulomb level acting only at "
                f"|v| < {reach:.3g} m/s (vs = {float(params['vs']):.3g} m/s), where {frac:.2%} of the "
                f"samples{' of that direction' if sign else ''} lie (< {MIN_SUPPORT_FRACTION:.0%}): "
                "the peak is fitted to a handful of samples near zero velocity, not to a Stribeck dip"),
                {"ratio": ratio, "reach_m_s": reach, "fraction": frac, "samples": int(np.sum(inside))}))
    return out


def _offset(params, v) -> list[Implausible]:
    if not ("F_off" in params and "Fc_pos" in params and "Fc_neg" in params):
        return []
    off = float(params["F_off"])
    level = 0.5 * (abs(float(params["Fc_pos"])) + abs(float(params["Fc_neg"])))
    speed = np.abs(v)
    still = float(np.mean(speed < STANDSTILL * float(speed.max())))
    if abs(off) > OFFSET_FRACTION * level and still < MIN_STANDSTILL_FRACTION:
        return [Implausible("F_off", "offset_asymmetric", (
            f"F_off = {off:.3g} N is {abs(off) / level:.0%} of the mean Coulomb level {level:.3g} N, "
            f"but with direction-dependent levels sliding data fix only Fc_pos + F_off = "
            f"{float(params['Fc_pos']) + off:.3g} N and Fc_neg - F_off = {float(params['Fc_neg']) - off:.3g} N; "
            f"only {still:.2%} of the samples are at standstill (|v| < {STANDSTILL:.0%} of max |v|) to "
            "tell them apart: the split is set by the search box and a few samples, not by physics"),
            {"F_off": off, "coulomb_level": level, "standstill_fraction": still})]
    return []


def _presliding(model, params, v, dt) -> list[Implausible]:
    if dt is None:
        return []
    stiff = []
    if "sigma0" in params:
        fc = params.get("Fc")
        if fc is None and "Fc_pos" in params:
            fc = 0.5 * (float(params["Fc_pos"]) + float(params["Fc_neg"]))
        if fc is not None:
            stiff.append(("sigma0", float(params["sigma0"]), abs(float(fc)) / float(params["sigma0"])))
    k = sorted(n for n in params if n[:1] == "k" and n[1:].isdigit())
    if k and "Fc" in params:
        for name in k:
            i = name[1:]
            alpha = float(params.get(f"alpha{i}", 1.0 / len(k)))
            stiff.append((name, float(params[name]), alpha * abs(float(params["Fc"])) / float(params[name])))
    if not stiff:
        return []
    travel = travel_since_reversal(v, dt)
    out = []
    for name, value, z in stiff:
        inside = int(np.sum(travel < z))
        frac = inside / max(v.size, 1)
        if frac < MIN_SUPPORT_FRACTION and inside < MIN_SUPPORT_SAMPLES:
            out.append(Implausible(name, "presliding_unvisited", (
                f"{name} = {value:.3g} N/m gives an elastic (pre-sliding) range of {z:.3g} m, and only "
                f"{inside} samples ({frac:.2%}) lie within it of a velocity reversal: the record barely "
                "visits pre-sliding, so this stiffness is set by those samples (or the box), not measured"),
                {"value": value, "range_m": z, "samples": inside, "fraction": frac}))
    return out


def check_plausibility(model, params: dict, velocity, dt: float | None = None) -> list[Implausible]:
    """The rules of the module docstring for ``model`` at its physical ``params``
    (``{name: value}``, [`jaxfric.Fit.params`][jaxfric.fit.Fit.params]) on the training ``velocity`` [m/s]
    sampled every ``dt`` [s] (``None``: the pre-sliding rule is skipped).

    Returns the broken rules (empty for a plausible fit). Network models (whose
    weights have no physical meaning) always return ``[]``."""
    if getattr(model, "needs_scaling", False):
        return []
    v = np.asarray(velocity, np.float64).ravel()
    if v.size == 0 or not np.all(np.isfinite(v)):
        raise ValueError("velocity must be a non-empty, finite 1-D record")
    p = {k: float(np.asarray(x)) for k, x in params.items() if np.ndim(x) == 0}
    return _stribeck(model, p, v) + _offset(p, v) + _presliding(model, p, v, dt)


def warn_implausible(model, found: list[Implausible], stacklevel: int = 3) -> None:
    """One [`PlausibilityWarning`][jaxfric.plausibility.PlausibilityWarning] per broken rule."""
    for f in found:
        warnings.warn(f"{type(model).__name__}: {f.message}. {WHAT_IT_MEANS.format(name=f.name)}",
                      PlausibilityWarning, stacklevel=stacklevel)
