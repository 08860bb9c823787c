"""True friction of the simulated rig: asymmetric, pressure-dependent Maxwell-slip.

Implements the generalised Maxwell-slip idea of docs/algorithms.md §8.4 with
rate-independent (instantly slipping) elements: each element is a spring that
saturates at its share of the Stribeck level. The element update
``F_i <- clip(F_i + k_i dx, -w_i s_-, +w_i s_+)`` is the exact solution of the
stick/slip law for a displacement increment ``dx``, so it is stable for any
step size and needs no stick/slip flag.
"""

from __future__ import annotations

import jax.numpy as jnp

from .params import SealFriction


def sliding_levels(fr: SealFriction, v, p1, p2):
    """Slip levels ``(s_+, s_-)`` [N] of the whole seal at velocity ``v`` and chamber pressures.

    ``s_pm = Fc_pm + (Fs_pm - Fc_pm) exp(-|v/vs|^shape) + c_cap p1 + c_rod p2``
    (asymmetric Stribeck curve plus the seal pressure effect, §7 of ALGORITHMS).
    Negative (cavitating) pressures do not lower the level.
    """
    # |v|^shape with a safe base: the gradient of |v| at 0 would be NaN for shape < 1
    speed = jnp.abs(v) / fr.stribeck_velocity
    safe = jnp.where(speed > 0, speed, 1.0)
    decay = jnp.where(speed > 0, jnp.exp(-(safe**fr.stribeck_shape)), 1.0)
    seal = fr.pressure_cap * jnp.maximum(p1, 0.0) + fr.pressure_rod * jnp.maximum(p2, 0.0)
    s_pos = fr.coulomb_pos + (fr.static_pos - fr.coulomb_pos) * decay + seal
    s_neg = fr.coulomb_neg + (fr.static_neg - fr.coulomb_neg) * decay + seal
    return jnp.maximum(s_pos, 0.0), jnp.maximum(s_neg, 0.0)


def _vector(field):
    return jnp.stack(jnp.broadcast_arrays(*field), -1) if isinstance(field, tuple) else jnp.asarray(field)


def element_update(fr: SealFriction, forces, dx, v, p1, p2):
    """Element forces [N] after a displacement increment ``dx`` [m] (exact Maxwell-slip step)."""
    k, w = _vector(fr.stiffness), _vector(fr.weights)
    s_pos, s_neg = sliding_levels(fr, v, p1, p2)
    return jnp.clip(forces + k * dx, -w * s_neg, w * s_pos)


def element_linearisation(fr: SealFriction, forces, v_n, p1_n, p2_n):
    """Element forces as a smooth function of ``(dx, v, p1, p2)`` around the current state.

    Used only to build the Jacobian of the implicit step: an element that slips
    and keeps being dragged the same way follows its slip level ``w s(v, p)``
    (zero stiffness, Stribeck slope, pressure effect); every other element is a
    spring ``F_i + k_i dx``. (Differentiating ``clip`` itself would give half
    the stiffness at the saturation bound and bias the step.)
    """
    k, w = _vector(fr.stiffness), _vector(fr.weights)
    s_pos_n, s_neg_n = sliding_levels(fr, v_n, p1_n, p2_n)
    tol = 1e-5 * (s_pos_n + s_neg_n) * w
    slip_pos = (forces >= w * s_pos_n - tol) & (v_n > 0)
    slip_neg = (forces <= -w * s_neg_n + tol) & (v_n < 0)

    def predict(dx, v, p1, p2):
        s_pos, s_neg = sliding_levels(fr, v, p1, p2)
        return jnp.where(slip_pos, w * s_pos, jnp.where(slip_neg, -w * s_neg, forces + k * dx))

    return predict


def friction_force(fr: SealFriction, forces, v):
    """Total friction force [N], positive when it opposes +x motion: ``sum F_i + viscous v``."""
    return jnp.sum(forces, axis=-1) + fr.viscous * v


def n_elements(fr: SealFriction) -> int:
    """Number of Maxwell-slip elements (static: taken from the parameter shapes)."""
    if isinstance(fr.stiffness, tuple):
        return len(fr.stiffness)
    return int(jnp.shape(fr.stiffness)[-1])
