"""``jaxfric.identify_motion``: friction from actuator force and position alone (§13.2).

No friction signal and no acceleration: the friction model sits inside the mechanics
(:func:`jaxfric.motion.simulate_motion`) and its parameters (optionally the mass, a
constant force offset and the initial velocity) are chosen so that the *simulated*
position (and/or velocity) matches the measured one, by the same optimisers as
:func:`jaxfric.identify`.

Closed-loop records drift in open-loop simulation (a double integrator with an
uncertain force balance): the validation metrics therefore start the free run from
the state estimated at the start of the validation window (measured position,
low-pass-differentiated velocity, friction state tracked along that velocity), and
report k-step-ahead errors (MATLAB ``compare(..., k)``) beside the free run.
"""

from __future__ import annotations

import dataclasses
import numbers

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from ..fit import Fit, load_fit, model_config, model_name, uncertainty_lines
from ..identification._api import _as_key, _history, _key_record, _stages, default_solver, resolve_model
from ..identification._objective import search_dtype
from ..identification._timing import Stopwatch
from ..metrics import friction_metrics
from ..models import Scaler
from ..optim import AbstractSolver, minimise
from ..records import DEFAULT_TRAIN_FRACTION, as_channel, check_sample_time, split_count
from ..uncertainty import assess_fit
from ._forward import k_step_positions, simulate_motion, track_states
from ._step import friction_step

__all__ = ["MotionData", "MotionFit", "identify_motion", "load_motion_fit", "motion_metrics"]

#: k of the k-step-ahead metrics when none is asked for: 10 samples.
DEFAULT_METRIC_HORIZON = 10
ERRORS = ("position", "velocity", "both")


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
        from ..rig.pipeline import differentiate, lowpass

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

    @property
    def n_samples(self) -> int:
        return int(self.force.size)


def _as_motion_data(data) -> MotionData:
    if isinstance(data, MotionData):
        return data
    if isinstance(data, tuple) and len(data) == 3:
        return MotionData.from_arrays(*data)
    raise ValueError("data must be a MotionData or a tuple (force [N], position [m], dt [s])")


def _split(n: int, train) -> int:
    """The records' split rule (:func:`jaxfric.records.split_count`); the mechanics need
    two samples on each side of it to start a free run from."""
    count = split_count(n, DEFAULT_TRAIN_FRACTION if train is None else train, whole=False)
    if not 2 <= count <= n - 2:
        raise ValueError(f"train must be a fraction or a sample count in [2, {n - 2}], got {train!r}")
    return count


class Layout(eqx.Module):
    """Where the mechanics' unknowns sit after the friction parameters in the search vector."""

    n_friction: int = eqx.field(static=True)
    fit_mass: bool = eqx.field(static=True)
    fit_offset: bool = eqx.field(static=True)
    fit_v0: bool = eqx.field(static=True)

    def unpack(self, y, args):
        i = self.n_friction
        theta = y[:i]
        mass, offset, dv0 = args["mass"], jnp.zeros((), y.dtype), jnp.zeros((), y.dtype)
        if self.fit_mass:
            mass, i = 10.0 ** y[i], i + 1
        if self.fit_offset:
            offset, i = y[i], i + 1
        if self.fit_v0:
            dv0 = y[i]
        return theta, mass, offset, dv0

    def names(self):
        return (("log10_mass",) if self.fit_mass else ()) + (("offset",) if self.fit_offset else ()) \
            + (("v0",) if self.fit_v0 else ())


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
        u = args["force"] - offset
        if self.horizon is None:
            out = simulate_motion(step, theta, mass, u, args["dt"], args["x"][0], args["v"][0] + dv0)
            return out["x"], out["v"], args["x"], args["v"]
        states = track_states(step, theta, args["v"], args["dt"])
        x_hat = k_step_positions(step, theta, mass, u, args["dt"], args["x"], args["v"], states,
                                 self.horizon)
        return x_hat, None, args["x"][self.horizon:], None

    def __call__(self, y, args):
        x_hat, v_hat, x, v = self.simulate(y, args)
        j = 0.0
        if self.error in ("position", "both"):
            j = j + jnp.mean((x_hat - x) ** 2) * args["inv_var_x"]
        if self.error in ("velocity", "both") and v_hat is not None:
            j = j + jnp.mean((v_hat - v) ** 2) * args["inv_var_v"]
        return j


