"""[`jaxfric.identify_motion`][jaxfric.motion.identify_motion]: friction from actuator force and position alone (§13.2).

No friction signal and no acceleration: the friction model sits inside the mechanics
([`jaxfric.motion.simulate_motion`][jaxfric.motion.simulate_motion]) and its parameters (optionally the mass, a
constant force offset and the initial velocity) are chosen so that the *simulated*
position (and/or velocity) matches the measured one, by the same optimisers as
[`jaxfric.identify`][jaxfric.identification.identify].

Closed-loop records drift in open-loop simulation (a double integrator with an
uncertain force balance): the validation metrics therefore start the free run from
the state estimated at the start of the validation window (measured position,
low-pass-differentiated velocity, friction state tracked along that velocity), and
report k-step-ahead errors (MATLAB ``compare(..., k)``) beside the free run.
"""

from __future__ import annotations

import dataclasses
import numbers
import warnings
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._warnings import ExtrapolationWarning
from ..covariance import DEFAULT_LEVEL, check_level
from ..fit import Fit, FitKindError, model_config, model_name, predict, uncertainty_lines
from .._timing import Stopwatch
from ..identification import from_box, resolve_model, search_dtype
from ..metrics import friction_metrics
from ..models import GreyBox, Scaler, SearchBox, friction_scales
from ..optim import AbstractSolver
from ..pipeline import (ENSEMBLE_DROP, best_member, baseline_stage, check_solver, global_search, history,
                        kept_members, key_record, resolve_keys, solver_stages)
from ..problem import AbstractProblem, Residuals, SearchCoordinates
from ..records import (DEFAULT_TRAIN_FRACTION, SAMPLE_TIME_RTOL, as_channel, check_int, check_sample_time,
                       same_sample_time, split_count)
from ..rig.pipeline import differentiate, lowpass
from ..uncertainty import assess_fit
from ._band import FreeRunPositions, position_band, window_maps
from ._baseline import BASELINE_LABEL, baseline_model, least_squares, least_squares_start, slow_attraction_grid
from ._forward import k_step_positions, motion_prediction, simulate_motion, track_states
from ._layout import Layout
from ._mechanics import Mechanics
from ._lm import _res_jit
from ._pipeline import GLOBAL_SAMPLES, MotionBudget, MotionSearch, default_search, run_search, start_costs
from ._residuals import (SumOfSquares, motion_coordinates, motion_residual, motion_residuals, motion_train_velocity,
                         search_layout, training_lengths)
from ._shooting import schedule, shoot
from ._step import friction_step

__all__ = ["MotionData", "MotionFit", "baseline_motion_fit", "identify_motion", "load_motion_fit", "motion_metrics"]

#: k of the k-step-ahead metrics when none is asked for: 10 samples.
DEFAULT_METRIC_HORIZON = 10
#: Leading samples of a validation record that set its initial state (the EMPS
#: benchmark's ``state_initialization_window_length``); they are not scored.
DEFAULT_INIT_WINDOW = 20
#: Degree of the polynomial the initial-state rule fits to the window's positions.
INIT_DEGREE = 2
#: A simulated record warns (`ExtrapolationWarning`) where more than this share of its
#: filtered velocity samples lie outside the fit's training range by more than
#: `EXTRAPOLATION_MARGIN` of that range's width: motion faster than any the fit was trained
#: on (or in a direction it never moved), where no judge computed on the training data can say
#: how the model predicts.
EXTRAPOLATION_SHARE = 0.01
#: See `EXTRAPOLATION_SHARE` (a fraction of the training velocity range's width).
EXTRAPOLATION_MARGIN = 0.05
ERRORS = ("position", "velocity", "both")
_CHANNELS = ("force", "position", "load", "velocity")


def _series(name, values) -> np.ndarray:
    a = as_channel(name, values)
    if a.size < 2:
        raise ValueError(f"{name} must hold at least 2 samples, got {a.size}")
    return a


@dataclasses.dataclass(frozen=True)
class MotionData:
    """A checked motion record (float64 NumPy, SI units).

    ``force``: actuator force F_act [N] along +x; ``position`` [m]; ``dt`` [s];
    ``load``: external force opposing +x [N] (zeros if absent). The net force
    ``force - load`` drives the mechanics. ``velocity``: the position low-passed
    (zero-phase Butterworth, order 4, ``cutoff`` Hz, default ``fs / 10``) and
    differentiated; used for initial states, data-centred bounds, velocity errors
    and the friction state of k-step predictions, never as a model input.
    """

    force: np.ndarray
    position: np.ndarray
    dt: float
    load: np.ndarray
    velocity: np.ndarray
    cutoff: float

    @classmethod
    def from_arrays(cls, force, position, dt, *, load=None, cutoff=None) -> "MotionData":
        f = _series("force", force)
        x = _series("position", position)
        if f.shape != x.shape:
            raise ValueError(f"force and position must have the same length, got {f.size} and {x.size}")
        ld = np.zeros_like(f) if load is None else _series("load", load)
        if ld.shape != f.shape:
            raise ValueError(f"load must have the length of force ({f.size}), got {ld.size}")
        dt = check_sample_time(dt, stamps_hint="for time stamps resample the channels onto a uniform "
                                                "grid first (jaxfric.rig.resample_uniform)")
        fs = 1.0 / dt
        cutoff = 0.1 * fs if cutoff is None else float(cutoff)
        if not 0.0 < cutoff < 0.5 * fs:
            raise ValueError(f"cutoff must lie in (0, fs/2) = (0, {0.5 * fs}) Hz, got {cutoff}")
        v, _ = differentiate(lowpass(x, fs, cutoff), float(dt))
        return cls(f, x, float(dt), ld, v, cutoff)

    @classmethod
    def from_pressures(cls, p1, p2, area1, area2, position, dt, **kw) -> "MotionData":
        """``F_act = p1 A1 - p2 A2`` (cap chamber p1 [Pa] on A1 [m^2], rod chamber on A2)."""
        return cls.from_arrays(_series("p1", p1) * area1 - _series("p2", p2) * area2, position, dt, **kw)

    @classmethod
    def from_voltage(cls, voltage, gain, position, dt, **kw) -> "MotionData":
        """``F_act = gain * voltage`` (a current-controlled drive: gain [N/V])."""
        return cls.from_arrays(_series("voltage", voltage) * float(gain), position, dt, **kw)

    @property
    def net_force(self) -> np.ndarray:
        return self.force - self.load

    def window(self, start: int, stop: int | None = None) -> "MotionData":
        """Samples ``[start, stop)`` as a record of their own (the velocity stays the one
        filtered over the whole record)."""
        return dataclasses.replace(self, **{k: getattr(self, k)[start:stop] for k in _CHANNELS})

    @property
    def n_samples(self) -> int:
        return int(self.force.size)


def _init_window(n) -> int:
    return check_int("init_window", n, 2, unit=" (samples)")


def _as_motion_data(data) -> MotionData:
    if isinstance(data, MotionData):
        return data
    if isinstance(data, tuple) and len(data) == 3:
        return MotionData.from_arrays(*data)
    raise ValueError("data must be a MotionData or a tuple (force [N], position [m], dt [s])")


def _split(n: int, train) -> int:
    """The records' split rule ([`jaxfric.records.split_count`][jaxfric.records.split_count]); the mechanics need
    two samples on each side of it to start a free run from."""
    count = split_count(n, DEFAULT_TRAIN_FRACTION if train is None else train, whole=False)
    if not 2 <= count <= n - 2:
        raise ValueError(f"train must be a fraction, a sample count in [2, {n - 2}] (two samples held "
                         f"back at least) or {n} / 1.0 (the whole record), got {train!r}")
    return count


