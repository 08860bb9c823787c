"""The result of [`jaxfric.identify`][jaxfric.identification.identify], and saving/loading it (docs/algorithms.md §6, §11 step 8).

A [`Fit`][jaxfric.fit.Fit] holds everything needed to *use* an identified model (θ, the §2.4
scalers, the sample time) and to *judge* it (the §6 metrics per window, the optimiser's record).

File format (one ``.npz`` file, no pickles): member ``header`` holds UTF-8 JSON
(``format``, ``format_version``, jaxfric version, model class and configuration,
the search box, metrics, settings, ...); members ``theta``, ``velocity_scaler``, ``friction_scaler``
(``[lo, hi]``, float64) and ``history_evals``/``history_f`` hold the arrays with
their exact dtypes, so save → load → predict is bit-identical; a fit from
``identify(..., keys=K)`` adds ``ensemble_theta`` (K × n). [`load_fit`][jaxfric.fit.load_fit] refuses
non-finite weights, scalers or sample time (they would predict NaN).

Prediction is honest about its data ([`Fit.predict`][jaxfric.fit.Fit.predict], [`Fit.predict_at`][jaxfric.fit.Fit.predict_at]). Writes go
through [`jaxfric.files.atomic_write`][jaxfric.files.atomic_write]: a crash never leaves a half-written fit.
"""

from __future__ import annotations

import dataclasses
import io
import json
import os
import warnings
import zipfile
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from . import models as _models
from ._warnings import ExtrapolationWarning, ResamplingWarning
from .covariance import DEFAULT_LEVEL, ParameterUncertainty, check_level
from .export import c_header, numpy_step
from .files import atomic_write, jsonable
from .models import AbstractFrictionModel, Scaler
from .problem import AbstractProblem, ForceBalanceProblem, rollout
from .records import check_sample_time, same_sample_time

__all__ = ["FORMAT_VERSION", "ExtrapolationWarning", "Fit", "FitKindError", "LazyUncertainty", "ResamplingWarning",
           "load_fit"]

FORMAT_NAME = "jaxfric.fit"
#: Version of the file layout written by `Fit.save`; `load_fit` reads
#: this version and older ones and refuses newer ones.
FORMAT_VERSION = 1

_WINDOWS = ("train", "valid", "all")

#: Longest record `Fit.predict_at` builds on the fit's time grid (a record at
#: a much coarser sample time than the fit's would otherwise allocate without bound).
MAX_RESAMPLED_SAMPLES = 50_000_000


def _jaxfric_version() -> str:
    # from the installed metadata, not the package root (an import only goes down)
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("jaxfric")
    except PackageNotFoundError:  # pragma: no cover - running from a source tree
        return "0.0.0+unknown"


def _tuples(x):
    """JSON lists back to tuples (model fields are hashable static values)."""
    if isinstance(x, list):
        return tuple(_tuples(v) for v in x)
    return x


def model_config(model: AbstractFrictionModel) -> dict[str, Any]:
    """The constructor arguments of ``model`` (its dataclass fields) as JSON values."""
    return {f.name: jsonable(getattr(model, f.name)) for f in dataclasses.fields(model)}


def model_from_config(class_name: str, config: dict[str, Any]) -> AbstractFrictionModel:
    """Rebuild a model saved by [`model_config`][jaxfric.fit.model_config]; only jaxfric's own model classes.
    The ``*_range`` keys of a 0.6/0.7 file are left out ([`old_box_entries`][jaxfric.fit.old_box_entries])."""
    cls = getattr(_models, class_name, None)
    if not (isinstance(cls, type) and issubclass(cls, AbstractFrictionModel)):
        raise ValueError(f"unknown friction model class {class_name!r} in the fit file")
    old = {f"{k}_range" for k in _models.DEFAULT_RANGES}
    try:
        return cls(**{k: _tuples(v) for k, v in config.items() if k not in old})
    except (TypeError, ValueError) as err:
        raise ValueError(f"cannot rebuild {class_name} from the fit file: {err}") from None


def old_box_entries(config: dict[str, Any]) -> dict[str, Any]:
    """The search box of a fit written by jaxfric 0.6/0.7, whose model configuration held
    it as ``*_range`` fields (``Fc_range`` -> ``Fc``; unset ones, ``None``, were the
    defaults): ``{name: (low, high)}``."""
    return {k: config[f"{k}_range"] for k in _models.DEFAULT_RANGES if config.get(f"{k}_range") is not None}


def model_name(model: AbstractFrictionModel) -> str | None:
    """The [`jaxfric.models.get`][jaxfric.models.get] name of ``model``'s class, if it has one."""
    for name in _models.available():
        if type(_models.get(name)) is type(model):
            return name
    return None


def _velocity_np(velocity) -> np.ndarray:
    v = np.asarray(velocity)
    if v.ndim != 1 or v.shape[0] == 0:
        raise ValueError(f"velocity must be a non-empty 1-D time series, got shape {v.shape}")
    if not np.issubdtype(v.dtype, np.number):
        raise ValueError(f"velocity must be numeric, got dtype {v.dtype}")
    if not np.all(np.isfinite(v)):
        raise ValueError("velocity holds NaN or inf")
    return v.astype(np.float64)


def unidentifiable_names(texts) -> set[str]:
    """Parameter names of ``Fit.diagnostics["unidentifiable"]`` entries, which are
    ``"name: reason"`` strings ([`jaxfric.identification.unidentifiable`][jaxfric.identification.unidentifiable])."""
    return {str(t).split(": ", 1)[0] for t in texts}