def motion_metrics(x, x_hat) -> dict:
    """Position metrics: ``rmse_mm`` (RMSE in mm), ``fit_percent`` (MATLAB FIT %),
    ``max_abs_mm``, plus the rest of :func:`jaxfric.metrics.friction_metrics` in metres."""
    x_hat = np.asarray(x_hat, np.float64)
    if not np.all(np.isfinite(x_hat)):
        return {"rmse_mm": float("inf"), "fit_percent": float("-inf"), "max_abs_mm": float("inf"),
                "finite": False}
    m = friction_metrics(np.asarray(x, np.float64), x_hat)
    m.update(rmse_mm=1e3 * m["rmse"], max_abs_mm=1e3 * m["max_abs"])
    return m


class MotionFit(Fit):
    """A friction model identified inside the mechanics (:func:`identify_motion`).

    Everything of :class:`jaxfric.Fit` (``predict`` gives the friction [N] for a
    velocity record, offset included; ``params``; ``save``; ``to_numpy``), plus the mechanics: ``mass`` [kg],
    ``offset`` [N] (a constant force added to the friction, 0 unless fitted),
    ``v0`` correction [m/s], the velocity filter ``cutoff`` [Hz], and :meth:`simulate`.
    ``metrics`` holds position metrics per window (``"train"``, ``"valid"``: free run;
    ``"train_kstep"``, ``"valid_kstep"``: k-step-ahead), see :func:`motion_metrics`.
    """

    @property
    def mechanics(self) -> dict:
        return self.settings["motion"]

    @property
    def mass(self) -> float:
        return float(self.mechanics["mass"])

    @property
    def offset(self) -> float:
        return float(self.mechanics["offset"])

    def predict(self, velocity, dt=None):
        """Friction [N] for a velocity record, the fitted constant offset included."""
        return super().predict(velocity, dt) + self.offset

    def friction_step(self):
        """The per-sample :class:`jaxfric.motion.FrictionStep` of this fit's model."""
        return friction_step(self.model, (self.velocity_scaler, self.friction_scaler))

    def simulate(self, force, x0, v0, dt=None, *, load=None, state0=None) -> dict:
        """Free-run ``{"x", "v", "friction"}`` for actuator force [N] (``load`` opposing
        +x subtracted) from position ``x0`` [m] and velocity ``v0`` [m/s]; ``friction``
        includes the fitted offset. Float64 NumPy."""
        f = _series("force", force)
        if load is not None:
            f = f - _series("load", load)
        dt = self.dt if dt is None else float(dt)
        theta = jnp.asarray(self.theta)
        out = _simulate_jit(self.friction_step(), theta, self.mass, jnp.asarray(f - self.offset, theta.dtype),
                            dt, x0, v0, state0)
        res = {k: np.asarray(v, np.float64) for k, v in out.items()}
        res["friction"] = res["friction"] + self.offset
        return res

    def simulate_from(self, data: MotionData, start: int = 0, stop: int | None = None) -> dict:
        """Free run over ``data[start:stop]`` from the state estimated at ``start``
        (measured position, filtered velocity, friction state tracked along it)."""
        data = _as_motion_data(data)
        stop = data.n_samples if stop is None else stop
        step = self.friction_step()
        theta = jnp.asarray(self.theta)
        s0 = None
        if start > 0:
            states = _track_jit(step, theta, jnp.asarray(data.velocity[: start + 1], theta.dtype), self.dt)
            s0 = jax.tree_util.tree_map(lambda a: a[start], states)
        v0 = data.velocity[start] + self.mechanics.get("v0", 0.0) * (start == 0)
        return self.simulate(data.net_force[start:stop], data.position[start], v0, state0=s0)

    def k_step(self, data: MotionData, horizon: int = DEFAULT_METRIC_HORIZON) -> np.ndarray:
        """k-step-ahead positions x̂[j + k] for j = 0..T-k-1 (MATLAB ``compare(..., k)``)."""
        data = _as_motion_data(data)
        step = self.friction_step()
        theta = jnp.asarray(self.theta)
        return np.asarray(_kstep_jit(step, theta, self.mass,
                                     jnp.asarray(data.net_force - self.offset, theta.dtype), self.dt,
                                     jnp.asarray(data.position, theta.dtype),
                                     jnp.asarray(data.velocity, theta.dtype), int(horizon)), np.float64)

    def evaluate(self, data: MotionData, n_train: int, horizon: int = DEFAULT_METRIC_HORIZON) -> dict:
        """Free-run and k-step position metrics on ``[0, n_train)`` and ``[n_train, T)``."""
        data = _as_motion_data(data)
        x = data.position
        tr = self.simulate_from(data, 0, n_train)["x"]
        va = self.simulate_from(data, n_train)["x"]
        ks = self.k_step(data, horizon)
        out = {"train": motion_metrics(x[:n_train], tr), "valid": motion_metrics(x[n_train:], va),
               "horizon": int(horizon)}
        target = x[horizon:]
        cut = n_train - horizon
        out["train_kstep"] = motion_metrics(target[:cut], ks[:cut])
        out["valid_kstep"] = motion_metrics(target[cut:], ks[cut:])
        return out

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
        lines += uncertainty_lines(self)
        return "\n".join(lines)

    def __repr__(self) -> str:
        m = self.metrics.get("valid") or {}
        tail = f", valid RMSE {m['rmse_mm']:.4g} mm" if "rmse_mm" in m else ""
        return f"MotionFit({type(self.model).__name__}, mass {self.mass:.4g} kg{tail})"


