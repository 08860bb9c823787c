"""One sample of a friction model at a time: the per-step form of every rollout.

``model.simulate(theta, velocity, dt)`` needs the whole velocity record in advance.
Inside the mechanics (``docs/algorithms.md §13.2``) the velocity of the next sample
depends on the friction of this one, so the friction has to advance one sample at a
time. A [`FrictionStep`][jaxfric.motion.FrictionStep] splits a model's recursion into

    F_k     = output(theta, s_k, v_k)          friction [N] at sample k
    s_{k+1} = update(theta, s_k, v_k)          zero-order hold of v_k over one sample
    s_0     = init(theta, v_0)

which reproduces ``model.simulate`` (and, with the §2.4 scalers, ``Fit.predict``)
sample for sample; ``tests/test_motion.py`` checks this for every model. The state
``s`` is a pytree of arrays (``()`` for static maps).

[`friction_step`][jaxfric.motion.friction_step] picks the implementation by the model's type (a
``functools.singledispatch`` on the class, so nominal types, no attribute guessing):

* LuGre, Dahl: the bristle state z and its exact zero-order-hold update (§8.2),
  symmetric or in the §13.1 asymmetric / offset forms;
* GMS: the element forces and their stick/slip directions (§8.4);
* Elman, ElmanFull: the context vector (§2.2, §2.3), in the fit's scaled units;
* GreyBox: its physical model's state and the network's context (``jaxfric.models.greybox``);
* any other model whose output ignores ``dt`` (``uses_dt = False``: the static maps
  Coulomb, Stribeck and their variants) is memoryless: ``output`` is the model's own
  ``simulate`` on one sample, so a new static form needs nothing here.

A new dynamic model registers its own step with ``friction_step.register(cls)``.
"""

from __future__ import annotations

import functools
from typing import Any

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array

from ..models import (GMS, AbstractFrictionModel, Dahl, Elman, ElmanFull, GreyBox, LuGre, Scaler,
                      stribeck_curve)
from ..models import add_offset, bristle_phi, by_direction, elman_full_hidden, elman_hidden

__all__ = ["FrictionStep", "StaticStep", "BristleStep", "GMSStep", "ElmanStep", "ElmanFullStep",
           "GreyBoxStep", "friction_step"]


class FrictionStep(eqx.Module):
    """Per-sample friction of one model (module docstring). Units: v in m/s, F in N,
    ``dt`` in s. ``implicit_state``: whether the motion integrator may advance the
    state with the *new* velocity (backward Euler in the state, needed for stiff
    bristle springs, [`jaxfric.motion.simulate_motion`][jaxfric.motion.simulate_motion])."""

    model: AbstractFrictionModel = eqx.field(static=True)

    implicit_state = False

    def init(self, theta, v0, dt) -> Any:
        return ()

    def output(self, theta, state, v, dt) -> Array:
        raise NotImplementedError

    def update(self, theta, state, v, dt) -> Any:
        return state


class StaticStep(FrictionStep):
    """Memoryless map: ``F_k = model.simulate(theta, [v_k])[0]``, no state."""

    def output(self, theta, state, v, dt):
        return self.model.simulate(theta, jnp.reshape(v, (1,)), dt)[0]


def _stribeck(model, p, v):
    """The Stribeck curve g(v) of LuGre or GMS at ``v``; with ``asymmetric=True`` (§13.1) by
    the ``_pos`` values for v > 0 and the ``_neg`` ones otherwise."""
    delta = model.stribeck_exponent
    if model.asymmetric:
        return jnp.where(v > 0, stribeck_curve(v, p["Fc_pos"], p["Fs_pos"], p["vs"], delta),
                         stribeck_curve(v, p["Fc_neg"], p["Fs_neg"], p["vs"], delta))
    return stribeck_curve(v, p["Fc"], p["Fs"], p["vs"], delta)