def diagnostic_flags(fit) -> dict[str, list[str]]:
    """``{name: reasons}`` of the parameters that the fit's analyses other than the
    intervals judge not identifiable: the model's excitation rules
    (``diagnostics["unidentifiable"]``) and the plausibility rules
    (``diagnostics["implausible"]``, [`jaxfric.plausibility`][jaxfric.plausibility])."""
    out: dict[str, list[str]] = {}
    for text in fit.diagnostics.get("unidentifiable", []):
        name, _, why = str(text).partition(": ")
        out.setdefault(name, []).append(why or "the model says these data cannot determine it")
    for d in fit.diagnostics.get("implausible", []):
        out.setdefault(str(d["name"]), []).append(f"{d['message']} (plausibility rule {d['rule']})")
    return out


def parameter_verdicts(fit, level: float = DEFAULT_LEVEL) -> dict[str, dict[str, Any]]:
    """One verdict per physical parameter, from every analysis of the fit together.

    A parameter is *not identifiable* when the model's excitation rules say the training
    data cannot determine it (``diagnostics["unidentifiable"]``), when it breaks a
    plausibility rule (``diagnostics["implausible"]``), or when its interval covers its
    whole search box ([`ParameterUncertainty.covers_box`][jaxfric.uncertainty.ParameterUncertainty.covers_box]). Its
    value was then set by the search box or by a handful of samples: it is not a
    measured property, and no output shows an interval for it ([`Fit.summary`][jaxfric.fit.Fit.summary],
    report.md, results.json, the fit file, the command line all say "not identifiable").

    Returns ``{name: {"value", "identifiable", "reasons", "on_bound", "at_limit",
    "interval"}}`` in the order of [`Fit.params`][jaxfric.fit.Fit.params] (a motion fit's
    mechanics after them): ``on_bound`` marks a parameter the search box stopped (widen
    its range; ``at_limit``: the range already starts at the least value the model
    allows), ``interval`` is ``[low, high]`` at ``level`` for an identifiable parameter
    of a fit with an uncertainty, else ``None``. ``{}`` for a network (its weights have no physical meaning).
    """
    if fit.model.needs_scaling:
        return {}
    flags = diagnostic_flags(fit)
    u = fit.uncertainty
    values = {k: float(v) for k, v in fit.params.items() if np.ndim(v) == 0}
    intervals = {}
    if u is not None:
        flags = u.not_identifiable(level, flags)
        intervals = u.intervals(level)
        for name, est in zip(u.names, u.estimate):
            values.setdefault(name, float(est))
    for name in flags:
        values.setdefault(name, None)
    bound = {d["name"]: bool(d.get("at_limit", False)) for d in fit.diagnostics.get("on_bound", [])}
    return {k: {"value": v, "identifiable": k not in flags, "reasons": list(flags.get(k, [])),
                "on_bound": k in bound, "at_limit": bound.get(k, False),
                "interval": (list(intervals[k]) if k in intervals and k not in flags else None)}
            for k, v in values.items()}


#: What the summary, report and command line say about parameters that are not identifiable.
NOT_IDENTIFIABLE_MEANING = ("not identifiable from these data: their values were set by the search box or a "
                            "few samples, not measured; do not read them as physical properties (the fit still "
                            "predicts records like its training data; where these parameters act, e.g. "
                            "pre-sliding, the Stribeck dip or standstill, it extrapolates)")


def grouped_reasons(verdicts: dict) -> list[tuple[list[str], str]]:
    """``[(names, reason)]``: the reasons of the parameters that are not identifiable, each
    reason once with every parameter it applies to (in order)."""
    groups: dict[str, list[str]] = {}
    for name, v in verdicts.items():
        for why in v["reasons"]:
            groups.setdefault(why, []).append(name)
    return [(names, why) for why, names in groups.items()]


def uncertainty_lines(fit) -> list[str]:
    """The summary lines of a fit's parameter uncertainty and of the parameters that are
    not identifiable (one verdict per parameter: ``parameter_verdicts``)."""
    lines = []
    if fit.model.needs_scaling:
        return lines
    if fit.uncertainty is not None:
        lines += fit.uncertainty.format(flags=diagnostic_flags(fit))
    groups = grouped_reasons(parameter_verdicts(fit))
    if groups:
        lines.append(f"! {NOT_IDENTIFIABLE_MEANING}:")
        lines += [f"!   {', '.join(names)}: {why}" for names, why in groups]
    return lines


def predict(model: AbstractFrictionModel, theta, scalers, velocity, dt, inputs=None) -> jax.Array:
    """Free-run friction [N] of ``model`` at ``theta`` for ``velocity`` [m/s] (§2.4):
    scale the input, roll out, unscale the output (``scalers = (velocity, friction)``
    [`Scaler`][jaxfric.models.Scaler] pair, or ``(None, None)`` for SI-unit models). Computed in
    ``theta``'s dtype. ``inputs``: the ``(C, T)`` measured channels of a model with
    ``input_names`` (e.g. chamber pressures [Pa]); ignored by the others. The checks, then
    [`jaxfric.problem.rollout`][jaxfric.problem.rollout]."""
    theta = jnp.asarray(theta)
    _velocity_np(velocity)
    return rollout(model, theta, scalers, jnp.asarray(velocity, theta.dtype), check_sample_time(dt), inputs)


class LazyUncertainty:
    """A fit's parameter uncertainty: given (a
    [`ParameterUncertainty`][jaxfric.uncertainty.ParameterUncertainty] or ``None``), or
    computed once, on first use, by a zero-argument callable (the Jacobian's compilation
    costs seconds that a fit nobody inspects should not pay). A memo, not a field: the fit
    holding it never changes; ``error`` says why the computation failed."""

    __slots__ = ("_value", "_source", "error")

    def __init__(self, value=None, source=None):
        self._value, self._source, self.error = value, source, None

    @property
    def pending(self) -> bool:
        """Whether a computation waits for its first use."""
        return self._value is None and self._source is not None

    def value(self):
        if self.pending:
            compute, self._source = self._source, None
            try:
                self._value = compute()
            except (ValueError, FloatingPointError, np.linalg.LinAlgError) as err:
                # a fit stays usable (and savable) without its intervals; say why
                self.error = str(err)
        return self._value


