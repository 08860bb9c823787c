"""Model-based friction compensation on the rig simulator (docs/algorithms.md §13.3).

A digital position loop at ``fs`` Hz drives the simulated rig's valve (the plant of
``jaxfric.rig``, integrated ``substeps`` times per control sample with the simulator's
own implicit step). The valve meters flow, so friction is compensated through the
cascade a valve-driven cylinder needs: an outer PID on position produces a force
demand, an inner loop turns the force error into a valve command::

    F_d = m a_ref + kp e + kd de/dt + ki int(e) + F_load(measured) + F_ff
    u   = clip(ff v_ref + kf (F_d - (p1 A1 - p2 A2)), -1, 1),      e = x_ref - x

``F_ff`` is the friction feed-forward: ``0`` (no compensation), an identified fit's
friction driven by the *reference* velocity ([`feedforward`][jaxfric.compensation.feedforward]: computed from the fit
and the reference alone, before the loop runs, so the rig's true friction cannot leak
into it), or, as the unattainable ideal, the rig's true friction at the current state
(``ideal=True``, read from the simulator's internal state). ``de/dt`` is the backward
difference of the measured position through a first-order low-pass (``velocity_cutoff``).

Metrics (§13.3): tracking RMS and maximum error after the initial hold, and stick-slip
amplitude = peak-to-peak tracking error on the slow ramps (constant low reference speed).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .records import same_sample_time
from .rig import friction as _fr
from .rig.params import Rig
from .rig.simulator import initial_state, load_force, substep

__all__ = ["Gains", "Reference", "compensation_study", "compensation_table", "feedforward",
           "reference", "track"]


class Gains(eqx.Module):
    """Cascade gains: outer ``kp`` [N/m], ``kd`` [N s/m], ``ki`` [N/(m s)]; inner ``kf``
    [1/N] (valve opening per newton of force error); ``ff`` [s/m] velocity feed-forward
    of the valve (~ 1 / valve-limited speed). Defaults tuned on the default [`Rig`][jaxfric.rig.Rig]."""

    kp: float = 1.0e6
    kd: float = 2.0e4
    ki: float = 5.0e6
    kf: float = 1.0e-4
    ff: float = 40.0


@dataclasses.dataclass(frozen=True)
class Reference:
    """Position reference sampled at ``fs``: ``x`` [m], ``v`` [m/s], ``a`` [m/s^2];
    ``hold``: samples of initial hold excluded from the metrics; ``ramp``: boolean mask of
    the slow-ramp samples (stick-slip metric)."""

    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    fs: float
    hold: int
    ramp: np.ndarray

    @property
    def dt(self) -> float:
        return 1.0 / self.fs


def reference(fs: float = 1000.0, *, x0: float = 0.05, amplitude: float = 0.01, period: float = 8.0,
              ramp_speed: float = 1.0e-3, ramp_time: float = 4.0, hold: float = 1.0) -> Reference:
    """Hold, one slow sinusoid (``amplitude`` [m], ``period`` [s]: two velocity reversals),
    then a slow ramp out and back at ``ramp_speed`` [m/s] (``ramp_time`` s each way, a
    reversal between), each speed change smoothed over 0.2 s."""
    dt = 1.0 / fs
    t_sin = np.arange(int(round(period * fs))) * dt
    w = 2 * np.pi / period
    v_sin = amplitude * w * np.sin(w * t_sin)  # starts and ends at rest
    n_r = int(round(ramp_time * fs))
    n_s = int(round(0.2 * fs))
    edge = 0.5 * (1 - np.cos(np.pi * np.arange(n_s) / n_s))
    up = np.concatenate([edge, np.ones(n_r - 2 * n_s), edge[::-1]]) * ramp_speed
    v = np.concatenate([np.zeros(int(round(hold * fs))), v_sin, np.zeros(n_s), up, -up, np.zeros(n_s)])
    x = x0 + np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1])) * dt])
    a = np.gradient(v, dt)
    ramp = np.abs(np.abs(v) - ramp_speed) < 1e-12
    return Reference(x, v, a, float(fs), int(round(hold * fs)), ramp)


def feedforward(fit, ref: Reference) -> np.ndarray:
    """Friction feed-forward [N] of ``fit`` along the reference velocity (§13.3).

    Only the fit and the reference enter: ``fit.predict`` of the reference velocity (a
    [`jaxfric.motion.MotionFit`][jaxfric.motion.MotionFit] includes its fitted offset). A fit
    made at another sample time (the Elman network is a discrete map at its data's rate)
    is evaluated on its own time grid and interpolated linearly. ``None`` means no
    compensation (zeros).
    """
    if fit is None:
        return np.zeros_like(ref.v)
    fit_dt = float(fit.dt)
    if same_sample_time(fit_dt, ref.dt):
        return np.asarray(fit.predict(ref.v, ref.dt), np.float64)
    t = np.arange(ref.v.size) * ref.dt
    tf = np.arange(int(np.floor(t[-1] / fit_dt)) + 1) * fit_dt
    return np.interp(t, tf, np.asarray(fit.predict(np.interp(tf, t, ref.v), fit_dt), np.float64))


def track(rig: Rig, ref: Reference, friction_ff=None, *, gains: Gains = Gains(), substeps: int = 4,
          ideal: bool = False, velocity_cutoff: float = 100.0) -> dict:
    """Run the cascade of the module docstring on ``rig`` (float64 NumPy results).

    ``friction_ff``: feed-forward [N] per reference sample ([`feedforward`][jaxfric.compensation.feedforward]), or
    ``None``; ``ideal=True`` instead feeds the rig's true friction at the current state.
    Returns ``t``, ``x``, ``error`` (x_ref - x), ``command``, ``friction`` (true) and
    ``feedforward`` (what the controller added).
    """
    n = ref.x.size
    ff = np.zeros(n) if friction_ff is None else np.asarray(friction_ff, np.float64)
    if ff.shape != (n,):
        raise ValueError(f"friction_ff must have one value per reference sample ({n}), got {ff.shape}")
    if not np.all(np.isfinite(ff)):
        raise ValueError("friction_ff holds NaN or inf")
    rig = jax.tree.map(lambda a: jnp.asarray(a, jnp.float64), rig)
    gains = jax.tree.map(lambda a: jnp.asarray(a, jnp.float64), gains)
    out = _track(rig, gains, jnp.asarray(ref.x), jnp.asarray(ref.v), jnp.asarray(ref.a), jnp.asarray(ff),
                 float(ref.fs), int(substeps), jnp.asarray(bool(ideal)), float(velocity_cutoff))
    res = {k: np.asarray(v, np.float64) for k, v in out.items()}
    res["t"] = np.arange(n) / ref.fs
    res["error"] = ref.x - res["x"]
    return res


@eqx.filter_jit
def _track(rig, gains, x_ref, v_ref, a_ref, ff, fs, substeps, ideal, cutoff):
    # ``ideal`` is a traced boolean, not a static flag: every controller of a study
    # (none, each fit's feed-forward, the true friction) runs one compiled program
    dt = 1.0 / fs
    h = jnp.asarray(dt / substeps)
    cyl = rig.cylinder
    a1, a2 = cyl.areas
    lp = 1.0 - jnp.exp(-2 * jnp.pi * cutoff * dt)  # first-order low-pass of de/dt
    y, fe = initial_state(rig, x_ref[0], jnp.float64)

    def control(carry, inp):
        (y, fe), integ, e_prev, de = carry
        k, xr, vr, ar, f_ff = inp
        t = k * dt
        x, p1, p2 = y[0], y[2], y[3]
        e = xr - x
        de = de + lp * ((e - e_prev) / dt - de)
        f_true = _fr.friction_force(rig.friction, fe, y[1])
        f_comp = jnp.where(ideal, f_true, f_ff)
        f_load = load_force(rig, t, x, y[1])
        f_d = cyl.mass * (ar + cyl.gravity) + gains.kp * e + gains.kd * de + gains.ki * integ + f_load + f_comp
        u = jnp.clip(gains.ff * vr + gains.kf * (f_d - (p1 * a1 - p2 * a2)), -1.0, 1.0)
        sub = (jnp.full((substeps,), t) + h * (jnp.arange(substeps) + 1), jnp.full((substeps,), xr),
               jnp.full((substeps,), vr), jnp.full((substeps,), u))
        (y2, fe2), _ = jax.lax.scan(lambda c, i: substep(rig, h, False, c, i), (y, fe), sub)
        return ((y2, fe2), integ + e * dt, e, de), {"x": x, "command": u, "friction": f_true,
                                                    "feedforward": f_comp}

    ks = jnp.arange(x_ref.shape[0], dtype=jnp.float64)
    zero = jnp.zeros(())
    _, obs = jax.lax.scan(control, ((y, fe), zero, zero, zero), (ks, x_ref, v_ref, a_ref, ff))
    return obs


def _segments(mask: np.ndarray) -> list[slice]:
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    return [slice(a, b) for a, b in zip(edges[::2], edges[1::2])]


def stick_slip(error: np.ndarray, ramp: np.ndarray) -> float:
    """Peak-to-peak tracking error [m] on each slow-ramp segment after its first quarter
    (the transient of the speed change), largest over the segments."""
    amps = [np.ptp(error[s][(s.stop - s.start) // 4:]) for s in _segments(ramp)]
    return float(max(amps)) if amps else float("nan")


def _metrics(res: dict, ref: Reference) -> dict:
    e = res["error"][ref.hold:]
    return {"rms_mm": 1e3 * float(np.sqrt(np.mean(e ** 2))), "max_mm": 1e3 * float(np.max(np.abs(e))),
            "stick_slip_um": 1e6 * stick_slip(res["error"], ref.ramp)}


def compensation_study(fits: dict, rig: Rig | None = None, *, ref: Reference | None = None,
                       gains: Gains = Gains(), substeps: int = 4) -> tuple[list[dict], dict]:
    """Tracking with no compensation, each fit's feed-forward and the ideal (true friction).

    ``fits``: ``{label: fit}`` (any object with ``predict(velocity, dt)``, e.g. a
    [`jaxfric.Fit`][jaxfric.fit.Fit]). Returns ``(rows, runs)``: one row per controller with
    ``rms_mm``, ``max_mm``, ``stick_slip_um`` (see the module docstring), and the
    ``track`` results by label (for [`plot_tracking`][jaxfric.compensation.plot_tracking]).
    """
    rig = Rig() if rig is None else rig
    ref = reference() if ref is None else ref
    runs = {"none": track(rig, ref, None, gains=gains, substeps=substeps)}
    for label, fit in fits.items():
        runs[label] = track(rig, ref, feedforward(fit, ref), gains=gains, substeps=substeps)
    runs["ideal (true friction)"] = track(rig, ref, None, gains=gains, substeps=substeps, ideal=True)
    rows = [{"compensation": k, **_metrics(v, ref)} for k, v in runs.items()]
    return rows, runs


def compensation_table(rows: list[dict]) -> str:
    """Markdown table of [`compensation_study`][jaxfric.compensation.compensation_study] rows (for ``jaxfric demo``'s report)."""
    lines = ["| compensation | tracking RMS [mm] | max error [mm] | stick-slip on slow ramp [um p-p] |",
             "|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['compensation']} | {r['rms_mm']:.4f} | {r['max_mm']:.4f} | {r['stick_slip_um']:.2f} |")
    return "\n".join(lines)


def plot_tracking(runs: dict, ref: Reference | None = None):
    """Figure: tracking error [mm] against time for every controller of a study, each in
    its model's look ([`jaxfric.styles.style`][jaxfric.styles.style]: the same colour as in the report's other
    figures; no compensation grey, the true friction dotted)."""
    import matplotlib.pyplot as plt

    from .styles import style

    fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    first = next(iter(runs.values()))
    if ref is not None:
        ax[0].plot(first["t"], 1e3 * ref.v, "k")
        ax[0].set_ylabel("reference velocity [mm/s]")
    for i, (label, r) in enumerate(runs.items()):
        ax[1].plot(r["t"], 1e3 * r["error"], lw=1, label=label, **style(label, i))
    ax[1].set_ylabel("tracking error [mm]")
    ax[1].set_xlabel("time [s]")
    ax[1].legend(fontsize=7)
    fig.tight_layout()
    return fig
