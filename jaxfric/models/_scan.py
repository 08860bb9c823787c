"""The friction models' time loops, compiled the way each platform runs them fastest.

A rollout is a loop over samples. On a CPU a step of ``lax.scan`` costs little to
start; on a GPU each step is at least one kernel launch. The model code is traced once.
The loop's form is chosen when it is lowered for a platform, through
``jax.lax.platform_dependent``, so the same program is right wherever it runs. That
covers ``jax.default_device``, arrays committed to a CPU on a GPU machine, and
ahead-of-time lowering. The branch for the other platform is folded away by XLA.

* `time_scan` (nonlinear recurrences: the Elman networks). Off the CPU it
  unrolls `ACCELERATOR_UNROLL` steps per loop iteration. On the CPU it keeps the
  model's own choice.
* `linear_recurrence` (``z_{k+1} = d_k z_k + g_k``: LuGre and Dahl's exact
  update). Off the CPU it runs as an associative (parallel-prefix) scan of ``log2 T``
  levels. On the CPU the sequential scan stays (the prefix scan does twice the
  arithmetic there).
* `reverse_affine_scan` (a loop run backwards whose carry is affine: the Elman
  network's adjoint). Off the CPU the same prefix scan; on the CPU the model's own
  loop, unchanged to the bit.

The measurements behind each choice: docs/scale.md, "Time loops per platform".
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

#: ``lax.scan`` unroll of nonlinear time loops on GPUs and other accelerators (docs/scale.md).
ACCELERATOR_UNROLL = 32


def time_loop(step: Callable, init, xs, cpu_unroll: int, unroll: int | None = None, reverse: bool = False):
    """``lax.scan(step, init, xs, reverse=reverse)`` over time: ``(final carry, stacked
    outputs)``, unrolled ``unroll`` times if given, else ``cpu_unroll`` on the CPU and
    `ACCELERATOR_UNROLL` elsewhere."""

    def scan_with(k):
        return lambda c, x: jax.lax.scan(step, c, x, unroll=k, reverse=reverse)

    if unroll is not None:
        return scan_with(unroll)(init, xs)
    return jax.lax.platform_dependent(init, xs, cpu=scan_with(cpu_unroll), default=scan_with(ACCELERATOR_UNROLL))


def time_scan(step: Callable, init, xs, cpu_unroll: int, unroll: int | None = None):
    """`time_loop` forwards, returning the stacked outputs only."""
    return time_loop(step, init, xs, cpu_unroll, unroll)[1]


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
    """`linear_recurrence_sequential` as an associative scan over time.

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
    `time_scan`). Elsewhere ``affine(xs)`` gives ``(d, g)`` (time first, then the
    carry's shape), `linear_recurrence_parallel` composes the steps in ``log2 T``
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
