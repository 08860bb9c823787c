"""The friction models' time loops, compiled the way each platform runs them fastest.

A rollout is a loop over samples. On a CPU a step of ``lax.scan`` costs little to
start. On a GPU each step is at least one kernel launch: on an H100 a 1600-sample
Elman rollout took 19-22 ms at ``unroll`` 1-2, whether it held 1 candidate or 4096
(``benchmarks/results/peers_gpu.md``). The model code is traced once. The loop's
form is chosen when it is lowered for a platform, through
``jax.lax.platform_dependent``, so the same program is right wherever it runs. That
covers ``jax.default_device``, arrays committed to a CPU on a GPU machine, and
ahead-of-time lowering. The branch for the other platform is folded away by XLA.

* :func:`time_scan` (nonlinear recurrences: the Elman networks). Off the CPU it
  unrolls :data:`ACCELERATOR_UNROLL` steps per loop iteration. On the H100 that took
  the rollout above to 1.1 ms (1 candidate), 1.5 ms (64) and 2.3 ms (4096). On the
  CPU it keeps the model's own choice.
* :func:`linear_recurrence` (``z_{k+1} = d_k z_k + g_k``: LuGre and Dahl's exact
  update). Off the CPU it runs as an associative (parallel-prefix) scan of ``log2 T``
  levels: 0.15 ms against 23 ms for the sequential scan on the H100, equal to 5e-15
  relative in float64 and 4e-6 in float32. On the CPU the sequential scan stays:
  the prefix scan does twice the arithmetic there and ran 2x slower.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree
from jaxtyping import Array

#: ``lax.scan`` unroll of nonlinear time loops on GPUs and other accelerators. On the
#: H100 32 was within 10 % of the best of 1-64 for 1, 64 and 4096 candidates (64 was
#: no better at 4096 and compiles longer).
ACCELERATOR_UNROLL = 32


def time_scan(step: Callable, init, xs, cpu_unroll: int, unroll: int | None = None):
    """``lax.scan(step, init, xs)`` over time: unrolled ``unroll`` times if given,
    else ``cpu_unroll`` on the CPU and :data:`ACCELERATOR_UNROLL` elsewhere.
    Returns the stacked outputs only."""

    def scan_with(k):
        return lambda c, x: jax.lax.scan(step, c, x, unroll=k)[1]

    if unroll is not None:
        return scan_with(unroll)(init, xs)
    return jax.lax.platform_dependent(
        init, xs, cpu=scan_with(cpu_unroll), default=scan_with(ACCELERATOR_UNROLL)
    )


def linear_recurrence_sequential(decay, gain, z0):
    """States ``z_0 .. z_{T-1}`` of ``z_{k+1} = decay_k z_k + gain_k`` (shape ``(P, T)``;
    ``z0``: ``(P,)``), one step after another in ``lax.scan``."""

    def step(z, coeffs):
        d, c = coeffs
        return d * z + c, z

    # (T, P) scan inputs: candidates on the fast axis, as in the Elman rollout.
    _, z = jax.lax.scan(step, z0, (decay.T, gain.T))
    return z.T


def linear_recurrence_parallel(decay, gain, z0):
    """:func:`linear_recurrence_sequential` as an associative scan over time.

    Step k is the affine map ``z ↦ d_k z + g_k``. Composing step i and then step j gives
    ``(d_i d_j, d_j g_i + g_j)``, so ``lax.associative_scan`` yields the maps from z_0 to
    every z_{k+1} in ``log2 T`` levels. With ``0 ≤ d ≤ 1`` (bristle models) the products
    only shrink, so nothing overflows; they may underflow to 0, which is then exact.
    """

    def compose(first, then):
        return first[0] * then[0], then[0] * first[1] + then[1]

    d, g = jax.lax.associative_scan(compose, (decay, gain), axis=1)
    after = d * z0[:, None] + g  # z_1 .. z_T
    return jnp.concatenate([z0[:, None], after[:, :-1]], axis=1)


def linear_recurrence(decay, gain, z0):
    """States of ``z_{k+1} = decay_k z_k + gain_k``: sequential on the CPU, an
    associative scan elsewhere (module docstring)."""
    return jax.lax.platform_dependent(
        decay, gain, z0, cpu=linear_recurrence_sequential, default=linear_recurrence_parallel
    )


def reverse_affine_scan(step: Callable, init, xs, affine: Callable, outputs: Callable,
                        cpu_unroll: int, unroll: int | None = None, parallel: bool | None = None):
    """Outputs of a loop run backwards in time from ``λ_T = init`` whose carry follows an
    affine recurrence (an adjoint, for instance)::

        λ_k, out_k = step(λ_{k+1}, x_k),      λ_k = d_k λ_{k+1} + g_k

    On the CPU ``step`` runs one sample after another (the reversed record through
    :func:`time_scan`). Elsewhere ``affine(xs)`` gives ``(d, g)`` (time first, then the
    carry's shape), :func:`linear_recurrence_parallel` composes the steps in ``log2 T``
    levels and ``outputs(λ_next, xs)`` computes every ``out_k`` from ``λ_{k+1}`` at once;
    that equals the loop up to floating-point reassociation. ``parallel``: ``True`` or
    ``False`` picks one form everywhere (``None``: by platform, as above). Returns the
    ``out_k`` stacked on a leading time axis, in time order.
    """

    def on_cpu(init, xs):
        rev = jax.tree_util.tree_map(lambda x: x[::-1], xs)
        out = time_scan(step, init, rev, cpu_unroll, unroll)
        return jax.tree_util.tree_map(lambda x: x[::-1], out)

    def run_parallel(init, xs):
        d, g = affine(xs)
        flat = (d.reshape(d.shape[0], -1)[::-1].T, g.reshape(g.shape[0], -1)[::-1].T)
        z = linear_recurrence_parallel(*flat, init.reshape(-1))  # (P, T): λ_T .. λ_1
        return outputs(z[:, ::-1].T.reshape(d.shape), xs)

    if parallel is not None:
        return (run_parallel if parallel else on_cpu)(init, xs)
    return jax.lax.platform_dependent(init, xs, cpu=on_cpu, default=run_parallel)



#: Newton iterations of :func:`elementwise_scan` off the CPU before the sequential loop
#: answers instead: a contracting network converges in 4-5 (benchmarks/results/parallel_scan*.md).
ELEMENTWISE_NEWTON_ITERATIONS = 30


def elementwise_scan(step: Callable, init, xs, outputs: Callable, cpu_unroll: int,
                     unroll: int | None = None, parallel: bool | None = None):
    """The stacked outputs of ``lax.scan(step, init, xs)`` for a recurrence whose carry is
    one array and whose step acts on each entry separately (diagonal Jacobian), as the
    Elman network's contexts ``c_{k+1} = α c_k + tanh(w u_k + r c_k + b)``.

    On the CPU ``step`` runs one sample after another (:func:`time_scan`). Elsewhere the
    carries come from Newton's method over the whole record (:func:`deer_scan`,
    elementwise, tolerance ``sqrt(eps)`` per entry, then the sequential loop if it has not
    converged in :data:`ELEMENTWISE_NEWTON_ITERATIONS`), and ``outputs(carries, xs)`` gives
    every output at once from the carries *before* each step. ``parallel``: ``True`` or
    ``False`` picks one form everywhere (``None``: by platform).
    """

    def on_cpu(init, xs):
        return time_scan(step, init, xs, cpu_unroll, unroll)

    def run_parallel(init, xs):
        info = deer_scan(lambda c, x: step(c, x)[0], init, xs, jacobian="elementwise",
                         max_iterations=ELEMENTWISE_NEWTON_ITERATIONS)
        before = jnp.concatenate([init[None], info.states[:-1]], axis=0)
        return outputs(before, xs)

    if parallel is not None:
        return (run_parallel if parallel else on_cpu)(init, xs)
    return jax.lax.platform_dependent(init, xs, cpu=on_cpu, default=run_parallel)

# ------------------------------------------------- parallel in time (jaxfric.parallel_scan)
#: Newton's method on a whole trajectory (DEER, Lim et al. 2024): the docstring of
#: :mod:`jaxfric.parallel_scan` gives the method, its exactness and when it pays off.
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

        def sequential(_):
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
