"""Simulated low-speed hydraulic press rig (the synthetic stand-in of docs/algorithms.md §7).

A single-rod double-acting cylinder, driven by a proportional valve under a PI
position controller (or an open-loop valve command), pushes a moving mass
against an external load through the seal friction of ``friction.py``.

State ``y = (x, v, p1, p2, u, I)``: position [m], velocity [m/s], chamber
pressures [Pa], spool opening [-], integral of the position error [m s].

    dx/dt  = v
    m dv/dt = p1 A1 - p2 A2 - F_L(t, x, v) - F_f - m g
    dp1/dt = beta / V1(x) (Q1 - Q12 - A1 v),      V1 = V01 + A1 x
    dp2/dt = beta / V2(x) (Q2 + Q12 + A2 v),      V2 = V02 + A2 (stroke - x)
    du/dt  = (u_cmd - u) / tau
    Q1 = Kv [a(u) r(ps - p1) - a(-u) r(p1 - pt)],  Q2 = rho Kv [a(-u) r(ps - p2) - a(u) r(p2 - pt)]

The oil column is stiff (hundreds of Hz) and the friction springs are stiffer
still for small masses, so each sub-step is linearly implicit (Rosenbrock-Euler,
L-stable): ``(I - h J) dy = h f(y_n)`` on a scaled state, with ``J`` from
``jax.jacfwd``. The friction elements are advanced afterwards by their exact
Maxwell-slip update with the solved displacement increment, and enter ``J``
through their stuck stiffness. Samples are taken every ``substeps`` sub-steps
(point sampling, as a DAQ without anti-alias filter does). With the defaults,
32 sub-steps agree with 256 to a friction nMSE below 1e-5 % (tests).

Not modelled: end stops (keep the reference inside the stroke), cavitation
(pressures may dip below zero in violent transients), valve flow forces.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import friction as _fr
from ..records import check_int
from .data import Measurements
from .params import Rig


# --------------------------------------------------------------------------- inputs
def default_velocity_profile(t):
    """Reference velocity [m/s] of docs/algorithms.md §7: ``0.010 sin(2 pi 0.2 t) + 0.004 sin(2 pi 0.53 t)``."""
    return 0.010 * jnp.sin(2 * jnp.pi * 0.2 * t) + 0.004 * jnp.sin(2 * jnp.pi * 0.53 * t)


def _default_position_offset(t):
    """Integral of [`default_velocity_profile`][jaxfric.rig.default_velocity_profile] from 0 to ``t`` [m]."""
    w1, w2 = 2 * jnp.pi * 0.2, 2 * jnp.pi * 0.53
    return 0.010 / w1 * (1 - jnp.cos(w1 * t)) + 0.004 / w2 * (1 - jnp.cos(w2 * t))


class Sensors(eqx.Module):
    """Sensor noise and quantisation of the measured channels.

    With ``relative=True`` (default) each ``noise_*`` is the Gaussian noise
    standard deviation as a fraction of that clean channel's standard deviation
    over the record (0.01 = 1 %, i.e. 40 dB SNR); with ``relative=False`` it is in
    SI units (m, Pa, N). ``quant_*`` are quantisation steps in SI units
    (m, Pa, N); 0 disables quantisation.
    """

    noise_position: float = 1.0e-4
    noise_pressure: float = 0.01
    noise_force: float = 0.01
    quant_position: float = 1.0e-6
    quant_pressure: float = 1.0e3
    quant_force: float = 0.5
    relative: bool = eqx.field(default=True, static=True)

    @classmethod
    def ideal(cls) -> "Sensors":
        """Noise-free, unquantised sensors."""
        return cls(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


class RigRecord(eqx.Module):
    """Output of [`simulate`][jaxfric.rig.simulate], all sampled at ``fs`` (SI units).

    Measured (noisy, quantised): ``t, x, p1, p2, load``.
    Ground truth: ``velocity``, ``acceleration``, ``friction`` (positive when it
    opposes +x), and the clean ``x_true, p1_true, p2_true, load_true`` and the
    spool opening ``valve``.
    """

    t: jax.Array
    x: jax.Array
    p1: jax.Array
    p2: jax.Array
    load: jax.Array
    velocity: jax.Array
    acceleration: jax.Array
    friction: jax.Array
    x_true: jax.Array
    p1_true: jax.Array
    p2_true: jax.Array
    load_true: jax.Array
    valve: jax.Array

    def measurements(self) -> Measurements:
        """The measured channels as [`Measurements`][jaxfric.rig.Measurements] (NumPy, float64) for the pipeline."""
        return Measurements.from_arrays(self.t, self.x, self.p1, self.p2, self.load)


# --------------------------------------------------------------------------- physics
def _opening(s, eps):
    """Smooth ``max(s, 0)`` with ``eps/2`` left at ``s = 0`` (centre leakage)."""
    return 0.5 * (s + jnp.sqrt(s * s + eps * eps))


def _root(dp, dp_lam):
    """``sign(dp) sqrt(|dp|)`` turning linear below ``dp_lam`` (laminar regime)."""
    return dp / jnp.sqrt(jnp.sqrt(dp * dp + dp_lam * dp_lam))


def load_force(rig: Rig, t, x, v):
    """External load [N] opposing +x (see [`Load`][jaxfric.rig.Load])."""
    ld = rig.load
    return (ld.offset + ld.amplitude * jnp.sin(2 * jnp.pi * ld.frequency * t + ld.phase)
            + ld.stiffness * (x - rig.cylinder.x0) + ld.damping * v)


def _derivative(rig: Rig, y, fe_pred, t, x_ref, v_ref, command, closed_loop: bool):
    """``dy/dt`` with friction elements predicted from ``fe_pred(x, v, p1, p2)``."""
    cyl, val, ctl = rig.cylinder, rig.valve, rig.controller
    x, v, p1, p2, u, integ = (y[i] for i in range(6))
    a1, a2 = cyl.areas
    if closed_loop:
        u_cmd = jnp.clip(ctl.feedforward * v_ref + ctl.kp * (x_ref - x) + ctl.ki * integ, -1.0, 1.0)
    else:
        u_cmd = jnp.clip(command, -1.0, 1.0)
    a_pos, a_neg = _opening(u, val.leak_opening), _opening(-u, val.leak_opening)
    kv = val.kv
    ps, pt, dpl = val.supply, val.tank, val.dp_laminar
    q1 = kv * (a_pos * _root(ps - p1, dpl) - a_neg * _root(p1 - pt, dpl))
    q2 = kv * val.ratio_b * (a_neg * _root(ps - p2, dpl) - a_pos * _root(p2 - pt, dpl))
    q12 = cyl.internal_leakage * (p1 - p2)
    # volumes never shrink below the dead volume, even if a user profile leaves the stroke
    xc = jnp.clip(x, 0.0, cyl.stroke)
    v1 = cyl.dead_volume_cap + a1 * xc
    v2 = cyl.dead_volume_rod + a2 * (cyl.stroke - xc)
    ff = _fr.friction_force(rig.friction, fe_pred(x, v, p1, p2), v)
    acc = (p1 * a1 - p2 * a2 - load_force(rig, t, x, v) - ff) / cyl.mass - cyl.gravity
    return jnp.stack([
        v,
        acc,
        val.bulk_modulus / v1 * (q1 - q12 - a1 * v),
        val.bulk_modulus / v2 * (q2 + q12 + a2 * v),
        (u_cmd - u) / val.time_constant,
        x_ref - x,
    ])


def _scales(rig: Rig):
    """State scales that make the implicit solve well conditioned in float32."""
    cyl, val = rig.cylinder, rig.valve
    a1, _ = cyl.areas
    vmax = val.kv * jnp.sqrt(val.supply) / a1
    one = jnp.ones_like(cyl.stroke)
    return jnp.stack([cyl.stroke, vmax, val.supply, val.supply, one, cyl.stroke * one])


def substep(rig: Rig, h, closed_loop, carry, inp):
    """One Rosenbrock-Euler step of the hydraulics + exact Maxwell-slip step of the seal."""
    y, fe = carry
    t1, x_ref, v_ref, command = inp
    scale = _scales(rig)
    fr = rig.friction
    x_n = y[0]

    linear = _fr.element_linearisation(fr, fe, y[1], y[2], y[3])

    def fe_pred(x, v, p1, p2):
        return linear(x - x_n, v, p1, p2)

    def f_scaled(ys):
        return _derivative(rig, ys * scale, fe_pred, t1, x_ref, v_ref, command, closed_loop) / scale

    ys = y / scale
    f0 = f_scaled(ys)
    jac = jax.jacfwd(f_scaled)(ys)
    eye = jnp.eye(6, dtype=y.dtype)
    dys = jnp.linalg.solve(eye - h * jac, h * f0)
    dy = dys * scale
    y_new = y + dy
    ctl = rig.controller
    # anti-windup: the integral alone never asks for more than full opening
    lim = jnp.where(ctl.ki > 0, 1.0 / jnp.where(ctl.ki > 0, ctl.ki, 1.0), jnp.inf)
    y_new = y_new.at[5].set(jnp.clip(y_new[5], -lim, lim))
    fe_new = _fr.element_update(fr, fe, dy[0], y_new[1], y_new[2], y_new[3])
    return (y_new, fe_new), None


def _observe(rig: Rig, t, y, fe):
    """Clean channels at one sample: the force balance holds exactly here."""
    cyl = rig.cylinder
    a1, a2 = cyl.areas
    x, v, p1, p2, u = y[0], y[1], y[2], y[3], y[4]
    fl = load_force(rig, t, x, v)
    ff = _fr.friction_force(rig.friction, fe, v)
    acc = (p1 * a1 - p2 * a2 - fl - ff) / cyl.mass - cyl.gravity
    return dict(x=x, v=v, a=acc, p1=p1, p2=p2, load=fl, friction=ff, valve=u)


def initial_state(rig: Rig, x_start, dtype):
    """Rest at ``x_start`` with pressures balancing the load (refined by the settling run)."""
    cyl, val = rig.cylinder, rig.valve
    a1, a2 = cyl.areas
    force = load_force(rig, 0.0, x_start, 0.0) + cyl.mass * cyl.gravity
    # bridge of equal orifices at rest: p1 + p2 = ps + pt
    p1 = (force + (val.supply + val.tank) * a2) / (a1 + a2)
    p2 = val.supply + val.tank - p1
    z = jnp.zeros((), dtype)
    y = jnp.stack([x_start + z, z, p1 + z, p2 + z, z, z]).astype(dtype)
    fe = jnp.zeros((_fr.n_elements(rig.friction),), dtype)
    return y, fe


def _add_noise(normal, clean, level, step, relative):
    """``clean`` plus ``level`` times the standard normal draws ``normal``, quantised to ``step``."""
    std = level * jnp.std(clean) if relative else level
    noisy = clean + std * normal
    safe = jnp.where(step > 0, step, 1.0)
    return jnp.where(step > 0, jnp.round(noisy / safe) * safe, noisy)


def _float_dtype(tree):
    leaves = [leaf for leaf in jax.tree.leaves(tree)]
    dtype = jnp.result_type(*leaves) if leaves else jnp.result_type(float)
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    return dtype


# --------------------------------------------------------------------------- entry point
def _check_simulate_inputs(key, n_samples, fs, substeps, settle_time, velocity_reference, command):
    """Reject bad arguments of [`simulate`][jaxfric.rig.simulate] before tracing (a clear ValueError instead
    of a ZeroDivisionError, a reshape error or a silently empty or NaN record)."""
    dtype = getattr(key, "dtype", None)
    typed = dtype is not None and jax.dtypes.issubdtype(dtype, jax.dtypes.prng_key)
    raw = dtype == jnp.uint32 and jnp.shape(key)[-1:] == (2,)
    if not (typed or raw):
        raise ValueError(f"key must be a JAX PRNG key (jax.random.key(seed)), got {key!r}")
    check_int("n_samples", n_samples, 2)
    check_int("substeps", substeps, 1)
    for name, value, zero_ok in (("fs", fs, False), ("settle_time", settle_time, True)):
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{name} must be a number, got {value!r}") from None
        if not np.isfinite(v) or v < 0.0 or (v == 0.0 and not zero_ok):
            need = "non-negative" if zero_ok else "positive"
            raise ValueError(f"{name} must be {need} and finite, got {value!r}")
    for name, arr in (("velocity_reference", velocity_reference), ("command", command)):
        if arr is None or isinstance(arr, jax.core.Tracer):
            continue  # traced under a caller's jit/vmap: checked for shape only, later
        a = np.asarray(arr)
        if not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a):
            raise ValueError(f"{name} must be real numbers, got dtype {a.dtype}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} holds NaN or inf")


def simulate(rig: Rig, key: jax.Array, *, n_samples: int = 2000, fs: float = 128.0, substeps: int = 32,
             velocity_reference=None, command=None, sensors: Sensors = Sensors(),
             settle_time: float = 1.0) -> RigRecord:
    """Simulate the rig and return sampled measurements plus the ground truth (docs/algorithms.md §7).

    rig: parameters (a pytree; vmap over a batched ``Rig`` for many rigs at once).
    key: PRNG key for the sensor noise; same key, same record.
    n_samples, fs: record length and sample rate [Hz] (paper: 2000 at 128 Hz).
    substeps: implicit sub-steps per sample (internal rate ``fs * substeps``).
    velocity_reference: ``None`` for the §7 profile
        ``v = 0.010 sin(2 pi 0.2 t) + 0.004 sin(2 pi 0.53 t)`` m/s, or an array of
        ``n_samples`` reference velocities [m/s]; the position reference is its
        integral from ``rig.cylinder.x0``. Tracked by the PI controller.
    command: open-loop valve command, ``n_samples`` values in [-1, 1]; when given,
        the controller is bypassed.
    sensors: noise and quantisation ([`Sensors`][jaxfric.rig.Sensors]).
    settle_time: seconds of holding still before ``t = 0`` so that pressures,
        controller and friction elements start from a consistent rest state
        (run through the same scan as the samples, so the sub-step is compiled once).

    The arithmetic follows the dtype of ``rig``'s leaves (Python floats give
    float32, or float64 when x64 is enabled). Jit-compatible; ``n_samples``,
    ``substeps``, ``fs`` and ``settle_time`` are static.
    """
    _check_simulate_inputs(key, n_samples, fs, substeps, settle_time, velocity_reference, command)
    # numbers become arrays here so that new parameter values never trigger a recompilation
    rig, sensors = jax.tree.map(jnp.asarray, (rig, sensors))
    return _simulate(rig, key, velocity_reference, command, sensors, int(n_samples), float(fs),
                     int(substeps), float(settle_time))


@eqx.filter_jit
def _simulate(rig, key, velocity_reference, command, sensors, n_samples, fs, substeps, settle_time):
    dtype = _float_dtype(rig)
    rig = jax.tree.map(lambda a: jnp.asarray(a, dtype), rig)
    sensors = jax.tree.map(lambda a: jnp.asarray(a, dtype), sensors)
    h = jnp.asarray(1.0 / (fs * substeps), dtype)
    closed_loop = command is None

    # sub-step grid: inputs are evaluated at the end of each sub-step
    ts = (jnp.arange(n_samples * substeps, dtype=dtype) + 1) / (fs * substeps)
    t_samples = jnp.arange(n_samples, dtype=dtype) / fs
    x0 = rig.cylinder.x0
    if velocity_reference is None:
        v_ref = default_velocity_profile(ts)
        x_ref = x0 + _default_position_offset(ts)
    else:
        vs = jnp.asarray(velocity_reference, dtype)
        if vs.shape != (n_samples,):
            raise ValueError(f"velocity_reference must have shape ({n_samples},), got {vs.shape}")
        xs = x0 + jnp.concatenate([jnp.zeros((1,), dtype), jnp.cumsum(0.5 * (vs[1:] + vs[:-1])) / fs])
        v_ref = jnp.interp(ts, t_samples, vs)
        x_ref = jnp.interp(ts, t_samples, xs)
    if closed_loop:
        u_in = jnp.zeros_like(ts)
        x_start, u_start = x0, jnp.zeros((), dtype)
    else:
        cs = jnp.asarray(command, dtype)
        if cs.shape != (n_samples,):
            raise ValueError(f"command must have shape ({n_samples},), got {cs.shape}")
        u_in = jnp.interp(ts, t_samples, cs)
        x_start, u_start = x0, cs[0]
    # settle: hold the start position (or the first command) with time frozen at 0.
    # It runs through the same nested scan as the samples, as leading "samples" whose
    # observations are dropped, so that the program holds one compiled copy of the
    # sub-step (jacfwd + 6x6 solve) instead of two. When n_settle is not a multiple of
    # substeps, the first sub-steps of the first settle sample are masked out (they
    # leave the state unchanged), so exactly n_settle sub-steps run.
    n_settle = int(round(settle_time * fs * substeps))
    n_hold = -(-n_settle // substeps)
    n_pad = n_hold * substeps - n_settle
    zero = jnp.zeros((), dtype)
    hold = tuple(jnp.full((n_hold * substeps,), val, dtype) for val in (zero, x_start, zero, u_start))
    sub_inputs = tuple(jnp.concatenate([a, b]).reshape(n_hold + n_samples, substeps)
                       for a, b in zip(hold, (ts, x_ref, v_ref, u_in)))
    active = (jnp.arange((n_hold + n_samples) * substeps) >= n_pad).reshape(n_hold + n_samples, substeps)
    inputs = (jnp.concatenate([jnp.zeros((n_hold,), dtype), t_samples]), (active, sub_inputs))

    def step(carry, inp):
        on, sub_inp = inp
        new, _ = substep(rig, h, closed_loop, carry, sub_inp)
        return jax.tree.map(lambda a, b: jnp.where(on, a, b), new, carry), None

    y, fe = initial_state(rig, x_start, dtype)
    y = y.at[4].set(u_start)

    def sample(carry, inp):
        t_k, sub_inputs = inp
        obs = _observe(rig, t_k, *carry)
        carry, _ = jax.lax.scan(step, carry, sub_inputs)
        return carry, obs

    _, obs = jax.lax.scan(sample, (y, fe), inputs)
    obs = {k: v[n_hold:] for k, v in obs.items()}

    # one key per channel, as four separate calls would draw; the normals are drawn under
    # one vmap so that the program holds one copy of the sampler instead of four
    channels = (obs["x"], obs["p1"], obs["p2"], obs["load"])
    levels = (sensors.noise_position, sensors.noise_pressure, sensors.noise_pressure, sensors.noise_force)
    quants = (sensors.quant_position, sensors.quant_pressure, sensors.quant_pressure, sensors.quant_force)
    normals = jax.vmap(lambda k: jax.random.normal(k, (n_samples,), dtype))(jax.random.split(key, 4))
    x_m, p1_m, p2_m, l_m = (_add_noise(z, c, lv, q, sensors.relative)
                            for z, c, lv, q in zip(normals, channels, levels, quants))
    return RigRecord(t=t_samples, x=x_m, p1=p1_m, p2=p2_m, load=l_m,
                     velocity=obs["v"], acceleration=obs["a"], friction=obs["friction"],
                     x_true=obs["x"], p1_true=obs["p1"], p2_true=obs["p2"], load_true=obs["load"],
                     valve=obs["valve"])