class BristleStep(FrictionStep):
    """LuGre / Dahl bristle state z, §8.1-8.3:

    ``a = sigma0 |v| / g(v)``, ``F = sigma0 z + sigma1 (v - a z) + sigma2 v (+ F_off)``,
    ``z' = z exp(-a h) + v h phi(a h)`` (exact under the hold), ``z_0 = sgn(v_0) g(v_0) / sigma0``.
    With ``asymmetric=True`` (§13.1) g and sigma2 take their ``_pos`` values for v > 0
    and ``_neg`` otherwise, as the models' rollouts do.
    """

    implicit_state = True

    def _params(self, theta, v):
        p = self.model.to_physical(theta)
        zero = jnp.zeros_like(p["sigma0"])
        if isinstance(self.model, LuGre):
            return p, p["sigma0"], p["sigma1"], by_direction(p, "sigma2", v), _stribeck(self.model, p, v)
        s2 = by_direction(p, "sigma2", v) if self.model.viscous else zero
        return p, p["sigma0"], zero, s2, by_direction(p, "Fc", v)

    def init(self, theta, v0, dt):
        _, s0, _, _, g = self._params(theta, v0)
        return jnp.sign(v0) * g / s0

    def output(self, theta, z, v, dt):
        p, s0, s1, s2, g = self._params(theta, v)
        a = s0 * jnp.abs(v) / g
        return add_offset(s0 * z + s1 * (v - a * z) + s2 * v, p)

    def update(self, theta, z, v, dt):
        _, s0, _, _, g = self._params(theta, v)
        x = s0 * jnp.abs(v) / g * dt
        return z * jnp.exp(-x) + v * dt * bristle_phi(x)


class GMSStep(FrictionStep):
    """Generalised Maxwell-slip, §8.4 (``jaxfric.models.gms``): state = (element forces
    F_i, stick/slip direction d_i in {-1, 0, +1}); ``F = sum_i F_i + sigma2 v (+ F_off)``;
    over one held sample an element slipping the way v moves (or beyond its level
    ``alpha_i s(v)``) relaxes exactly, ``F_i <- t_i + (F_i - t_i) exp(-C h / s(v))`` with
    ``t_i = alpha_i s(v) sgn(v)``; a sticking one moves by ``k_i v h`` and stops at ``t_i``
    when it reaches its level. ``F_i(0) = alpha_i s(v_0) sgn(v_0)``. The explicit state
    update is the model's own (stable for any h), so ``implicit_state`` stays False.
    """

    def _params(self, theta, v):
        m = self.model
        p = m.to_physical(theta)
        n = m.num_elements
        k = jnp.stack([p[f"k{i}"] for i in range(1, n + 1)], axis=-1)
        alpha = jnp.stack([p[f"alpha{i}"] for i in range(1, n + 1)], axis=-1)
        return p, k, alpha, _stribeck(m, p, v)

    def init(self, theta, v0, dt):
        _, _, alpha, s = self._params(theta, v0)
        force = alpha * (s * jnp.sign(v0))
        return force, jnp.broadcast_to(jnp.sign(v0), force.shape).astype(force.dtype)

    def output(self, theta, state, v, dt):
        p, _, _, _ = self._params(theta, v)
        return add_offset(jnp.sum(state[0]) + by_direction(p, "sigma2", v) * v, p)

    def update(self, theta, state, v, dt):
        force, direction = state
        p, k, alpha, s = self._params(theta, v)
        sv = jnp.sign(v)
        level = alpha * s
        target = level * sv
        relaxed = target + (force - target) * jnp.exp(-p["C"] * dt / s)
        stuck = force + k * (v * dt)
        moving = sv != 0
        slips = moving & ((direction == sv) | (sv * force >= level))
        reaches = moving & (sv * stuck >= level)
        new_force = jnp.where(slips, relaxed, jnp.where(reaches, target, stuck))
        new_direction = jnp.where(slips | reaches, sv, jnp.zeros_like(direction))
        return new_force, new_direction


class _ScaledStep(FrictionStep):
    """An Elman network on §2.4-scaled data: velocity in, newtons out through the scalers;
    ``y = v.h (+ b_o)`` from the hidden layer ``h`` of the subclass's ``_hidden``."""

    velocity_scaler: Scaler
    friction_scaler: Scaler

    def _u(self, v):
        return self.velocity_scaler.scale(v)

    def output(self, theta, c, v, dt):
        p, h = self._hidden(theta, c, v)
        y = jnp.sum(p["v"] * h) + (p["b_o"] if self.model.output_bias else 0.0)
        return self.friction_scaler.unscale(y)


