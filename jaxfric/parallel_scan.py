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
tolerance. [`DeerResult`][jaxfric.parallel_scan.DeerResult] says which happened.

Two Jacobian forms:

* ``"dense"``: the n × n Jacobian by ``jax.jacfwd`` (the motion models' 2-3 states);
* ``"elementwise"``: the step acts on each state entry separately (the diagonal Elman
  network's contexts, one per neuron and candidate), so the Jacobian is diagonal and
  one ``jax.jvp`` with a vector of ones gives it; the scan then multiplies vectors.

On a CPU the sequential scan does T steps of little work each, and stays faster
(``benchmarks/results/parallel_scan.md``); this is for accelerators and long records.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree
from jaxtyping import Array

from .models import time_scan

__all__ = ["DeerResult", "deer_scan", "elman_rollout", "simulate_motion_parallel"]

JACOBIANS = ("dense", "elementwise")


class DeerResult(NamedTuple):
    """States after each step (a pytree like the carry with a leading ``T`` axis, as
    ``lax.scan``'s stacked carries), the Newton ``iterations`` taken, whether they
    ``converged`` and whether the sequential scan was used instead (``fell_back``)."""

    states: Any
    iterations: Array
    converged: Array
    fell_back: Array


def _default_rtol(dtype) -> float:
    # sqrt(eps): one more quadratic step after the update fell below it leaves ~eps.
    return float(jnp.finfo(dtype).eps) ** 0.5


def _compose(first, then, elementwise: bool):
    """The affine map ``then ∘ first`` of ``s ↦ A s + b`` pairs (leading axes batched)."""
    a1, b1 = first
    a2, b2 = then
    if elementwise:
        return a2 * a1, a2 * b1 + b2
    return jnp.einsum("...ij,...jk->...ik", a2, a1), jnp.einsum("...ij,...j->...i", a2, b1) + b2


def linear_solve(jac, bias, s0, elementwise: bool):
    """States ``s_1 .. s_T`` of ``s_{k+1} = J_k s_k + b_k`` by an associative scan over time.

    ``jac``: ``(T, n)`` (elementwise) or ``(T, n, n)``; ``bias``: ``(T, n)``; ``s0``: ``(n,)``.
    """
    a, c = jax.lax.associative_scan(lambda p, q: _compose(p, q, elementwise), (jac, bias), axis=0)
    if elementwise:
        return a * s0 + c
    return jnp.einsum("tij,j->ti", a, s0) + c


def deer_scan(step: Callable, init, xs, *, jacobian: str = "dense", rtol: float | None = None,
              max_iterations: int | None = None, fallback: bool = True,
              chunk: int | None = None) -> DeerResult:
    """The carries of ``lax.scan(lambda c, x: (step(c, x), None), init, xs)`` after every
    step, computed by Newton iterations over the whole trajectory (module docstring).

    Args:
        step: ``step(carry, x) -> carry`` (a pytree of floating arrays, same structure).
        init: the carry ``s_0``.
        xs: the inputs, a pytree with a leading time axis ``T``.
        jacobian: ``"dense"`` (``jax.jacfwd``; for small states) or ``"elementwise"``
            (the step's Jacobian is diagonal: entry i of the new carry depends on entry
            i of the old one only; not checked).
        rtol: per-component tolerance on the last Newton update (default
            ``sqrt(eps)`` of the carry's dtype).
        max_iterations: Newton iterations before falling back (default ``min(T, 100)``).
        fallback: use the sequential scan when the iterations did not converge or an
            iterate is not finite; ``False`` returns the last iterate as it is.
        chunk: solve ``chunk`` steps at a time, one stretch after another, each from the
            last state of the one before (``None``: the whole record at once). Newton then
            sees a shorter horizon; ``iterations`` sums over the chunks, ``converged`` is
            whether all did, ``fell_back`` whether any did not.
    """
    if jacobian not in JACOBIANS:
        raise ValueError(f"jacobian must be one of {JACOBIANS}, got {jacobian!r}")
    s0, unravel = ravel_pytree(init)
    if not jnp.issubdtype(s0.dtype, jnp.floating):
        raise ValueError(f"the carry must hold floating arrays, got dtype {s0.dtype}")
    leaves = jax.tree_util.tree_leaves(xs)
    if not leaves:
        raise ValueError("xs must hold at least one array with a leading time axis")
    T = leaves[0].shape[0]
    if T == 0:
        raise ValueError("xs is empty: nothing to scan")
    elementwise = jacobian == "elementwise"
    tol = _default_rtol(s0.dtype) if rtol is None else float(rtol)
    if not tol > 0:
        raise ValueError(f"rtol must be positive, got {rtol!r}")
    iters = min(T, 100) if max_iterations is None else int(max_iterations)
    if iters < 1:
        raise ValueError(f"max_iterations must be >= 1, got {max_iterations!r}")
    if chunk is not None and (isinstance(chunk, bool) or int(chunk) < 1):
        raise ValueError(f"chunk must be None or >= 1, got {chunk!r}")
    chunk = None if chunk is None else int(chunk)

    def f(s, x):
        out, _ = ravel_pytree(step(unravel(s), x))
        return out.astype(s0.dtype)

    if elementwise:
        def linearise(s, x):
            value, slope = jax.jvp(lambda z: f(z, x), (s,), (jnp.ones_like(s),))
            return value, slope
    else:
        def linearise(s, x):
            return f(s, x), jax.jacfwd(f)(s, x)

    def solve(first, xc):
        """Newton over one stretch of inputs from the state ``first``; returns the states,
        the iterations, whether they converged and whether the scan answered instead."""
        n = jax.tree_util.tree_leaves(xc)[0].shape[0]

        def newton(states):
            # In correction form: the scan carries the change δ_k (δ_0 = 0) driven by the
            # residual f(s_k) - s_{k+1}, which goes to 0, so its rounding shrinks with it;
            # scanning the states themselves (bias f - J s) left a floor of 1e-8 relative
            # in the velocity of a Stribeck motion model, 1e4 times the problem's own.
            prev = jnp.concatenate([first[None], states[:-1]], axis=0)
            value, jac = jax.vmap(linearise)(prev, xc)
            return states + linear_solve(jac, value - states, jnp.zeros_like(first), elementwise)

        def cond(carry):
            i, _, done, finite = carry
            return (i < min(iters, n)) & ~done & finite

        def body(carry):
            i, states, _, _ = carry
            new = newton(states)
            moved = jnp.max(jnp.abs(new - states), axis=0)
            scale = jnp.max(jnp.abs(new), axis=0)
            finite = jnp.all(jnp.isfinite(new))
            done = finite & jnp.all(moved <= tol * scale + tiny)
            return i + 1, new, done, finite

        guess = jnp.broadcast_to(first, (n,) + first.shape)
        i, states, converged, _ = jax.lax.while_loop(
            cond, body, (jnp.asarray(0), guess, jnp.asarray(False), jnp.asarray(True)))

        def sequential(_):  # unrolled off the CPU like every time loop (models/_scan.py)
            def one(c, x):
                nxt = f(c, x)
                return nxt, nxt

            return time_scan(one, first, xc, cpu_unroll=1)

        fell_back = jnp.asarray(False)
        if fallback:
            fell_back = ~converged
            states = jax.lax.cond(converged, lambda _: states, sequential, None)
        return states, i, converged, fell_back

    tiny = jnp.finfo(s0.dtype).tiny
    if chunk is None or chunk >= T:
        states, i, converged, fell_back = solve(s0, xs)
    else:
        # Chunks one after another, each from the last state of the one before: a shorter
        # horizon for Newton (fewer stick-slip events, less growth of the linearised
        # error). The tail is padded with the last input; padded steps come after every
        # real one, so they change none of them, and are dropped.
        count = -(-T // chunk)
        pad = count * chunk - T
        xs_c = jax.tree_util.tree_map(
            lambda a: jnp.concatenate([a, jnp.repeat(a[-1:], pad, axis=0)]).reshape(
                (count, chunk) + a.shape[1:]), xs)

        def over_chunks(first, xc):
            st, it, conv, fb = solve(first, xc)
            return st[-1], (st, it, conv, fb)

        _, (st, its, convs, fbs) = jax.lax.scan(over_chunks, s0, xs_c)
        states = st.reshape((count * chunk,) + s0.shape)[:T]
        i, converged, fell_back = jnp.sum(its), jnp.all(convs), jnp.any(fbs)
    return DeerResult(jax.vmap(unravel)(states), i, converged, fell_back)


# ------------------------------------------------------------------ the models
def elman_rollout(model, thetas, velocity, *, rtol: float | None = None,
                  max_iterations: int | None = None, fallback: bool = True,
                  chunk: int | None = None, return_info: bool = False):
    """[`jaxfric.models.Elman.simulate_batch`][jaxfric.models.AbstractFrictionModel.simulate_batch] (docs/algorithms.md §2.2) with the
    context recurrence ``c_{k+1} = α c_k + tanh(w u_k + r c_k + b)`` solved by
    [`deer_scan`][jaxfric.parallel_scan.deer_scan] (elementwise: each neuron's context of each candidate is its own
    scalar recurrence, Jacobian ``α + r (1 - h²)``). Returns ``(P, T)`` outputs (and the
    [`DeerResult`][jaxfric.parallel_scan.DeerResult] with ``return_info``)."""
    from .models import Elman, elman_hidden

    if type(model) is not Elman:
        raise ValueError(f"elman_rollout takes a jaxfric.models.Elman, got {type(model).__name__}")
    thetas, u = model._prepare(thetas, velocity)
    p = model.to_physical(thetas)
    shape = (model.neurons, thetas.shape[0])
    w, r, b, v, alpha, c0 = (p[k].T.reshape(-1) for k in model._BLOCKS)

    def step(c, uk):
        return alpha * c + elman_hidden(uk, c, w, r, b)

    info = deer_scan(step, c0, u, jacobian="elementwise", rtol=rtol, max_iterations=max_iterations,
                     fallback=fallback, chunk=chunk)
    prev = jnp.concatenate([c0[None], info.states[:-1]], axis=0)  # c_0 .. c_{T-1}
    h = elman_hidden(u[:, None], prev, w, r, b)
    y = jnp.sum((v * h).reshape((u.shape[0],) + shape), axis=1).T
    if model.output_bias:
        y = y + p["b_o"][:, None]
    return (y, info) if return_info else y


def simulate_motion_parallel(step, theta, mass, force, dt, x0, v0, state0=None, *,
                             rtol: float | None = None, max_iterations: int | None = None,
                             fallback: bool = True, chunk: int | None = None,
                             return_info: bool = False):
    """[`jaxfric.motion.simulate_motion`][jaxfric.motion.simulate_motion] (docs/algorithms.md §13.2) with the state
    ``(x, v, friction state)`` -- 2 states for static maps, 3 for LuGre and Dahl --
    solved by [`deer_scan`][jaxfric.parallel_scan.deer_scan] with dense Jacobians. Same arguments and outputs
    (``{"x", "v", "friction"}``, sample k before the step driven by ``force[k]``)."""
    from .motion import advance_motion, motion_start

    force, dt, inv_m, x0, v0, s0 = motion_start(step, theta, mass, force, dt, x0, v0, state0)

    def one(carry, u):
        x, v, s = carry
        x, v, s, _ = advance_motion(step, theta, inv_m, dt, x, v, s, u)
        return x, v, s

    info = deer_scan(one, (x0, v0, s0), force, jacobian="dense", rtol=rtol,
                     max_iterations=max_iterations, fallback=fallback, chunk=chunk)
    prev = jax.tree_util.tree_map(lambda first, rest: jnp.concatenate([first[None], rest[:-1]], axis=0),
                                  (x0, v0, s0), info.states)
    x, v, s = prev
    friction = jax.vmap(lambda si, vi: step.output(theta, si, vi, dt))(s, v)
    out = {"x": x, "v": v, "friction": friction}
    return (out, info) if return_info else out
