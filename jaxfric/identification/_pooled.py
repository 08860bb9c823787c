"""The identification cost over several training records (docs/algorithms.md §2.4, §11 step 4).

    J(θ) = c · (1/N) Σ_r Σ_k (y_r(k) − ŷ_r(k; θ))²,      N = Σ_r N_r

ŷ_r is the free-run prediction of record r, rolled out from the model's initial
state at the record's first sample: no state crosses a record boundary, since the
records were not measured back to back. J pools the squared errors of every training
sample, so a long record weighs more than a short one, exactly as if the samples
came from one record; with one record J equals [`OutputErrorCost`][jaxfric.identification.OutputErrorCost]'s.

Records keep their own lengths (a tuple of arrays in `PooledCostData`, one
rollout each), so nothing is padded and ``vmap`` over θ still reaches each model's
batched rollout. Scaling and ``c`` are those of §2.4 on the training samples of all
records together.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from ..models import AbstractFrictionModel
from ._data import RecordSet


class PooledCostData(eqx.Module):
    """Per-record model inputs ``u`` and targets ``y`` (tuples of 1-D arrays, scaled
    or SI), the shared sample time ``dt``, the constant ``c`` (``inv_norm``) and each
    record's measured channels over its training samples (``inputs``: ``(C, N_r)``
    arrays for a model with ``input_names``, else ``None`` per record)."""

    u: tuple[Array, ...]
    y: tuple[Array, ...]
    dt: Array
    inv_norm: Array
    inputs: tuple = ()


class PooledOutputErrorCost(eqx.Module):
    """J(θ) of the module docstring; ``cost(theta, data) -> scalar``."""

    model: AbstractFrictionModel = eqx.field(static=True)

    def _errors(self, theta, data: PooledCostData) -> list[Array]:
        inputs = data.inputs or (None,) * len(data.u)
        return [y - self.model.simulate(theta, u, data.dt, x) for u, y, x in zip(data.u, data.y, inputs)]

    def residuals(self, theta, data: PooledCostData) -> Array:
        """Residual vector ``r`` with ``Σ r² = J`` (for least-squares refinement)."""
        n = sum(y.shape[0] for y in data.y)
        return jnp.concatenate(self._errors(theta, data)) * jnp.sqrt(data.inv_norm / n)

    def __call__(self, theta, data: PooledCostData) -> Array:
        n = sum(y.shape[0] for y in data.y)
        total = sum(jnp.sum(e * e) for e in self._errors(theta, data))
        return total / n * data.inv_norm


def pooled_cost_data(model: AbstractFrictionModel, records: RecordSet, scalers, dtype) -> PooledCostData:
    """`PooledCostData` for the training windows of ``records`` in ``dtype``."""
    sv, sf = scalers
    us, ys, xs = [], [], []
    for r in records.train_records:
        v, f = r.train_velocity, r.train_friction
        x = model.inputs_from(r, r.n_samples)
        xs.append(None if x is None else jnp.asarray(x[:, : r.n_train], dtype))
        if model.needs_scaling:
            # the same jnp path as Fit.predict (see _objective.cost_data)
            us.append(jnp.asarray(sv.scale(jnp.asarray(v, dtype)), dtype))
            ys.append(jnp.asarray(sf.scale(jnp.asarray(f, dtype)), dtype))
        else:
            us.append(jnp.asarray(v, dtype))
            ys.append(jnp.asarray(f, dtype))
    inv_norm = 1.0 if model.needs_scaling else 1.0 / float(np.var(records.train_friction))
    return PooledCostData(u=tuple(us), y=tuple(ys), dt=jnp.asarray(records.dt, dtype),
                          inv_norm=jnp.asarray(inv_norm, dtype), inputs=tuple(xs))
