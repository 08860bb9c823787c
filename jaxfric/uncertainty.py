"""Parameter uncertainty of a physical friction fit (docs/uncertainty.md).

The residual vector r(θ) of each kind of fit, its Jacobian J = ∂r/∂θ at θ̂
(``jax.jacfwd``), and the covariance estimators of [`jaxfric.covariance`][jaxfric.covariance] (Jacobian,
Newey–West, block bootstrap) applied to them; the plausibility rules; what the report
and CLI show.

Each kind of fit says how its residuals are built ([`FitKind`][jaxfric.uncertainty.FitKind]): a force-balance
[`jaxfric.Fit`][jaxfric.fit.Fit] here (friction prediction minus measured friction), a
[`jaxfric.motion.MotionFit`][jaxfric.motion.MotionFit] in [`jaxfric.motion`][jaxfric.motion] (simulated minus measured
position), which registers it with [`register_fit_kind`][jaxfric.uncertainty.register_fit_kind]. A record type defined
above this module ([`jaxfric.identification.RecordSet`][jaxfric.identification.RecordSet]) registers how to read its
training records with [`register_training_records`][jaxfric.uncertainty.register_training_records]. Both are looked up along the
class's MRO, and registered by the module that defines the class, so the registration
has run whenever an instance exists; this module imports nothing above it.

The linearisation (r, J, the physical values and their Jacobian) is one compiled XLA
program (`_linearise`), not some thirty small ones run op by op. Its residual
function is a pytree (`_ForceBalance`, an ``eqx.Module``): the records are its
array leaves, traced inputs of the program, and only the model's configuration, the
training lengths and the dtypes are static, so a second fit of the same model on
records of the same lengths reuses the compiled program.
"""

from __future__ import annotations

import dataclasses
import functools
import warnings
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._warnings import ExtrapolationWarning
from .covariance import (DEFAULT_LEVEL, DEFAULT_METHODS, DEFAULT_RCOND, DEFAULT_REPLICATES, METHODS,
                         MAX_REPORT_CORRELATION, NOT_IDENTIFIABLE, ParameterUncertainty, _check_level, _check_methods,
                         andrews_bandwidth, block_bootstrap_covariance, correlation_text, hac_covariance,
                         interval_text, jacobian_covariance, number_text)
from .fit import (NOT_IDENTIFIABLE_MEANING, Fit, _check_dt, _velocity_np, diagnostic_flags, grouped_reasons,
                  parameter_verdicts, rollout)
from .plausibility import check_plausibility, warn_implausible
from .records import FrictionData, as_channel

__all__ = [
    "METHODS",
    "ParameterUncertainty",
    "andrews_bandwidth",
    "assess_fit",
    "block_bootstrap_covariance",
    "coverage",
    "hac_covariance",
    "jacobian_covariance",
    "parameter_uncertainty",
    "prediction_interval",
]


# ----------------------------------------------------------------------- fit kinds
@dataclasses.dataclass(frozen=True)
class Residuals:
    """A fit's training residuals r(y) (``fn``: ``(p,) -> (n,)``) in its search
    coordinates ``y`` (linearised at ``y``), the lengths of the independent ``segments``
    r is made of (no Newey–West lag crosses one), the ``unit`` of r, and per coordinate
    its physical ``names``, ``kinds`` (``"log10"``, ``"linear"``, ...) and search box.

    ``fn`` is best a pytree callable (an ``eqx.Module`` or ``jax.tree_util.Partial``)
    holding the records as array leaves: its compiled linearisation is then shared by
    every fit with equal static parts (model configuration, lengths) and array shapes.
    A plain closure works too, compiled afresh on each call (its captured arrays are
    constants of the program, and the closure is not kept alive by a cache)."""

    fn: Callable
    y: Any
    segments: tuple[int, ...]
    unit: str
    names: tuple[str, ...]
    kinds: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray


@dataclasses.dataclass(frozen=True)
class FitKind:
    """How the uncertainty code reads one class of fit: ``residuals(fit, data)`` gives its
    [`Residuals`][jaxfric.uncertainty.Residuals] over the training data, ``train_velocity(fit, data)`` the
    training velocity the plausibility rules look at."""

    residuals: Callable[[Any, Any], Residuals]
    train_velocity: Callable[[Any, Any], np.ndarray]


