"""Parameter uncertainty of a physical friction fit (docs/uncertainty.md).

The residual vector r(θ) of each kind of fit, its Jacobian J = ∂r/∂θ at θ̂
(``jax.jacfwd``), and the covariance estimators of [`jaxfric.covariance`][jaxfric.covariance] (Jacobian,
Newey–West, block bootstrap) applied to them; the plausibility rules; what the report
and CLI show.

Each fit names its problem ([`Fit.problem`][jaxfric.fit.Fit.problem], a
[`jaxfric.problem.AbstractProblem`][jaxfric.problem.AbstractProblem]), which says how its residuals are built: a
force-balance [`jaxfric.Fit`][jaxfric.fit.Fit] (friction prediction minus measured friction,
[`jaxfric.problem.ForceBalanceProblem`][jaxfric.problem.ForceBalanceProblem]), a [`jaxfric.motion.MotionFit`][jaxfric.motion.MotionFit] (simulated
minus measured position, [`jaxfric.motion.MotionProblem`][jaxfric.motion.MotionProblem]). This module asks the fit, so it
imports neither ``identification`` nor ``motion``, and looks nothing up.

The linearisation (r, J, the physical values and their Jacobian) is one compiled XLA
program (`_linearise`), not some thirty small ones run op by op. Its residual
function is a pytree (an ``eqx.Module``): the records are its array leaves, traced
inputs of the program, and only the model's configuration, the training lengths and
the dtypes are static, so a second fit of the same model on records of the same
lengths reuses the compiled program.
"""

from __future__ import annotations

import functools
import warnings
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._warnings import ExtrapolationWarning
from .covariance import (DEFAULT_LEVEL, DEFAULT_METHODS, DEFAULT_RCOND, DEFAULT_REPLICATES, METHODS,
                         MAX_REPORT_CORRELATION, NOT_IDENTIFIABLE, ParameterUncertainty, check_level,
                         _check_methods, andrews_bandwidth, block_bootstrap_covariance, correlation_text,
                         hac_covariance, interval_text, jacobian_covariance, number_text)
from .fit import NOT_IDENTIFIABLE_MEANING, Fit, diagnostic_flags, grouped_reasons, parameter_verdicts
from .plausibility import check_plausibility, warn_implausible
from .problem import ForceBalanceProblem

__all__ = ["METHODS", "ParameterUncertainty", "andrews_bandwidth", "assess_fit", "block_bootstrap_covariance",
           "coverage", "hac_covariance", "jacobian_covariance", "parameter_uncertainty", "prediction_interval"]


def _problem(fit):
    """The fit's problem (it says how the fit's residuals are built)."""
    if not isinstance(fit, Fit):
        raise TypeError(f"no parameter uncertainty for a {type(fit).__name__}: not a jaxfric fit")
    return fit.problem()


# ----------------------------------------------------------------------- uncertainty
def _physical(model, y, kinds):
    """Physical value of every coordinate of ``y`` (a motion fit's mechanics appended)."""
    k = model.num_params
    vals = model._coord_values(y[:k])
    out = [vals[c[1]] for c in model._coords]
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
    check_level(level)
    problem = _problem(fit)
    if fit.model.needs_scaling:
        raise ValueError(f"{type(fit.model).__name__} is a black-box network: its weights have no "
                         "physical meaning, so no parameter intervals (use keys=K for an ensemble band)")
    if "block_bootstrap" in methods and key is None:
        raise ValueError("method 'block_bootstrap' needs key= (a PRNG key or int seed)")
    res = problem.residuals(fit, data)
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
    fit has none (a network, a file saved without it) or another kind of band (a motion
    fit's is about position: ``fit.prediction_interval(record)``)."""
    if not isinstance(fit.problem(), ForceBalanceProblem):
        raise ValueError("a friction band over velocity is a force-balance fit's; a motion fit's band is about "
                         "position: fit.prediction_interval(record)")
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
    velocity = _problem(fit).train_velocity(fit, data)
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
                  and isinstance(fit.problem(), ForceBalanceProblem))
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
                _, lo, hi = prediction_interval(fit, data.velocity, level, inputs=inputs)
            except ValueError:
                pass
            else:
                out["band"] = {**_window_coverage(fit, data, lo, hi),
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
    return {"members": len(fit.ensemble.get("J", [])), **_window_coverage(fit, data, lo, hi),
            "mean_half_width_N": float(np.mean(hi - lo) / 2)}


def _window_coverage(fit, data, lo, hi) -> dict:
    """[`coverage`][jaxfric.uncertainty.coverage] of the measured friction on the training and validation windows."""
    f, n = np.asarray(data.friction), fit.n_train
    return {"train": coverage(f[:n], lo[:n], hi[:n]), "valid": coverage(f[n:], lo[n:], hi[n:]) if n < f.size else None}


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
            L += [f"| {a} | " + " | ".join(f"{x:+.2f}" for x in row) + " |" for a, row in zip(names, corr["matrix"])]
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
