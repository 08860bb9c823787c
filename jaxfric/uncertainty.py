"""Parameter uncertainty of a physical friction fit (docs/uncertainty.md).

For a least-squares fit θ̂ of a residual vector r(θ) (friction prediction minus
measured friction for :func:`jaxfric.identify`, simulated minus measured position for
:func:`jaxfric.identify_motion`), with J = ∂r/∂θ at θ̂ (``jax.jacfwd``):

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
confident zero variance a pseudo-inverse would give.

Intervals at level 1 − α use Student's t with n − p degrees of freedom: θ̂ ± t se
in search coordinates, mapped to physical units (so a log10 coordinate gives a
positive, asymmetric interval); an interval that covers the search box means the data
do not determine that parameter (:meth:`ParameterUncertainty.covers_box`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from scipy import stats

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

#: Covariance estimators (see the module docstring); the first is the default shown.
METHODS = ("hac", "jacobian", "block_bootstrap")
#: What :func:`parameter_uncertainty` computes unless told (the bootstrap needs a key).
DEFAULT_METHODS = ("hac", "jacobian")
#: Default level of :meth:`ParameterUncertainty.intervals`.
DEFAULT_LEVEL = 0.95
#: report.md prints the whole correlation matrix up to this many parameters.
MAX_REPORT_CORRELATION = 12
#: Bootstrap replicates of ``"block_bootstrap"``.
DEFAULT_REPLICATES = 400


# ----------------------------------------------------------------------- estimators
# NumPy float64: J is (n, p) with p a handful, so the linear algebra costs microseconds
# and, unlike eager jnp, compiles nothing for each new record length.
def _scaled_inverse(jac: np.ndarray, rcond: float) -> tuple[np.ndarray, int]:
    """(JᵀJ)⁻¹ by the SVD of J with unit-norm columns; singular values below ``rcond``
    times the largest are raised to it (the regularisation of the module docstring).
    Returns ``(inverse, rank)``."""
    norms = np.linalg.norm(jac, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    _, s, vt = np.linalg.svd(jac / norms, full_matrices=False)
    floor = rcond * s[0] if s[0] > 0 else 1.0
    rank = int(np.sum(s > floor))
    s = np.maximum(s, floor)
    inv = (vt.T / s**2) @ vt
    return inv / norms[:, None] / norms[None, :], rank


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
    n, p = jac.shape
    inv, rank = _scaled_inverse(jac, rcond)
    s2 = float(np.sum(resid**2) / max(n - p, 1))
    return s2 * inv, s2, rank


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
    inv, _ = _scaled_inverse(jac, rcond)
    g = jac * resid[:, None]
    cuts = np.cumsum((0,) + tuple(segments or (n,)))
    omega = sum(_long_run(g[a:b], float(bandwidth)) for a, b in zip(cuts[:-1], cuts[1:]))
    return inv @ omega @ inv * (n / max(n - p, 1))


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
        inv, _ = _scaled_inverse(j, rcond)
        deltas[b] = -inv @ (j.T @ r)
    return np.atleast_2d(np.cov(deltas, rowvar=False))


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
        default: the method :meth:`stderr`/:meth:`intervals` use without one.
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
        """``(p, p)`` correlation matrix (order :attr:`names`), in search coordinates
        (for log10 and linear coordinates the same as in physical units, to first order)."""
        c = self.cov_theta[self._method(method)]
        d = np.sqrt(np.clip(np.diag(c), 1e-300, None))
        return np.clip(c / d[:, None] / d[None, :], -1.0, 1.0)

    def t_quantile(self, level: float) -> float:
        _check_level(level)
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
        return [k for i, k in enumerate(self.names)
                if lo[i] <= self.lower[i] and hi[i] >= self.upper[i]]

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
        reach = t * np.sqrt(np.clip(lam, 0.0, None)) * np.max(np.abs(q), axis=0)
        lam = np.where(reach > 1.0, lam / np.maximum(reach, 1.0) ** 2, lam)
        return (q * lam) @ q.T * half[:, None] * half[None, :]

    def strongly_correlated(self, threshold: float = 0.99, method=None) -> list[tuple[str, str, float]]:
        """Pairs with |correlation| above ``threshold``: the data fix a combination only."""
        r = self.correlation(method)
        p = len(self.names)
        return [(self.names[a], self.names[b], float(r[a, b]))
                for a in range(p) for b in range(a + 1, p) if abs(r[a, b]) > threshold]

    def table(self, level: float = DEFAULT_LEVEL) -> list[dict[str, Any]]:
        """One row per parameter: estimate, standard errors per method, interval
        (default method), ``covers_box``."""
        ivs = self.intervals(level)
        ses = {m: self.stderr(m) for m in self.cov}
        loose = set(self.covers_box(level))
        return [{"name": k, "estimate": float(self.estimate[i]),
                 **{f"se_{m}": ses[m][k] for m in self.cov},
                 "low": ivs[k][0], "high": ivs[k][1], "covers_box": k in loose}
                for i, k in enumerate(self.names)]

    def format(self, level: float = DEFAULT_LEVEL) -> list[str]:
        """Lines for :meth:`jaxfric.Fit.summary`."""
        methods = [m for m in METHODS if m in self.cov]
        head = (f"uncertainty ({self.default}, {level:.0%} t-intervals, n={self.n}, dof={self.dof}, "
                f"residual lag-1 corr {self.lag1:.2f}, Newey-West lag {self.bandwidth:.0f}"
                + (f", rank {self.rank} of {len(self.names)}" if self.rank < len(self.names) else "") + "):")
        lines = [head, f"  {'param':<10}{'estimate':>12}" + "".join(f"{'se ' + m:>18}" for m in methods)
                 + f"{'interval':>28}"]
        for row in self.table(level):
            lines.append(f"  {row['name']:<10}{row['estimate']:>12.4g}"
                         + "".join(f"{row['se_' + m]:>18.3g}" for m in methods)
                         + f"   [{row['low']:.4g}, {row['high']:.4g}]"
                         + ("  covers the box: not determined" if row["covers_box"] else ""))
        for a, b, r in self.strongly_correlated():
            lines.append(f"  corr({a}, {b}) = {r:+.3f}: the data fix a combination of the two, not each")
        return lines

    # ------------------------------------------------------------------ json
    def to_json(self) -> dict[str, Any]:
        def mat(m):
            return [[float(x) for x in row] for row in np.asarray(m)]

        return {"names": list(self.names), "kinds": list(self.kinds),
                "estimate": [float(x) for x in self.estimate], "theta": [float(x) for x in self.theta],
                "lower": [float(x) for x in self.lower], "upper": [float(x) for x in self.upper],
                "cov_theta": {k: mat(v) for k, v in self.cov_theta.items()},
                "cov": {k: mat(v) for k, v in self.cov.items()},
                "n": self.n, "dof": self.dof, "s2": float(self.s2), "rank": self.rank,
                "bandwidth": float(self.bandwidth), "residual": self.residual, "default": self.default,
                "lag1": float(self.lag1), "segments": list(self.segments),
                "stderr": self.stderr(), "intervals_95": {k: list(v) for k, v in self.intervals().items()},
                "covers_box": self.covers_box()}

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


def _check_level(level) -> None:
    if not (isinstance(level, (int, float)) and 0.0 < float(level) < 1.0):
        raise ValueError(f"level must be a probability in (0, 1), e.g. 0.95, got {level!r}")


def _check_methods(methods) -> tuple[str, ...]:
    methods = (methods,) if isinstance(methods, str) else tuple(methods)
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise ValueError(f"method must be one or more of {METHODS}, got {bad or methods!r}")
    return methods


# ----------------------------------------------------------------------- residuals
def _coords(model):
    return tuple(model._coords)


def _friction_residuals(fit, data):
    """``(r(θ) -> (n,), segments)`` over the training samples the fit was made on."""
    from .fit import predict
    from .identification._data import RecordSet, as_records

    model = fit.model
    if isinstance(data, RecordSet):
        recs = list(data.train_records)
    elif isinstance(data, (list, tuple)) and data and not _is_triplet(data):
        recs = list(as_records(None, list(data), None).train_records)
    else:
        recs = [_one_record(data, fit.n_train)]
    parts = []
    for r in recs:
        x = model.inputs_from(r, r.velocity.shape[0])
        parts.append((np.asarray(r.velocity), np.asarray(r.friction)[: r.n_train], r.n_train,
                      None if x is None else np.asarray(x)))
    scalers = (fit.velocity_scaler, fit.friction_scaler)

    def resid(theta):
        out = [predict(model, theta, scalers, v, fit.dt, x)[:n] - jnp.asarray(f, theta.dtype)
               for v, f, n, x in parts]
        return jnp.concatenate(out)

    return resid, tuple(p[2] for p in parts), "friction [N]"


def _one_record(data, n_train: int):
    """The record a single-record fit was trained on, with its first ``n_train`` samples
    as the training window (a ``(velocity, friction, dt)`` tuple or a FrictionData)."""
    from .records import FrictionData, as_channel

    if _is_triplet(data):
        v, f, _ = data
        rec = None
    elif isinstance(data, FrictionData):
        v, f, rec = data.velocity, data.friction, data
    else:
        raise ValueError("data must be the fit's training record (FrictionData or (velocity, friction, dt)), "
                         f"a list of training records, or a RecordSet; got {type(data).__name__}")
    v, f = as_channel("velocity", v), as_channel("friction", f)
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


#: A motion fit's mechanics coordinates: search name -> (physical name, kind).
_MECHANICS = {"log10_mass": ("mass", "log10"), "offset": ("offset", "linear"), "v0": ("v0", "linear")}


def _motion_residuals(fit, data):
    """Simulation residuals of an :func:`jaxfric.identify_motion` fit over its training
    window (free-run position and/or velocity, each divided by its standard deviation
    for ``error="both"``; k-step positions for a k-step fit), and the extra mechanics
    coordinates it identified."""
    from .motion import MotionData, k_step_positions, simulate_motion, track_states
    from .motion._step import friction_step

    mech = fit.settings["motion"]
    if not isinstance(data, MotionData):
        data = MotionData.from_arrays(*data) if isinstance(data, tuple) else data
    n = fit.n_train
    names = list(mech.get("search_names") or [])
    extra = names[fit.model.num_params:]
    unknown = [e for e in extra if e not in _MECHANICS]
    if unknown or "y" not in mech or len(mech["y"]) != len(names):
        raise ValueError(f"motion fit with search coordinates {names} not understood by the "
                         f"uncertainty code (mechanics it knows: {sorted(_MECHANICS)})")
    # a fit on whole records (identify_motion(train=[...])) attaches them concatenated
    records = (mech.get("records") or {}).get("train")
    error, horizon = mech.get("error", "position"), mech.get("horizon")
    if records is not None and (sum(records) != n or error != "position" or horizon is not None):
        raise ValueError("motion fit on several records with a velocity or k-step cost: no uncertainty")
    if not hasattr(data, "net_force"):
        raise ValueError(f"a motion fit's uncertainty needs its MotionData, got {type(data).__name__}")
    force = np.asarray(data.net_force[:n])
    x, v = np.asarray(data.position[:n]), np.asarray(data.velocity[:n])
    error, horizon = mech.get("error", "position"), mech.get("horizon")
    step = friction_step(fit.model, (fit.velocity_scaler, fit.friction_scaler))
    sx, sv = float(np.std(x)), float(max(np.std(v), 1e-300))
    m_fixed = float(mech["mass"])

    def split(y):
        theta = y[: fit.model.num_params]
        i = fit.model.num_params
        mass, off, dv0 = jnp.asarray(m_fixed, y.dtype), jnp.zeros((), y.dtype), jnp.zeros((), y.dtype)
        for name in extra:
            if name == "log10_mass":
                mass = 10.0 ** y[i]
            elif name == "offset":
                off = y[i]
            elif name == "v0":
                dv0 = y[i]
            i += 1
        return theta, mass, off, dv0

    def resid(y):
        theta, mass, off, dv0 = split(y)
        dt = jnp.asarray(fit.dt, y.dtype)
        u = jnp.asarray(force, y.dtype) - off
        xs, vs = jnp.asarray(x, y.dtype), jnp.asarray(v, y.dtype)
        if horizon is not None:
            states = track_states(step, theta, vs, dt)
            xh = k_step_positions(step, theta, mass, u, dt, xs, vs, states, int(horizon))
            return xh - xs[int(horizon):]
        if records is not None:  # whole training records, each run from its own start
            cuts = np.cumsum((0,) + tuple(records))
            return jnp.concatenate([
                simulate_motion(step, theta, mass, u[a:b], dt, xs[a], vs[a] + dv0)["x"] - xs[a:b]
                for a, b in zip(cuts[:-1], cuts[1:])])
        out = simulate_motion(step, theta, mass, u, dt, xs[0], vs[0] + dv0)
        if error == "position":
            return out["x"] - xs
        if error == "velocity":
            return out["v"] - vs
        return jnp.concatenate([(out["x"] - xs) / sx, (out["v"] - vs) / sv])

    unit = {"position": "position [m]", "velocity": "velocity [m/s]"}.get(error, "scaled position+velocity")
    if horizon is not None:
        unit = f"{int(horizon)}-step position [m]"
    segs = (n,) if error != "both" or horizon is not None else (n, n)
    if records is not None:
        segs = tuple(records)
    y0 = np.asarray(mech["y"], np.float64)
    kinds = tuple(c[2] for c in _coords(fit.model)) + tuple(_MECHANICS[e][1] for e in extra)
    phys = tuple(c[1] for c in _coords(fit.model)) + tuple(_MECHANICS[e][0] for e in extra)
    lower, upper = (np.asarray(b, np.float64) for b in fit.model.bounds(fit.box))
    if extra:
        sb = mech.get("search_bounds")
        if sb is not None:
            lower = np.asarray(sb[0], np.float64)
            upper = np.asarray(sb[1], np.float64)
        else:  # bounds of the mechanics were not recorded: treat them as unbounded
            lower = np.concatenate([lower, np.full(len(extra), -np.inf)])
            upper = np.concatenate([upper, np.full(len(extra), np.inf)])
    return resid, segs, unit, y0, kinds, phys, lower, upper


def _physical(fit, y, kinds, phys):
    """Physical value of every coordinate of ``y`` (a motion fit's mechanics appended)."""
    model = fit.model
    k = model.num_params
    vals = model._coord_values(y[:k])
    out = [vals[c[1]] for c in _coords(model)]
    for kind, x in zip(kinds[k:], y[k:]):
        out.append(10.0**x if kind == "log10" else x)
    return jnp.stack(out)


def _jacobian(resid, theta):
    """∂r/∂θ by forward mode: p ≤ a dozen columns, one JVP each."""
    return jax.jacfwd(resid)(theta)


def parameter_uncertainty(fit, data, *, method=DEFAULT_METHODS, level: float = DEFAULT_LEVEL,
                          key=None, replicates: int = DEFAULT_REPLICATES, bandwidth=None,
                          rcond: float = DEFAULT_RCOND) -> ParameterUncertainty:
    """Covariances, standard errors and intervals of a physical fit's parameters.

    Args:
        fit: a :class:`jaxfric.Fit` of a physical model (from :func:`jaxfric.identify`),
            or a :class:`jaxfric.motion.MotionFit`.
        data: what the fit was trained on: the record given to ``identify`` (its first
            ``fit.n_train`` samples are used), a list of training records, or the
            :class:`jaxfric.motion.MotionData` of a motion fit.
        method: one or more of :data:`METHODS` (default :data:`DEFAULT_METHODS`); the
            first is the default the result shows. ``"block_bootstrap"`` needs ``key``.
        bandwidth: Newey–West lag L; default :func:`andrews_bandwidth`.
        rcond: relative singular-value floor (module docstring).

    Computed in ``fit.theta``'s dtype (enable x64 for long records). Raises
    ``ValueError`` for a network fit (its weights have no physical meaning), an unknown
    method, or a bootstrap without a key.
    """
    methods = _check_methods(method)
    _check_level(level)
    if fit.model.needs_scaling:
        raise ValueError(f"{type(fit.model).__name__} is a black-box network: its weights have no "
                         "physical meaning, so no parameter intervals (use keys=K for an ensemble band)")
    if "block_bootstrap" in methods and key is None:
        raise ValueError("method 'block_bootstrap' needs key= (a PRNG key or int seed)")
    if "motion" in fit.settings:
        resid, segs, unit, y0, kinds, phys, lower, upper = _motion_residuals(fit, data)
        theta = jnp.asarray(y0, jnp.asarray(fit.theta).dtype)
    else:
        resid, segs, unit = _friction_residuals(fit, data)
        theta = jnp.asarray(fit.theta)
        kinds = tuple(c[2] for c in _coords(fit.model))
        phys = tuple(c[1] for c in _coords(fit.model))
        lower, upper = (np.asarray(b, np.float64) for b in fit.model.bounds(fit.box))
    r = np.asarray(resid(theta), np.float64)
    jac = np.asarray(_jacobian(resid, theta), np.float64)
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
    d = np.asarray(jax.jacfwd(lambda y: _physical(fit, y, kinds, phys))(theta), np.float64)
    lag1 = float(np.dot(r[1:], r[:-1]) / max(np.dot(r, r), 1e-300))
    return ParameterUncertainty(
        names=phys, kinds=kinds, estimate=np.asarray(_physical(fit, theta, kinds, phys), np.float64),
        theta=np.asarray(theta, np.float64), lower=lower, upper=upper,
        cov_theta={m: np.asarray(c, np.float64) for m, c in covs.items()},
        cov={m: np.asarray(d @ c @ d.T, np.float64) for m, c in covs.items()},
        n=n, dof=max(n - p, 1), s2=float(s2), rank=int(rank), bandwidth=float(L), residual=unit,
        default=methods[0], lag1=lag1, segments=tuple(int(s) for s in segs))


def prediction_interval(fit, velocity, level: float = DEFAULT_LEVEL, *, dt=None, inputs=None,
                        method=None, noise: bool = True):
    """``(prediction, low, high)`` [N] for a velocity record: ŷ ± t sqrt(j Σ jᵀ + s²),
    j = ∂ŷ/∂θ at the fit (``jax.jacfwd``), Σ the fit's covariance (``method``, default
    the fit's) with each parameter's interval capped at its search box
    (:meth:`ParameterUncertainty.box_capped`: an undetermined parameter moves inside its
    box, not by its linearised ±10⁹), s² its residual variance (left out with
    ``noise=False``: then the band is the confidence band of the mean prediction only).
    The band of a new *measurement* assumes the training residual variance holds on
    the new record."""
    from .fit import predict

    _check_level(level)
    u = fit.uncertainty
    if u is None:
        raise ValueError("this fit has no parameter uncertainty (a network, or a fit loaded from an "
                         "older file): jaxfric.uncertainty.parameter_uncertainty(fit, data) makes one")
    if "motion" in fit.settings:
        raise ValueError("prediction_interval gives friction bands of a force-balance fit; a motion "
                         "fit's uncertainty is about position")
    method = u._method(method)
    theta = jnp.asarray(fit.theta)
    dt = fit.dt if dt is None else dt

    def f(th):
        return predict(fit.model, th, (fit.velocity_scaler, fit.friction_scaler), velocity, dt, inputs)

    y, jvp_cols = f(theta), jax.jacfwd(f)(theta)
    cov = u.box_capped(method, level)
    var = jnp.einsum("ta,ab,tb->t", jvp_cols, jnp.asarray(cov, theta.dtype), jvp_cols)
    var = np.asarray(var, np.float64) + (u.s2 if noise else 0.0)
    half = u.t_quantile(level) * np.sqrt(np.clip(var, 0.0, None))
    y = np.asarray(y, np.float64)
    return y, y - half, y + half


def coverage(y, low, high) -> float:
    """Fraction of ``y`` inside ``[low, high]``."""
    y = np.asarray(y)
    return float(np.mean((y >= low) & (y <= high)))



def assess_fit(fit, data) -> None:
    """What :func:`jaxfric.identify` and :func:`jaxfric.identify_motion` run on every
    physical fit: the plausibility rules (:func:`jaxfric.plausibility.check_plausibility`,
    into ``fit.diagnostics["implausible"]``, each with a
    :class:`~jaxfric.plausibility.PlausibilityWarning`), and the training ``data``
    attached so that :attr:`jaxfric.Fit.uncertainty` is computed on first use (the
    Jacobian's compilation costs seconds that a fit nobody inspects should not pay)."""
    from .plausibility import check_plausibility, warn_implausible

    if fit.model.needs_scaling:
        return
    if "motion" in fit.settings:
        velocity = np.asarray(data.velocity)[: fit.n_train]
    elif hasattr(data, "train_velocity"):
        velocity = np.asarray(data.train_velocity)
    else:
        velocity = np.asarray(data[0] if _is_triplet(data) else data.velocity)[: fit.n_train]
    found = check_plausibility(fit.model, fit.params, velocity, fit.dt)
    fit.diagnostics["implausible"] = [f.to_json() for f in found]
    warn_implausible(fit.model, found, stacklevel=4)
    fit._training_data = data


# ----------------------------------------------------------------------- report
def report_summary(fit, data, level: float = DEFAULT_LEVEL) -> dict | None:
    """What report.md and results.json show of a fit's uncertainty: the parameter table,
    strongly correlated pairs, the plausibility warnings and, for a force-balance fit on
    one split record ``data``, the prediction band's measured coverage on the training
    and validation windows. ``None`` for a fit without uncertainty or warnings."""
    u = None if fit.model.needs_scaling else fit.uncertainty
    implausible = list(fit.diagnostics.get("implausible", []))
    one_record = (getattr(data, "velocity", None) is not None and len(data.velocity) == fit.n_samples
                  and "motion" not in fit.settings)
    ensemble = _ensemble_band(fit, data) if one_record and fit.ensemble else None
    if u is None and not implausible and ensemble is None:
        return None
    out: dict[str, Any] = {"level": level, "implausible": implausible, "ensemble_band": ensemble}
    if u is not None:
        out.update(method=u.default, residual=u.residual, n=u.n, lag1=u.lag1, bandwidth=u.bandwidth,
                   rank=u.rank, table=u.table(level), correlated=[list(x) for x in u.strongly_correlated()],
                   correlation={"names": list(u.names),
                                "matrix": np.round(u.correlation(), 3).tolist()},
                   error=fit.diagnostics.get("uncertainty_error"))
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


def _g(x, fmt: str = ".3g") -> str:
    """A number of a JSON summary (``"inf"`` text for non-finite ones, ``None``: ``-``)."""
    if x is None:
        return "-"
    try:
        return format(float(x), fmt)
    except (TypeError, ValueError):
        return str(x)


def _ensemble_band(fit, data) -> dict | None:
    """Measured coverage of an ensemble's min–max band (``fit.predict_band``)."""
    import warnings

    from ._warnings import ExtrapolationWarning

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
    """Markdown lines of :func:`report_summary` for a model's section of report.md."""
    if not summary:
        return []
    L: list[str] = []
    if summary.get("table"):
        lvl = f"{summary['level']:.0%}"
        L += ["", f"Parameter uncertainty ({lvl} intervals, Newey–West covariance of the {summary['n']} "
              f"training residuals in {summary['residual']}, lag-1 autocorrelation {summary['lag1']:.2f}; "
              "see docs/uncertainty.md):", "",
              f"| parameter | estimate | se (Newey–West) | se (independent residuals) | {lvl} interval | |",
              "|---|---|---|---|---|---|"]
        for row in summary["table"]:
            L.append(f"| {row['name']} | {_g(row['estimate'], '.5g')} | {_g(row.get('se_hac'))} | "
                     f"{_g(row.get('se_jacobian'))} | [{_g(row['low'], '.4g')}, {_g(row['high'], '.4g')}] | "
                     + ("covers the search box: **not determined by the data**" if row["covers_box"] else "")
                     + " |")
        corr = summary.get("correlation")
        if corr and 1 < len(corr["names"]) <= MAX_REPORT_CORRELATION:
            names = corr["names"]
            L += ["", "Correlation of the estimates:", "", "| | " + " | ".join(names) + " |",
                  "|---|" + "---|" * len(names)]
            L += [f"| {a} | " + " | ".join(f"{x:+.2f}" for x in row) + " |"
                  for a, row in zip(names, corr["matrix"])]
        for a, b, r in summary.get("correlated", []):
            L += ["", f"corr({a}, {b}) = {r:+.3f}: the data fix a combination of the two, not each."]
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
    for d in summary.get("implausible", []):
        L += ["", f"**Physically implausible ({d['rule']}):** {d['message']}."]
    return L


def cli_lines(fit, level: float = DEFAULT_LEVEL) -> list[str]:
    """The command line's short account of a physical fit: one line of intervals, and a
    line per strongly correlated pair (nothing for a network or a fit without them)."""
    u = None if fit.model.needs_scaling else fit.uncertainty
    if u is None:
        return []
    loose = set(u.covers_box(level))
    parts = [f"{k} {float(u.estimate[i]):.4g} " + ("(not determined: the interval covers the box)" if k in loose
                                                  else f"[{lo:.3g}, {hi:.3g}]")
             for i, (k, (lo, hi)) in enumerate(u.intervals(level).items())]
    lines = [f"  {level:.0%} intervals ({u.default}): " + ", ".join(parts)]
    lines += [f"  corr({a}, {b}) = {r:+.3f}: the data fix a combination only" for a, b, r in u.strongly_correlated()]
    return lines