_FIT_KINDS: dict[type, FitKind] = {}
_TRAINING_RECORDS: dict[type, Callable[[Any], tuple]] = {}


def register_fit_kind(fit_type: type, kind: FitKind) -> None:
    """Use ``kind`` for fits of ``fit_type`` and its subclasses (unless they register
    their own)."""
    _FIT_KINDS[fit_type] = kind


def register_training_records(data_type: type, records: Callable[[Any], tuple]) -> None:
    """Read the training records of a force-balance fit's data of ``data_type`` with
    ``records(data)``: records ([`jaxfric.FrictionData`][jaxfric.rig.FrictionData]) whose first ``n_train``
    samples trained the fit."""
    _TRAINING_RECORDS[data_type] = records


def _registered(registry: dict, obj):
    return next((registry[c] for c in type(obj).__mro__ if c in registry), None)


def _fit_kind(fit) -> FitKind:
    kind = _registered(_FIT_KINDS, fit)
    if kind is None:
        raise TypeError(f"no parameter uncertainty for a {type(fit).__name__}: not a jaxfric fit")
    return kind


def _coords(model):
    return tuple(model._coords)


# ----------------------------------------------------------------------- force balance
def _training_windows(fit, data) -> tuple:
    """The records a force-balance fit was trained on, each with its training length."""
    records = _registered(_TRAINING_RECORDS, data)
    if records is not None:
        return tuple(records(data))
    if isinstance(data, (list, tuple)) and data and not _is_triplet(data):
        return tuple(_one_record(d) for d in data)  # a list of records, each trained on whole
    return (_one_record(data, fit.n_train),)


def _friction_residuals(fit, data) -> Residuals:
    """Prediction minus measured friction over the training samples the fit was made on,
    each record run from its own initial state (`_ForceBalance`)."""
    if "motion" in fit.settings:
        raise ValueError("a motion fit read as a force-balance Fit (load_fit): read it with "
                         "jaxfric.motion.load_motion_fit for its uncertainty")
    model = fit.model
    records = []
    for r in _training_windows(fit, data):
        x = model.inputs_from(r, r.velocity.shape[0])
        records.append((_velocity_np(r.velocity), np.asarray(r.friction)[: r.n_train],
                        None if x is None else np.asarray(x)))
    resid = _ForceBalance(model=model, scalers=(fit.velocity_scaler, fit.friction_scaler),
                          dt=np.asarray(_check_dt(fit.dt), np.float64), records=tuple(records),
                          n_train=tuple(int(r[1].shape[0]) for r in records))
    lower, upper = (np.asarray(b, np.float64) for b in model.bounds(fit.box))
    return Residuals(fn=resid, y=fit.theta, segments=resid.n_train, unit="friction [N]",
                     names=tuple(c[1] for c in _coords(model)), kinds=tuple(c[2] for c in _coords(model)),
                     lower=lower, upper=upper)


class _ForceBalance(eqx.Module):
    """r(θ) of a force-balance fit: [`jaxfric.fit.predict`][jaxfric.fit.predict] of each record minus its
    measured friction over the first ``n_train`` samples, concatenated. The records
    (velocity, friction, input channels), the scalers and ``dt`` are array leaves, so
    traced inputs of the compiled linearisation; the model (its static configuration)
    and the lengths are its static part."""

    model: Any
    scalers: tuple
    dt: np.ndarray
    records: tuple  # ((velocity, training friction, inputs or None), ...)
    n_train: tuple[int, ...] = eqx.field(static=True)

    def __call__(self, theta):
        out = [rollout(self.model, theta, self.scalers, v, self.dt, x)[:n] - jnp.asarray(f, theta.dtype)
               for (v, f, x), n in zip(self.records, self.n_train)]
        return jnp.concatenate(out)


def _friction_train_velocity(fit, data) -> np.ndarray:
    return np.concatenate([np.asarray(r.velocity)[: r.n_train] for r in _training_windows(fit, data)])