_simulate_jit = eqx.filter_jit(simulate_motion)
_track_jit = eqx.filter_jit(track_states)


@eqx.filter_jit
def _kstep_jit(step, theta, mass, force, dt, x, v, horizon):
    states = track_states(step, theta, v, dt)
    return k_step_positions(step, theta, mass, force, dt, x, v, states, horizon)


def load_motion_fit(path) -> MotionFit:
    """Read a :class:`MotionFit` written by ``MotionFit.save``."""
    fit = load_fit(path)
    if "motion" not in fit.settings:
        raise ValueError(f"{path} holds a force-balance fit, not a motion fit: use jaxfric.load_fit")
    out = MotionFit.__new__(MotionFit)
    out.__dict__.update(fit.__dict__)
    return out


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


def identify_motion(
    model,
    data,
    *,
    key,
    mass,
    train=0.8,
    solver: AbstractSolver | None = None,
    error: str = "position",
    horizon: int | None = None,
    fit_offset: bool = False,
    fit_v0: bool = False,
    offset_range=None,
    box=None,
    data_bounds: bool = True,
    dtype=None,
    model_options: dict | None = None,
    metric_horizon: int = DEFAULT_METRIC_HORIZON,
    progress=None,
) -> MotionFit:
    """Identify friction inside ``m dv/dt = F_act - F_f - F_load`` from force and position (§13.2).

    Args:
        model: a jaxfric friction model or its name (as :func:`jaxfric.identify`).
        data: :class:`MotionData` or ``(force [N], position [m], dt [s])``.
        key: PRNG key or int seed. Same key, same fit.
        mass: known moving mass [kg], or a ``(low, high)`` range to identify it (log search).
        train: training fraction or sample count (default 0.8); the rest is validation.
        solver: default :func:`jaxfric.identification.default_solver` (MAPSO-NMDS).
        error: ``"position"`` (default), ``"velocity"`` (against the filtered velocity)
            or ``"both"``; each term is a mean squared error / variance (1 - R^2).
        horizon: ``None`` = free-run simulation error over the training window (default);
            an int k = k-step-ahead position error from every measured state.
        fit_offset: add a constant force offset [N] to the friction (e.g. the EMPS
            reference model's offset); range ``offset_range`` (default +-0.25 of the
            95th percentile of |force|).
        fit_v0: identify a correction of the initial velocity (range +-0.05 max|v|).
        box: the friction model's search box, a partial mapping physical name ->
            (low, high) (a :class:`jaxfric.models.SearchBox`, as in :func:`jaxfric.identify`).
        data_bounds: centre the box entries left out on the record, using the
            filtered velocity and the net force as the friction scale.
        metric_horizon: k of the k-step metrics reported beside the free run.

    Elman networks work on scaled data (§2.4): the velocity scaler is fitted on the
    training window's filtered velocity; with no friction signal the friction scaler
    maps +-(95th percentile of |net force|) to +-1.

    Raises ``ValueError`` before any optimisation for bad data, split, mass, options.
    """
    with Stopwatch() as total:
        data = _as_motion_data(data)
        n = data.n_samples
        n_train = _split(n, train)
        if error not in ERRORS:
            raise ValueError(f"error must be one of {ERRORS}, got {error!r}")
        if horizon is not None and (isinstance(horizon, bool) or not isinstance(horizon, numbers.Integral)
                                    or not 1 <= horizon < n_train):
            raise ValueError(f"horizon must be None (free run) or an int in [1, {n_train - 1}], got {horizon!r}")
        if horizon is not None and error != "position":
            raise ValueError("k-step costs use the position error only: pass error='position'")
        if not 1 <= int(metric_horizon) < n - n_train:
            raise ValueError(f"metric_horizon must lie in [1, {n - n_train - 1}], got {metric_horizon!r}")
        mass0, mass_range = _mass_setting(mass)
        model = resolve_model(model, model_options)
        u = data.net_force
        vt, ut = data.velocity[:n_train], u[:n_train]
        f_level = float(np.percentile(np.abs(ut), 95.0))
        if f_level <= 0 or np.ptp(data.position[:n_train]) <= 0:
            raise ValueError("the training window has no force or no motion: nothing to identify")
        box = model.search_box(box, *((vt, ut) if data_bounds else ()))
        scalers = (None, None)
        if model.needs_scaling:
            scalers = (Scaler.fit(vt), Scaler(lo=np.float64(-f_level), hi=np.float64(f_level)))
        if solver is None:
            solver = default_solver(model)
        if not isinstance(solver, AbstractSolver):
            raise ValueError(f"solver must be a jaxfric solver, got {type(solver).__name__}")
        solver.check()
        key, seed = _as_key(key)
        dtype = search_dtype(dtype)

        layout = Layout(model.num_params, mass_range is not None, bool(fit_offset), bool(fit_v0))
        lower, upper = (list(b) for b in model.bounds(box))
        if mass_range is not None:
            lower.append(np.log10(mass_range[0]))
            upper.append(np.log10(mass_range[1]))
        if fit_offset:
            lo, hi = (-0.25 * f_level, 0.25 * f_level) if offset_range is None else offset_range
            lower.append(float(lo))
            upper.append(float(hi))
        if fit_v0:
            vmax = 0.05 * float(np.max(np.abs(vt)))
            lower.append(-vmax)
            upper.append(vmax)
        lower, upper = np.asarray(lower, np.float64), np.asarray(upper, np.float64)

        x_tr = data.position[:n_train]
        args = {
            "force": jnp.asarray(ut, dtype), "x": jnp.asarray(x_tr, dtype),
            "v": jnp.asarray(vt, dtype), "dt": jnp.asarray(data.dt, dtype),
            "mass": jnp.asarray(mass0, dtype),
            "inv_var_x": jnp.asarray(1.0 / np.var(x_tr), dtype),
            "inv_var_v": jnp.asarray(1.0 / max(np.var(vt), 1e-300), dtype),
            "scalers": jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), scalers),
        }
        cost = MotionCost(model, layout, error, None if horizon is None else int(horizon))
        with Stopwatch() as sw:
            sol = jax.block_until_ready(minimise(cost, solver, (lower, upper), args=args, key=key,
                                                 dtype=dtype, progress=progress))
        y = np.asarray(sol.value)
        theta, m_hat, off, dv0 = (np.asarray(a) for a in layout.unpack(jnp.asarray(y), args))
        key_data, key_impl = _key_record(key)
        fit = MotionFit(
            model=model, theta=theta, velocity_scaler=scalers[0], friction_scaler=scalers[1],
            dt=data.dt, n_train=n_train, n_samples=n, metrics={}, stages=_stages(sol, solver),
            history=_history(sol), solution=sol, key_data=key_data, key_impl=key_impl, seed=seed,
            timings={"compile_s": sw.compile_s, "run_s": sw.run_s}, box=box,
            settings={
                "model_name": model_name(model), "model_config": model_config(model),
                "solver": repr(solver), "dtype": str(np.dtype(dtype)), "data_bounds": bool(data_bounds),
                "motion": {"mass": float(m_hat), "mass_range": mass_range, "offset": float(off),
                           "v0": float(dv0), "error": error, "horizon": horizon,
                           "cutoff": data.cutoff, "search_names": list(model.param_names) + list(layout.names()),
                           "y": [float(a) for a in y]},
            },
        )
        metrics = fit.evaluate(data, n_train, int(metric_horizon))
        fit.metrics = {**metrics, "num_params": int(y.size), "cost": float(sol.f)}
    assess_fit(fit, data)  # plausibility now, parameter uncertainty on first use
    fit.timings["total_s"] = total.wall_s
    return fit
