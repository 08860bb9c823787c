"""Recurrences evaluated in parallel over time: Newton's method on the whole trajectory.

A time loop ``s_{k+1} = f(s_k, x_k)`` (k = 0 .. T-1, ``s_0`` given) is a chain of T
dependent steps: ``lax.scan`` runs them one after another, which on a GPU is T tiny
kernels. DEER (Lim et al., "Parallelizing non-linear sequential models over the
sequence length", ICLR 2024) and its quasi-Newton relatives (Gonzalez et al., "Towards
scalable and stable parallelization of nonlinear RNNs", NeurIPS 2024) solve for all
states at once (docs/algorithms.md, "Parallel-in-time evaluation"):

    guess S = (s_1 .. s_T); repeat
        J_k = ∂f/∂s (s_k, x_k),   r_k = f(s_k, x_k) - s_{k+1}        (all k at once)
        S  <- S + δ,  δ the solution of the *linear* recurrence δ_{k+1} = J_k δ_k + r_k, δ_0 = 0

and the linear recurrence is a parallel prefix (``lax.associative_scan``) over the
affine maps ``δ ↦ J_k δ + r_k``: composing them costs ``log2 T`` levels of
matrix products. This is Newton's method on the residual ``s_{k+1} - f(s_k, x_k)``, so
it converges quadratically near the solution, and after ``i`` iterations at least the
first ``i`` states are exact (the first linearisation is exact at s_0, and so on), so
it terminates in at most T iterations whatever the guess.

Exactness: iterations stop when every state component moved by at most ``rtol`` times
that component's largest magnitude over the record (per component, because a position
in metres and a bristle deflection of 1e-6 m share one state vector); the last Newton
update then leaves an error of order ``rtol²`` (quadratic convergence). If that has
not happened after ``max_iterations``, or an iterate is not finite (an unstable
linearisation can overflow), the sequential ``lax.scan`` computes the answer instead
(``fallback=True``, the default), so the result is always the sequential one to the
tolerance. :class:`DeerResult` says which happened.

Two Jacobian forms:

* ``"dense"``: the n × n Jacobian by ``jax.jacfwd`` (the motion models' 2-3 states);
* ``"elementwise"``: the step acts on each state entry separately (the diagonal Elman
  network's contexts, one per neuron and candidate), so the Jacobian is diagonal and
  one ``jax.jvp`` with a vector of ones gives it; the scan then multiplies vectors.

On a CPU the sequential scan does T steps of little work each, and stays faster
(``benchmarks/results/parallel_scan.md``); this is for accelerators and long records.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .models._scan import JACOBIANS, DeerResult, deer_scan, linear_solve

__all__ = ["JACOBIANS", "DeerResult", "deer_scan", "linear_solve", "elman_rollout",
           "simulate_motion_parallel"]


# ------------------------------------------------------------------ the models
def elman_rollout(model, thetas, velocity, *, rtol: float | None = None,
                  max_iterations: int | None = None, fallback: bool = True,
                  chunk: int | None = None, return_info: bool = False):
    """:meth:`jaxfric.models.Elman.simulate_batch` (docs/algorithms.md §2.2) with the
    context recurrence ``c_{k+1} = α c_k + tanh(w u_k + r c_k + b)`` solved by
    :func:`deer_scan` (elementwise: each neuron's context of each candidate is its own
    scalar recurrence, Jacobian ``α + r (1 - h²)``). Returns ``(P, T)`` outputs (and the
    :class:`DeerResult` with ``return_info``)."""
    from .models import Elman

    if type(model) is not Elman:
        raise ValueError(f"elman_rollout takes a jaxfric.models.Elman, got {type(model).__name__}")
    thetas, u = model._prepare(thetas, velocity)
    p = model.to_physical(thetas)
    shape = (model.neurons, thetas.shape[0])
    w, r, b, v, alpha, c0 = (p[k].T.reshape(-1) for k in model._BLOCKS)

    def step(c, uk):
        return alpha * c + jnp.tanh(w * uk + r * c + b)

    info = deer_scan(step, c0, u, jacobian="elementwise", rtol=rtol, max_iterations=max_iterations,
                     fallback=fallback, chunk=chunk)
    prev = jnp.concatenate([c0[None], info.states[:-1]], axis=0)  # c_0 .. c_{T-1}
    h = jnp.tanh(w * u[:, None] + r * prev + b)
    y = jnp.sum((v * h).reshape((u.shape[0],) + shape), axis=1).T
    if model.output_bias:
        y = y + p["b_o"][:, None]
    return (y, info) if return_info else y


def simulate_motion_parallel(step, theta, mass, force, dt, x0, v0, state0=None, *,
                             rtol: float | None = None, max_iterations: int | None = None,
                             fallback: bool = True, chunk: int | None = None,
                             return_info: bool = False):
    """:func:`jaxfric.motion.simulate_motion` (docs/algorithms.md §13.2) with the state
    ``(x, v, friction state)`` -- 2 states for static maps, 3 for LuGre and Dahl --
    solved by :func:`deer_scan` with dense Jacobians. Same arguments and outputs
    (``{"x", "v", "friction"}``, sample k before the step driven by ``force[k]``)."""
    from .motion._forward import _advance, _start

    force, dt, inv_m, x0, v0, s0 = _start(step, theta, mass, force, dt, x0, v0, state0)

    def one(carry, u):
        x, v, s = carry
        x, v, s, _ = _advance(step, theta, inv_m, dt, x, v, s, u)
        return x, v, s

    info = deer_scan(one, (x0, v0, s0), force, jacobian="dense", rtol=rtol,
                     max_iterations=max_iterations, fallback=fallback, chunk=chunk)
    prev = jax.tree_util.tree_map(lambda first, rest: jnp.concatenate([first[None], rest[:-1]], axis=0),
                                  (x0, v0, s0), info.states)
    x, v, s = prev
    friction = jax.vmap(lambda si, vi: step.output(theta, si, vi, dt))(s, v)
    out = {"x": x, "v": v, "friction": friction}
    return (out, info) if return_info else out