class MotionCost(eqx.Module):
    """J = normalised mean squared free-run (or k-step) error of position and/or velocity.

    Position errors are divided by var(x_train), velocity errors by var(v_train), so J
    is ``1 - R^2`` (summed for ``"both"``). Data travel in ``args``.
    """

    model: object = eqx.field(static=True)
    layout: Layout
    error: str = eqx.field(static=True)
    horizon: int | None = eqx.field(static=True)

    def simulate(self, y, args):
        theta, mass, offset, dv0 = self.layout.unpack(y, args)
        step = friction_step(self.model, args["scalers"])
        return motion_prediction(step, theta, mass, args["force"] - offset, args["dt"], args["x"],
                                 args["v"], dv0, self.horizon)

    def residuals(self, y, args):
        """The terms of J as a vector (``J = sum(residuals**2)``), for Levenberg–Marquardt."""
        x_hat, v_hat, x, v = self.simulate(y, args)
        out = []
        if self.error in ("position", "both"):
            out.append(motion_residual(x_hat, x, args["inv_var_x"] / x.shape[0]))
        if self.error in ("velocity", "both") and v_hat is not None:
            out.append(motion_residual(v_hat, v, args["inv_var_v"] / v.shape[0]))
        out.append(self.model.penalty(y[:self.model.num_params]))  # the model's own rows (GreyBox's ridge)
        return jnp.concatenate(out)

    def __call__(self, y, args):
        x_hat, v_hat, x, v = self.simulate(y, args)
        j = 0.0
        if self.error in ("position", "both"):
            j = j + jnp.mean(motion_residual(x_hat, x) ** 2) * args["inv_var_x"]
        if self.error in ("velocity", "both") and v_hat is not None:
            j = j + jnp.mean(motion_residual(v_hat, v) ** 2) * args["inv_var_v"]
        pen = self.model.penalty(y[:self.model.num_params])
        return j + jnp.sum(pen * pen)


class ShootingResiduals(eqx.Module):
    """Weighted position errors of `jaxfric.motion._shooting.shoot` over the
    concatenated training records: ``r_k = sqrt(w_k) (x̂_k - x̃_k)`` (`motion_residual`). With the
    per-record weights ``1 / (var(x_r) N)`` (``N`` all training samples) the sum of
    squares is the pooled ``1 - R^2`` of `MotionCost`."""

    model: object = eqx.field(static=True)
    layout: Layout

    def __call__(self, y, args):
        theta, mass, offset, dv0 = self.layout.unpack(y, args)
        step = friction_step(self.model, args["scalers"])
        plan = args["plan"]
        v = args["v"] + dv0 * plan.reset
        x_hat = shoot(step, theta, mass, args["force"] - offset, args["dt"], args["x"], v, plan)
        # the model's own regularisation rows (GreyBox's ridge; none for the other models)
        return jnp.concatenate([motion_residual(x_hat, args["x"], plan.weight), self.model.penalty(theta)])


def motion_metrics(x, x_hat) -> dict:
    """Position metrics: ``rmse_mm`` (RMSE in mm), ``fit_percent`` (MATLAB FIT %),
    ``max_abs_mm``, plus the rest of [`jaxfric.metrics.friction_metrics`][jaxfric.metrics.friction_metrics] in metres."""
    x_hat = np.asarray(x_hat, np.float64)
    if not np.all(np.isfinite(x_hat)):
        return {"rmse_mm": float("inf"), "fit_percent": float("-inf"), "max_abs_mm": float("inf"), "finite": False}
    m = friction_metrics(np.asarray(x, np.float64), x_hat)
    m.update(rmse_mm=1e3 * m["rmse"], max_abs_mm=1e3 * m["max_abs"])
    return m


