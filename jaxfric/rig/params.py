"""Parameters of the simulated low-speed press-cylinder rig (docs/algorithms.md §7).

Every number is a pytree leaf (a float or an array), so a batch of rigs is just a
``Rig`` whose leaves carry a leading axis and ``jax.vmap`` runs them in one call.
All quantities are SI: m, kg, s, Pa, N, m^3. Nothing here depends on the dtype;
the simulator casts the leaves to one float dtype when it starts.

Sign conventions (shared with the force balance in ``pipeline``):
``x`` grows when the rod extends (cap chamber 1 grows); chamber 1 acts on the
full bore area ``A1``, chamber 2 on the annulus ``A2``; the external load
``F_L`` and the friction ``F_f`` oppose +x; ``gravity`` is the component of g
that pulls towards -x (9.81 for a vertical axis with x pointing up).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np


def _concrete(value):
    """``value`` as a NumPy array, or None while it is being traced."""
    try:
        return np.asarray(value, dtype=float)
    except Exception:  # jax tracers refuse conversion; nothing to check then
        return None


def _check_geometry(bore, rod) -> None:
    """Raise ValueError for impossible diameters (concrete inputs only, batches included)."""
    b, r = _concrete(bore), _concrete(rod)
    if b is None or r is None:
        return
    if not np.all(np.isfinite(b) & (b > 0.0)):
        raise ValueError(f"bore diameter must be positive and finite (m), got {bore!r}")
    if not np.all(np.isfinite(r) & (r >= 0.0)):
        raise ValueError(f"rod diameter must be non-negative and finite (m), got {rod!r}")
    if np.any(r >= b):
        raise ValueError(f"rod diameter ({rod!r} m) must be smaller than the bore ({bore!r} m)")


def piston_areas(bore, rod):
    """Cap-side and rod-side areas ``A1 = pi D^2/4``, ``A2 = pi (D^2 - d^2)/4`` in m^2 (docs/algorithms.md §7)."""
    _check_geometry(bore, rod)
    a1 = jnp.pi * bore**2 / 4.0
    a2 = jnp.pi * (bore**2 - rod**2) / 4.0
    return a1, a2


class Cylinder(eqx.Module):
    """Single-rod double-acting cylinder and the mass it moves.

    bore, rod: piston and rod diameters [m]; stroke [m]; dead_volume_cap /
    dead_volume_rod: oil volume of each chamber at its end of stroke, hoses
    included [m^3]; mass: moving mass, piston + rod + tool [kg]; gravity:
    component of g pulling towards -x [m/s^2] (0 = horizontal axis);
    x0: piston position where the record starts [m]; internal_leakage:
    laminar piston leakage coefficient from chamber 1 to 2 [m^3/(s Pa)].
    """

    bore: float = 0.10
    rod: float = 0.07
    stroke: float = 0.20
    dead_volume_cap: float = 2.0e-4
    dead_volume_rod: float = 2.0e-4
    mass: float = 120.0
    gravity: float = 0.0
    x0: float = 0.05
    internal_leakage: float = 2.0e-13

    def __check_init__(self):
        _check_geometry(self.bore, self.rod)

    @property
    def areas(self):
        """``(A1, A2)`` in m^2."""
        return piston_areas(self.bore, self.rod)


class Valve(eqx.Module):
    """4/3 proportional valve with a first-order spool and turbulent orifices.

    Each metering edge passes ``Q = Kv * a(u) * sign(dp) sqrt(|dp|)`` with
    ``Kv = nominal_flow / sqrt(nominal_drop)`` (flow per edge at full opening).
    supply / tank: pressures [Pa]; nominal_flow [m^3/s] at nominal_drop per edge
    [Pa]; ratio_b: gain of the B-side (rod chamber) edges relative to the A side
    (0.5 = the usual 2:1 spool for a differential cylinder, which keeps both
    chamber pressures steady through a reversal); leak_opening: centre leakage,
    as a fraction of full opening (keeps the chambers pressurised at u = 0);
    time_constant: spool lag [s]; dp_laminar: pressure drop [Pa] below which
    the square-root law turns linear (laminar regularisation, keeps the
    Jacobian finite at dp = 0); bulk_modulus: effective oil bulk modulus [Pa].
    """

    supply: float = 10.0e6
    tank: float = 0.0
    nominal_flow: float = 10.0 / 60000.0  # 10 L/min
    nominal_drop: float = 3.5e6
    ratio_b: float = 0.5
    leak_opening: float = 0.01
    time_constant: float = 0.005
    dp_laminar: float = 1.0e5
    bulk_modulus: float = 1.4e9

    @property
    def kv(self):
        """Orifice coefficient per edge at full opening [m^3/(s sqrt(Pa))]."""
        return self.nominal_flow / jnp.sqrt(self.nominal_drop)


class Load(eqx.Module):
    """External load seen by the rod force sensor, opposing +x [N].

    ``F_L(t, x, v) = offset + amplitude sin(2 pi frequency t + phase) + stiffness (x - x0) + damping v``
    (a press forming a slowly varying, spring-like, viscoplastic workpiece).
    offset, amplitude [N]; frequency [Hz]; phase [rad]; stiffness [N/m];
    damping [N s/m]. The damping also tames the oil-column mode (~190 Hz with
    the defaults), which the falling Stribeck curve would otherwise excite.
    """

    offset: float = 5000.0
    amplitude: float = 1500.0
    frequency: float = 0.11
    phase: float = 0.0
    stiffness: float = 1.0e5
    damping: float = 5.0e4


class SealFriction(eqx.Module):
    """True friction of the rig: richer than LuGre on purpose (docs/algorithms.md §7, §8.4).

    Generalised Maxwell-slip form with rate-independent elements. Element i is
    a spring of stiffness ``k_i`` [N/m] that slips at ``weights_i * s(v, p)``:

        s_+(v, p) = Fc_+ + (Fs_+ - Fc_+) exp(-|v/vs|^shape) + c_cap p1 + c_rod p2   (v >= 0 side)
        s_-(v, p) = the same with Fc_-, Fs_-                                       (v <  0 side)
        F_f = sum_i F_i + viscous * v

    so the sliding level is asymmetric (``coulomb_pos`` != ``coulomb_neg``,
    ``static_pos`` != ``static_neg`` [N]), grows with the chamber pressures that
    energise the seals (``pressure_cap``, ``pressure_rod`` [N/Pa]), and the
    pre-sliding hysteresis has the non-local memory of several elements.
    ``weights`` should sum to 1 so that the sliding friction equals ``s``.
    stribeck_velocity [m/s]; stribeck_shape (exponent, 2 in LuGre); viscous [N s/m].
    """

    stiffness: tuple = (1.5e7, 3.0e6, 6.0e5, 1.5e5)
    weights: tuple = (0.3, 0.3, 0.2, 0.2)
    coulomb_pos: float = 270.0
    coulomb_neg: float = 150.0
    static_pos: float = 440.0
    static_neg: float = 230.0
    stribeck_velocity: float = 2.0e-3
    stribeck_shape: float = 1.0
    pressure_cap: float = 0.0
    pressure_rod: float = 2.5e-5
    viscous: float = 4000.0

    @classmethod
    def off(cls, n_elements: int = 4) -> "SealFriction":
        """No friction at all (for checking the force bookkeeping)."""
        zeros = (0.0,) * n_elements
        return cls(stiffness=(1.0e6,) * n_elements, weights=zeros, coulomb_pos=0.0,
                   coulomb_neg=0.0, static_pos=0.0, static_neg=0.0, pressure_cap=0.0,
                   pressure_rod=0.0, viscous=0.0)


class Controller(eqx.Module):
    """Position controller driving the valve: PI on the position error plus velocity feed-forward.

    ``u = clip(feedforward * v_ref + kp * (x_ref - x) + ki * integral(x_ref - x), -1, 1)``.
    feedforward [s/m] ~ 1 / (valve-limited velocity at u = 1); kp [1/m]; ki [1/(m s)].
    Ignored when the simulator is given an open-loop valve command.
    """

    feedforward: float = 40.0
    kp: float = 400.0
    ki: float = 800.0


class Rig(eqx.Module):
    """The whole rig: geometry, valve, load, friction and controller (all SI)."""

    cylinder: Cylinder = Cylinder()
    valve: Valve = Valve()
    load: Load = Load()
    friction: SealFriction = SealFriction()
    controller: Controller = Controller()
