"""Multiple shooting: the forward model with the state re-set from measurements, §13.2.

One ``lax.scan`` serves every cost of [`jaxfric.identify_motion`][jaxfric.motion.identify_motion]:

* **free run** of a record: the state is set from the measurements at the record's first
  sample only;
* **multiple shooting** with segments of ``L`` samples: the state is set again at every
  segment start, so an error made early stops feeding the later samples (a smoother,
  better-conditioned cost on a closed-loop, integrating plant);
* **several records** pooled in one call: the records are concatenated and the state is
  set at each record's first sample, so no state crosses a record boundary.

A *forced* sample ``k`` takes position and velocity from the record
(``x_k = x̃_k``, ``v_k = ṽ_k``); its friction state keeps what the scan carried, except at
a *reset* sample where it is ``step.init(theta, ṽ_k)``. Forcing ``m`` consecutive samples
before a segment start therefore *tracks* the friction state along the measured velocity
for ``m`` samples (a lead-in), as [`jaxfric.motion.track_states`][jaxfric.motion.track_states] does. Which samples
are forced and reset, and the weight of each sample's squared error, are data (arrays),
so one compiled scan serves every segment length.

The step itself is [`jaxfric.motion.simulate_motion`][jaxfric.motion.simulate_motion]'s ([`advance_motion`][jaxfric.motion.advance_motion]).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._forward import advance_motion
from ._step import FrictionStep

__all__ = ["Schedule", "shoot", "schedule"]


class Schedule(eqx.Module):
    """Per-sample arrays of one multiple-shooting layout (all ``(T,)``).

    ``forced``: take x, v from the measurement at this sample; ``reset``: also
    re-initialise the friction state (``step.init``) here; ``weight``: weight of the
    squared position error of this sample (0 on forced samples, which are exact).
    """

    forced: jax.Array
    reset: jax.Array
    weight: jax.Array


def schedule(starts, total: int, *, segment: int | None = None, lead: int = 0, weights=None,
             dtype=np.float64) -> Schedule:
    """The `Schedule` of records that begin at ``starts`` in a concatenation of
    ``total`` samples.

    Each record's first ``lead + 1`` samples are forced (its friction state starts from
    ``step.init`` and is carried along the measured velocity over them). ``segment=None``:
    then a free run to the record's end. An int ``L``: a new segment every ``L`` samples
    after the first, each with its own ``lead`` forced samples before it. ``weights``:
    per-record weight of one sample's squared error (default 1); forced samples weigh 0.
    """
    starts = [int(s) for s in starts]
    ends = starts[1:] + [int(total)]
    forced = np.zeros(total, bool)
    reset = np.zeros(total, bool)
    weight = np.zeros(total, dtype)
    for i, (a, b) in enumerate(zip(starts, ends)):
        reset[a] = True
        forced[a:min(a + lead + 1, b)] = True
        weight[a:b] = 1.0 if weights is None else weights[i]
        if segment is not None:
            for s in range(a + lead + int(segment), b, int(segment)):
                forced[max(a, s - lead):s + 1] = True
        weight[a:b][forced[a:b]] = 0.0
    return Schedule(forced=jnp.asarray(forced), reset=jnp.asarray(reset), weight=jnp.asarray(weight, dtype))


def shoot(step: FrictionStep, theta, mass, force, dt, x_meas, v_meas, plan: Schedule) -> jax.Array:
    """Positions x̂_k, ``(T,)``, of the forward model under ``plan`` (module docstring).

    ``force``: net force u_k [N] held over sample k; ``x_meas``, ``v_meas``: measured
    position [m] and (filtered) velocity [m/s] used on forced samples. Pure JAX.
    """
    force = jnp.asarray(force)
    dtype = jnp.result_type(force, jnp.asarray(theta), float)
    dt = jnp.asarray(dt, dtype)
    inv_m = 1.0 / jnp.asarray(mass, dtype)
    x_meas = jnp.asarray(x_meas, dtype)
    v_meas = jnp.asarray(v_meas, dtype)
    # the initial friction states of every sample at once (vectorised, outside the scan)
    inits = jax.vmap(lambda vm: step.init(theta, vm, dt))(v_meas)
    s0 = jax.tree_util.tree_map(lambda a: a[0], inits)

    def body(carry, inp):
        x, v, s = carry
        u, xm, vm, forced, reset, s_init = inp
        x = jnp.where(forced, xm, x)
        v = jnp.where(forced, vm, v)
        s = jax.tree_util.tree_map(lambda a, b: jnp.where(reset, a, b), s_init, s)
        x_new, v_new, s_new, _ = advance_motion(step, theta, inv_m, dt, x, v, s, u)
        return (x_new, v_new, s_new), x

    _, x_hat = jax.lax.scan(body, (x_meas[0], v_meas[0], s0),
                            (force.astype(dtype), x_meas, v_meas, plan.forced, plan.reset, inits))
    return x_hat