class MotionFit(Fit):
    """A friction model identified inside the mechanics ([`identify_motion`][jaxfric.motion.identify_motion]).

    Everything of [`jaxfric.Fit`][jaxfric.fit.Fit] (``predict`` gives the friction [N] for a
    velocity record, offset included; ``params``; ``save``; ``to_numpy``), plus the mechanics: ``mass`` [kg],
    ``offset`` [N] (a constant force added to the friction, 0 unless fitted),
    ``v0`` correction [m/s], the velocity filter ``cutoff`` [Hz], and [`simulate`][jaxfric.motion.MotionFit.simulate].
    ``metrics`` holds position metrics per window (``"train"``, ``"valid"``: free run;
    ``"train_kstep"``, ``"valid_kstep"``: k-step-ahead), see [`motion_metrics`][jaxfric.motion.motion_metrics].
    """

    #: The constructor's arguments: `Fit`'s, and the mechanics.
    FIELDS = Fit.FIELDS + ("mechanics",)

    def __init__(self, *, mechanics: Mechanics, **fields):
        if not isinstance(mechanics, Mechanics):
            raise TypeError(f"mechanics must be a jaxfric.motion.Mechanics, got {type(mechanics).__name__}")
        if "motion" in (fields.get("settings") or {}):
            raise ValueError("a MotionFit keeps its mechanics in mechanics=Mechanics(...), not in settings['motion'] "
                             "(a fit file's form: load_motion_fit reads it)")
        super().__init__(**fields)
        object.__setattr__(self, "mechanics", mechanics)  # after Fit's fields, before anyone reads it

    @classmethod
    def given(cls, model, params, *, mass: float, dt: float, offset: float = 0.0, v0: float = 0.0,
              n_train: int = 0, n_samples: int = 0, settings: dict | None = None,
              mechanics: dict | None = None) -> "MotionFit":
        """A motion fit holding given parameters rather than identified ones (published
        values, a least-squares baseline, a test's truth), to be simulated and scored like
        an identified fit. ``params``: physical values by name (``model.from_physical``) or
        ``theta`` in search coordinates; ``mass`` [kg], ``offset`` [N] (added to the
        friction), ``v0`` [m/s] the initial-velocity correction; ``settings`` more entries;
        ``mechanics`` more fields of [`Mechanics`][jaxfric.motion.Mechanics] by name."""
        theta = model.from_physical(**params) if isinstance(params, dict) else params
        return cls(model=model, theta=np.asarray(theta, np.float64), velocity_scaler=None, friction_scaler=None,
                   dt=dt, n_train=n_train, n_samples=n_samples, metrics={}, settings=settings,
                   mechanics=Mechanics(mass=mass, offset=offset, v0=v0, **(mechanics or {})))

    @classmethod
    def problem(cls) -> "MotionProblem":
        """[`MotionProblem`][jaxfric.motion.MotionProblem]: how a motion fit's data, coordinates, residuals and score are read."""
        return MotionProblem()

    @classmethod
    def from_fields(cls, fields: dict, path="the fit") -> "MotionFit":
        """A motion fit from a file's constructor fields: its ``settings["motion"]`` entries
        become [`Mechanics`][jaxfric.motion.Mechanics]; a force-balance fit's fields are refused."""
        settings = dict(fields.get("settings") or {})
        if "motion" not in settings:
            raise FitKindError(f"{path} holds a force-balance fit, not a motion fit: use jaxfric.load_fit")
        mechanics = Mechanics.from_json(settings.pop("motion"))
        return cls(**{**fields, "settings": settings}, mechanics=mechanics)

    @property
    def mass(self) -> float:
        """The moving mass [kg] (``mechanics.mass``)."""
        return self.mechanics.mass

    @property
    def offset(self) -> float:
        """The constant force added to the friction [N] (``mechanics.offset``)."""
        return self.mechanics.offset

    def to_dict(self, include_theta: bool = True) -> dict:
        """`Fit.to_dict`'s summary, the mechanics as ``settings["motion"]`` (the file's form)."""
        out = super().to_dict(include_theta)
        out["settings"] = {**out["settings"], "motion": self.mechanics.to_json()}
        return out

    def prediction_interval(self, data, level: float = DEFAULT_LEVEL, *, init_window: int = DEFAULT_INIT_WINDOW,
                            method=None, noise: bool = True):
        """``(x̂, low, high)`` [m]: the position band of a free run of a record (the
        ``simulate(data, init_window=N)`` run, whose positions ``x̂`` it returns):
        x̂ ± t √(j Σ jᵀ + σ_w² h hᵀ + s²), j = ∂x̂/∂θ along the run (``jax.jacfwd``, θ the
        fit's search coordinates, mass and offset included where identified), Σ the fit's
        box-capped covariance (``method``, default the fit's Newey–West), h = ∂x̂/∂x̃ the
        run's sensitivity to the ``init_window`` positions its initial state comes from and
        σ_w² their noise (the residual variance of the rule's polynomial), s² the variance of
        the fit's training position residuals (left out with ``noise=False``). docs/uncertainty.md;
        its coverage on new motion is measured in ``benchmarks/results/motion_band.md``
        (below the nominal level where the force offset drifts between records).
        ``ValueError`` for a fit without parameter uncertainty (a network), and with
        ``noise=True`` for one whose cost was not the free-run position (velocity, k-step)."""
        check_level(level)
        u = self._need_uncertainty()
        if noise and (self.mechanics.error not in (None, "position") or self.mechanics.horizon is not None):
            raise ValueError(f"this fit's residuals are {u.residual}, not free-run positions, so their variance "
                             "is not a position's: pass noise=False for the parameters' band alone")
        data, n = self._checked_record(data, init_window)
        st = self.initial_state(data.position[:n], n)
        layout, _ = search_layout(self)
        y = jnp.asarray(self.mechanics.y, jnp.asarray(self.theta).dtype)
        degree = min(INIT_DEGREE, n - 1)
        x_map, v_map = window_maps(n, self.dt, degree)
        window_dof = n - degree - 1
        window_var = float(np.sum((data.position[:n] - st["x_window"]) ** 2) / window_dof) if window_dof else 0.0
        positions = FreeRunPositions(step=self.friction_step(), layout=layout, mass=np.asarray(self.mass, np.float64),
                                     dt=np.asarray(self.dt, np.float64), force=np.asarray(data.net_force[n - 1:]),
                                     x_window=st["x_window"], v_window=st["v_window"], x_map=x_map, v_map=v_map)
        centre, half = position_band(positions, y, u.box_capped(method, level), window_var, u.t_quantile(level),
                                     u.s2 if noise else 0.0)
        return centre, centre - half, centre + half

    def predict(self, velocity, dt=None):
        """Friction [N] for a velocity record, the fitted constant offset included."""
        dt = self.dt if dt is None else dt
        if self.model.uses_dt and not same_sample_time(check_sample_time(dt), self.dt):
            return self.predict_at(np.arange(np.shape(velocity)[-1]) * dt, velocity)  # the offset added there
        return super().predict(velocity, dt) + self.offset

    def predict_at(self, t, velocity):
        """[`Fit.predict_at`][jaxfric.fit.Fit.predict_at]'s friction [N], the fitted constant offset included."""
        return super().predict_at(t, velocity) + self.offset

    def friction_step(self):
        """The per-sample [`jaxfric.motion.FrictionStep`][jaxfric.motion.FrictionStep] of this fit's model."""
        return friction_step(self.model, (self.velocity_scaler, self.friction_scaler))

    def simulate(self, force, x0=None, v0=None, dt=None, *, load=None, state0=None,
                 init_window: int | None = None) -> dict:
        """Free-run ``{"x", "v", "friction"}`` (float64 NumPy; ``friction`` includes the
        fitted offset).

        Two forms:

        * ``simulate(force, x0, v0)``: actuator force [N] (``load`` opposing +x
          subtracted) from position ``x0`` [m], velocity ``v0`` [m/s] and friction state
          ``state0`` (default ``step.init(v0)``);
        * ``simulate(record, init_window=N)``: a [`MotionData`][jaxfric.motion.MotionData] record whose initial
          state is estimated from its first ``N`` samples only, by the rule of
          [`initial_state`][jaxfric.motion.MotionFit.initial_state]; the outputs cover the whole record (samples before
          ``N - 1`` are the rule's smoothed estimates, the free run starts at ``N - 1``).
          The record's positions after sample ``N - 1`` and its filtered ``velocity``
          are never read for the run (the velocity only to warn, with an
          [`ExtrapolationWarning`][jaxfric.fit.ExtrapolationWarning], where the record moves outside
          the training velocity range,
          [`EXTRAPOLATION_SHARE`][jaxfric.motion.EXTRAPOLATION_SHARE]); its force is (it is the input).
        """
        if isinstance(force, MotionData):
            if init_window is None:
                raise ValueError("simulate(record) needs init_window=N: the number of leading "
                                 "samples the initial state is estimated from")
            return self._simulate_record(force, init_window)
        if x0 is None or v0 is None:
            raise ValueError("simulate(force, x0, v0): give the initial position and velocity, or pass "
                             "a MotionData record with init_window=N")
        if init_window is not None:
            raise ValueError("init_window applies to simulate(record, init_window=N), not to a force array")
        f = _series("force", force)
        if load is not None:
            f = f - _series("load", load)
        dt = self.dt if dt is None else float(dt)
        theta = jnp.asarray(self.theta)
        out = _simulate_jit(self.friction_step(), theta, jnp.asarray(self.mass, theta.dtype), jnp.asarray(f - self.offset, theta.dtype),
                            jnp.asarray(dt, theta.dtype), jnp.asarray(x0, theta.dtype), jnp.asarray(v0, theta.dtype), state0)
        res = {k: np.asarray(v, np.float64) for k, v in out.items()}
        res["friction"] = res["friction"] + self.offset
        return res

    def initial_state(self, position, init_window: int, dt: float | None = None) -> dict:
        """The initial-state rule (docs/motion.md): from ``position[:N]`` only.

        A polynomial of degree ``min(2, N - 1)`` is fitted by least squares to the first
        ``N`` positions; its value and slope at sample ``N - 1`` are ``x0`` and ``v0``,
        and the friction state is tracked along its slope over samples ``0 .. N - 1``
        ([`jaxfric.motion.track_states`][jaxfric.motion.track_states]), giving ``state0`` at sample ``N - 1``.
        Returns ``{"x0", "v0", "state0", "x_window", "v_window"}`` (the polynomial's
        values and slopes on the window). Reads nothing past ``position[N - 1]``.
        """
        n = _init_window(init_window)
        x = np.asarray(position, np.float64)
        if x.ndim != 1 or x.size < n:
            raise ValueError(f"init_window={n} needs at least {n} position samples, got {x.size}")
        x = x[:n]
        if not np.all(np.isfinite(x)):
            raise ValueError("the initial-state window holds NaN or inf positions")
        dt = self.dt if dt is None else float(dt)
        tau = (np.arange(n) - (n - 1)) * dt
        coef = np.polyfit(tau, x, min(INIT_DEGREE, n - 1))
        x_win = np.polyval(coef, tau)
        v_win = np.polyval(np.polyder(coef), tau)
        theta = jnp.asarray(self.theta)
        states = _track_jit(self.friction_step(), theta, jnp.asarray(v_win, theta.dtype), jnp.asarray(dt, theta.dtype))
        s0 = jax.tree_util.tree_map(lambda a: a[n - 1], states)
        return {"x0": float(x_win[-1]), "v0": float(v_win[-1]), "state0": s0, "x_window": x_win, "v_window": v_win}

    def _checked_record(self, data, init_window) -> tuple:
        """``(record, N)`` for a free run from the first ``N`` samples, or a ``ValueError``;
        warns where the record leaves the training velocity range."""
        data = _as_motion_data(data)
        if not same_sample_time(data.dt, self.dt):
            raise ValueError(f"the record's sample time {data.dt} s differs from the fit's {self.dt} s "
                             f"by more than {SAMPLE_TIME_RTOL:g} relative: resample it to the fit's rate")
        n = _init_window(init_window)
        if data.n_samples <= n:
            raise ValueError(f"init_window={n} leaves nothing to simulate in a record of {data.n_samples} samples")
        self._warn_new_motion(data.velocity)
        return data, n

    def _simulate_record(self, data, init_window) -> dict:
        data, n = self._checked_record(data, init_window)
        st = self.initial_state(data.position[:n], n)
        out = self.simulate(data.net_force[n - 1:], st["x0"], st["v0"], state0=st["state0"])
        head = n - 1
        # the window's friction without predict's per-sample range check: the record was checked above
        fr = (predict(self.model, self.theta, (self.velocity_scaler, self.friction_scaler), st["v_window"][:head],
                      self.dt) + self.offset) if head else np.zeros(0)
        return {"x": np.concatenate([st["x_window"][:head], out["x"]]),
                "v": np.concatenate([st["v_window"][:head], out["v"]]),
                "friction": np.concatenate([np.asarray(fr, np.float64), out["friction"]])}

    def _warn_new_motion(self, velocity) -> None:
        """`ExtrapolationWarning` where a record's motion leaves the training velocity range
        (faster, or in a direction the training record never moved): more than
        `EXTRAPOLATION_SHARE` of its samples beyond it by `EXTRAPOLATION_MARGIN` of its width."""
        if self.velocity_range is None:
            return
        lo, hi = self.velocity_range
        v = np.asarray(velocity, np.float64)
        pad = EXTRAPOLATION_MARGIN * (hi - lo)
        share = float(np.mean((v < lo - pad) | (v > hi + pad)))
        if share > EXTRAPOLATION_SHARE:
            warnings.warn(
                f"{share:.0%} of the record's velocity samples lie outside the training range "
                f"[{lo:.4g}, {hi:.4g}] m/s (this record: {v.min():.4g} to {v.max():.4g} m/s): the "
                f"{type(self.model).__name__} fit predicts velocities it was never trained on, where no "
                "judge of the training data can say how it predicts; compare with the least-squares "
                "baseline on this record (docs/motion.md)", ExtrapolationWarning, stacklevel=4)

    def simulate_from(self, data: MotionData, start: int = 0, stop: int | None = None) -> dict:
        """Free run over ``data[start:stop]`` from the state estimated at ``start``.

        Reads: the position ``data.position[start]``; the velocity
        ``data.velocity[start]`` (plus the fitted ``v0`` correction when ``start == 0``),
        which comes from a *zero-phase* low-pass of the whole record's position, so it
        depends on positions after ``start`` too; the friction state tracked along
        ``data.velocity[:start + 1]``; and the net force ``data[start:stop]``. This is
        the rule of the training cost and of the held-back block of a single-record
        fit. To start from a window of leading samples only (a benchmark's protocol),
        use ``simulate(record, init_window=N)``.
        """
        data = _as_motion_data(data)
        stop = data.n_samples if stop is None else stop
        step = self.friction_step()
        theta = jnp.asarray(self.theta)
        s0 = None
        if start > 0:
            states = _track_jit(step, theta, jnp.asarray(data.velocity[: start + 1], theta.dtype), jnp.asarray(self.dt, theta.dtype))
            s0 = jax.tree_util.tree_map(lambda a: a[start], states)
        v0 = data.velocity[start] + self.mechanics.v0 * (start == 0)
        return self.simulate(data.net_force[start:stop], data.position[start], v0, state0=s0)

    def score(self, data: MotionData, init_window: int = 20) -> dict:
        """[`motion_metrics`][jaxfric.motion.motion_metrics] of ``simulate(data, init_window=N)`` on samples ``N`` onward
        (a benchmark's protocol: the first ``N`` samples only set the initial state)."""
        data = _as_motion_data(data)
        n = _init_window(init_window)
        x_hat = self.simulate(data, init_window=n)["x"]
        return motion_metrics(data.position[n:], x_hat[n:])

    def k_step(self, data: MotionData, horizon: int = DEFAULT_METRIC_HORIZON) -> np.ndarray:
        """k-step-ahead positions x̂[j + k] for j = 0..T-k-1 (MATLAB ``compare(..., k)``)."""
        data = _as_motion_data(data)
        step = self.friction_step()
        theta = jnp.asarray(self.theta)
        return np.asarray(_kstep_jit(step, theta, jnp.asarray(self.mass, theta.dtype),
                                     jnp.asarray(data.net_force - self.offset, theta.dtype), jnp.asarray(self.dt, theta.dtype),
                                     jnp.asarray(data.position, theta.dtype),
                                     jnp.asarray(data.velocity, theta.dtype), int(horizon)), np.float64)

    def evaluate(self, data: MotionData, n_train: int, horizon: int = DEFAULT_METRIC_HORIZON) -> dict:
        """Free-run and k-step position metrics on ``[0, n_train)`` and ``[n_train, T)`` (an
        `ExtrapolationWarning` where the held-back part moves outside the training velocities)."""
        data = _as_motion_data(data)
        self._warn_new_motion(data.velocity[n_train:])
        x = data.position
        theta = jnp.asarray(self.theta)
        # simulate_from(data, 0, n_train), simulate_from(data, n_train) and k_step(data, horizon)
        # in one compiled call (one compilation instead of four)
        tr, va, ks = (np.asarray(a, np.float64) for a in _evaluate_jit(
            self.friction_step(), theta, jnp.asarray(self.mass, theta.dtype), jnp.asarray(data.net_force - self.offset, theta.dtype),
            jnp.asarray(self.dt, theta.dtype), jnp.asarray(x, theta.dtype), jnp.asarray(data.velocity, theta.dtype),
            data.velocity[0] + self.mechanics.v0, int(n_train), int(horizon)))
        out = {"train": motion_metrics(x[:n_train], tr), "valid": motion_metrics(x[n_train:], va),
               "horizon": int(horizon)}
        target = x[horizon:]
        cut = n_train - horizon
        out["train_kstep"] = motion_metrics(target[:cut], ks[:cut])
        out["valid_kstep"] = motion_metrics(target[cut:], ks[cut:])
        return out

    def evaluate_records(self, train_records, valid_records=(), init_window: int = DEFAULT_INIT_WINDOW) -> dict:
        """Free-run metrics per record: each training record from its first sample
        ([`simulate_from`][jaxfric.motion.MotionFit.simulate_from], as the training cost), each validation record from its
        first ``init_window`` samples ([`simulate`][jaxfric.motion.MotionFit.simulate] with ``init_window``), scored on
        the rest. ``"train"``/``"valid"`` pool the errors of all records of a kind;
        ``"records"`` lists each record's metrics."""
        runs = _record_runs([self], train_records, valid_records, init_window)
        return {"records": {k: [motion_metrics(*r) for r in rs] for k, rs in runs.items()},
                "init_window": int(init_window), **_pooled_metrics(runs)}

    def member(self, i: int) -> "MotionFit":
        """Ensemble member ``i`` (``identify_motion(..., keys=K)``) as a fit of its own."""
        self.ensemble_kept()  # a motion ensemble, or ValueError
        e = self.ensemble
        # the best member's uncertainty is not this member's: none
        return self.replace(
            theta=np.asarray(e["theta"][i], np.float64), ensemble=None, uncertainty=None,
            mechanics=self.mechanics.replace(mass=e["mass"][i], offset=e["offset"][i], v0=e["v0"][i]))

    def simulate_ensemble(self, record, init_window: int = DEFAULT_INIT_WINDOW) -> dict:
        """The kept ensemble members' free runs of ``record`` ([`simulate`][jaxfric.motion.MotionFit.simulate] with
        ``init_window``): ``{"x": their average, "lower", "upper": the elementwise min and
        max, "members": (K_kept, T)}`` [m]."""
        members = np.stack([self.member(i).simulate(record, init_window=init_window)["x"]
                            for i in self.ensemble_kept()])
        return {"x": members.mean(axis=0), "lower": members.min(axis=0), "upper": members.max(axis=0),
                "members": members}

    def ensemble_kept(self) -> list:
        """Indices of the members that predict together (the dropped ones left out)."""
        if not self.ensemble or "kept" not in self.ensemble:
            raise ValueError("this fit has no motion ensemble: identify_motion(..., keys=K) makes one")
        return list(self.ensemble["kept"])

    def ensemble_metrics(self, data, n_train, train_records=(), valid_records=(),
                         init_window: int = DEFAULT_INIT_WINDOW) -> dict:
        """[`motion_metrics`][jaxfric.motion.motion_metrics] of the kept members' average free run, on the windows
        of [`evaluate`][jaxfric.motion.MotionFit.evaluate] (``data`` given) or of [`evaluate_records`][jaxfric.motion.MotionFit.evaluate_records]."""
        fits = [self.member(i) for i in self.ensemble_kept()]
        if data is not None:
            x = data.position
            tr = np.mean([f.simulate_from(data, 0, n_train)["x"] for f in fits], axis=0)
            va = np.mean([f.simulate_from(data, n_train)["x"] for f in fits], axis=0)
            return {"train": motion_metrics(x[:n_train], tr), "valid": motion_metrics(x[n_train:], va)}
        return _pooled_metrics(_record_runs(fits, train_records, valid_records, init_window))

    def summary(self) -> str:
        lines = [f"{type(self.model).__name__} motion fit: {self.num_params} friction parameters, "
                 f"mass {self.mass:.4g} kg, offset {self.offset:.4g} N"]
        lines.append(f"{'window':<13}{'RMSE [mm]':>11}{'FIT %':>9}{'MAX [mm]':>10}")
        for w in ("train", "valid", "train_kstep", "valid_kstep"):
            m = self.metrics.get(w)
            if m:
                lines.append(f"{w:<13}{m['rmse_mm']:>11.4g}{m['fit_percent']:>9.2f}{m['max_abs_mm']:>10.4g}")
        if not self.model.needs_scaling:
            lines.append("params: " + ", ".join(f"{k}={float(v):.4g}" for k, v in self.params.items()))
        base = self.metrics.get("baseline")
        if base:
            lines.append("baseline (least squares Coulomb + viscous + offset): "
                         + ", ".join(f"{w} {base[w]['rmse_mm']:.4g} mm" for w in ("train", "valid") if w in base))
        ens = self.metrics.get("ensemble")
        if ens and self.ensemble:
            e = self.ensemble
            lines.append(f"ensemble: {len(e['train_rmse_mm'])} members (best #{e['best']}), average of "
                         f"{len(e['kept'])}: " + ", ".join(f"{w} {ens[w]['rmse_mm']:.4g} mm" for w in ("train", "valid")
                                                            if w in ens)
                         + (f"; dropped (training RMSE > {ENSEMBLE_DROP:g} x the best): {e['dropped']}"
                            if e["dropped"] else ""))
        lines += uncertainty_lines(self)
        return "\n".join(lines)

    def __repr__(self) -> str:
        m = self.metrics.get("valid") or {}
        tail = f", valid RMSE {m['rmse_mm']:.4g} mm" if "rmse_mm" in m else ""
        return f"MotionFit({type(self.model).__name__}, mass {self.mass:.4g} kg{tail})"


