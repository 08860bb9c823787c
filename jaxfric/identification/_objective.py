"""The identification cost J(θ) (docs/algorithms.md §2.4, §11 step 4).

    J(θ) = c · (1/N_train) Σ_k (y(k) − ŷ(k; θ))²

with ŷ the model's free-run (simulation) output: measured friction is never fed
back. For black-box models (``needs_scaling``: the Elman networks) ``u`` and ``y``
are velocity and friction scaled to [−1, 1] with min/max of the training window
(MATLAB ``mapminmax``, §2.4) and ``c = 1``, exactly the spec's cost. Physical
models see SI units and ``c = 1 / var(F_train)``: J is then the training MSE % of
§6 divided by 100, dimensionless and of order 1 whatever the force level, so the
optimisers' absolute tolerances mean the same thing for every rig.

The cost is a hashable ``eqx.Module`` whose only field (the model) is static, and
all data travel in :class:`CostData` through ``args``. ``jit`` therefore caches one
executable per (model configuration, solver, shapes, dtype): a new record of the
same length never recompiles.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from ..models import AbstractFrictionModel, Elman, Scaler
from ._data import Record


class CostData(eqx.Module):
    """What J needs from the record, as arrays (traced, never static).

    ``u``: model input over the training window (scaled, or m/s);
    ``y``: target over the training window (scaled, or N);
    ``dt``: sample time [s] (0-d); ``inv_norm``: the constant ``c`` above (0-d);
    ``inputs``: the model's measured channels over the training window
    (``model.input_names``, e.g. chamber pressures) or ``None``.
    """

    u: Array
    y: Array
    dt: Array
    inv_norm: Array
    inputs: Array | None = None


class OutputErrorCost(eqx.Module):
    """J(θ) of the module docstring for one model; ``cost(theta, data) -> scalar``."""

    model: AbstractFrictionModel = eqx.field(static=True)

    def residuals(self, theta, data: CostData) -> Array:
        """Residual vector ``r`` with ``Σ r² = J`` (for least-squares refinement)."""
        y_hat = self.model.simulate(theta, data.u, data.dt, data.inputs)
        scale = jnp.sqrt(data.inv_norm / data.y.shape[0])
        return (data.y - y_hat) * scale

    def __call__(self, theta, data: CostData) -> Array:
        if isinstance(self.model, Elman):
            return _elman_cost(self.model, theta, data)
        return _plain_cost(self.model, theta, data)


def _plain_cost(model, theta, data: CostData) -> Array:
    e = data.y - model.simulate(theta, data.u, data.dt, data.inputs)
    return jnp.mean(e * e) * data.inv_norm


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _elman_cost(model, theta, data: CostData) -> Array:
    """J of the Elman network, whose derivative uses the network's hand-written adjoint
    (:meth:`jaxfric.models.Elman.simulate_vjp`, 2–3× faster than JAX's reverse mode
    of the scan). Values (and ``vmap`` over candidates) take the ordinary path."""
    return _plain_cost(model, theta, data)


@_elman_cost.defjvp
def _elman_cost_jvp(model, primals, tangents):
    # dJ = ∇_θJ·dθ + ∂J/∂y·dy: linear in the tangents, so jax.linearize and its
    # transpose (what optimistix's BFGS calls) give the gradient from one forward and
    # one adjoint loop. The input u, dt and inv_norm are data, never differentiated.
    theta, data = primals
    d_theta, d_data = tangents
    y_hat, pullback = model.simulate_vjp(theta, data.u)
    e = data.y - y_hat
    n = data.y.shape[0]
    f = jnp.mean(e * e) * data.inv_norm
    g_y = (2.0 * data.inv_norm / n) * e
    grad = pullback(-g_y)
    return f, jnp.dot(grad, d_theta) + jnp.dot(g_y, d_data.y)


def search_dtype(dtype=None):
    """The floating dtype of the search: ``dtype`` or JAX's default float (float32
    unless the caller enabled x64; the library never switches it)."""
    dtype = jnp.float64 if dtype is None else dtype
    if not jnp.issubdtype(dtype, jnp.floating):
        raise ValueError(f"dtype must be a floating dtype, got {dtype!r}")
    return jax.dtypes.canonicalize_dtype(dtype)


def fit_scalers(model: AbstractFrictionModel, record: Record):
    """``(velocity_scaler, friction_scaler)`` on the training window, or ``(None, None)``
    for models that work in SI units (§2.4)."""
    if not model.needs_scaling:
        return None, None
    return Scaler.fit(record.train_velocity), Scaler.fit(record.train_friction)


def cost_data(model, record: Record, scalers, dtype) -> CostData:
    """Build :class:`CostData` for the training window in the search ``dtype``."""
    sv, sf = scalers
    v, f = record.train_velocity, record.train_friction
    if model.needs_scaling:
        # The same jnp path as Fit.predict, so training and prediction see
        # bit-identical inputs.
        u = sv.scale(jnp.asarray(v, dtype))
        y = sf.scale(jnp.asarray(f, dtype))
        inv_norm = 1.0
    else:
        u, y = v, f
        inv_norm = 1.0 / float(np.var(f))
    inputs = model.inputs_from(record, record.n_samples)
    return CostData(
        u=jnp.asarray(u, dtype),
        y=jnp.asarray(y, dtype),
        dt=jnp.asarray(record.dt, dtype),
        inv_norm=jnp.asarray(inv_norm, dtype),
        inputs=None if inputs is None else jnp.asarray(inputs[:, : record.n_train], dtype),
    )
