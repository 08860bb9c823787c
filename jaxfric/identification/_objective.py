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
all data travel in [`CostData`][jaxfric.identification.CostData] through ``args``. ``jit`` therefore caches one
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

from ..models import AbstractFrictionModel, Elman, Scaler, elman_hidden, time_loop
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
    ([`jaxfric.models.Elman.simulate_vjp`][jaxfric.models.Elman.simulate_vjp], 2–3× faster than JAX's reverse mode
    of the scan). Values (and ``vmap`` over candidates) take the ordinary path."""
    return _plain_cost(model, theta, data)


@_elman_cost.defjvp
def _elman_cost_jvp(model, primals, tangents):
    # dJ = ∇_θJ·dθ + ∂J/∂y·dy: linear in the tangents, so jax.linearize and its
    # transpose (what optimistix's BFGS calls) give the gradient from one forward and
    # one adjoint loop. The input u, dt and inv_norm are data, never differentiated.
    theta, data = primals
    d_theta, d_data = tangents
    f, grad, g_y = _elman_value_and_grad(model)(theta, data)
    return f, jnp.dot(grad, d_theta) + jnp.dot(g_y, d_data.y)


@functools.lru_cache(maxsize=None)
def _elman_value_and_grad(model):
    """``(J, ∇_θJ, ∂J/∂y)`` of one network by [`simulate_vjp`][jaxfric.models.Elman.simulate_vjp].

    Under ``vmap`` over θ (an ensemble's gradient stage runs its members' BFGS side by
    side) the batching rule runs `_elman_value_and_grad_batch` on the CPU, one loop
    for all members, instead of JAX's far slower default batching of the single-network
    loops (docs/algorithms.md §2.2, "measured"); other platforms take JAX's batching
    (the comment in the rule says why).
    """

    def single(theta, data):
        y_hat, pullback = model.simulate_vjp(theta, data.u)
        e = data.y - y_hat
        n = data.y.shape[0]
        f = jnp.mean(e * e) * data.inv_norm
        g_y = (2.0 * data.inv_norm / n) * e
        return f, pullback(-g_y), g_y

    value_and_grad = jax.custom_batching.custom_vmap(single)

    @value_and_grad.def_vmap
    def _batched(axis_size, in_batched, theta, data):
        theta_batched, data_batched = in_batched
        if any(jax.tree_util.tree_leaves(data_batched)):
            # Members with data of their own: each runs its own loops.
            data_axes = jax.tree_util.tree_map(lambda b: 0 if b else None, data_batched)
            out = jax.lax.map(lambda a: value_and_grad(*a), (
                theta if theta_batched else jnp.broadcast_to(theta, (axis_size,) + theta.shape),
                jax.tree_util.tree_map(
                    lambda x, ax: x if ax == 0 else jnp.broadcast_to(x, (axis_size,) + jnp.shape(x)),
                    data, data_axes)))
            return out, (True, True, True)
        if not theta_batched:
            theta = jnp.broadcast_to(theta, (axis_size,) + theta.shape)
        # Off the CPU, JAX's batching of the single network's loops: its adjoint runs as a
        # parallel prefix scan there (models/_scan.py), where the blocked batch below
        # would run two more sequential passes; memory is K·N·T per array, which a GPU holds.
        out = jax.lax.platform_dependent(
            theta, data, cpu=functools.partial(_elman_value_and_grad_batch, model),
            default=jax.vmap(single, in_axes=(0, None)))
        return out, (True, True, True)

    return value_and_grad


#: Time samples per block of `_elman_value_and_grad_batch`: a block's
#: ``(TIME_BLOCK, K·N)`` arrays stay in the CPU's cache (30 neurons, 8 networks: 120 kB
#: each in float32), where whole-record arrays (19 MB each on EMPS) made the
#: vectorised parts bound by memory traffic.
TIME_BLOCK = 128


def _elman_value_and_grad_batch(model: Elman, thetas, data: CostData, block: int = TIME_BLOCK):
    """``(J, ∇_θJ, ∂J/∂y)`` of ``K`` networks on one record, each with a leading ``K`` axis.

    The forward and reverse equations of [`jaxfric.models.Elman.simulate_vjp`][jaxfric.models.Elman.simulate_vjp]
    (docs/algorithms.md §2.2) for K networks at once, their contexts carried as one flat
    ``(K·N,)`` vector. Time runs in blocks of ``block`` samples. The forward pass keeps only
    each block's first context and the outputs; the reverse pass recomputes a block's
    contexts from its first one, then h_k, δ_k and the block's share of the sums
    vectorised around a loop that carries λ alone. Nothing of size ``T × K·N`` is
    stored, and each step loop writes one array: on the CPU a step loop that wrote
    several arrays ran several times slower, and whole-record temporaries were bound
    by memory traffic.
    """
    u = jnp.asarray(data.u)
    k_members, n_neurons, t = thetas.shape[0], model.neurons, u.shape[0]
    p = model.to_physical(thetas)
    w, r, b, v, alpha, c0 = (p[name].reshape(-1) for name in model._BLOCKS)  # (K·N,)
    n_blocks = -(-t // block)
    pad = n_blocks * block - t
    u_b = jnp.pad(u, (0, pad)).reshape(n_blocks, block)
    y_b = jnp.pad(data.y, (0, pad)).reshape(n_blocks, block)
    kept = (jnp.arange(n_blocks * block) < t).reshape(n_blocks, block, 1)

    def context(c, uk):
        return alpha * c + elman_hidden(uk, c, w, r, b)

    def forward_block(c, u_blk):
        def step(c, uk):
            h = elman_hidden(uk, c, w, r, b)
            return alpha * c + h, jnp.sum((v * h).reshape(k_members, n_neurons), axis=1)

        c_next, y = _time_loop(model, step, c, u_blk)
        return c_next, (c, y)

    _, (starts, y_hat) = jax.lax.scan(forward_block, c0, u_b)  # (B, K·N), (B, block, K)
    if model.output_bias:
        y_hat = y_hat + p["b_o"]
    e = jnp.where(kept, y_b[..., None] - y_hat, 0.0)
    f = jnp.sum(e * e, axis=(0, 1)) / t * data.inv_norm
    g_y = (2.0 * data.inv_norm / t) * e
    gy = -g_y
    ones = jnp.ones((block,), u.dtype)  # column sums as dot products (BLAS)

    def backward_block(carry, blk):
        lam, d_w, d_r, d_b, d_v, d_alpha = carry
        start, gy_blk, u_blk = blk
        _, cs = _time_loop(model, lambda c, uk: (context(c, uk), c), start, u_blk)
        hs = elman_hidden(u_blk[:, None], cs, w, r, b)
        g = jnp.broadcast_to(gy_blk[:, :, None], gy_blk.shape + (n_neurons,)).reshape(block, -1)
        a, slope = v * g, 1.0 - hs * hs
        lam, lam_next = _time_loop(
            model, lambda lam, x: (alpha * lam + r * ((x[0] + lam) * x[1]), lam), lam, (a, slope),
            reverse=True)
        delta = (a + lam_next) * slope
        return (lam, d_w + u_blk @ delta, d_r + ones @ (delta * cs), d_b + ones @ delta,
                d_v + ones @ (g * hs), d_alpha + ones @ (lam_next * cs)), None

    zero = jnp.zeros_like(c0)
    (lam0, d_w, d_r, d_b, d_v, d_alpha), _ = jax.lax.scan(
        backward_block, (zero,) * 6, (starts, gy, u_b), reverse=True)
    flat = {"w": d_w, "r": d_r, "b": d_b, "v": d_v, "alpha": d_alpha, "c0": lam0}
    grads = {name: x.reshape(k_members, n_neurons) for name, x in flat.items()}
    if model.output_bias:
        grads["b_o"] = jnp.sum(gy, axis=(0, 1))
    return f, model.from_physical(**grads), g_y.reshape(n_blocks * block, k_members)[:t].T


def _time_loop(model, step, init, xs, reverse=False):
    """``(final carry, outputs)`` of ``step`` over time (`jaxfric.models.time_loop`),
    unrolled as the model says, else not on the CPU (docs/algorithms.md §2.2, "measured")."""
    return time_loop(step, init, xs, 1, model.unroll, reverse)


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
    """Build [`CostData`][jaxfric.identification.CostData] for the training window in the search ``dtype``."""
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
    return CostData(u=jnp.asarray(u, dtype), y=jnp.asarray(y, dtype), dt=jnp.asarray(record.dt, dtype),
                    inv_norm=jnp.asarray(inv_norm, dtype),
                    inputs=None if inputs is None else jnp.asarray(inputs[:, : record.n_train], dtype))