def _record_runs(fits, train_records, valid_records, init_window: int) -> dict:
    """``{"train": runs, "valid": runs}``, per record ``(measured positions, the fits' average
    free run)``: a training record from its first sample ([`MotionFit.simulate_from`][jaxfric.motion.MotionFit.simulate_from]),
    a validation record from its first ``init_window`` samples, scored on the rest."""
    def run(r, train):
        if train:
            return r.position, np.mean([f.simulate_from(r)["x"] for f in fits], axis=0)
        return r.position[init_window:], np.mean(
            [f.simulate(r, init_window=init_window)["x"][init_window:] for f in fits], axis=0)
    return {kind: [run(r, kind == "train") for r in map(_as_motion_data, recs)]
            for kind, recs in (("train", train_records), ("valid", valid_records))}


def _pooled_metrics(runs: dict) -> dict:
    """[`motion_metrics`][jaxfric.motion.motion_metrics] of each kind's records pooled (kinds with none left out)."""
    return {k: motion_metrics(*(np.concatenate(a) for a in zip(*rs))) for k, rs in runs.items() if rs}


class MotionProblem(AbstractProblem):
    """Friction identified inside the mechanics from force and position alone (§13.2): a
    [`MotionFit`][jaxfric.motion.MotionFit]'s search vector is its model's θ then the mechanics it
    identified, its residuals the simulated minus the measured positions (and/or velocities)
    over the training window, its score [`MotionFit.score`][jaxfric.motion.MotionFit.score] (headline: RMSE [mm]).
    ``data``: the [`MotionData`][jaxfric.motion.MotionData] (or ``(force, position, dt)``) the fit was
    trained on, its first ``fit.n_train`` samples (several training records concatenated)."""

    metric: ClassVar[str] = "rmse_mm"
    metric_label: ClassVar[str] = "free-run RMSE"
    metric_unit: ClassVar[str] = "mm"

    def coordinates(self, fit) -> SearchCoordinates:
        return motion_coordinates(fit)

    def training_records(self, fit, data) -> tuple:
        data = _as_motion_data(data)
        cuts = np.cumsum((0,) + (training_lengths(fit) or (fit.n_train,)))
        return tuple(data.window(int(a), int(b)) for a, b in zip(cuts[:-1], cuts[1:]))

    def residuals(self, fit, data) -> Residuals:
        return motion_residuals(fit, _as_motion_data(data))

    def train_velocity(self, fit, data) -> np.ndarray:
        return motion_train_velocity(fit, _as_motion_data(data))

    def score(self, fit, record) -> dict:
        return fit.score(record)


