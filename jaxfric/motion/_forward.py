"""The forward model: friction inside the mechanics, one ``lax.scan`` over samples.

``docs/algorithms.md §13.2``::

    m dv/dt = u(t) - F_f(v, s),      dx/dt = v,      u = F_act - F_load (held over a sample)

Discretisation at the recording's sample time h (one step per sample):

* the friction acts at the *end* of the step (backward Euler in the friction), solved
  by one Newton step from the current velocity (linearly implicit / Rosenbrock-Euler)::

      Phi(w)   = output(update(s_k, w*), w)        w* = w for bristle states, else v_k
      v_{k+1}  = v_k + (h/m) (u_k - Phi(v_k)) / (1 + (h/m) max(Phi'(v_k), 0))
      x_{k+1}  = x_k + h (v_k + v_{k+1}) / 2
      s_{k+1}  = update(s_k, w*)  with w = v_{k+1}

  ``Phi'`` comes from ``jax.jvp``. The implicit part makes the step stable for any
  viscous coefficient, LuGre micro-damping and (because the bristle state sees the new
  velocity) any bristle stiffness: for the spring F = sigma0 z it is backward Euler,
  which damps instead of blowing up when sigma0 h^2 / m > 4. Negative slopes (the
  Stribeck dip) are left explicit (``max(., 0)``) so the denominator never nears 0.
* static maps use jaxfric's smooth sign ``tanh(v / v_eps)``. At v = 0 the Newton step
  then drives the mass to the velocity where friction balances the force, i.e. it
  "sticks" with a creep speed below ``v_eps atanh(|u|/F_s)``: a documented smooth
  sign, not Karnopp's switch, so the same code handles every model and stays
  differentiable. The integrator is first order in h (checked against
  ``scipy.integrate.solve_ivp`` in the tests).

The friction series reported (``F_k = output(s_k, v_k)``) is what the mechanics felt.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array

from ._step import FrictionStep

__all__ = ["advance_motion", "motion_start", "simulate_motion", "track_states", "k_step_positions"]


def advance_motion(step: FrictionStep, theta, inv_m, dt, x, v, s, u):
    """One sample of [`simulate_motion`][jaxfric.motion.simulate_motion]'s scheme (this module's
    docstring, §13.2): ``(x, v, s, u_k) -> (x', v', s', F_k)``, with ``inv_m`` = 1/m."""
    f_now = step.output(theta, s, v, dt)

    def phi(w):
        w_state = w if step.implicit_state else v
        return step.output(theta, step.update(theta, s, w_state, dt), w, dt)

    f_end, slope = jax.jvp(phi, (v,), (jnp.ones_like(v),))
    r = dt * inv_m
    v_new = v + r * (u - f_end) / (1.0 + r * jnp.maximum(slope, 0.0))
    x_new = x + 0.5 * dt * (v + v_new)
    s_new = step.update(theta, s, v_new if step.implicit_state else v, dt)
    return x_new, v_new, s_new, f_now


def motion_start(step, theta, mass, force, dt, x0, v0, state0):
    """The free run's inputs in one dtype (the force's and theta's, at least float) and its
    initial state ``(x0, v0, friction state)``; the friction state defaults to
    ``step.init(theta, v0, dt)``."""
    force = jnp.asarray(force)
    dtype = jnp.result_type(force, jnp.asarray(theta), float)
    force = force.astype(dtype)
    dt = jnp.asarray(dt, dtype)
    inv_m = 1.0 / jnp.asarray(mass, dtype)
    x0, v0 = jnp.asarray(x0, dtype), jnp.asarray(v0, dtype)
    s0 = step.init(theta, v0, dt) if state0 is None else state0
    return force, dt, inv_m, x0, v0, s0


def simulate_motion(step: FrictionStep, theta, mass, force, dt, x0, v0, state0=None) -> dict:
    """Free-run position, velocity and friction for the net force ``force`` [N], §13.2.

    ``step``: [`jaxfric.motion.friction_step`][jaxfric.motion.friction_step] of the model; ``theta``: its search
    vector; ``mass`` [kg]; ``force``: ``(T,)`` net force u_k = F_act - F_load held over
    each sample; ``dt`` [s]; ``x0`` [m], ``v0`` [m/s]: state at sample 0; ``state0``:
    friction state (default ``step.init(theta, v0)``). Returns ``{"x", "v", "friction"}``,
    each ``(T,)``, sample k before the step driven by ``force[k]``. Pure JAX: jit,
    grad and vmap work.
    """
    force, dt, inv_m, x0, v0, s0 = motion_start(step, theta, mass, force, dt, x0, v0, state0)

    def body(carry, u):
        x, v, s = carry
        x, v_next, s, f = advance_motion(step, theta, inv_m, dt, x, v, s, u)
        return (x, v_next, s), (carry[0], v, f)

    _, (x, v, f) = jax.lax.scan(body, (x0, v0, s0), force)
    return {"x": x, "v": v, "friction": f}


def track_states(step: FrictionStep, theta, velocity, dt):
    """Friction states s_0..s_{T-1} along a measured velocity record, advanced as
    [`simulate_motion`][jaxfric.motion.simulate_motion] advances them (so a simulation started at sample j from
    ``states[j]`` continues consistently). Returns a pytree with a leading ``T`` axis."""
    velocity = jnp.asarray(velocity)
    s0 = step.init(theta, velocity[0], dt)
    ahead = jnp.concatenate([velocity[1:], velocity[-1:]])

    def body(s, vv):
        v, v_next = vv
        s_new = step.update(theta, s, v_next if step.implicit_state else v, dt)
        return s_new, s

    _, states = jax.lax.scan(body, s0, (velocity, ahead))
    return states


def k_step_positions(step: FrictionStep, theta, mass, force, dt, x, v, states, horizon: int) -> Array:
    """k-step-ahead position predictions (MATLAB ``compare(..., k)``), §13.2.

    From every sample j (position ``x[j]``, velocity ``v[j]``, friction state
    ``states[j]``, all measured or estimated) simulate ``horizon`` samples with the
    measured force and return the predicted ``x[j + horizon]`` for
    j = 0 .. T - horizon - 1, shape ``(T - horizon,)``. Vectorised over the starts.
    """
    force = jnp.asarray(force)
    n = force.shape[0] - horizon
    if n < 1:
        raise ValueError(f"horizon {horizon} must be shorter than the record ({force.shape[0]} samples)")
    dtype = jnp.result_type(force, jnp.asarray(theta), float)
    dt = jnp.asarray(dt, dtype)
    inv_m = 1.0 / jnp.asarray(mass, dtype)
    windows = force[jnp.arange(n)[:, None] + jnp.arange(horizon)[None, :]].astype(dtype)
    start = jax.tree_util.tree_map(lambda a: a[:n], states)

    def one(u_win, x0, v0, s0):
        def body(carry, u):
            xk, vk, sk = carry
            xk, vk, sk, _ = advance_motion(step, theta, inv_m, dt, xk, vk, sk, u)
            return (xk, vk, sk), None

        (xk, _, _), _ = jax.lax.scan(body, (x0, v0, s0), u_win)
        return xk

    return jax.vmap(one)(windows, jnp.asarray(x[:n], dtype), jnp.asarray(v[:n], dtype), start)


def motion_prediction(step: FrictionStep, theta, mass, force, dt, x, v, dv0, horizon: int | None):
    """``(x̂, v̂, x, v)``: what a motion cost compares, §13.2. ``horizon=None``: the free
    run from the first measured sample (its velocity shifted by ``dv0``) against the whole
    record; an int ``h``: the h-step-ahead positions from tracked friction states
    against ``x[h:]``, with no velocity (``None``). The one prediction behind the
    free-run and k-step cost (``MotionCost``) and the residuals of a fit's uncertainty
    (``MotionResiduals``), which weigh the errors each their own way."""
    if horizon is None:
        out = simulate_motion(step, theta, mass, force, dt, x[0], v[0] + dv0)
        return out["x"], out["v"], x, v
    states = track_states(step, theta, v, dt)
    return k_step_positions(step, theta, mass, force, dt, x, v, states, horizon), None, x[horizon:], None