class ElmanStep(_ScaledStep):
    """Diagonal-context Elman network, §2.2: ``h = tanh(w u + r c + b)``,
    ``y = v.h (+ b_o)``, ``c' = alpha c + h``, ``c_0`` learned."""

    def init(self, theta, v0, dt):
        return self.model.to_physical(theta)["c0"]

    def _hidden(self, theta, c, v):
        p = self.model.to_physical(theta)
        return p, elman_hidden(self._u(v), c, p["w"], p["r"], p["b"])

    def update(self, theta, c, v, dt):
        p, h = self._hidden(theta, c, v)
        return p["alpha"] * c + h


class ElmanFullStep(_ScaledStep):
    """Full-context Elman network, §2.3: ``h = tanh(w u + W_c c + b)``, ``y = v.h + b_o``, ``c' = h``."""

    def init(self, theta, v0, dt):
        p = self.model.to_physical(theta)
        return p["c0"] if self.model.learn_c0 else jnp.zeros_like(p["w"])

    def _hidden(self, theta, c, v):
        p = self.model.to_physical(theta)
        return p, elman_full_hidden(self._u(v), c, p["w"], p["W_c"], p["b"])

    def update(self, theta, c, v, dt):
        return self._hidden(theta, c, v)[1]


@functools.singledispatch
def friction_step(model: AbstractFrictionModel, scalers=(None, None)) -> FrictionStep:
    """The [`FrictionStep`][jaxfric.motion.FrictionStep] of ``model`` (module docstring). ``scalers`` =
    ``(velocity, friction)`` [`Scaler`][jaxfric.models.Scaler] pair for models with ``needs_scaling``.

    Raises ``ValueError`` for a model with internal state that has no registered step.
    """
    if not isinstance(model, AbstractFrictionModel):
        raise ValueError(f"expected a jaxfric friction model, got {type(model).__name__}")
    if model.uses_dt or model.needs_scaling:
        raise ValueError(
            f"{type(model).__name__} has internal state and no per-sample step: register one "
            "with jaxfric.motion.friction_step.register")
    return StaticStep(model)


@friction_step.register(LuGre)
@friction_step.register(Dahl)
def _bristle(model, scalers=(None, None)):
    return BristleStep(model)


@friction_step.register(GMS)
def _gms(model, scalers=(None, None)):
    return GMSStep(model)


def _scalers(model, scalers):
    sv, sf = scalers
    if not (isinstance(sv, Scaler) and isinstance(sf, Scaler)):
        raise ValueError(f"{type(model).__name__} works on scaled data: pass its "
                         "(velocity, friction) Scaler pair")
    return sv, sf


@friction_step.register(Elman)
def _elman(model, scalers=(None, None)):
    return ElmanStep(model, *_scalers(model, scalers))


@friction_step.register(ElmanFull)
def _elman_full(model, scalers=(None, None)):
    return ElmanFullStep(model, *_scalers(model, scalers))


class GreyBoxStep(FrictionStep):
    """[`jaxfric.models.GreyBox`][jaxfric.models.GreyBox]: state = (physical model's state,
    network context c); ``F = F_phys + B tanh(v.h)``, ``h = tanh(w u + r c + b)``,
    ``c' = α c + (1 − α) h``, ``u = v / v_net``. ``implicit_state`` is the physical step's."""

    inner: FrictionStep

    @property
    def implicit_state(self):  # type: ignore[override]
        return self.inner.implicit_state

    def _parts(self, theta, v):
        theta_p, net = self.model._split(theta)
        level = self.model.correction_bound(theta) / self.model.bound
        return theta_p, net, level, v / net["vscale"]

    def init(self, theta, v0, dt):
        theta_p, net, _, _ = self._parts(theta, v0)
        return self.inner.init(theta_p, v0, dt), net["c0"]

    def output(self, theta, state, v, dt):
        theta_p, net, level, u = self._parts(theta, v)
        h, _ = self.model.network_step(net, state[1], u)
        return self.inner.output(theta_p, state[0], v, dt) + self.model.correction(level, net, h)

    def update(self, theta, state, v, dt):
        theta_p, net, _, u = self._parts(theta, v)
        _, c = self.model.network_step(net, state[1], u)
        return self.inner.update(theta_p, state[0], v, dt), c


@friction_step.register(GreyBox)
def _greybox(model, scalers=(None, None)):
    return GreyBoxStep(model, friction_step(model.physical))