_simulate_jit = eqx.filter_jit(simulate_motion)
_track_jit = eqx.filter_jit(track_states)


@eqx.filter_jit
def _kstep_jit(step, theta, mass, force, dt, x, v, horizon):
    states = track_states(step, theta, v, dt)
    return k_step_positions(step, theta, mass, force, dt, x, v, states, horizon)


@eqx.filter_jit
def _evaluate_jit(step, theta, mass, force, dt, x, v, v0_train, n_train, horizon):
    """[`MotionFit.evaluate`][jaxfric.motion.MotionFit.evaluate]'s three simulations (``n_train``, ``horizon``: Python ints)."""
    states = track_states(step, theta, v, dt)
    train = simulate_motion(step, theta, mass, force[:n_train], dt, x[0], v0_train)["x"]
    s0 = jax.tree_util.tree_map(lambda a: a[n_train], states)
    valid = simulate_motion(step, theta, mass, force[n_train:], dt, x[n_train], v[n_train], s0)["x"]
    return train, valid, k_step_positions(step, theta, mass, force, dt, x, v, states, horizon)


def load_motion_fit(path) -> MotionFit:
    """Read a [`MotionFit`][jaxfric.motion.MotionFit] written by ``MotionFit.save``
    ([`MotionFit.load`][jaxfric.fit.Fit.load]; errors as [`jaxfric.load_fit`][jaxfric.fit.load_fit]'s, and a
    force-balance fit's file is refused)."""
    return MotionFit.load(path)


def _mass_setting(mass):
    if isinstance(mass, numbers.Real) and not isinstance(mass, bool):
        if not (np.isfinite(mass) and mass > 0):
            raise ValueError(f"mass must be positive and finite (kg), got {mass!r}")
        return float(mass), None
    try:
        lo, hi = (float(m) for m in mass)
    except (TypeError, ValueError):
        raise ValueError(f"mass must be a number (known, kg) or a (low, high) range to identify, "
                         f"got {mass!r}") from None
    if not (0 < lo < hi and np.isfinite(hi)):
        raise ValueError(f"mass range must satisfy 0 < low < high, got {(lo, hi)}")
    return float(np.sqrt(lo * hi)), (lo, hi)


def _as_record_list(name, value) -> list:
    items = list(value.values()) if isinstance(value, dict) else (list(value) if isinstance(value, list) else [value])
    if not items:
        raise ValueError(f"{name} must hold at least one record")
    out = []
    for i, item in enumerate(items):
        try:
            out.append(_as_motion_data(item))
        except ValueError as e:
            raise ValueError(f"{name}[{i}]: {e}") from None
    return out


def _records(data, train, valid):
    """``(train_records, valid_records, data, n_train)``: the records form (``data`` None,
    ``n_train`` None) or one record split by ``train`` (``valid`` must then be None)."""
    if data is not None:
        if valid is not None:
            raise ValueError("valid= goes with train=[records...]; with data, train is the split "
                             "(a fraction or a sample count)")
        if isinstance(train, (list, dict, MotionData)):
            raise ValueError("give either data (split by train=fraction) or train=[records...], not both")
        data = _as_motion_data(data)
        if not isinstance(train, bool) and isinstance(train, numbers.Real) and (
                train == 1.0 if isinstance(train, float) else train == data.n_samples):
            return [data], [], None, None  # the whole record trains; nothing is held back
        n_train = _split(data.n_samples, train)
        return [data.window(0, n_train)], [], data, n_train
    if train is None or isinstance(train, numbers.Real):
        raise ValueError("no data: pass a record (data, split by train=fraction) or train=[records...]")
    tr = _as_record_list("train", train)
    va = [] if valid is None else _as_record_list("valid", valid)
    dts = {r.dt for r in tr + va}
    if max(dts) - min(dts) > 1e-9 * max(dts):
        raise ValueError(f"every record must have the same sample time, got {sorted(dts)}")
    return tr, va, None, None


def _pooled(records, dtype, scalers, mass0, *, segment=None, lead=0, windows=None):
    """The shooting cost's data for ``records`` concatenated (see `ShootingResiduals`).
    ``windows=(length, total)``: short windows spread over the records instead (global stage)."""
    total = sum(r.n_samples for r in records)
    parts, starts, weights, at = [], [], [], 0
    for r in records:
        w = 1.0 / (max(float(np.var(r.position)), 1e-300) * total)
        if windows is None:
            parts.append((r.net_force, r.position, r.velocity))
            starts.append(at)
            weights.append(w)
            at += r.n_samples
            continue
        length, budget = windows
        count = max(1, int(budget * r.n_samples / total) // length)
        first = np.linspace(0, max(r.n_samples - length, 0), count).astype(int)
        for a in first:
            sl = slice(a, a + length)
            parts.append((r.net_force[sl], r.position[sl], r.velocity[sl]))
            starts.append(at)
            weights.append(w * total / (count * len(records) * min(length, r.n_samples)))
            at += min(length, r.n_samples - a)
    u, x, v = (np.concatenate([p[j] for p in parts]) for j in range(3))
    return {"force": jnp.asarray(u, dtype), "x": jnp.asarray(x, dtype), "v": jnp.asarray(v, dtype),
            "dt": jnp.asarray(records[0].dt, dtype), "mass": jnp.asarray(mass0, dtype),
            "scalers": jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), scalers),
            "plan": schedule(starts, at, segment=segment, lead=lead, weights=weights, dtype=dtype)}