def _one_record(data, n_train: int | None = None):
    """A record a force-balance fit was trained on (a ``(velocity, friction, dt)`` tuple or
    a FrictionData), with its first ``n_train`` samples (default: all) as the training
    window."""
    if _is_triplet(data):
        v, f, _ = data
        rec = None
    elif isinstance(data, FrictionData):
        v, f, rec = data.velocity, data.friction, data
    else:
        raise ValueError("data must be the fit's training record (FrictionData or (velocity, friction, dt)), "
                         f"a list of training records, or a RecordSet; got {type(data).__name__}")
    v, f = as_channel("velocity", v), as_channel("friction", f)
    n_train = v.shape[0] if n_train is None else n_train
    if v.shape != f.shape or v.shape[0] < n_train:
        raise ValueError(f"the record ({v.shape[0]} velocity, {f.shape[0]} friction samples) does not hold "
                         f"the fit's {n_train} training samples")

    return _Window(v, f, int(n_train), rec)


@dataclasses.dataclass(frozen=True)
class _Window:
    """A record's velocity, friction and training length; other attributes (a Cylinder's
    chamber pressures) come from the record it was read from, if any."""

    velocity: np.ndarray
    friction: np.ndarray
    n_train: int
    source: Any = None

    def __getattr__(self, name):
        if name == "source":  # not set yet (copying): no recursion
            raise AttributeError(name)
        return getattr(self.source, name)


def _is_triplet(data) -> bool:
    return isinstance(data, tuple) and len(data) == 3 and np.ndim(data[2]) == 0


register_fit_kind(Fit, FitKind(residuals=_friction_residuals, train_velocity=_friction_train_velocity))


# ----------------------------------------------------------------------- uncertainty
def _physical(model, y, kinds):
    """Physical value of every coordinate of ``y`` (a motion fit's mechanics appended)."""
    k = model.num_params
    vals = model._coord_values(y[:k])
    out = [vals[c[1]] for c in _coords(model)]
    for kind, x in zip(kinds[k:], y[k:]):
        out.append(10.0**x if kind == "log10" else x)
    return jnp.stack(out)


def _linearisation(resid, model, kinds, theta):
    """``(r, J, b, D)``: the residuals r(θ), J = ∂r/∂θ, the physical values b(θ) and
    D = ∂b/∂θ, by forward mode (p ≤ a dozen columns, one JVP each; the primal of the
    JVPs gives r and b)."""
    def both(f):  # (value, value): jacfwd's aux gives the primal of the same trace
        def value_twice(t):
            y = f(t)
            return y, y
        return value_twice

    jac, r = jax.jacfwd(both(resid), has_aux=True)(theta)
    d, b = jax.jacfwd(both(lambda y: _physical(model, y, kinds)), has_aux=True)(theta)
    return r, jac, b, d


#: The compiled linearisation of a pytree residual function: its arrays (records, dt,
#: θ) are traced, its other leaves, the model and ``kinds`` are static and hashed, so
#: one program serves every fit with the same configuration and record shapes.
_linearise = eqx.filter_jit(_linearisation)


def _linearise_once(resid, model, kinds, theta):
    """`_linearise` for a pytree ``resid``; a plain closure (hashed by identity, so
    never reused) is compiled by a ``jax.jit`` that dies with this call, so that no
    cache keeps the closure and the arrays it captured alive."""
    if isinstance(resid, (eqx.Module, jax.tree_util.Partial)):
        return _linearise(resid, model, kinds, theta)
    return jax.jit(lambda t: _linearisation(resid, model, kinds, t))(theta)


