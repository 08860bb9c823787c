"""Covariance estimators of a least-squares fit and their result (docs/uncertainty.md).

NumPy and SciPy (JAX only for the bootstrap's key): no fit, record or model is imported here, so [`jaxfric.fit`][jaxfric.fit] can
read a saved [`ParameterUncertainty`][jaxfric.uncertainty.ParameterUncertainty] and [`jaxfric.uncertainty`][jaxfric.uncertainty] (which builds
the residuals of each kind of fit) sits above it.

For a least-squares fit θ̂ of a residual vector r(θ) (friction prediction minus
measured friction for [`jaxfric.identify`][jaxfric.identification.identify], simulated minus measured position for
[`jaxfric.identify_motion`][jaxfric.motion.identify_motion]), with J = ∂r/∂θ at θ̂ (``jax.jacfwd``):

* ``"jacobian"`` — the classical nonlinear least-squares covariance (Seber & Wild 1989,
  §2.1): Σ = s² (JᵀJ)⁻¹, s² = Σ r² / (n − p). It assumes independent residuals.
* ``"hac"`` (default) — the sandwich with a Newey–West (Bartlett-kernel) estimate of
  the long-run score covariance (Newey & West 1987; bandwidth by Andrews 1991's AR(1)
  plug-in): Σ = (JᵀJ)⁻¹ Ω (JᵀJ)⁻¹, Ω = Σ_l w_l Γ_l, w_l = 1 − |l|/(L + 1),
  Γ_l = Σ_t g_t g_{t−l}ᵀ with scores g_t = J_t r_t. It stays honest when the residuals
  are correlated in time — as friction residuals always are (model error is smooth).
* ``"block_bootstrap"`` — a moving-block bootstrap (Künsch 1989) of the one-step
  Gauss–Newton refit from θ̂: resample time blocks of (J_t, r_t), θ* − θ̂ =
  (J*ᵀJ*)⁻¹ J*ᵀ r*; Σ is the covariance of the replicates (keyed, same key same result).

Covariances are computed in search coordinates (log10 for stiffnesses, damping and
the Stribeck velocity, which span decades) after scaling J's columns to unit norm, and
mapped to the physical units the user sees by the delta method (Σ_p = D Σ_θ Dᵀ,
D = ∂p/∂θ). Directions the data do not determine (singular values of the scaled J
below ``rcond`` times the largest) are *regularised*, not dropped: their variance is
set as if the singular value were ``rcond`` times the largest, so the parameters that
load on them get huge standard errors and correlations near ±1 instead of the
confident zero variance a pseudo-inverse would give. The sandwich and the bootstrap see
almost no variance there (their scores vanish with J's column), so each adds the
Jacobian covariance's variance along those directions.

Intervals at level 1 − α use Student's t with n − p degrees of freedom: θ̂ ± t se
in search coordinates, mapped to physical units (so a log10 coordinate gives a
positive, asymmetric interval); an interval that covers the search box means the data
do not determine that parameter ([`ParameterUncertainty.covers_box`][jaxfric.uncertainty.ParameterUncertainty.covers_box]).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import numpy as np
from scipy import stats

__all__ = ["METHODS", "ParameterUncertainty", "andrews_bandwidth", "block_bootstrap_covariance",
           "hac_covariance", "jacobian_covariance"]

#: Covariance estimators (see the module docstring); the first is the default shown.
METHODS = ("hac", "jacobian", "block_bootstrap")
#: What `parameter_uncertainty` computes unless told (the bootstrap needs a key).
DEFAULT_METHODS = ("hac", "jacobian")
#: Default level of `ParameterUncertainty.intervals`.
DEFAULT_LEVEL = 0.95
#: report.md prints the whole correlation matrix up to this many parameters.
MAX_REPORT_CORRELATION = 12
#: Bootstrap replicates of ``"block_bootstrap"``.
DEFAULT_REPLICATES = 400
#: What every output shows instead of the interval of a parameter the data do not determine.
NOT_IDENTIFIABLE = "not identifiable"
#: The reason [`ParameterUncertainty.not_identifiable`][jaxfric.uncertainty.ParameterUncertainty.not_identifiable] gives for an interval covering the box.
COVERS_BOX = "its {level:.0%} interval covers its whole search box: the data do not determine it"


# ------------------------------------------------------------------ text
# The one formatter of the uncertainty texts: Fit.summary (`ParameterUncertainty.format`),
# report.md (`jaxfric.uncertainty.report_markdown`) and the command line
# (`jaxfric.uncertainty.cli_lines`) write numbers, intervals and correlations through these.
def number_text(x, fmt: str = ".3g") -> str:
    """``x`` in ``fmt``; ``-`` for ``None``; text (a JSON summary's ``"inf"``) as it is."""
    if x is None:
        return "-"
    try:
        return format(float(x), fmt)
    except (TypeError, ValueError):
        return str(x)


def interval_text(interval, fmt: str = ".4g", missing: str = NOT_IDENTIFIABLE) -> str:
    """``[low, high]`` in ``fmt``, or ``missing`` where there is no interval to show (a
    parameter that is not identifiable: its numbers are never shown)."""
    if not interval:
        return missing
    return f"[{number_text(interval[0], fmt)}, {number_text(interval[1], fmt)}]"


def correlation_text(a: str, b: str, r: float) -> str:
    """The sentence for a strongly correlated pair of estimates."""
    return f"corr({a}, {b}) = {r:+.3f}: the data fix a combination of the two, not each"


# ----------------------------------------------------------------------- estimators
# NumPy float64: J is (n, p) with p a handful, so the linear algebra costs microseconds
# and, unlike eager jnp, compiles nothing for each new record length.
def _scaled_inverse(jac: np.ndarray, rcond: float) -> tuple[np.ndarray, int, np.ndarray]:
    """(JᵀJ)⁻¹ by the SVD of J with unit-norm columns; singular values below ``rcond``
    times the largest are raised to it (the regularisation of the module docstring).
    Returns ``(inverse, rank, free)``, ``free`` the inverse's part along those raised
    directions (zero when every direction is determined)."""
    norms = np.linalg.norm(jac, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    _, s, vt = np.linalg.svd(jac / norms, full_matrices=False)
    floor = rcond * s[0] if s[0] > 0 else 1.0
    determined = s > floor
    rank = int(np.sum(determined))
    s = np.maximum(s, floor)
    inv = (vt.T / s**2) @ vt
    free = (vt[~determined].T / floor**2) @ vt[~determined]
    scale = norms[:, None] * norms[None, :]
    return inv / scale, rank, free / scale


#: Default relative singular-value floor: a combination of (unit-norm) columns this much
#: weaker than the best-determined one is taken as undetermined. float32 rollouts
#: resolve relative changes of ~1e-7, so a singular value ratio below ~1e-5 is noise.
DEFAULT_RCOND = 1e-6


def _as64(jac, resid):
    jac, resid = np.asarray(jac, np.float64), np.asarray(resid, np.float64)
    if jac.ndim != 2 or resid.shape != jac.shape[:1]:
        raise ValueError(f"jac must be (n, p) and resid (n,), got {jac.shape} and {resid.shape}")
    return jac, resid


def jacobian_covariance(jac, resid, rcond: float = DEFAULT_RCOND):
    """Σ = s² (JᵀJ)⁻¹, s² = Σ r² / (n − p) (classical, independent residuals).

    ``jac``: ``(n, p)``; ``resid``: ``(n,)``. Returns ``(cov, s2, rank)``."""
    jac, resid = _as64(jac, resid)
    _, p = jac.shape
    inv, rank, _ = _scaled_inverse(jac, rcond)
    s2 = _residual_variance(resid, p)
    return s2 * inv, s2, rank


def _residual_variance(resid: np.ndarray, p: int) -> float:
    """s² = Σ r² / (n − p)."""
    return float(np.sum(resid**2) / max(resid.size - p, 1))


def _long_run(g: np.ndarray, bandwidth: float) -> np.ndarray:
    """Σ_l w_l Γ_l with Bartlett weights, Γ_l = Σ_t g_t g_{t-l}ᵀ (all lags by FFT)."""
    n, p = g.shape
    m = 1 << (2 * n - 1).bit_length()
    f = np.fft.rfft(g, n=m, axis=0)
    # irfft(F_a conj(F_b))[l] = Σ_t g_a(t + l) g_b(t)
    lags = int(min(n - 1, np.floor(bandwidth)))
    cross = np.fft.irfft(f[:, :, None] * np.conj(f[:, None, :]), n=m, axis=0)[: lags + 1]
    w = 1.0 - np.arange(lags + 1) / (bandwidth + 1.0)
    w[0] = 0.5  # Γ_0 once after symmetrising
    s = np.einsum("l,lab->ab", w, cross)
    return s + s.T


def hac_covariance(jac, resid, bandwidth: float, rcond: float = DEFAULT_RCOND, segments=None):
    """Newey–West sandwich Σ = (JᵀJ)⁻¹ Ω (JᵀJ)⁻¹ · n / (n − p), Ω = Σ_l w_l Γ_l with
    Bartlett weights w_l = max(0, 1 − l / (L + 1)), L = ``bandwidth``.

    ``segments``: lengths of independent records concatenated in ``jac``/``resid``
    (no lag crosses a boundary); default one record."""
    jac, resid = _as64(jac, resid)
    n, p = jac.shape
    inv, _, free = _scaled_inverse(jac, rcond)
    g = jac * resid[:, None]
    cuts = np.cumsum((0,) + tuple(segments or (n,)))
    omega = sum(_long_run(g[a:b], float(bandwidth)) for a, b in zip(cuts[:-1], cuts[1:]))
    return inv @ omega @ inv * (n / max(n - p, 1)) + _undetermined(free, resid, p)


def _undetermined(free: np.ndarray, resid: np.ndarray, p: int) -> np.ndarray:
    """The variance of the directions the data do not determine, s² times the raised
    inverse ``free`` (as the Jacobian covariance gives them). A sandwich's or a bootstrap's
    own variance there is near zero, since J's column vanishes with its scores: it would
    read an undetermined parameter as exactly known."""
    return _residual_variance(resid, p) * free


def andrews_bandwidth(jac, resid, segments=None) -> float:
    """Bartlett-kernel bandwidth of Andrews (1991, eq. 6.2 and 6.4) from AR(1) fits to
    each score series g_a(t) = J_ta r_t: L = 1.1447 (α n)^{1/3},
    α = Σ_a 4ρ_a²σ_a⁴/((1−ρ_a)⁶(1+ρ_a)²) / Σ_a σ_a⁴/(1−ρ_a)⁴. ρ is clipped to
    [0, 0.999] and L to [0, n/2]."""
    jac, resid = _as64(jac, resid)
    g = jac * resid[:, None]
    n = g.shape[0]
    cuts = np.cumsum((0,) + tuple(segments or (n,)))
    num = den = 0.0
    for a in range(g.shape[1]):
        x = [g[s:e, a] - g[s:e, a].mean() for s, e in zip(cuts[:-1], cuts[1:])]
        xx = sum(float(np.dot(c[:-1], c[:-1])) for c in x)
        if xx <= 0:
            continue
        rho = float(np.clip(sum(float(np.dot(c[1:], c[:-1])) for c in x) / xx, 0.0, 0.999))
        sig2 = sum(float(np.sum((c[1:] - rho * c[:-1]) ** 2)) for c in x) / max(n - 1, 1)
        num += 4 * rho**2 * sig2**2 / ((1 - rho) ** 6 * (1 + rho) ** 2)
        den += sig2**2 / (1 - rho) ** 4
    if den <= 0:
        return 0.0
    return float(min(1.1447 * (num / den * n) ** (1.0 / 3.0), 0.5 * n))


def block_bootstrap_covariance(jac, resid, key, block: int, replicates: int = DEFAULT_REPLICATES,
                               rcond: float = DEFAULT_RCOND) -> np.ndarray:
    """Moving-block bootstrap (Künsch 1989) of the one-step Gauss–Newton refit:
    ``replicates`` resamples of ⌈n / block⌉ blocks of consecutive rows of (J, r),
    each giving δ* = −(J*ᵀJ*)⁻¹ J*ᵀ r*; returns the covariance of the δ* (``(p, p)``).
    The residuals are not re-centred: at an optimum Jᵀr = 0, so E δ* ≈ 0. The block
    starts come from ``key`` (a JAX key or int seed): same key, same result."""
    jac, resid = _as64(jac, resid)
    n, p = jac.shape
    block = int(max(1, min(block, n)))
    nb = -(-n // block)
    k = jax.random.key(key) if isinstance(key, int) else key
    starts = np.asarray(jax.random.randint(k, (replicates, nb), 0, n - block + 1))
    idx = (starts[:, :, None] + np.arange(block)[None, None, :]).reshape(replicates, -1)[:, :n]
    deltas = np.empty((replicates, p))
    for b in range(replicates):
        j, r = jac[idx[b]], resid[idx[b]]
        inv, _, _ = _scaled_inverse(j, rcond)
        deltas[b] = -inv @ (j.T @ r)
    return np.atleast_2d(np.cov(deltas, rowvar=False)) + _undetermined(_scaled_inverse(jac, rcond)[2], resid, p)


# ----------------------------------------------------------------------- result
@dataclasses.dataclass(frozen=True)
class ParameterUncertainty:
    """Uncertainty of a fit's parameters (module docstring). NumPy values.

    Attributes:
        names: the parameters, one per search coordinate, by physical name (``Fs`` for
            the ratio ``Fs/Fc``; GMS's ``split_i``; a motion fit adds ``mass``,
            ``offset``, ``v0`` when it identified them).
        kinds: the search coordinate of each (``"log10"``, ``"linear"``, ``"ratio"``).
        estimate: the fitted values in physical units (SI).
        theta: the fitted search coordinates.
        lower, upper: the search box in search coordinates.
        cov_theta: ``{method: (p, p)}`` covariance in search coordinates.
        cov: ``{method: (p, p)}`` covariance in physical units (delta method).
        n, dof: residuals used and degrees of freedom n − p.
        s2: residual variance Σ r² / (n − p) (in ``residual_unit``²).
        rank: numerical rank of J at ``rcond``; p when every direction is determined.
        bandwidth: the Newey–West lag L (and the bootstrap block length L + 1).
        residual: what r is (``"friction [N]"``, ``"position [m]"``, ...).
        default: the method [`stderr`][jaxfric.uncertainty.ParameterUncertainty.stderr]/[`intervals`][jaxfric.uncertainty.ParameterUncertainty.intervals] use without one.
        lag1: lag-1 autocorrelation of the residuals (0 for independent ones).
    """

    names: tuple[str, ...]
    kinds: tuple[str, ...]
    estimate: np.ndarray
    theta: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    cov_theta: dict
    cov: dict
    n: int
    dof: int
    s2: float
    rank: int
    bandwidth: float
    residual: str = "friction [N]"
    default: str = "hac"
    lag1: float = 0.0
    segments: tuple[int, ...] = ()

    def _method(self, method):
        method = self.default if method is None else method
        if method not in self.cov:
            raise ValueError(f"no {method!r} covariance in this fit; it holds {sorted(self.cov)}")
        return method

    def stderr(self, method=None) -> dict[str, float]:
        """``{name: standard error}`` in physical units."""
        c = self.cov[self._method(method)]
        return {k: float(np.sqrt(max(c[i, i], 0.0))) for i, k in enumerate(self.names)}

    def correlation(self, method=None) -> np.ndarray:
        """``(p, p)`` correlation matrix (order [`names`][jaxfric.uncertainty.ParameterUncertainty.names]), in search coordinates
        (for log10 and linear coordinates the same as in physical units, to first order)."""
        c = self.cov_theta[self._method(method)]
        d = np.sqrt(np.clip(np.diag(c), 1e-300, None))
        return np.clip(c / d[:, None] / d[None, :], -1.0, 1.0)

    def t_quantile(self, level: float) -> float:
        check_level(level)
        return float(stats.t.ppf(0.5 + 0.5 * level, max(self.dof, 1)))

    def theta_intervals(self, level: float = DEFAULT_LEVEL, method=None) -> tuple[np.ndarray, np.ndarray]:
        """θ̂ ± t se in search coordinates."""
        se = np.sqrt(np.clip(np.diag(self.cov_theta[self._method(method)]), 0.0, None))
        t = self.t_quantile(level)
        return self.theta - t * se, self.theta + t * se

    def intervals(self, level: float = DEFAULT_LEVEL, method=None) -> dict[str, tuple[float, float]]:
        """``{name: (low, high)}`` at ``level`` in physical units (log10 coordinates map
        their interval through 10^x, so it stays positive; the ratio ``Fs`` uses the
        delta method's standard error)."""
        method = self._method(method)
        lo, hi = self.theta_intervals(level, method)
        se = self.stderr(method)
        t = self.t_quantile(level)
        out = {}
        for i, (name, kind) in enumerate(zip(self.names, self.kinds)):
            if kind == "log10":
                with np.errstate(over="ignore"):
                    out[name] = (float(10.0 ** lo[i]), float(10.0 ** hi[i]))
            else:
                e = float(self.estimate[i])
                out[name] = (e - t * se[name], e + t * se[name])
        return out

    def covers_box(self, level: float = DEFAULT_LEVEL, method=None) -> list[str]:
        """Parameters whose interval covers their whole search box: the data do not
        determine them."""
        lo, hi = self.theta_intervals(level, method)
        return [k for i, k in enumerate(self.names) if lo[i] <= self.lower[i] and hi[i] >= self.upper[i]]

    def box_capped(self, method=None, level: float = DEFAULT_LEVEL) -> np.ndarray:
        """The search-coordinate covariance with its undetermined *directions* shrunk to
        the search box. In box-normalised coordinates (each parameter divided by its box
        half-width) Σ = Q Λ Qᵀ; an eigenvalue whose t-interval along its direction q
        reaches beyond the box (t √λ max|q_i| > 1) is lowered to the box's edge. A
        combination the data determine (small λ) keeps its variance, so a pair correlated
        at −1 still cancels; a direction the data leave free moves over the box, not by
        its linearised ±10⁹."""
        c = np.asarray(self.cov_theta[self._method(method)], np.float64)
        t = self.t_quantile(level)
        se = np.sqrt(np.clip(np.diag(c), 0.0, None))
        half = 0.5 * (np.asarray(self.upper, np.float64) - np.asarray(self.lower, np.float64))
        half = np.where(np.isfinite(half) & (half > 0), half, np.maximum(10.0 * t * se, 1e-300))
        z = c / half[:, None] / half[None, :]
        lam, q = np.linalg.eigh(0.5 * (z + z.T))
        lam = np.clip(lam, 0.0, None)  # a negative eigenvalue is rounding: no variance, not a negative one
        reach = t * np.sqrt(lam) * np.max(np.abs(q), axis=0)
        lam = np.where(reach > 1.0, lam / np.maximum(reach, 1.0) ** 2, lam)
        return (q * lam) @ q.T * half[:, None] * half[None, :]

    def strongly_correlated(self, threshold: float = 0.99, method=None) -> list[tuple[str, str, float]]:
        """Pairs with |correlation| above ``threshold``: the data fix a combination only."""
        r = self.correlation(method)
        p = len(self.names)
        return [(self.names[a], self.names[b], float(r[a, b]))
                for a in range(p) for b in range(a + 1, p) if abs(r[a, b]) > threshold]

    def not_identifiable(self, level: float = DEFAULT_LEVEL, flags=None, method=None) -> dict[str, list[str]]:
        """``{name: reasons}`` of the parameters the data do not determine: those ``flags``
        names (``{name: reasons}`` from the fit's other analyses, e.g. the model's
        excitation rules and the plausibility rules: [`Fit.verdicts`][jaxfric.fit.Fit.verdicts])
        and those whose interval covers their search box ([`covers_box`][jaxfric.uncertainty.ParameterUncertainty.covers_box], with
        ``COVERS_BOX`` as the reason). Their intervals are never shown as numbers:
        [`table`][jaxfric.uncertainty.ParameterUncertainty.table], [`format`][jaxfric.uncertainty.ParameterUncertainty.format] and [`to_json`][jaxfric.uncertainty.ParameterUncertainty.to_json] say "not identifiable" instead."""
        out = {str(k): list(v) for k, v in dict(flags or {}).items()}
        for name in self.covers_box(level, method):
            out.setdefault(name, []).append(COVERS_BOX.format(level=level))
        return out

    def table(self, level: float = DEFAULT_LEVEL, flags=None) -> list[dict[str, Any]]:
        """One row per parameter: estimate, standard errors per method, interval
        (default method), ``covers_box``, and the verdict in the same row: ``identifiable``
        and its ``reasons`` ([`not_identifiable`][jaxfric.uncertainty.ParameterUncertainty.not_identifiable] with ``flags``). The ``low``, ``high``
        of a row that is not identifiable are the linearisation's numbers, not an interval
        of the parameter: every text output shows "not identifiable" instead."""
        ivs = self.intervals(level)
        ses = {m: self.stderr(m) for m in self.cov}
        loose = set(self.covers_box(level))
        bad = self.not_identifiable(level, flags)
        return [{"name": k, "estimate": float(self.estimate[i]),
                 **{f"se_{m}": ses[m][k] for m in self.cov},
                 "low": ivs[k][0], "high": ivs[k][1], "covers_box": k in loose,
                 "identifiable": k not in bad, "reasons": bad.get(k, [])}
                for i, k in enumerate(self.names)]

    def format(self, level: float = DEFAULT_LEVEL, flags=None) -> list[str]:
        """Lines for [`jaxfric.Fit.summary`][jaxfric.fit.Fit.summary]: a parameter that is not identifiable
        ([`not_identifiable`][jaxfric.uncertainty.ParameterUncertainty.not_identifiable] with ``flags``) shows "not identifiable" where its
        interval would be."""
        methods = [m for m in METHODS if m in self.cov]
        head = (f"uncertainty ({self.default}, {level:.0%} t-intervals, n={self.n}, dof={self.dof}, "
                f"residual lag-1 corr {self.lag1:.2f}, Newey-West lag {self.bandwidth:.0f}"
                + (f", rank {self.rank} of {len(self.names)}" if self.rank < len(self.names) else "") + "):")
        lines = [head, f"  {'param':<10}{'estimate':>12}" + "".join(f"{'se ' + m:>18}" for m in methods)
                 + f"{'interval':>28}"]
        for row in self.table(level, flags):
            lines.append(f"  {row['name']:<10}{row['estimate']:>12.4g}"
                         + "".join(f"{row['se_' + m]:>18.3g}" for m in methods)
                         + "   " + interval_text((row["low"], row["high"]) if row["identifiable"] else None))
        for a, b, r in self.strongly_correlated():
            lines.append("  " + correlation_text(a, b, r))
        return lines

    # ------------------------------------------------------------------ json
    def to_json(self, flags=None) -> dict[str, Any]:
        """The JSON form [`from_json`][jaxfric.uncertainty.ParameterUncertainty.from_json] reads, with the 95 % intervals of the identifiable
        parameters only (``intervals_95``) and the others under ``not_identifiable``
        (``{name: reasons}``, [`not_identifiable`][jaxfric.uncertainty.ParameterUncertainty.not_identifiable] with ``flags``)."""
        def mat(m):
            return [[float(x) for x in row] for row in np.asarray(m)]

        bad = self.not_identifiable(DEFAULT_LEVEL, flags)
        return {"names": list(self.names), "kinds": list(self.kinds),
                "estimate": [float(x) for x in self.estimate], "theta": [float(x) for x in self.theta],
                "lower": [float(x) for x in self.lower], "upper": [float(x) for x in self.upper],
                "cov_theta": {k: mat(v) for k, v in self.cov_theta.items()},
                "cov": {k: mat(v) for k, v in self.cov.items()},
                "n": self.n, "dof": self.dof, "s2": float(self.s2), "rank": self.rank,
                "bandwidth": float(self.bandwidth), "residual": self.residual, "default": self.default,
                "lag1": float(self.lag1), "segments": list(self.segments),
                "stderr": self.stderr(),
                "intervals_95": {k: list(v) for k, v in self.intervals().items() if k not in bad},
                "not_identifiable": bad, "covers_box": self.covers_box()}

    @classmethod
    def from_json(cls, d: dict) -> "ParameterUncertainty":
        arr = lambda x: np.asarray(x, np.float64)  # noqa: E731
        return cls(names=tuple(d["names"]), kinds=tuple(d["kinds"]), estimate=arr(d["estimate"]),
                   theta=arr(d["theta"]), lower=arr(d["lower"]), upper=arr(d["upper"]),
                   cov_theta={k: arr(v) for k, v in d["cov_theta"].items()},
                   cov={k: arr(v) for k, v in d["cov"].items()}, n=int(d["n"]), dof=int(d["dof"]),
                   s2=float(d["s2"]), rank=int(d["rank"]), bandwidth=float(d["bandwidth"]),
                   residual=d.get("residual", "friction [N]"), default=d.get("default", "hac"),
                   lag1=float(d.get("lag1", 0.0)), segments=tuple(d.get("segments", ())))


def check_level(level) -> None:
    """``ValueError`` unless ``level`` is a probability in (0, 1) (an interval's level)."""
    if not (isinstance(level, (int, float)) and 0.0 < float(level) < 1.0):
        raise ValueError(f"level must be a probability in (0, 1), e.g. 0.95, got {level!r}")


def _check_methods(methods) -> tuple[str, ...]:
    methods = (methods,) if isinstance(methods, str) else tuple(methods)
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise ValueError(f"method must be one or more of {METHODS}, got {bad or methods!r}")
    return methods