def identify_motion(model, data=None, *, key=None, mass, train=0.8, valid=None,
                    solver: AbstractSolver | None = None, search: MotionSearch | None = None,
                    error: str = "position", horizon: int | None = None, fit_offset: bool = False,
                    fit_v0: bool = False, offset_range=None, box=None, data_bounds: bool = True, dtype=None,
                    model_options: dict | None = None, metric_horizon: int = DEFAULT_METRIC_HORIZON,
                    init_window: int = DEFAULT_INIT_WINDOW, max_evals: int | None = None,
                    max_time: float | None = None, progress=None, keys=None) -> MotionFit:
    """Identify friction inside ``m dv/dt = F_act - F_f - F_load`` from force and position (§13.2).

    Args:
        model: a jaxfric friction model or its name (as [`jaxfric.identify`][jaxfric.identification.identify]).
        data: one record, [`MotionData`][jaxfric.motion.MotionData] or ``(force [N], position [m], dt [s])``,
            split by ``train`` into a training and a held-back block. Leave it out to
            train on whole records (``train=[...]``).
        key: PRNG key or int seed. Same key, same fit.
        mass: known moving mass [kg], or a ``(low, high)`` range to identify it (log search).
        train: with ``data``: the training fraction or sample count (default 0.8; ``1.0`` or
            the record's length trains on the whole record, with no held-back block). Without:
            a record, a list or a mapping name -> record, each used whole for training
            (the cost pools them, each simulated from its own first sample).
        valid: with ``train=[...]``: a record or a list of records, each used whole for
            validation; its state is estimated from its first ``init_window`` samples
            ([`MotionFit.initial_state`][jaxfric.motion.MotionFit.initial_state]) and the rest is scored.
        search: the default pipeline's settings ([`MotionSearch`][jaxfric.motion.MotionSearch]: a short PSO on
            windows, then Levenberg–Marquardt on multiple-shooting segments; default
            [`jaxfric.motion.default_search`][jaxfric.motion.default_search] of the model; docs/motion.md). Ignored
            when ``solver`` is given.
        solver: a jaxfric solver to run instead, on the final cost (the pre-0.9 behaviour
            with [`jaxfric.identification.default_solver`][jaxfric.identification.default_solver]; slow on long records).
        error: ``"position"`` (default), ``"velocity"`` (against the filtered velocity)
            or ``"both"``; each term is a mean squared error / variance (1 - R^2).
            Velocity errors and ``horizon`` take one record (``data``).
        horizon: ``None`` = free-run simulation error (default); an int k = k-step-ahead
            position error from every measured state.
        fit_offset: add a constant force offset [N] to the friction (e.g. the EMPS
            reference model's offset); range ``offset_range`` (default +-0.25 of the
            95th percentile of |force|).
        fit_v0: identify a correction of each record's initial velocity (range +-0.05 max|v|).
        box: the friction model's search box, a partial mapping physical name ->
            (low, high) (a [`jaxfric.models.SearchBox`][jaxfric.models.SearchBox], as in [`jaxfric.identify`][jaxfric.identification.identify]).
        data_bounds: centre the box entries left out on the training data, using the
            filtered velocity and the net force as the friction scale ``F``; GMS's attraction
            rate ``C`` then starts at ``F`` per second ([`ATTRACTION_TIME_S`][jaxfric.motion.ATTRACTION_TIME_S]), not at the
            force-balance box's ``0.1 F``: slower attractions fit one record's drift
            (docs/motion.md).
        metric_horizon: k of the k-step metrics reported beside the free run (``data`` form).
        init_window: leading samples of each validation record that set its state.
        max_evals, max_time: a budget (cost evaluations, wall seconds) checked between
            stages and after every gradient step; the run then ends with the best point
            so far and ``fit.mechanics.stopped`` says why ([`MotionBudget`][jaxfric.motion.MotionBudget]).
        progress: ``True`` for progress bars (the global stage's, then one per
            Levenberg–Marquardt stage), or a callable sink (as [`jaxfric.minimise`][jaxfric.optim.minimise]).
        keys: an ensemble: ``K`` members (their keys ``jax.random.split(key, K)``) or a
            batch of keys (then no ``key``). Each member is ``identify_motion(...,
            key=keys[i])``; the fit returned is the member with the lowest training
            free-run RMSE, and ``fit.ensemble`` holds every member. Members whose
            training RMSE exceeds `ENSEMBLE_DROP` times the best are dropped
            and listed; the rest predict together: [`MotionFit.simulate_ensemble`][jaxfric.motion.MotionFit.simulate_ensemble]
            (their average and band) and ``metrics["ensemble"]`` (the average's metrics).

    Metrics ([`motion_metrics`][jaxfric.motion.motion_metrics], position in mm and FIT %): ``data`` form:
    ``"train"``, ``"valid"`` (free run of the held-back block from the state at its
    start, [`MotionFit.simulate_from`][jaxfric.motion.MotionFit.simulate_from]), ``"train_kstep"``, ``"valid_kstep"``;
    records form: ``"train"`` and ``"valid"`` pooled over the records and
    ``metrics["records"]`` per record.

    Elman networks work on scaled data (§2.4): the velocity scaler is fitted on the
    training records' filtered velocity; with no friction signal the friction scaler
    maps +-(95th percentile of |net force|) to +-1.

    Raises ``ValueError`` before any optimisation for bad data, split, mass, options.
    """
    options = {name: value for name, value in locals().items() if name not in ("model", "data", "key", "keys")}
    if keys is not None:
        return _ensemble(model, data, resolve_keys(key, keys).members, options)
    # a grey-box's physical fit: the same call, on the physical model (an instance: no model_options)
    physical_options = dict(options, data=data, key=key, model_options=None)
    with Stopwatch() as total:
        # Every check first, so bad input fails before any long computation.
        plan = _plan_stage(model, data, train=train, valid=valid, error=error, horizon=horizon,
                           metric_horizon=metric_horizon, init_window=init_window, max_evals=max_evals,
                           max_time=max_time, search=search, mass=mass, model_options=model_options, box=box,
                           data_bounds=data_bounds, solver=solver, key=key, dtype=dtype, fit_offset=fit_offset,
                           offset_range=offset_range, fit_v0=fit_v0)
        objective = _costs(plan.model, plan.layout, plan.search, plan.tr_records, plan.scalers, plan.mass0,
                           plan.dtype, error, horizon, plan.legacy_cost)
        est = least_squares(plan.tr_records, plan.mass0 if plan.mass_range is None else None)
        found = _search_stage(plan, objective, est, solver, progress, physical_options)
        fit = _fit_stage(plan, objective, found, solver)
        fit = _baseline_row(fit, plan, est)
        data = plan.data if plan.data is not None else _concatenated(plan.tr_records)
    fit = assess_fit(fit, data)  # plausibility now, parameter uncertainty on first use
    return fit.replace(timings={**fit.timings, "total_s": total.wall_s})


@dataclasses.dataclass(frozen=True)
class _MotionPlan:
    """What [`identify_motion`][jaxfric.motion.identify_motion] checked and set up before any optimisation:
    the records and their split, the model and its search settings, the box, the scalers,
    the keys, and the search vector's ``layout`` in ``[lower, upper]`` (`_search_vector`)."""

    model: object
    search: MotionSearch
    tr_records: list
    va_records: list
    data: MotionData | None
    n_train: int | None
    legacy_cost: bool
    metric_horizon: int
    init_window: int
    budget: MotionBudget
    mass0: float
    mass_range: tuple | None
    vt: np.ndarray
    box: object
    scalers: tuple
    run_keys: object
    dtype: object
    layout: Layout
    lower: np.ndarray
    upper: np.ndarray
    error: str
    horizon: int | None
    data_bounds: bool


def _plan_stage(model, data, *, train, valid, error, horizon, metric_horizon, init_window, max_evals, max_time,
                search, mass, model_options, box, data_bounds, solver, key, dtype, fit_offset, offset_range,
                fit_v0) -> _MotionPlan:
    """The records, options and search vector of [`identify_motion`][jaxfric.motion.identify_motion], checked
    in this order (a ``ValueError`` names the first problem, before any optimisation)."""
    tr_records, va_records, data, n_train = _records(data, train, valid)
    legacy_cost, metric_horizon, init_window = _checked_windows(
        data, n_train, va_records, error, horizon, metric_horizon, init_window)
    budget = MotionBudget(max_evals, max_time)
    budget.check()
    if search is not None and not isinstance(search, MotionSearch):
        raise ValueError(f"search must be a jaxfric.motion.MotionSearch, got {type(search).__name__}")
    mass0, mass_range = _mass_setting(mass)
    model = resolve_model(model, model_options)
    search = default_search(model) if search is None else search
    search.check()
    vt = np.concatenate([r.velocity for r in tr_records])
    ut = np.concatenate([r.net_force for r in tr_records])
    f_level = float(np.percentile(np.abs(ut), 95.0))
    if f_level <= 0 or max(np.ptp(r.position) for r in tr_records) <= 0:
        raise ValueError("the training data have no force or no motion: nothing to identify")
    box = _motion_box(model, box, vt, ut, data_bounds)
    scalers = ((Scaler.fit(vt), Scaler(lo=np.float64(-f_level), hi=np.float64(f_level)))
               if model.needs_scaling else (None, None))
    if solver is not None:
        check_solver(solver)
    run_keys = resolve_keys(key)
    dtype = search_dtype(dtype)
    layout, lower, upper = _search_vector(model, box, mass_range, fit_offset, offset_range, fit_v0, f_level, vt)
    return _MotionPlan(model, search, tr_records, va_records, data, n_train, legacy_cost, metric_horizon,
                       init_window, budget, mass0, mass_range, vt, box, scalers, run_keys, dtype, layout, lower,
                       upper, error, horizon, bool(data_bounds))


