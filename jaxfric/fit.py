"""The result of :func:`jaxfric.identify`, and saving/loading it (ALGORITHMS.md §6, §11 step 8).

A :class:`Fit` holds everything needed to *use* an identified model — the model
configuration, θ in search coordinates, the training-window scalers of §2.4 and
the sample time — plus everything needed to *judge* it: metrics on the training
window, the validation window and the whole record (§6), the optimiser's
solution and history, the stage-by-stage cost, timings, the key and the settings.

File format (one ``.npz`` file, no pickles): member ``header`` holds UTF-8 JSON
(``format``, ``format_version``, jaxfric version, model class and configuration,
metrics, settings, ...); members ``theta``, ``velocity_scaler``, ``friction_scaler``
(``[lo, hi]``, float64) and ``history_evals``/``history_f`` hold the arrays with
their exact dtypes, so save → load → predict is bit-identical. Writes go to a
temporary file in the target directory, then ``os.replace``: a crash never leaves
a half-written fit under the final name.
"""

from __future__ import annotations

import dataclasses
import io
import json
import os
import tempfile
import zipfile
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from . import models as _models
from .models import AbstractFrictionModel, Scaler

__all__ = ["FORMAT_VERSION", "Fit", "load_fit", "rollout_model"]

FORMAT_NAME = "jaxfric.fit"
#: Version of the file layout written by :meth:`Fit.save`; :func:`load_fit` reads
#: this version and older ones and refuses newer ones.
FORMAT_VERSION = 1

_WINDOWS = ("train", "valid", "all")


def _jaxfric_version() -> str:
    from . import __version__

    return __version__


def _jsonable(x):
    """Python scalars/lists from NumPy/JAX values and tuples (recursively)."""
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.ndarray, jax.Array)):
        return _jsonable(np.asarray(x).tolist())
    if isinstance(x, np.generic):
        return x.item()
    return x


def _tuples(x):
    """JSON lists back to tuples (model fields are hashable static values)."""
    if isinstance(x, list):
        return tuple(_tuples(v) for v in x)
    return x


def model_config(model: AbstractFrictionModel) -> dict[str, Any]:
    """The constructor arguments of ``model`` (its dataclass fields) as JSON values."""
    return {f.name: _jsonable(getattr(model, f.name)) for f in dataclasses.fields(model)}


def model_from_config(class_name: str, config: dict[str, Any]) -> AbstractFrictionModel:
    """Rebuild a model saved by :func:`model_config`; only jaxfric's own model classes."""
    cls = getattr(_models, class_name, None)
    if not (isinstance(cls, type) and issubclass(cls, AbstractFrictionModel)):
        raise ValueError(f"unknown friction model class {class_name!r} in the fit file")
    try:
        return cls(**{k: _tuples(v) for k, v in config.items()})
    except (TypeError, ValueError) as err:
        raise ValueError(f"cannot rebuild {class_name} from the fit file: {err}") from None


def model_name(model: AbstractFrictionModel) -> str | None:
    """The :func:`jaxfric.models.get` name of ``model``'s class, if it has one."""
    for name in _models.available():
        if type(_models.get(name)) is type(model):
            return name
    return None


def rollout_model(model: AbstractFrictionModel) -> AbstractFrictionModel:
    """``model`` with its search ranges reset, for rollouts.

    Physical models keep their search box in ``*_range`` fields, which never enter
    the rollout (``AbstractPhysicalModel``'s contract) but do enter the jit cache
    key, since the model is static. Rolling out with the ranges cleared lets fits
    on different records (hence different data-centred boxes) share one compiled
    rollout and one compiled optimiser.
    """
    if not isinstance(model, _models.AbstractPhysicalModel):
        return model
    reset = {f.name: None for f in dataclasses.fields(model) if f.name.endswith("_range")}
    return dataclasses.replace(model, **reset) if reset else model


def _check_velocity(velocity, dtype) -> jax.Array:
    v = np.asarray(velocity)
    if v.ndim != 1 or v.shape[0] == 0:
        raise ValueError(f"velocity must be a non-empty 1-D time series, got shape {v.shape}")
    if not np.issubdtype(v.dtype, np.number):
        raise ValueError(f"velocity must be numeric, got dtype {v.dtype}")
    if not np.all(np.isfinite(v)):
        raise ValueError("velocity holds NaN or inf")
    return jnp.asarray(velocity, dtype)