def parameter_uncertainty(fit, data, *, method=DEFAULT_METHODS, level: float = DEFAULT_LEVEL,
                          key=None, replicates: int = DEFAULT_REPLICATES, bandwidth=None,
                          rcond: float = DEFAULT_RCOND) -> ParameterUncertainty:
    """Covariances, standard errors and intervals of a physical fit's parameters.

    Args:
        fit: a [`jaxfric.Fit`][jaxfric.fit.Fit] of a physical model (from [`jaxfric.identify`][jaxfric.identification.identify]),
            or a [`jaxfric.motion.MotionFit`][jaxfric.motion.MotionFit].
        data: what the fit was trained on: the record given to ``identify`` (its first
            ``fit.n_train`` samples are used), a list of training records, or the
            [`jaxfric.motion.MotionData`][jaxfric.motion.MotionData] of a motion fit.
        method: one or more of [`METHODS`][jaxfric.uncertainty.METHODS] (default [`DEFAULT_METHODS`][jaxfric.covariance.DEFAULT_METHODS]); the
            first is the default the result shows. ``"block_bootstrap"`` needs ``key``.
        bandwidth: Newey–West lag L; default [`andrews_bandwidth`][jaxfric.uncertainty.andrews_bandwidth].
        rcond: relative singular-value floor (module docstring).

    Computed in ``fit.theta``'s dtype (enable x64 for long records). The residuals,
    their Jacobian and the physical values' Jacobian are one compiled program
    (`_linearise`), reused by later calls on fits of the same model configuration
    and record lengths (the first call pays its compilation, about a second). Raises
    ``ValueError`` for a network fit (its weights have no physical meaning), an unknown
    method, or a bootstrap without a key.
    """
    methods = _check_methods(method)
    _check_level(level)
    kind = _fit_kind(fit)
    if fit.model.needs_scaling:
        raise ValueError(f"{type(fit.model).__name__} is a black-box network: its weights have no "
                         "physical meaning, so no parameter intervals (use keys=K for an ensemble band)")
    if "block_bootstrap" in methods and key is None:
        raise ValueError("method 'block_bootstrap' needs key= (a PRNG key or int seed)")
    res = kind.residuals(fit, data)
    resid, segs, kinds = res.fn, res.segments, res.kinds
    theta = jnp.asarray(res.y, jnp.asarray(fit.theta).dtype)
    r, jac, estimate, d = (np.asarray(a, np.float64) for a in _linearise_once(resid, fit.model, kinds, theta))
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(jac))):
        raise ValueError("the fit's residuals or their Jacobian are not finite: no uncertainty "
                         "(a diverged fit, or float32 overflow: enable x64)")
    p = theta.shape[0]
    n = int(r.shape[0])
    cov_t, s2, rank = jacobian_covariance(jac, r, rcond)
    L = andrews_bandwidth(jac, r, segs) if bandwidth is None else float(bandwidth)
    covs = {}
    for m in methods:
        if m == "jacobian":
            covs[m] = cov_t
        elif m == "hac":
            covs[m] = hac_covariance(jac, r, L, rcond, segs)
        else:
            covs[m] = block_bootstrap_covariance(jac, r, key, int(round(L)) + 1, replicates, rcond)
    lag1 = float(np.dot(r[1:], r[:-1]) / max(np.dot(r, r), 1e-300))
    return ParameterUncertainty(
        names=res.names, kinds=kinds, estimate=estimate,
        theta=np.asarray(theta, np.float64), lower=res.lower, upper=res.upper,
        cov_theta={m: np.asarray(c, np.float64) for m, c in covs.items()},
        cov={m: np.asarray(d @ c @ d.T, np.float64) for m, c in covs.items()},
        n=n, dof=max(n - p, 1), s2=float(s2), rank=int(rank), bandwidth=float(L), residual=res.unit,
        default=methods[0], lag1=lag1, segments=tuple(int(s) for s in segs))


def prediction_interval(fit, velocity, level: float = DEFAULT_LEVEL, *, dt=None, inputs=None,
                        method=None, noise: bool = True):
    """``(prediction, low, high)`` [N] for a velocity record: [`jaxfric.Fit.prediction_interval`][jaxfric.fit.Fit.prediction_interval]
    (ŷ ± t sqrt(j Σ jᵀ + s²) with the box-capped covariance); a ``ValueError`` names why a
    fit has none (a network, a motion fit, a file saved without it)."""
    if fit.uncertainty is None:
        raise ValueError("this fit has no parameter uncertainty (a network, or a fit loaded from an "
                         "older file): jaxfric.uncertainty.parameter_uncertainty(fit, data) makes one")
    return fit.prediction_interval(velocity, level, dt=dt, inputs=inputs, method=method, noise=noise)


def coverage(y, low, high) -> float:
    """Fraction of ``y`` inside ``[low, high]``."""
    y = np.asarray(y)
    return float(np.mean((y >= low) & (y <= high)))