def _search_stage(plan: _MotionPlan, objective, est, solver, progress, physical_options) -> tuple:
    """``(y, stages, stopped, solution, stopwatch)``: the user's ``solver`` on the final cost,
    else the default search (`run_search`) from the swarm's starts, the least-squares start
    (with the slow-attraction grid, `MotionSearch.slow_starts`) and, for a grey-box, its
    physical model's fit."""
    residuals, cost, free, glob, stage_data, search = objective
    lower, upper, dtype = plan.lower, plan.upper, plan.dtype
    sol, stopped = None, None
    with Stopwatch() as sw:
        if solver is not None:
            sol, _ = global_search(cost, free, lower, upper, solver, plan.run_keys, dtype=dtype, progress=progress)
            y = np.asarray(sol.value)
            stages = solver_stages(sol, solver)
        else:
            extra, y0, before, grid = [], None, [], []
            if search.least_squares_start and not plan.legacy_cost:
                start = least_squares_start(plan.model, est, plan.vt, plan.box, plan.layout, lower, upper)
                extra = [] if start is None else [start]
                if search.slow_starts:
                    grid = slow_attraction_grid(plan.model, start, lower, upper)
            if isinstance(plan.model, GreyBox):  # from its physical model's fit, correction off
                y0, before = _greybox_start(plan.model, plan.box, lower, upper, physical_options)
            y, stages, stopped = run_search(search, plan.budget, residuals, cost, lower, upper,
                                            global_data=glob, stage_data=stage_data,
                                            key=plan.run_keys.key, dtype=dtype, progress=progress,
                                            y0=y0, extra_starts=extra, grid_starts=grid)
            stages = before + stages
    return np.asarray(y, np.float64), stages, stopped, sol, sw


def _fit_stage(plan: _MotionPlan, objective, found, solver) -> MotionFit:
    """The [`MotionFit`][jaxfric.motion.MotionFit] at the search's end ``found``, with its metrics
    (`_scored`) and training cost."""
    residuals, cost, free = objective[:3]
    y, stages, stopped, sol, sw = found
    model, tr_records, dtype = plan.model, plan.tr_records, plan.dtype
    j_final = _training_cost(residuals, cost, y, plan.lower, plan.upper, free, dtype,
                             plan.legacy_cost or solver is not None)
    theta, m_hat, off, dv0 = (np.asarray(a) for a in plan.layout.unpack(jnp.asarray(y, dtype), free))
    key_data, key_impl = key_record(plan.run_keys.key)
    n_tr_total = sum(r.n_samples for r in tr_records)
    n_all = (plan.data.n_samples if plan.data is not None
             else n_tr_total + sum(r.n_samples for r in plan.va_records))
    fit = MotionFit(
        model=model, theta=theta, velocity_scaler=plan.scalers[0], friction_scaler=plan.scalers[1],
        dt=tr_records[0].dt, n_train=n_tr_total, n_samples=n_all, metrics={}, stages=stages,
        velocity_range=(float(plan.vt.min()), float(plan.vt.max())),
        history=history(sol), solution=sol, key_data=key_data, key_impl=key_impl, seed=plan.run_keys.seed,
        timings={"compile_s": sw.compile_s, "run_s": sw.run_s}, box=plan.box,
        settings={
            "model_name": model_name(model), "model_config": model_config(model),
            "solver": repr(solver) if solver is not None else repr(plan.search),
            "dtype": str(np.dtype(dtype)), "data_bounds": plan.data_bounds,
        },
        mechanics=Mechanics(
            mass=m_hat, mass_range=plan.mass_range, offset=off, v0=dv0, error=plan.error, horizon=plan.horizon,
            cutoff=tr_records[0].cutoff, search_names=list(model.param_names) + list(plan.layout.names()),
            search_bounds=[plan.lower.tolist(), plan.upper.tolist()], y=[float(a) for a in y], stopped=stopped,
            starts=start_costs(stages) if solver is None else [],
            records=None if plan.data is not None else
            {"train": [r.n_samples for r in tr_records], "valid": [r.n_samples for r in plan.va_records]},
            init_window=plan.init_window),
    )
    # the fit above only simulates for its metrics; the one returned carries them
    return fit.replace(metrics={**_scored(fit, *_scoring(plan)), "num_params": int(y.size), "cost": j_final})


def _scoring(plan: _MotionPlan) -> tuple:
    """`_scored`'s arguments after the fit, from ``plan``."""
    return plan.data, plan.n_train, plan.metric_horizon, plan.tr_records, plan.va_records, plan.init_window


def _baseline_row(fit: MotionFit, plan: _MotionPlan, est) -> MotionFit:
    """``fit`` with the least-squares baseline ``est`` (`baseline_motion_fit`) scored the same
    way beside it, and its warning where the fit is worse on training
    ([`jaxfric.pipeline.baseline_stage`][jaxfric.pipeline.baseline_stage])."""
    base = baseline_motion_fit(est.M, est.Fc, est.Fv, est.offset, dt=plan.tr_records[0].dt, n_train=fit.n_train)
    base = base.replace(metrics=_scored(base, *_scoring(plan)))
    fit = fit.replace(mechanics=fit.mechanics.replace(
        baseline={"M": est.M, "Fc": est.Fc, "Fv": est.Fv, "offset": est.offset}))
    return baseline_stage(fit, base.metrics, label=BASELINE_LABEL, advice=BASELINE_ADVICE, stacklevel=3)


#: The slowest attraction a motion fit's data-centred box allows [s]: GMS's attraction rate
#: ``C`` starts at ``F / ATTRACTION_TIME_S`` (``F`` the friction scale of
#: [`jaxfric.models.friction_scales`][jaxfric.models.friction_scales]) instead of the force-balance
#: box's ``0.1 F`` per second (10 s).
ATTRACTION_TIME_S = 1.0


def _motion_box(model, box, vt, ut, data_bounds: bool) -> SearchBox:
    """``model.search_box`` of the training data (``data_bounds``), with the attraction rate
    ``C`` (GMS) bounded below by ``F / ATTRACTION_TIME_S`` unless the caller's ``box`` gives
    ``C``. In a free run an attraction of seconds is a slow memory that follows one record's
    drift (measured: docs/motion.md, "Deeper on training, worse on new motion")."""
    full = model.search_box(box, *((vt, ut) if data_bounds else ()))
    if not data_bounds or not isinstance(full, SearchBox) or "C" not in full or (box is not None and "C" in box):
        return full  # a network has no box (None); no attraction rate; or the caller's C
    f = float(friction_scales(vt, ut)[0])
    lo, hi = full["C"]
    return SearchBox({**full, "C": (max(lo, f / ATTRACTION_TIME_S), hi)})


def _search_vector(model, box, mass_range, fit_offset, offset_range, fit_v0, f_level, vt):
    """``(layout, lower, upper)`` of [`identify_motion`][jaxfric.motion.identify_motion]'s search vector: θ, then
    the mechanics identified (`._layout`): ``log10`` of the mass in ``mass_range``, the
    offset in ``offset_range`` (default ±0.25 ``f_level``, the 95th percentile of
    |net force|), the initial-velocity correction in ±0.05 max|``vt``|."""
    layout = Layout(model.num_params, mass_range is not None, bool(fit_offset), bool(fit_v0))
    rows = list(zip(*model.bounds(box)))
    if mass_range is not None:
        rows.append((np.log10(mass_range[0]), np.log10(mass_range[1])))
    if fit_offset:
        rows.append((-0.25 * f_level, 0.25 * f_level) if offset_range is None else offset_range)
    if fit_v0:
        vmax = 0.05 * float(np.max(np.abs(vt)))
        rows.append((-vmax, vmax))
    lower, upper = (np.asarray(b, np.float64) for b in zip(*rows))
    return layout, lower, upper