class FitKindError(ValueError):
    """A fit file holds another kind of fit than the loader reads (a motion fit given to
    [`load_fit`][jaxfric.fit.load_fit], a force-balance fit to ``jaxfric.motion.load_motion_fit``)."""


class Fit:
    """An identified friction model and its report (returned by [`jaxfric.identify`][jaxfric.identification.identify]).

    Attributes:
        model: the friction model.
        box: the [`jaxfric.models.SearchBox`][jaxfric.models.SearchBox] the fit searched (complete: defaults,
            data-centred entries and the user's), ``None`` for the Elman networks,
            whose box is part of their configuration.
        theta: parameters in search coordinates (NumPy, the search dtype).
        velocity_scaler, friction_scaler: the §2.4 training-window [`Scaler`][jaxfric.models.Scaler]
            of a model with ``needs_scaling``, else ``None``.
        dt: sample time [s] of the identification record.
        n_train, n_samples: training-window length and record length.
        metrics: ``{"train", "valid", "all"}`` → [`jaxfric.metrics.friction_metrics`][jaxfric.metrics.friction_metrics]
            dicts (newtons), plus ``"num_params"`` and ``"cost"`` (the final J).
        stages: one dict per optimiser stage (``stage``, ``J``, ``num_evals``/``num_steps``,
            ...), in order: e.g. MAPSO, Nelder–Mead, BFGS.
        history: ``{"evals": ..., "f": ...}`` best J against evaluations (NumPy).
        solution: the optimiser's [`jaxfric.Solution`][jaxfric.optim.Solution] (``None`` after loading).
        timings: seconds: ``compile_s``, ``run_s`` (optimiser), ``refine_compile_s``,
            ``refine_run_s``, ``total_s`` (wall, everything including checks and metrics).
        key_data, key_impl, seed: the PRNG key used (see [`key`][jaxfric.fit.Fit.key]).
        settings: solver, refinement, dtype, data-bounds and split settings (JSON values).
        version: jaxfric version that produced the fit.
        velocity_range: ``(min, max)`` [m/s] of the training velocity (``None`` if
            unknown: fits saved before 0.7); prediction beyond it warns.
        uncertainty: the [`jaxfric.uncertainty.ParameterUncertainty`][jaxfric.uncertainty.ParameterUncertainty] of a physical
            fit ([`stderr`][jaxfric.fit.Fit.stderr], [`intervals`][jaxfric.fit.Fit.intervals], [`correlation`][jaxfric.fit.Fit.correlation],
            [`prediction_interval`][jaxfric.fit.Fit.prediction_interval]; docs/uncertainty.md), computed on first use.
        diagnostics: ``{"on_bound": [...], "unidentifiable": [...]}``: parameters
            that ended on a bound of the search box (name, side, value, range, what
            to widen) and parameters the model says the data cannot determine, as
            ``"name: reason"`` strings ([`unidentifiable_names`][jaxfric.fit.unidentifiable_names] takes the names);
            [`summary`][jaxfric.fit.Fit.summary] and the report mark both kinds. ``"implausible"``: the
            [`jaxfric.plausibility`][jaxfric.plausibility] rules a physical fit breaks (name, rule, message,
            evidence).
        ensemble: for ``identify(..., keys=K)``: the members' ``theta`` ``(K, n)``,
            final costs ``J``, keys, per-member validation MSE %, the index of the
            best member (this fit) and the spread of each parameter; else ``None``.

    A fit is immutable: everything it reports is computed before it is built, setting
    an attribute raises ``dataclasses.FrozenInstanceError``, and
    [`replace`][jaxfric.fit.Fit.replace] returns a changed copy. The constructor's
    ``uncertainty`` is a ``ParameterUncertainty``, ``None``, or a zero-argument callable
    computing it on first use ([`LazyUncertainty`][jaxfric.fit.LazyUncertainty]).
    """

    #: The constructor's arguments, in order: what [`replace`][jaxfric.fit.Fit.replace] copies.
    FIELDS = ("model", "theta", "velocity_scaler", "friction_scaler", "dt", "n_train", "n_samples",
              "metrics", "stages", "history", "solution", "timings", "key_data", "key_impl", "seed",
              "settings", "version", "velocity_range", "diagnostics", "ensemble", "box", "uncertainty")

    def __init__(self, *, model, theta, velocity_scaler, friction_scaler, dt, n_train,
                 n_samples, metrics, stages=(), history=None, solution=None, timings=None,
                 key_data=None, key_impl=None, seed=None, settings=None, version=None,
                 velocity_range=None, diagnostics=None, ensemble=None, box=None, uncertainty=None):
        object.__setattr__(self, "_frozen", False)
        self.model = model
        self.box = model.search_box(box)
        self.theta = model.check_theta(np.asarray(theta))
        self.velocity_scaler = velocity_scaler
        self.friction_scaler = friction_scaler
        self.dt = float(dt)
        self.n_train = int(n_train)
        self.n_samples = int(n_samples)
        self.metrics = dict(metrics or {})
        self.stages = [dict(s) for s in stages]
        self.history = history if history is not None else {
            "evals": np.zeros(0, np.int64), "f": np.zeros(0, np.float64)}
        self.solution = solution
        self.timings = dict(timings or {})
        self.key_data = None if key_data is None else [int(k) for k in key_data]
        self.key_impl = key_impl
        self.seed = seed
        self.settings = dict(settings or {})
        self.version = version if version is not None else _jaxfric_version()
        if velocity_range is None and velocity_scaler is not None:
            # the network's scaler is exactly the training min/max (§2.4)
            velocity_range = (np.asarray(velocity_scaler.lo), np.asarray(velocity_scaler.hi))
        self.velocity_range = (None if velocity_range is None
                               else (float(velocity_range[0]), float(velocity_range[1])))
        self.diagnostics = {"on_bound": [], "unidentifiable": [], **dict(diagnostics or {})}
        self.ensemble = None if ensemble is None else dict(ensemble)
        # parameter uncertainty (jaxfric.uncertainty): given, or computed on first use by
        # the zero-argument callable identify passes with the training data (never
        # saved: only the result is); jaxfric.uncertainty sits above this module
        if not isinstance(uncertainty, LazyUncertainty):
            uncertainty = (LazyUncertainty(source=uncertainty) if callable(uncertainty)
                           and not isinstance(uncertainty, ParameterUncertainty) else LazyUncertainty(uncertainty))
        self._uncertainty = uncertainty
        object.__setattr__(self, "_frozen", True)

    # ------------------------------------------------------------- frozen
    def __setattr__(self, name, value):
        if self.__dict__.get("_frozen", False):
            raise dataclasses.FrozenInstanceError(
                f"cannot assign to {type(self).__name__}.{name}: a fit is immutable; "
                f"fit.replace({name.lstrip('_')}=...) returns a new one")
        object.__setattr__(self, name, value)

    def __delattr__(self, name):
        raise dataclasses.FrozenInstanceError(f"cannot delete {type(self).__name__}.{name}: a fit is immutable")

    def replace(self, **changes) -> "Fit":
        """A new fit of the same type with ``changes`` (constructor arguments, `FIELDS`)
        and every other field as here; a pending uncertainty stays pending (shared)."""
        unknown = sorted(set(changes) - set(self.FIELDS))
        if unknown:
            raise TypeError(f"{type(self).__name__}.replace: unknown field(s) {unknown}; fields are {list(self.FIELDS)}")
        return type(self)(**{**self.fields(), **changes})

    def fields(self) -> dict:
        """The constructor's arguments that rebuild this fit (`FIELDS`; a pending
        uncertainty stays pending): ``MotionFit(**fit.fields())`` reads a loaded fit as a
        motion fit."""
        args = {name: getattr(self, name) for name in self.FIELDS if name != "uncertainty"}
        args["uncertainty"] = self._uncertainty
        return args

    @classmethod
    def load(cls, path) -> "Fit":
        """Read a fit of this kind written by [`save`][jaxfric.fit.Fit.save] (errors: [`load_fit`][jaxfric.fit.load_fit])."""
        fields = _file_fields(path)
        try:
            return cls.from_fields(fields, path)
        except (KeyError, TypeError, IndexError) as err:
            raise ValueError(f"{path}: the fit file is incomplete or corrupted ({err!r})") from None

    @classmethod
    def from_fields(cls, fields: dict, path="the fit") -> "Fit":
        """A fit of this kind from the constructor fields a file holds (``settings`` as
        written); a subclass reads its own entries out of them. A force-balance fit refuses
        a motion fit's fields (they carry ``settings["motion"]``, the mechanics)."""
        if "motion" in (fields.get("settings") or {}):
            raise FitKindError(f"{path} holds a motion fit: read it with jaxfric.motion.load_motion_fit")
        return cls(**fields)

    @classmethod
    def problem(cls) -> AbstractProblem:
        """The problem this kind of fit solves ([`jaxfric.problem.AbstractProblem`][jaxfric.problem.AbstractProblem]): how
        its data, search coordinates, residuals and score are read. A force-balance fit's is
        [`jaxfric.problem.ForceBalanceProblem`][jaxfric.problem.ForceBalanceProblem]; a subclass solving another names its own."""
        return ForceBalanceProblem()

    # ---------------------------------------------------------- uncertainty
    @property
    def uncertainty(self):
        """The [`jaxfric.uncertainty.ParameterUncertainty`][jaxfric.uncertainty.ParameterUncertainty] of a physical model's
        parameters (Newey–West and Jacobian covariances, docs/uncertainty.md), or
        ``None`` (a network; a fit loaded from a file without it). Computed on first
        use from the training data [`jaxfric.identify`][jaxfric.identification.identify] passed."""
        return self._uncertainty.value()

    @property
    def uncertainty_error(self) -> str | None:
        """Why the uncertainty could not be computed (``None``: it was, or was never asked for)."""
        self._uncertainty.value()
        return self._uncertainty.error or self.diagnostics.get("uncertainty_error")

    def _need_uncertainty(self):
        u = self.uncertainty
        if u is None:
            why = self.uncertainty_error or (
                "a network has no physical parameters" if self.model.needs_scaling
                else "none was computed: jaxfric.uncertainty.parameter_uncertainty(fit, data)")
            raise ValueError(f"this fit has no parameter uncertainty: {why}")
        return u

    @property
    def stderr(self) -> dict[str, float]:
        """``{name: standard error}`` of the physical parameters (SI units; the fit's
        default, Newey–West covariance). ``ValueError`` when the fit has none."""
        return self._need_uncertainty().stderr()

    def intervals(self, level: float = 0.95, method: str | None = None) -> dict[str, tuple[float, float]]:
        """``{name: (low, high)}`` confidence intervals at ``level`` (SI units);
        ``method`` ``"hac"`` (default), ``"jacobian"`` (independent residuals) or
        another the fit holds. See docs/uncertainty.md for how to read them."""
        return self._need_uncertainty().intervals(level, method)

    def verdicts(self, level: float = DEFAULT_LEVEL) -> dict[str, dict[str, Any]]:
        """One verdict per physical parameter (``parameter_verdicts``): whether the data
        determine it, why not, and its interval when they do. [`intervals`][jaxfric.fit.Fit.intervals] gives the
        linearisation's numbers for every parameter; only those this marks identifiable
        are intervals of the parameter."""
        return parameter_verdicts(self, level)

    @property
    def correlation(self) -> np.ndarray:
        """Correlation matrix of the parameters, in the order of ``fit.uncertainty.names``;
        entries near ±1 mark combinations the data fix while the parts stay free."""
        return self._need_uncertainty().correlation()

    def prediction_interval(self, velocity, level: float = 0.95, dt=None, inputs=None, method=None,
                            noise: bool = True):
        """``(prediction, low, high)`` [N] for a velocity record: ŷ ± t sqrt(j Σ jᵀ + s²),
        j = ∂ŷ/∂θ at the fit (``jax.jacfwd``), Σ the fit's covariance (``method``, default
        the fit's) with each parameter's interval capped at its search box
        ([`jaxfric.covariance.ParameterUncertainty.box_capped`][jaxfric.uncertainty.ParameterUncertainty.box_capped]: an undetermined
        parameter moves inside its box, not by its linearised ±10⁹), s² its residual
        variance (left out with ``noise=False``: then the band is the confidence band of
        the mean prediction only). The band of a new *measurement* assumes the training
        residual variance holds on the new record (docs/uncertainty.md)."""
        check_level(level)
        u = self._need_uncertainty()
        method = u._method(method)
        theta = jnp.asarray(self.theta)
        dt = self.dt if dt is None else dt

        def f(th):
            return predict(self.model, th, (self.velocity_scaler, self.friction_scaler), velocity, dt, inputs)

        y, jvp_cols = f(theta), jax.jacfwd(f)(theta)
        cov = u.box_capped(method, level)
        var = jnp.einsum("ta,ab,tb->t", jvp_cols, jnp.asarray(cov, theta.dtype), jvp_cols)
        var = np.asarray(var, np.float64) + (u.s2 if noise else 0.0)
        half = u.t_quantile(level) * np.sqrt(np.clip(var, 0.0, None))
        y = np.asarray(y, np.float64)
        return y, y - half, y + half

    # ------------------------------------------------------------------ use
    @property
    def num_params(self) -> int:
        return self.model.num_params

    @property
    def params(self) -> dict[str, np.ndarray]:
        """Named parameters: physical values in SI units for physical models (e.g.
        LuGre ``sigma0`` [N/m], ``Fc`` [N]); the weight blocks (scaled units) for the
        Elman networks. NumPy arrays."""
        return {k: np.asarray(v) for k, v in self.model.to_physical(jnp.asarray(self.theta)).items()}

    @property
    def key(self):
        """The PRNG key the fit was made with (re-wrapped from [`key_data`][jaxfric.fit.Fit.key_data])."""
        if self.key_data is None:
            return None
        data = np.asarray(self.key_data, np.uint32)
        if self.key_impl is None:
            return data
        return jax.random.wrap_key_data(data, impl=self.key_impl)

    def predict(self, velocity, dt=None, inputs=None) -> jax.Array:
        """Free-run friction prediction [N] for a velocity record [m/s] (§2.4).

        The model state starts from its initial condition at the first sample
        (learned ``c0`` for the Elman network, the steady state for LuGre); the
        velocity is scaled with the training-window scaler and the output mapped
        back to newtons. ``dt`` [s] defaults to the identification record's. ``inputs``:
        the ``(C, T)`` channels named by ``model.input_names`` (e.g. ``[p1, p2]`` in
        Pa for [`jaxfric.models.Cylinder`][jaxfric.models.Cylinder]); ignored by the other models.

        One output sample per input sample, always. A ``dt`` other than the fit's
        is handled by [`predict_at`][jaxfric.fit.Fit.predict_at] (resampling onto the fit's grid, with a
        [`ResamplingWarning`][jaxfric.fit.ResamplingWarning]) for every model whose output depends on the
        sample time; static maps ignore it. Velocities outside the training range
        give an [`ExtrapolationWarning`][jaxfric.fit.ExtrapolationWarning].
        """
        v = _velocity_np(velocity)
        dt = check_sample_time(self.dt if dt is None else dt)
        if self.model.uses_dt and not same_sample_time(dt, self.dt):
            if inputs is not None:
                raise ValueError(
                    f"dt = {dt:.6g} s differs from the fit's {self.dt:.6g} s and input channels "
                    f"were given: resample the record (velocity and {list(self.model.input_names)}) "
                    "to the fit's sample time first")
            return self.predict_at(np.arange(v.shape[0]) * dt, velocity)
        self._warn_extrapolation(v)
        return predict(self.model, self.theta, (self.velocity_scaler, self.friction_scaler),
                       velocity, self.dt if self.model.uses_dt else dt, inputs)

    def predict_at(self, t, velocity) -> jax.Array:
        """Friction [N] at the time stamps ``t`` [s] (any increasing grid, uniform or
        not) for the velocity samples ``velocity`` [m/s] taken there.

        The model was identified at the sample time [`dt`][jaxfric.fit.Fit.dt], and a recurrent model
        (the Elman network, LuGre, Dahl) is a function of it: when ``t`` is not a
        uniform grid of step [`dt`][jaxfric.fit.Fit.dt], the velocity is interpolated linearly onto
        one (from ``t[0]``, one step past ``t[-1]``), rolled out, and the prediction
        interpolated back to ``t``, with a [`ResamplingWarning`][jaxfric.fit.ResamplingWarning]. The result has
        one sample per input sample. Linear interpolation does not low-pass: a record
        sampled much finer than the fit should be filtered to the fit's bandwidth first.

        Raises:
            ValueError: ``t`` and ``velocity`` of different lengths, ``t`` not
                strictly increasing or not finite, or a grid longer than
                [`MAX_RESAMPLED_SAMPLES`][jaxfric.fit.MAX_RESAMPLED_SAMPLES] samples.
        """
        v = _velocity_np(velocity)
        t = np.asarray(t, np.float64) if np.ndim(t) else np.asarray([t], np.float64)
        if t.shape != v.shape:
            raise ValueError(f"t and velocity must have the same length, got {t.shape} and {v.shape}")
        if not np.all(np.isfinite(t)):
            raise ValueError("t holds NaN or inf")
        steps = np.diff(t)
        if np.any(steps <= 0.0):
            raise ValueError(f"time stamps must increase strictly (index {int(np.argmax(steps <= 0)) + 1})")
        self._warn_extrapolation(v)
        scalers = (self.velocity_scaler, self.friction_scaler)
        dtype = jnp.asarray(self.theta).dtype  # float32 unless x64 is on: never ask JAX for a dtype it lacks
        uniform = steps.size == 0 or (np.ptp(steps) <= 1e-6 * self.dt and same_sample_time(float(steps.mean()), self.dt))
        if not self.model.uses_dt or uniform:
            return predict(self.model, self.theta, scalers, jnp.asarray(v, dtype), self.dt)
        m = int(np.ceil((t[-1] - t[0]) / self.dt - 1e-9)) + 1
        if m > MAX_RESAMPLED_SAMPLES:
            raise ValueError(f"resampling this record onto the fit's sample time {self.dt:.6g} s needs {m} "
                             f"samples (> {MAX_RESAMPLED_SAMPLES}); pass a shorter record")
        step = float(np.median(steps))
        warnings.warn(
            f"the record's sample time ({step:.6g} s{'' if np.ptp(steps) <= 1e-6 * step else ', irregular'}) "
            f"differs from the fit's ({self.dt:.6g} s): the velocity was interpolated onto the fit's "
            f"grid ({m} samples), rolled out there and the prediction interpolated back to the "
            f"{t.size} input samples",
            ResamplingWarning, stacklevel=3)
        grid = t[0] + self.dt * np.arange(m)
        y = predict(self.model, self.theta, scalers, jnp.asarray(np.interp(grid, t, v), dtype), self.dt)
        return jnp.asarray(np.interp(t, grid, np.asarray(y, np.float64)), dtype)

    def predict_band(self, velocity, dt=None) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` [N]: the elementwise min and max of the ensemble members'
        predictions ([`ensemble`][jaxfric.fit.Fit.ensemble], from ``identify(..., keys=K)``), so the band
        always holds the best member's [`predict`][jaxfric.fit.Fit.predict]. Raises ``ValueError`` for a
        fit without an ensemble."""
        members = self.ensemble_predictions(velocity, dt)
        return members.min(axis=0), members.max(axis=0)

    def ensemble_predictions(self, velocity, dt=None) -> np.ndarray:
        """``(K, T)`` predictions [N] of the ensemble members (see [`predict_band`][jaxfric.fit.Fit.predict_band])."""
        if not self.ensemble or "theta" not in self.ensemble:
            raise ValueError("this fit has no ensemble: identify(..., keys=K) makes one")
        out = []
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ExtrapolationWarning)  # said once, below
            for theta in np.asarray(self.ensemble["theta"]):
                member = Fit(model=self.model, theta=theta, velocity_scaler=self.velocity_scaler,
                             friction_scaler=self.friction_scaler, dt=self.dt, n_train=self.n_train,
                             n_samples=self.n_samples, metrics={}, box=self.box)
                out.append(np.asarray(member.predict(velocity, dt), np.float64))
        return np.stack(out)

    def _warn_extrapolation(self, v: np.ndarray) -> None:
        rng = self.velocity_range
        if rng is None:
            return
        lo, hi = rng
        tol = 1e-6 * max(hi - lo, abs(hi), abs(lo))
        outside = (v < lo - tol) | (v > hi + tol)
        if outside.any():
            warnings.warn(
                f"{int(outside.sum())} of {v.size} velocity samples lie outside the training range "
                f"[{lo:.4g}, {hi:.4g}] m/s (min {v.min():.4g}, max {v.max():.4g}): the "
                f"{type(self.model).__name__} extrapolates there",
                ExtrapolationWarning, stacklevel=4)

    # --------------------------------------------------------------- export
    def to_numpy(self):
        """A pure-NumPy per-sample step ``f, state = step(v, state)`` of this fit
        ([`jaxfric.export.numpy_step`][jaxfric.export.numpy_step]), for controllers outside JAX."""
        return numpy_step(self)

    def to_c_header(self, path=None, *, prefix: str = "jaxfric") -> str:
        """C99 header with this fit's per-sample step and weights
        ([`jaxfric.export.c_header`][jaxfric.export.c_header]); written to ``path`` if given."""
        return c_header(self, path, prefix=prefix)

    # --------------------------------------------------------------- report
    def to_dict(self, include_theta: bool = True) -> dict[str, Any]:
        """A JSON-able summary (plain Python values)."""

        def scaler(s):
            return None if s is None else [float(np.asarray(s.lo)), float(np.asarray(s.hi))]

        uncertainty = self.uncertainty  # first, so a failure is in the diagnostics below
        out = {
            "model": {"class": type(self.model).__name__, "name": model_name(self.model),
                      "config": model_config(self.model), "param_names": list(self.model.param_names)},
            "box": None if self.box is None else self.box.to_json(),
            "num_params": self.num_params, "dt": self.dt, "n_train": self.n_train, "n_samples": self.n_samples,
            "scalers": {"velocity": scaler(self.velocity_scaler), "friction": scaler(self.friction_scaler)},
            "metrics": jsonable(self.metrics), "stages": jsonable(self.stages), "timings": jsonable(self.timings),
            "key": {"data": self.key_data, "impl": self.key_impl, "seed": self.seed},
            "settings": jsonable(self.settings), "jaxfric_version": self.version,
            "train_velocity_range": None if self.velocity_range is None else list(self.velocity_range),
            "diagnostics": jsonable({**self.diagnostics, **(
                {"uncertainty_error": self._uncertainty.error} if self._uncertainty.error else {})}),
        }
        if uncertainty is not None:
            out["uncertainty"] = uncertainty.to_json(diagnostic_flags(self))
        if not self.model.needs_scaling:
            out["verdicts"] = jsonable(self.verdicts())
        if self.ensemble:
            out["ensemble"] = jsonable({k: v for k, v in self.ensemble.items() if include_theta or k != "theta"})
        if not self.model.needs_scaling:
            out["params"] = {k: jsonable(v) for k, v in self.params.items()}
        if include_theta:
            out["theta"] = jsonable(self.theta)
            out["theta_dtype"] = str(self.theta.dtype)
        return out

    def stage_counts(self) -> list[tuple[str, float, int, bool]]:
        """``(stage, J, count, count_is_evaluations)`` per optimiser stage: the count is the
        stage's evaluations where it recorded them, else its steps."""
        return [(st.get("stage", "?"), float(st.get("J", float("nan"))),
                 st.get("num_evals", st.get("num_steps")), "num_evals" in st)
                for st in self.stages]

    def summary(self) -> str:
        """A short text table: model, metrics per window, stages and timings."""
        lines = [f"{type(self.model).__name__} fit: {self.num_params} parameters, "
                 f"{self.n_train} training / {self.n_samples - self.n_train} validation samples"]
        lines.append(f"{'window':<7}{'MSE %':>10}{'MAX [N]':>11}{'FIT %':>9}{'R2':>9}")
        for w in _WINDOWS:
            m = self.metrics.get(w)
            if m:
                lines.append(f"{w:<7}{m['mse_percent']:>10.4f}{m['max_abs']:>11.3g}"
                             f"{m['fit_percent']:>9.2f}{m['r2']:>9.5f}")
        if self.stages:
            parts = [f"{name} J={J:.4g} ({n} {'evals' if evals else 'steps'})"
                     for name, J, n, evals in self.stage_counts()]
            lines.append("stages: " + " -> ".join(parts))
        base = self.metrics.get("baseline")
        if base:
            lines.append(f"baseline, {self.settings.get('baseline', {}).get('model', 'least squares')}: "
                         + ", ".join(f"{w} MSE {base[w]['mse_percent']:.4g} %" for w in ("train", "valid")
                                     if w in base))
        records = self.metrics.get("records") or []
        if len(records) > 1:
            lines.append(f"{'record':<16}{'role':<7}{'samples':>8}{'MSE %':>10}{'MAX [N]':>11}")
            for r in records:
                m = r.get("all") or {}
                mse, mx = m.get("mse_percent"), m.get("max_abs")
                lines.append(f"{str(r['name'])[:15]:<16}{r['role']:<7}{r['n_samples']:>8}"
                             + (f"{mse:>10.4f}{mx:>11.3g}" if mse is not None else f"{'-':>10}{'-':>11}"))
        if not self.model.needs_scaling:
            verdicts = self.verdicts()
            lines.append("params: " + ", ".join(
                f"{k}={float(v):.4g}" + (" [on bound]" if verdicts.get(k, {}).get("on_bound") else "")
                + ("" if verdicts.get(k, {"identifiable": True})["identifiable"] else " [not identifiable]")
                for k, v in self.params.items()))
        if self.box is not None:
            lines.append(f"box: {self.box}")
        for d in self.diagnostics.get("on_bound", []):
            lines.append(f"! {d['message']}")
        lines += uncertainty_lines(self)
        if self.ensemble:
            e = self.ensemble
            vm = [x for x in e.get("valid_mse_percent", []) if x is not None]
            lines.append(f"ensemble: {len(e.get('J', []))} members (best #{e.get('best')}), "
                         + (f"validation MSE % {min(vm):.4g}..{max(vm):.4g}" if vm else "no validation"))
            for name, sp in (e.get("spread") or {}).items():
                lines.append(f"  {name}: median {sp['median']:.4g}, 5-95 % [{sp['p5']:.4g}, {sp['p95']:.4g}], "
                             f"min..max [{sp['min']:.4g}, {sp['max']:.4g}]")
        t = self.timings
        if t:
            lines.append("time [s]: " + ", ".join(f"{k[:-2]} {v:.2f}" for k, v in t.items() if k.endswith("_s")))
        return "\n".join(lines)

    def __repr__(self) -> str:
        m = self.metrics.get("valid") or {}  # None for a fit with no validation part
        mse = m.get("mse_percent")
        tail = f", valid MSE {mse:.4g} %" if mse is not None else ""
        return f"Fit({type(self.model).__name__}, {self.num_params} params{tail})"

    # ----------------------------------------------------------------- files
    def save(self, path) -> None:
        """Write the fit to ``path`` (one ``.npz`` file, see the module docstring), atomically."""
        header = self.to_dict(include_theta=False)
        header.update(format=FORMAT_NAME, format_version=FORMAT_VERSION)
        blob = json.dumps(header, allow_nan=True).encode("utf-8")

        def scaler(s):
            return np.zeros(0) if s is None else np.array([np.asarray(s.lo), np.asarray(s.hi)], np.float64)

        arrays = {"header": np.frombuffer(blob, dtype=np.uint8), "theta": np.asarray(self.theta),
                  "velocity_scaler": scaler(self.velocity_scaler), "friction_scaler": scaler(self.friction_scaler),
                  "history_evals": np.asarray(self.history["evals"]), "history_f": np.asarray(self.history["f"])}
        if self.ensemble and "theta" in self.ensemble:
            arrays["ensemble_theta"] = np.asarray(self.ensemble["theta"])
        def write(tmp):
            # np.savez on a name would append ".npz" to the temporary's; give it the file
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)

        atomic_write(os.fspath(path), write)


def _read(path) -> tuple[dict, dict[str, np.ndarray]]:
    if not isinstance(path, (str, bytes, os.PathLike)):
        # open(3) would read (and then close) file descriptor 3
        raise ValueError(f"path must be a file name (str or os.PathLike), got {type(path).__name__} {path!r}")
    with open(path, "rb") as fh:
        raw = fh.read()
    if not raw.startswith(b"PK"):
        # np.load would try it as a pickle and suggest allow_pickle, which must never be used here
        raise ValueError(f"{os.fsdecode(path)} is not a readable jaxfric fit file: not an .npz archive "
                         "(fits are written by Fit.save / jaxfric identify; corrupted or truncated?)")
    try:
        with np.load(io.BytesIO(raw), allow_pickle=False) as z:
            arrays = {name: z[name] for name in z.files}
    except (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError) as err:
        raise ValueError(f"{path} is not a readable jaxfric fit file (corrupted or truncated?): {err}") from None
    if "header" not in arrays:
        raise ValueError(f"{path} is not a jaxfric fit file: no header")
    try:
        header = json.loads(arrays["header"].tobytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ValueError(f"{path}: the fit header is corrupted: {err}") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT_NAME:
        raise ValueError(f"{path} is not a jaxfric fit file (format {header.get('format')!r})"
                         if isinstance(header, dict) else f"{path}: the fit header is corrupted")
    return header, arrays


def _finite_array(path, name: str, a: np.ndarray) -> np.ndarray:
    if not np.issubdtype(a.dtype, np.number) or not np.all(np.isfinite(a)):
        raise ValueError(f"{path}: the fit's {name} holds NaN or inf (or is not numeric): the file is "
                         "corrupted, or was saved from a diverged fit; it would predict NaN")
    return a


def _file_fields(path) -> dict:
    """The constructor fields of the fit stored at ``path`` (`load_fit` says what is checked)."""
    header, arrays = _read(path)
    version = header.get("format_version")
    if not isinstance(version, int) or version < 1:
        raise ValueError(f"{path}: unknown fit format version {version!r}")
    if version > FORMAT_VERSION:
        raise ValueError(f"{path} was written in fit format version {version} by jaxfric "
                         f"{header.get('jaxfric_version')}; this jaxfric ({_jaxfric_version()}) reads up to "
                         f"version {FORMAT_VERSION}: upgrade jaxfric")
    try:
        m = header["model"]
        model = model_from_config(m["class"], m["config"])
        box = header["box"] if "box" in header else old_box_entries(m["config"])

        def scaler(name):
            a = arrays[name]
            if a.size == 0:
                return None
            _finite_array(path, name.replace("_", " "), a)
            if a.shape != (2,) or not a[1] > a[0]:
                raise ValueError(f"{path}: the fit's {name.replace('_', ' ')} {a.tolist()} is not a "
                                 "range [lo, hi] with lo < hi")
            return Scaler(lo=np.float64(a[0]), hi=np.float64(a[1]))

        theta = _finite_array(path, "weights (theta)", arrays["theta"])
        dt = header["dt"]
        if not (isinstance(dt, (int, float)) and np.isfinite(dt) and dt > 0):
            raise ValueError(f"{path}: the fit's sample time dt = {dt!r} is not a positive number")
        uncertainty = header.get("uncertainty")
        if uncertainty is not None:
            uncertainty = ParameterUncertainty.from_json(uncertainty)
        ensemble = header.get("ensemble")
        if ensemble is not None and "ensemble_theta" in arrays:
            ensemble = {**ensemble, "theta": _finite_array(path, "ensemble weights", arrays["ensemble_theta"])}
        vrange = header.get("train_velocity_range")
        if vrange is not None and not (len(vrange) == 2 and np.all(np.isfinite(np.asarray(vrange, float)))):
            raise ValueError(f"{path}: the training velocity range {vrange!r} is not two finite numbers")
        key = header.get("key") or {}
        return dict(
            model=model, theta=theta, velocity_scaler=scaler("velocity_scaler"),
            friction_scaler=scaler("friction_scaler"), dt=header["dt"], n_train=header["n_train"],
            n_samples=header["n_samples"], metrics=header["metrics"], stages=header.get("stages", ()),
            history={"evals": arrays["history_evals"], "f": arrays["history_f"]}, solution=None,
            timings=header.get("timings"), key_data=key.get("data"), key_impl=key.get("impl"), seed=key.get("seed"),
            settings=header.get("settings"), version=header.get("jaxfric_version"), velocity_range=vrange,
            diagnostics=header.get("diagnostics"), ensemble=ensemble, box=box, uncertainty=uncertainty)
    except (KeyError, TypeError, IndexError) as err:
        raise ValueError(f"{path}: the fit file is incomplete or corrupted ({err!r})") from None


def load_fit(path) -> Fit:
    """Read a force-balance fit written by [`Fit.save`][jaxfric.fit.Fit.save]
    ([`Fit.load`][jaxfric.fit.Fit.load]; a motion fit's file: ``jaxfric.motion.load_motion_fit``).

    A file written by jaxfric 0.6/0.7 kept the search box in the model configuration
    (``Fc_range``, ``sigma0_range``, ...): those entries become [`Fit.box`][jaxfric.fit.Fit.box] (the
    unset ones its defaults, as they were then).

    Raises:
        ValueError: ``path`` is not a file name (an int would be a file descriptor); the
            file is not an ``.npz`` archive, is corrupted or truncated, is not a
            jaxfric fit, holds a motion fit ([`FitKindError`][jaxfric.fit.FitKindError]), was written in a newer (or unknown) format
            version than this jaxfric reads, or holds non-finite (or, for the scalers,
            empty-range) weights, scalers or sample time.
        FileNotFoundError: no such file.
    """
    return Fit.load(path)