def assess_fit(fit, data):
    """What [`jaxfric.identify`][jaxfric.identification.identify] and [`jaxfric.identify_motion`][jaxfric.motion.identify_motion] run on every
    physical fit: the plausibility rules ([`jaxfric.plausibility.check_plausibility`][jaxfric.plausibility.check_plausibility],
    into ``fit.diagnostics["implausible"]``, each with a
    [`PlausibilityWarning`][jaxfric.plausibility.PlausibilityWarning]), and the training ``data``
    attached so that [`jaxfric.Fit.uncertainty`][jaxfric.fit.Fit.uncertainty] is computed on first use (the
    Jacobian's compilation costs seconds that a fit nobody inspects should not pay).
    Returns the fit with both (a new one: a fit is immutable), ``fit`` itself for a network."""
    if fit.model.needs_scaling:
        return fit
    velocity = _fit_kind(fit).train_velocity(fit, data)
    found = check_plausibility(fit.model, fit.params, velocity, fit.dt)
    warn_implausible(fit.model, found, stacklevel=4)
    # the computation reads the model, parameters and scalers, which the new fit shares
    return fit.replace(diagnostics={**fit.diagnostics, "implausible": [f.to_json() for f in found]},
                       uncertainty=functools.partial(parameter_uncertainty, fit, data, method=DEFAULT_METHODS))


# ----------------------------------------------------------------------- report
def report_summary(fit, data, level: float = DEFAULT_LEVEL) -> dict | None:
    """What report.md and results.json show of a physical fit's parameters: one verdict
    per parameter (``verdicts``, [`Fit.verdicts`][jaxfric.fit.Fit.verdicts]: value,
    identifiable or not and why, interval), the uncertainty table (each row carrying the
    same verdict), strongly correlated pairs, the plausibility rules broken (evidence
    for the verdicts) and, for a force-balance fit on one split record ``data``, the
    prediction band's measured coverage on the training and validation windows. ``None``
    for a fit with none of these (a network without an ensemble)."""
    u = None if fit.model.needs_scaling else fit.uncertainty
    implausible = list(fit.diagnostics.get("implausible", []))
    verdicts = parameter_verdicts(fit, level)
    one_record = (getattr(data, "velocity", None) is not None and len(data.velocity) == fit.n_samples
                  and "motion" not in fit.settings)
    ensemble = _ensemble_band(fit, data) if one_record and fit.ensemble else None
    if u is None and not implausible and not verdicts and ensemble is None:
        return None
    out: dict[str, Any] = {"level": level, "verdicts": verdicts, "implausible": implausible,
                           "ensemble_band": ensemble}
    if u is not None:
        out.update(method=u.default, residual=u.residual, n=u.n, lag1=u.lag1, bandwidth=u.bandwidth,
                   rank=u.rank, table=u.table(level, diagnostic_flags(fit)), correlated=[list(x) for x in u.strongly_correlated()],
                   correlation={"names": list(u.names),
                                "matrix": np.round(u.correlation(), 3).tolist()},
                   error=fit.uncertainty_error)
        if one_record:
            try:
                inputs = fit.model.inputs_from(data, len(data.velocity))
                y, lo, hi = prediction_interval(fit, data.velocity, level, inputs=inputs)
            except ValueError:
                y = None
            if y is not None:
                f, n = np.asarray(data.friction), fit.n_train
                out["band"] = {"train": coverage(f[:n], lo[:n], hi[:n]),
                               "valid": coverage(f[n:], lo[n:], hi[n:]) if n < f.size else None,
                               "median_half_width_N": float(np.median(hi - lo) / 2),
                               "max_half_width_N": float(np.max(hi - lo) / 2)}
    return out