def _checked_windows(data, n_train, va_records, error, horizon, metric_horizon, init_window):
    """``(legacy_cost, metric_horizon, init_window)`` of [`identify_motion`][jaxfric.motion.identify_motion],
    checked: the cost is the legacy one-record cost for a k-step ``horizon`` or a velocity
    ``error``; a short held-back block gets a shorter metric horizon."""
    if error not in ERRORS:
        raise ValueError(f"error must be one of {ERRORS}, got {error!r}")
    legacy_cost = horizon is not None or error != "position"
    if legacy_cost and data is None:
        raise ValueError("k-step (horizon) and velocity costs take one record with a held-back block: "
                         "pass data and a train fraction below 1")
    if horizon is not None:
        check_int("horizon", horizon, 1, n_train - 1, " (or None: the free run)")
        if error != "position":
            raise ValueError("k-step costs use the position error only: pass error='position'")
    metric_horizon = check_int("metric_horizon", metric_horizon)
    if data is not None:
        metric_horizon = min(metric_horizon, data.n_samples - n_train - 1)
    init_window = _init_window(init_window)
    for i, r in enumerate(va_records):
        if r.n_samples <= init_window:
            raise ValueError(f"valid[{i}] has {r.n_samples} samples, not more than init_window={init_window}")
    return legacy_cost, metric_horizon, init_window


def _costs(model, layout, search, tr_records, scalers, mass0, dtype, error, horizon, legacy: bool):
    """``(residuals, cost, free, glob, stage_data, search)`` of a motion search: the
    multiple-shooting residuals of the training records (the default), or one free-run or
    k-step cost of one record (``legacy``: a k-step ``horizon`` or a velocity ``error``, one
    Levenberg–Marquardt stage on it). ``free``: the training data; ``glob``: the global
    stage's; ``stage_data(h)``: a shooting stage's for segments of ``h`` samples."""
    if legacy:
        x_tr, v_tr = tr_records[0].position, tr_records[0].velocity
        free = {"force": jnp.asarray(tr_records[0].net_force, dtype), "x": jnp.asarray(x_tr, dtype),
                "v": jnp.asarray(v_tr, dtype), "dt": jnp.asarray(tr_records[0].dt, dtype),
                "mass": jnp.asarray(mass0, dtype), "inv_var_x": jnp.asarray(1.0 / np.var(x_tr), dtype),
                "inv_var_v": jnp.asarray(1.0 / max(np.var(v_tr), 1e-300), dtype),
                "scalers": jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), scalers)}
        cost = MotionCost(model, layout, error, None if horizon is None else int(horizon))
        search = MotionSearch(search.particles, search.generations, search.global_window, search.lead,
                              (None,), (sum(search.steps),), search.rtol)
        # Levenberg–Marquardt needs the terms of J, not J itself
        return cost.residuals, cost, free, free, lambda h: free, search
    residuals = ShootingResiduals(model, layout)
    free = _pooled(tr_records, dtype, scalers, mass0)
    glob = _pooled(tr_records, dtype, scalers, mass0, lead=search.lead,
                   windows=(search.lead + search.global_window, GLOBAL_SAMPLES))

    def stage_data(h):
        return free if h is None else _pooled(tr_records, dtype, scalers, mass0, segment=h, lead=search.lead)
    return residuals, SumOfSquares(residuals), free, glob, stage_data, search


def _ensemble(model, data, members, options) -> MotionFit:
    """``identify_motion(..., keys=K)``: every member in turn (same shapes: compiled once);
    the best member and those kept by their training free-run RMSE
    ([`jaxfric.pipeline.best_member`][jaxfric.pipeline.best_member], [`kept_members`][jaxfric.pipeline.kept_members])."""
    count = int(members.shape[0])
    with Stopwatch() as total:
        fits = [identify_motion(model, data, key=members[i], **options) for i in range(count)]
        train = np.array([f.metrics["train"]["rmse_mm"] for f in fits])
        best = best_member(train)
        kept = kept_members(train)
        fit = fits[best].replace(ensemble={
            "theta": np.stack([f.theta for f in fits]), "mass": [f.mass for f in fits],
            "offset": [f.offset for f in fits], "v0": [f.mechanics.v0 for f in fits],
            "train_rmse_mm": train.tolist(),
            "valid_rmse_mm": [f.metrics["valid"]["rmse_mm"] if "valid" in f.metrics else None for f in fits],
            "best": best, "kept": kept, "dropped": [i for i in range(count) if i not in kept],
            "keys": [key_record(members[i])[0] for i in range(count)],
        })
        tr_records, va_records, whole, n_train = _records(data, options["train"], options["valid"])
        metrics = {**fit.metrics, "ensemble": fit.ensemble_metrics(whole, n_train, tr_records, va_records)}
    return fit.replace(metrics=metrics, timings={**fit.timings, "members_s": [f.timings["total_s"] for f in fits],
                                                 "total_s": total.wall_s})


def baseline_motion_fit(M: float, Fc: float, Fv: float, offset: float, *, dt: float,
                        n_train: int = 0) -> MotionFit:
    """The least-squares Coulomb + viscous + offset baseline (mass ``M`` [kg], ``Fc`` [N],
    ``Fv`` [N s/m], ``offset`` [N]; `._baseline.least_squares`) as a fit of its own
    ([`MotionFit.given`][jaxfric.motion.MotionFit.given]), with the smoothing of
    `._baseline.baseline_model`; a negative ``Fc`` or ``Fv`` is held at its model's floor."""
    return MotionFit.given(baseline_model(), dict(Fc=max(Fc, 0.0), sigma2=max(Fv, 1e-12)), mass=M, offset=offset,
                           dt=dt, n_train=n_train, settings={"model_name": "coulomb"})


def _greybox_start(model: GreyBox, box, lower, upper, options: dict):
    """``(y0, stages)``: a [`GreyBox`][jaxfric.models.GreyBox] search starts from its physical
    model's own ``identify_motion`` fit (same data, key and mechanics; the physical entries
    of ``box``) with the network's output weights at zero, where the grey-box *is* that fit;
    ``stages`` is one row for the physical fit, put before the grey-box's own."""
    phys = model.physical
    fit = identify_motion(phys, **{**options, "box": {k: box[k] for k in phys.box_keys}})
    y = np.asarray(fit.mechanics.y, np.float64)
    y0 = np.concatenate([y[:phys.num_params], model.network_start(box), y[phys.num_params:]])
    row = {"stage": f"physical {type(phys).__name__} fit", "start": None, "J": fit.metrics["cost"],
           "num_evals": int(sum(s.get("num_evals", 0) for s in fit.stages or [])),
           "num_steps": 0, "seconds": fit.timings.get("total_s"), "reason": "done"}
    return np.clip(y0, lower, upper), [row]


def _scored(fit, data, n_train, metric_horizon, tr_records, va_records, init_window) -> dict:
    """The metrics of ``fit`` ([`MotionFit.evaluate`][jaxfric.motion.MotionFit.evaluate] of the one record ``data``,
    else [`MotionFit.evaluate_records`][jaxfric.motion.MotionFit.evaluate_records])."""
    if data is not None:
        return fit.evaluate(data, n_train, int(metric_horizon))
    return fit.evaluate_records(tr_records, va_records, init_window)


#: What a fit worse than the baseline should try ([`jaxfric.pipeline.warn_if_worse`][jaxfric.pipeline.warn_if_worse]).
BASELINE_ADVICE = ("the search did not reach its optimum or the model cannot express the baseline: use the "
                   "baseline, another key or more starts (MotionSearch(starts=...))")


def _training_cost(residuals, cost, y, lower, upper, free, dtype, scalar: bool) -> float:
    """J of the free run at ``y``. After the default search this reuses the residual
    function Levenberg–Marquardt compiled (same shapes), instead of compiling the cost again."""
    if scalar:
        return float(eqx.filter_jit(cost)(jnp.asarray(y, dtype), free))
    lo, hi = jnp.asarray(lower, dtype), jnp.asarray(upper, dtype)
    z = from_box(jnp.asarray(y, dtype), lo, hi, 0.0)
    r = np.asarray(_res_jit(z, (residuals, lo, hi, free)), np.float64)
    return float(r @ r) if np.all(np.isfinite(r)) else float("inf")


def _concatenated(records) -> MotionData:
    """The training records end to end (for the plausibility check, which reads velocities)."""
    return dataclasses.replace(records[0], **{k: np.concatenate([getattr(r, k) for r in records]) for k in _CHANNELS})