def predict(model: AbstractFrictionModel, theta, scalers, velocity, dt) -> jax.Array:
    """Free-run friction [N] of ``model`` at ``theta`` for ``velocity`` [m/s] (§2.4):
    scale the input, roll out, unscale the output (``scalers = (velocity, friction)``
    :class:`Scaler` pair, or ``(None, None)`` for SI-unit models). Computed in
    ``theta``'s dtype."""
    theta = jnp.asarray(theta)
    dtype = theta.dtype
    v = _check_velocity(velocity, dtype)
    if not (np.ndim(dt) == 0 and np.isfinite(float(dt)) and float(dt) > 0.0):
        raise ValueError(f"dt must be a positive, finite sample time in seconds, got {dt!r}")
    dt = jnp.asarray(dt, dtype)
    model = rollout_model(model)
    if model.needs_scaling:
        sv, sf = scalers
        return sf.unscale(model.simulate(theta, sv.scale(v), dt))
    return model.simulate(theta, v, dt)


class Fit:
    """An identified friction model and its report (returned by :func:`jaxfric.identify`).

    Attributes:
        model: the friction model (with the search box actually used).
        theta: parameters in search coordinates (NumPy, the search dtype).
        velocity_scaler, friction_scaler: the §2.4 training-window :class:`Scaler`
            of a model with ``needs_scaling``, else ``None``.
        dt: sample time [s] of the identification record.
        n_train, n_samples: training-window length and record length.
        metrics: ``{"train", "valid", "all"}`` → :func:`jaxfric.metrics.friction_metrics`
            dicts (newtons), plus ``"num_params"`` and ``"cost"`` (the final J).
        stages: one dict per optimiser stage (``stage``, ``J``, ``num_evals``/``num_steps``,
            ...), in order: e.g. MAPSO, Nelder–Mead, BFGS.
        history: ``{"evals": ..., "f": ...}`` best J against evaluations (NumPy).
        solution: the optimiser's :class:`jaxfric.Solution` (``None`` after loading).
        timings: seconds: ``compile_s``, ``run_s`` (optimiser), ``refine_compile_s``,
            ``refine_run_s``, ``total_s`` (wall, everything including checks and metrics).
        key_data, key_impl, seed: the PRNG key used (see :attr:`key`).
        settings: solver, refinement, dtype, data-bounds and split settings (JSON values).
        version: jaxfric version that produced the fit.
    """

    def __init__(self, *, model, theta, velocity_scaler, friction_scaler, dt, n_train,
                 n_samples, metrics, stages=(), history=None, solution=None, timings=None,
                 key_data=None, key_impl=None, seed=None, settings=None, version=None):
        self.model = model
        self.theta = model.check_theta(np.asarray(theta))
        self.velocity_scaler = velocity_scaler
        self.friction_scaler = friction_scaler
        self.dt = float(dt)
        self.n_train = int(n_train)
        self.n_samples = int(n_samples)
        self.metrics = metrics
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
        """The PRNG key the fit was made with (re-wrapped from :attr:`key_data`)."""
        if self.key_data is None:
            return None
        data = np.asarray(self.key_data, np.uint32)
        if self.key_impl is None:
            return data
        return jax.random.wrap_key_data(data, impl=self.key_impl)

    def predict(self, velocity, dt=None) -> jax.Array:
        """Free-run friction prediction [N] for a velocity record [m/s] (§2.4).

        The model state starts from its initial condition at the first sample
        (learned ``c0`` for the Elman network, the steady state for LuGre); the
        velocity is scaled with the training-window scaler and the output mapped
        back to newtons. ``dt`` defaults to the identification record's.
        """
        dt = self.dt if dt is None else dt
        return predict(self.model, self.theta, (self.velocity_scaler, self.friction_scaler),
                       velocity, dt)

    # --------------------------------------------------------------- export
    def to_numpy(self):
        """A pure-NumPy per-sample step ``f, state = step(v, state)`` of this fit
        (:func:`jaxfric.export.numpy_step`), for controllers outside JAX."""
        from .export import numpy_step

        return numpy_step(self)

    def to_c_header(self, path=None, *, prefix: str = "jaxfric") -> str:
        """C99 header with this fit's per-sample step and weights
        (:func:`jaxfric.export.c_header`); written to ``path`` if given."""
        from .export import c_header

        return c_header(self, path, prefix=prefix)

    # --------------------------------------------------------------- report
    def to_dict(self, include_theta: bool = True) -> dict[str, Any]:
        """A JSON-able summary (plain Python values)."""

        def scaler(s):
            return None if s is None else [float(np.asarray(s.lo)), float(np.asarray(s.hi))]

        out = {
            "model": {
                "class": type(self.model).__name__,
                "name": model_name(self.model),
                "config": model_config(self.model),
                "param_names": list(self.model.param_names),
            },
            "num_params": self.num_params,
            "dt": self.dt,
            "n_train": self.n_train,
            "n_samples": self.n_samples,
            "scalers": {"velocity": scaler(self.velocity_scaler),
                        "friction": scaler(self.friction_scaler)},
            "metrics": _jsonable(self.metrics),
            "stages": _jsonable(self.stages),
            "timings": _jsonable(self.timings),
            "key": {"data": self.key_data, "impl": self.key_impl, "seed": self.seed},
            "settings": _jsonable(self.settings),
            "jaxfric_version": self.version,
        }
        if not self.model.needs_scaling:
            out["params"] = {k: _jsonable(v) for k, v in self.params.items()}
        if include_theta:
            out["theta"] = _jsonable(self.theta)
            out["theta_dtype"] = str(self.theta.dtype)
        return out

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
            parts = []
            for s in self.stages:
                n = s.get("num_evals", s.get("num_steps"))
                unit = "evals" if "num_evals" in s else "steps"
                parts.append(f"{s['stage']} J={s['J']:.4g} ({n} {unit})")
            lines.append("stages: " + " -> ".join(parts))
        if not self.model.needs_scaling:
            lines.append("params: " + ", ".join(
                f"{k}={float(v):.4g}" for k, v in self.params.items()))
        t = self.timings
        if t:
            lines.append(
                "time [s]: " + ", ".join(f"{k[:-2]} {v:.2f}" for k, v in t.items() if k.endswith("_s")))
        return "\n".join(lines)

    def __repr__(self) -> str:
        m = self.metrics.get("valid", {})
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

        arrays = {
            "header": np.frombuffer(blob, dtype=np.uint8),
            "theta": np.asarray(self.theta),
            "velocity_scaler": scaler(self.velocity_scaler),
            "friction_scaler": scaler(self.friction_scaler),
            "history_evals": np.asarray(self.history["evals"]),
            "history_f": np.asarray(self.history["f"]),
        }
        path = os.fspath(path)
        directory = os.path.dirname(os.path.abspath(path))
        fd, tmp = tempfile.mkstemp(prefix=".jaxfric-fit-", suffix=".tmp", dir=directory)
        try:
            with os.fdopen(fd, "wb") as fh:
                np.savez(fh, **arrays)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise


def _read(path) -> tuple[dict, dict[str, np.ndarray]]:
    with open(path, "rb") as fh:
        raw = fh.read()
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


def load_fit(path) -> Fit:
    """Read a fit written by :meth:`Fit.save`.

    Raises:
        ValueError: the file is corrupted or truncated, is not a jaxfric fit, or was
            written in a newer (or unknown) format version than this jaxfric reads.
        FileNotFoundError: no such file.
    """
    header, arrays = _read(path)
    version = header.get("format_version")
    if not isinstance(version, int) or version < 1:
        raise ValueError(f"{path}: unknown fit format version {version!r}")
    if version > FORMAT_VERSION:
        raise ValueError(
            f"{path} was written in fit format version {version} by jaxfric "
            f"{header.get('jaxfric_version')}; this jaxfric ({_jaxfric_version()}) reads up to "
            f"version {FORMAT_VERSION}: upgrade jaxfric"
        )
    try:
        m = header["model"]
        model = model_from_config(m["class"], m["config"])

        def scaler(name):
            a = arrays[name]
            return None if a.size == 0 else Scaler(lo=np.float64(a[0]), hi=np.float64(a[1]))

        key = header.get("key") or {}
        return Fit(
            model=model,
            theta=arrays["theta"],
            velocity_scaler=scaler("velocity_scaler"),
            friction_scaler=scaler("friction_scaler"),
            dt=header["dt"],
            n_train=header["n_train"],
            n_samples=header["n_samples"],
            metrics=header["metrics"],
            stages=header.get("stages", ()),
            history={"evals": arrays["history_evals"], "f": arrays["history_f"]},
            solution=None,
            timings=header.get("timings"),
            key_data=key.get("data"),
            key_impl=key.get("impl"),
            seed=key.get("seed"),
            settings=header.get("settings"),
            version=header.get("jaxfric_version"),
        )
    except (KeyError, TypeError, IndexError) as err:
        raise ValueError(f"{path}: the fit file is incomplete or corrupted ({err!r})") from None