def _ensemble_band(fit, data) -> dict | None:
    """Measured coverage of an ensemble's min–max band (``fit.predict_band``)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ExtrapolationWarning)
            lo, hi = fit.predict_band(data.velocity)
    except ValueError:
        return None
    f, n = np.asarray(data.friction), fit.n_train
    return {"members": len(fit.ensemble.get("J", [])), "train": coverage(f[:n], lo[:n], hi[:n]),
            "valid": coverage(f[n:], lo[n:], hi[n:]) if n < f.size else None,
            "mean_half_width_N": float(np.mean(hi - lo) / 2)}


def report_markdown(summary: dict | None) -> list[str]:
    """Markdown lines of [`report_summary`][jaxfric.uncertainty.report_summary] for a model's section of report.md: one
    table of the parameters (value, standard errors, interval and verdict), the reasons
    of every parameter that is not identifiable (each reason once), correlations and
    the prediction bands."""
    if not summary:
        return []
    L: list[str] = []
    lvl = f"{summary['level']:.0%}"
    verdicts = summary.get("verdicts") or {}
    rows = {row["name"]: row for row in summary.get("table") or []}
    if verdicts:
        if rows:
            L += ["", f"Parameter uncertainty ({lvl} intervals, Newey–West covariance of the {summary['n']} "
                  f"training residuals in {summary['residual']}, lag-1 autocorrelation {summary['lag1']:.2f}; "
                  "see docs/uncertainty.md), one verdict per parameter:", "",
                  f"| parameter | value (SI) | se (Newey–West) | se (independent residuals) | {lvl} interval | verdict |",
                  "|---|---|---|---|---|---|"]
        else:
            L += ["", "| parameter | value (SI) | verdict |", "|---|---|---|"]
        for name, v in verdicts.items():
            marks = [] if v["identifiable"] else [f"**{NOT_IDENTIFIABLE}**"]
            if v.get("on_bound"):
                marks.append("**at the least value the model allows**" if v.get("at_limit")
                             else "**on a bound: widen its range**")
            verdict = ", ".join(marks) or "identifiable"
            value = number_text(v.get("value"), ".6g")
            if rows:
                row = rows.get(name, {})
                interval = interval_text(v.get("interval"), ".4g", NOT_IDENTIFIABLE if not v["identifiable"] else "-")
                L.append(f"| {name} | {value} | {number_text(row.get('se_hac'))} | {number_text(row.get('se_jacobian'))} | "
                         f"{interval} | {verdict} |")
            else:
                L.append(f"| {name} | {value} | {verdict} |")
        groups = grouped_reasons(verdicts)
        if groups:
            L += ["", f"**{NOT_IDENTIFIABLE_MEANING[0].upper() + NOT_IDENTIFIABLE_MEANING[1:]}.** Why:", ""]
            L += [f"- {', '.join(names)}: {why}" for names, why in groups]
        corr = summary.get("correlation")
        if corr and 1 < len(corr["names"]) <= MAX_REPORT_CORRELATION:
            names = corr["names"]
            L += ["", "Correlation of the estimates:", "", "| | " + " | ".join(names) + " |",
                  "|---|" + "---|" * len(names)]
            L += [f"| {a} | " + " | ".join(f"{x:+.2f}" for x in row) + " |"
                  for a, row in zip(names, corr["matrix"])]
        for a, b, r in summary.get("correlated", []):
            L += ["", correlation_text(a, b, r) + "."]
        band = summary.get("band")
        if band:
            cov = [f"{band['train']:.1%} of the training samples"]
            if band.get("valid") is not None:
                cov.append(f"{band['valid']:.1%} of the validation samples")
            L += ["", f"{lvl} prediction band (parameter covariance, capped at the search box, plus the "
                  f"training residual variance; half-width median {band['median_half_width_N']:.3g} N, "
                  f"max {band['max_half_width_N']:.3g} N) holds " + " and ".join(cov) + "."]
    eb = summary.get("ensemble_band")
    if eb:
        L += ["", f"The {eb['members']} members' min–max band (mean half-width {eb['mean_half_width_N']:.3g} N) "
              f"holds {eb['train']:.1%} of the training"
              + (f" and {eb['valid']:.1%} of the validation samples" if eb.get("valid") is not None else " samples")
              + ": it shows the optimiser's spread, not where new data fall."]
    return L


def cli_lines(fit, level: float = DEFAULT_LEVEL) -> list[str]:
    """The command line's short account of a physical fit: one line of intervals (a
    parameter that is not identifiable says so instead, [`Fit.verdicts`][jaxfric.fit.Fit.verdicts]),
    a line naming those parameters and what that means, and a line per strongly
    correlated pair (nothing for a network)."""
    verdicts = parameter_verdicts(fit, level)
    if not verdicts:
        return []
    u = fit.uncertainty
    lines = []
    if u is not None:
        parts = [f"{k} {v['value']:.4g} " + interval_text(v["interval"], ".3g", f"({NOT_IDENTIFIABLE})")
                 for k, v in verdicts.items() if k in u.names]
        lines.append(f"  {level:.0%} intervals ({u.default}): " + ", ".join(parts))
    loose = [k for k, v in verdicts.items() if not v["identifiable"]]
    if loose:
        lines.append(f"  not identifiable from these data: {', '.join(loose)}; their values were set by the search "
                     "box or a few samples, not measured: no physical properties (report.md says why)")
    if u is not None:
        lines += ["  " + correlation_text(a, b, r) for a, b, r in u.strongly_correlated()]
    return lines
