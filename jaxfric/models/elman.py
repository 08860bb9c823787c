"""Elman recurrent networks as friction models (docs/algorithms.md §2).

Both networks map (scaled) piston velocity u(k) to (scaled) friction y(k) in
free run: the measured friction is never fed back (§2.4). They are fitted on
data scaled to [-1, 1] with [`jaxfric.models.Scaler`][jaxfric.models.Scaler], so
``needs_scaling = True``.

Parameter layout of ``theta`` (blocks of N, one block per kind, so the bounds
are simple and a block is a contiguous slice)::

    Elman      [ w | r | b | v | alpha | c0 ] (+ [b_o])              6N (+1)
    ElmanFull  [ w | W_c (row-major N*N) | b | v | c0 ] (+ [b_o])    N + N^2 + 3N (+1)

Performance: one scan over time with the state stored as an ``(N, P)`` array
(candidates on the fast axis, held flat in the loop) is the fastest measured form
(docs/scale.md, "Time loops per platform"). Hence [`Elman.simulate_batch`][jaxfric.models.AbstractFrictionModel.simulate_batch] is the
primitive; [`simulate`][jaxfric.models.AbstractFrictionModel.simulate] calls it with P = 1, and ``vmap(simulate)`` over
theta is routed back to it by a custom batching rule (see
[`AbstractFrictionModel.simulate`][jaxfric.models.AbstractFrictionModel.simulate]).

Dynamics: with |r| up to 5 (the §2.4 box) most random networks are chaotic
(docs/algorithms.md §2.4); ``context_weight_bound`` narrows the r box.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractFrictionModel
from ._scan import reverse_affine_scan, time_scan

__all__ = ["Elman", "ElmanFull", "elman_full_hidden", "elman_hidden"]


def elman_hidden(u, c, w, r, b):
    """The diagonal-context Elman network's hidden layer, §2.2: ``h = tanh(w u + r c + b)``,
    elementwise over any broadcastable shapes (neurons, candidates, time). The one home of
    the recurrence: the rollouts and the adjoint here, the batched cost gradient of
    ``jaxfric.identification``, the motion step and the grey-box network call it; the
    context then moves as ``c' = α c + h``.
    ``jaxfric.export`` replays it in NumPy and C, outside JAX by design."""
    return jnp.tanh(w * u + r * c + b)


def elman_full_hidden(u, c, w, W_c, b):
    """The full-context Elman network's hidden layer, §2.3: ``h = tanh(w u + W_c c + b)``
    with ``W_c`` of shape ``(..., N, N)`` (row i: the weights into hidden unit i) and
    ``c``, ``w``, ``b`` of shape ``(..., N)``; leading axes (candidates) batch. The one home
    of the recurrence: [`ElmanFull`][jaxfric.models.ElmanFull]'s batched rollout and the motion
    step call it; the context then is ``c' = h``. ``jaxfric.export`` replays it in NumPy
    and C, outside JAX by design."""
    return jnp.tanh(w * u + jnp.einsum("...ij,...j->...i", W_c, c) + b)


def _check_neurons(neurons) -> None:
    if isinstance(neurons, bool) or not isinstance(neurons, (int, np.integer)):
        raise ValueError(f"neurons must be a positive integer, got {neurons!r}")
    if neurons < 1:
        raise ValueError(f"neurons must be >= 1, got {neurons}")


def _check_positive(name: str, value: float, upper: float | None = None) -> None:
    if not np.isfinite(value) or value <= 0.0 or (upper is not None and value >= upper):
        rng = f"(0, {upper})" if upper is not None else "(0, inf)"
        raise ValueError(f"{name} must lie in {rng}, got {value!r}")


def _check_unroll(unroll) -> None:
    if unroll is not None and (isinstance(unroll, bool) or int(unroll) < 1):
        raise ValueError(f"unroll must be None or >= 1, got {unroll}")


class Elman(AbstractFrictionModel):
    """Locally recurrent (diagonal-context) Elman network, docs/algorithms.md §2.2 (Option A).

    For hidden neurons j = 1..N, with scaled velocity u(k) as input::

        h_j(k) = tanh(w_j u(k) + r_j c_j(k) + b_j)
        y(k)   = sum_j v_j h_j(k)  (+ b_o)
        c_j(k+1) = alpha_j c_j(k) + h_j(k),        c_j(1) = c0_j

    i.e. c_j(k) = alpha_j c_j(k-1) + h_j(k-1) with the initial context c0_j a
    free parameter, as the paper stresses (§2.1). Six parameters per neuron
    (w, r, b, v, alpha, c0), so 6N = 180 for N = 30; the optional output bias
    b_o adds one.

    Hyperparameters (static):
        neurons: number of hidden neurons N (>= 1).
        output_bias: include b_o (default ``False``, giving exactly 6N).
        weight_bound: |w|, |b| <= weight_bound (default 5, §2.4 table).
        context_weight_bound: |r| <= this (default 5, §2.4 table; see the
            module's dynamics note for why a smaller box may fit more easily).
        output_weight_bound: |v| <= this (default 2).
        alpha_max: alpha in [0, alpha_max] (default 0.99, keeps contexts stable).
        c0_bound: |c0| <= this (default 1); also the bound of |b_o|.
        unroll: ``lax.scan`` unroll factor of the time loop; ``None`` (default)
            picks the fastest measured: on the CPU 2 for float32 and 1 for float64,
            on a GPU or other accelerator 32 (``jaxfric.models._scan``).

    All quantities are dimensionless (scaled data, see [`Scaler`][jaxfric.models.Scaler]).
    """

    neurons: int = eqx.field(default=30, static=True)
    output_bias: bool = eqx.field(default=False, static=True)
    weight_bound: float = eqx.field(default=5.0, static=True)
    context_weight_bound: float = eqx.field(default=5.0, static=True)
    output_weight_bound: float = eqx.field(default=2.0, static=True)
    alpha_max: float = eqx.field(default=0.99, static=True)
    c0_bound: float = eqx.field(default=1.0, static=True)
    unroll: int | None = eqx.field(default=None, static=True)

    needs_scaling = True

    def __check_init__(self):
        _check_neurons(self.neurons)
        _check_positive("weight_bound", self.weight_bound)
        _check_positive("context_weight_bound", self.context_weight_bound)
        _check_positive("output_weight_bound", self.output_weight_bound)
        _check_positive("alpha_max", self.alpha_max, upper=1.0)
        _check_positive("c0_bound", self.c0_bound)
        _check_unroll(self.unroll)

    _BLOCKS = ("w", "r", "b", "v", "alpha", "c0")

    @property
    def param_names(self) -> tuple[str, ...]:
        names = tuple(f"{blk}[{j}]" for blk in self._BLOCKS for j in range(self.neurons))
        return names + (("b_o",) if self.output_bias else ())

    @property
    def num_params(self) -> int:
        return 6 * self.neurons + int(self.output_bias)

    def bounds(self, box=None) -> tuple[np.ndarray, np.ndarray]:
        """Search box of §2.4: w, r, b in ±5; v in ±2; alpha in [0, 0.99]; c0, b_o in ±1
        (set by the options; a ``box`` is refused, [`search_box`][jaxfric.models.AbstractFrictionModel.search_box])."""
        self.search_box(box)
        cb = self.c0_bound
        # per block of _BLOCKS (w, r, b, v, alpha, c0), N entries each; then b_o
        hi = (self.weight_bound, self.context_weight_bound, self.weight_bound, self.output_weight_bound,
              self.alpha_max, cb)
        lo = tuple(-h for h in hi[:4]) + (0.0, -cb)
        tail = 1 if self.output_bias else 0
        lower = np.concatenate([np.repeat(np.asarray(lo, float), self.neurons), [-cb] * tail])
        upper = np.concatenate([np.repeat(np.asarray(hi, float), self.neurons), [cb] * tail])
        return lower.astype(np.float64), upper.astype(np.float64)

    def to_physical(self, theta: Float[ArrayLike, "... n"]) -> dict[str, Array]:
        """Split ``theta`` into the named weight blocks, each of shape ``(..., N)``.

        Keys: ``w`` (input weight), ``r`` (context weight), ``b`` (hidden bias),
        ``v`` (output weight), ``alpha`` (context self-feedback), ``c0``
        (initial context) and, with ``output_bias``, ``b_o`` of shape ``(...)``.
        All dimensionless (scaled units).
        """
        theta = jnp.asarray(theta)
        n = self.neurons
        out = {name: theta[..., i * n : (i + 1) * n] for i, name in enumerate(self._BLOCKS)}
        if self.output_bias:
            out["b_o"] = theta[..., 6 * n]
        return out

    def from_physical(self, *, w, r, b, v, alpha, c0, b_o=None) -> Array:
        """Concatenate named weight blocks (each ``(..., N)``) into ``theta``."""
        blocks = [jnp.asarray(x) for x in (w, r, b, v, alpha, c0)]
        for name, x in zip(self._BLOCKS, blocks):
            if x.shape[-1:] != (self.neurons,):
                raise ValueError(f"{name} must have last axis of length {self.neurons}, got {x.shape}")
        if self.output_bias:
            if b_o is None:
                raise ValueError("this Elman has output_bias=True: pass b_o")
            blocks.append(jnp.asarray(b_o)[..., None])
        elif b_o is not None:
            raise ValueError("this Elman has output_bias=False: b_o must not be given")
        return jnp.concatenate(blocks, axis=-1)

    def _simulate_batch(self, thetas, velocity, dt=None) -> Float[Array, "P T"]:
        """Free-run outputs of ``P`` networks on one scaled velocity record (§2.2).

        One ``lax.scan`` over time carries the contexts of all candidates as one
        flat vector, the ``(N, P)`` array (candidates on the fast axis) in row-major
        order; only the output sum over neurons sees the 2-D shape. ``dt`` is
        accepted for interface uniformity and ignored (the network is a
        discrete-time map at the data's sample rate).
        """
        del dt
        thetas, u = self._prepare(thetas, velocity)
        p = self.to_physical(thetas)
        # (N, P): candidates on the fast axis vectorise best on CPU (module docstring); flattened,
        # because small 2-D states ran slower per element (benchmarks/results/peers.md, "Small ENN batches").
        shape = (self.neurons, thetas.shape[0])
        w, r, b, v, alpha, c0 = (p[k].T.reshape(-1) for k in self._BLOCKS)

        def step(c, uk):
            h = elman_hidden(uk, c, w, r, b)
            return alpha * c + h, jnp.sum((v * h).reshape(shape), axis=0)

        cpu_unroll = 1 if jnp.dtype(u.dtype).itemsize >= 8 else 2
        y = time_scan(step, c0, u, cpu_unroll, self.unroll).T
        if self.output_bias:
            y = y + p["b_o"][:, None]
        return y

    def simulate_vjp(self, theta: Float[ArrayLike, " n"], velocity: Float[ArrayLike, " T"]):
        """Free run of one network and its hand-written adjoint (BPTT, docs/algorithms.md §2.2).

        Returns ``(y, pullback)`` with ``y`` as [`simulate`][jaxfric.models.AbstractFrictionModel.simulate] and
        ``pullback(g_y) = (∂y/∂θ)ᵀ g_y``. With ``a_k = w u_k + r c_k + b``,
        ``h_k = tanh a_k``, ``c_{k+1} = α c_k + h_k`` and ``λ_k = ∂L/∂c_k``
        (``λ_T = 0``), one reverse loop runs

            δ_k = (v g_k + λ_{k+1}) (1 − h_k²),     λ_k = α λ_{k+1} + r δ_k

        and the gradient is a set of sums over time: ∂w = Σ δ_k u_k, ∂r = Σ δ_k c_k,
        ∂b = Σ δ_k, ∂v = Σ g_k h_k, ∂α = Σ λ_{k+1} c_k, ∂c0 = λ_0, ∂b_o = Σ g_k.

        Why: this loop carries only λ and leaves the sums to vectorised reductions, where
        JAX's reverse mode of the forward scan is several times slower (docs/algorithms.md
        §2.2, "measured"). The λ recurrence is
        affine, ``λ_k = (α + r s_k) λ_{k+1} + r v g_k s_k`` with ``s_k = 1 − h_k²``, so off
        the CPU it runs as a parallel prefix scan (`reverse_affine_scan`).
        """
        theta, u = self._prepare(jnp.asarray(theta)[None, :], velocity)
        p = {k: x[0] for k, x in self.to_physical(theta).items()}
        w, r, b, v, alpha, c0 = (p[k] for k in self._BLOCKS)

        def forward(c, uk):
            h = elman_hidden(uk, c, w, r, b)
            return alpha * c + h, (c, h)

        cpu_unroll = 1 if jnp.dtype(u.dtype).itemsize >= 8 else 2
        cs, hs = time_scan(forward, c0, u, cpu_unroll, self.unroll)
        y = hs @ v
        if self.output_bias:
            y = y + p["b_o"]

        def pullback(gy):
            gy = jnp.asarray(gy, u.dtype)

            def backward(lam, inputs):
                g, h = inputs
                delta = (v * g + lam) * (1.0 - h * h)
                return alpha * lam + r * delta, (delta, lam)

            def affine(inputs):  # backward's λ update as λ ↦ d_k λ + g_k
                g, h = inputs
                slope = 1.0 - h * h
                return alpha + r * slope, r * (v * g[:, None]) * slope

            def outputs(lam_next, inputs):  # backward's outputs from every λ_{k+1} at once
                g, h = inputs
                return (v * g[:, None] + lam_next) * (1.0 - h * h), lam_next

            delta, lam_next = reverse_affine_scan(backward, jnp.zeros_like(c0), (gy, hs), affine,
                                                  outputs, cpu_unroll, self.unroll)
            lam0 = alpha * lam_next[0] + r * delta[0]
            grads = {"w": u @ delta, "r": jnp.sum(delta * cs, axis=0), "b": jnp.sum(delta, axis=0),
                     "v": gy @ hs, "alpha": jnp.sum(lam_next * cs, axis=0), "c0": lam0}
            if self.output_bias:
                grads["b_o"] = jnp.sum(gy)
            return self.from_physical(**grads)

        return y, pullback


class ElmanFull(AbstractFrictionModel):
    """Classic Elman network with a full context matrix, docs/algorithms.md §2.3 (Option B)::

        h(k)   = tanh(w u(k) + W_c c(k) + b)
        y(k)   = v . h(k) + b_o
        c(k+1) = h(k),          c(1) = c0 (learned) or 0

    Parameter count N + N^2 + N + N (+ N for c0) (+ 1 for b_o): 1021 for N = 30
    with the defaults. Offered for comparison with the 6N-parameter Option A.

    Hyperparameters (static): ``neurons``; ``output_bias`` (default ``True``,
    as in MATLAB's ``elmannet``); ``learn_c0`` (default ``True``);
    ``weight_bound`` for |w|, |b| (default 5); ``context_bound`` for |W_c|
    (default 1: each hidden unit sums N context terms, so a smaller box keeps
    the pre-activations in the same range); ``output_weight_bound`` for |v|
    (default 2); ``c0_bound`` for |c0| and |b_o| (default 1); ``unroll`` of the
    time loop (default ``None``: 1 on the CPU, 32 on a GPU, as for [`Elman`][jaxfric.models.Elman]).
    Dimensionless.
    """

    neurons: int = eqx.field(default=30, static=True)
    output_bias: bool = eqx.field(default=True, static=True)
    learn_c0: bool = eqx.field(default=True, static=True)
    weight_bound: float = eqx.field(default=5.0, static=True)
    context_bound: float = eqx.field(default=1.0, static=True)
    output_weight_bound: float = eqx.field(default=2.0, static=True)
    c0_bound: float = eqx.field(default=1.0, static=True)
    unroll: int | None = eqx.field(default=None, static=True)

    needs_scaling = True

    def __check_init__(self):
        _check_neurons(self.neurons)
        for name in ("weight_bound", "context_bound", "output_weight_bound", "c0_bound"):
            _check_positive(name, getattr(self, name))
        _check_unroll(self.unroll)

    def _sizes(self) -> list[tuple[str, int]]:
        n = self.neurons
        sizes = [("w", n), ("W_c", n * n), ("b", n), ("v", n)]
        if self.learn_c0:
            sizes.append(("c0", n))
        if self.output_bias:
            sizes.append(("b_o", 1))
        return sizes

    @property
    def param_names(self) -> tuple[str, ...]:
        n = self.neurons
        names: list[str] = []
        for name, size in self._sizes():
            if name == "W_c":
                names += [f"W_c[{i},{j}]" for i in range(n) for j in range(n)]
            elif name == "b_o":
                names.append("b_o")
            else:
                names += [f"{name}[{j}]" for j in range(size)]
        return tuple(names)

    @property
    def num_params(self) -> int:
        return sum(size for _, size in self._sizes())

    def bounds(self, box=None) -> tuple[np.ndarray, np.ndarray]:
        self.search_box(box)
        half = {"w": self.weight_bound, "W_c": self.context_bound, "b": self.weight_bound,
                "v": self.output_weight_bound, "c0": self.c0_bound, "b_o": self.c0_bound}
        upper = np.concatenate([np.full(size, half[name]) for name, size in self._sizes()])
        return (-upper).astype(np.float64), upper.astype(np.float64)

    def to_physical(self, theta: Float[ArrayLike, "... n"]) -> dict[str, Array]:
        """Named blocks: ``w``, ``b``, ``v``, ``c0`` ``(..., N)``; ``W_c`` ``(..., N, N)``
        (row i = weights into hidden unit i); ``b_o`` ``(...)``. Dimensionless."""
        theta = jnp.asarray(theta)
        n = self.neurons
        out: dict[str, Array] = {}
        start = 0
        for name, size in self._sizes():
            block = theta[..., start : start + size]
            if name == "W_c":
                block = block.reshape(block.shape[:-1] + (n, n))
            elif name == "b_o":
                block = block[..., 0]
            out[name] = block
            start += size
        return out

    def from_physical(self, *, w, W_c, b, v, c0=None, b_o=None) -> Array:
        """Inverse of [`to_physical`][jaxfric.models.ElmanFull.to_physical]."""
        given = {"w": w, "W_c": W_c, "b": b, "v": v, "c0": c0, "b_o": b_o}
        parts = []
        for name, size in self._sizes():
            x = given.pop(name)
            if x is None:
                raise ValueError(f"{name} is required for this ElmanFull configuration")
            x = jnp.asarray(x)
            if name == "W_c":
                x = x.reshape(x.shape[:-2] + (size,))
            elif name == "b_o":
                x = x[..., None]
            if x.shape[-1] != size:
                raise ValueError(f"{name} has the wrong size {x.shape}")
            parts.append(x)
        extra = [k for k, x in given.items() if x is not None]
        if extra:
            raise ValueError(f"{extra} not used by this ElmanFull configuration")
        return jnp.concatenate(parts, axis=-1)

    def _simulate_batch(self, thetas, velocity, dt=None) -> Float[Array, "P T"]:
        """Free-run outputs of ``P`` networks on one scaled velocity record (§2.3)."""
        del dt
        thetas, u = self._prepare(thetas, velocity)
        p = self.to_physical(thetas)
        c0 = p["c0"] if self.learn_c0 else jnp.zeros_like(p["w"])
        w, b, v, Wc = p["w"], p["b"], p["v"], p["W_c"]

        def step(c, uk):
            h = elman_full_hidden(uk, c, w, Wc, b)
            return h, jnp.sum(v * h, axis=-1)

        y = time_scan(step, c0, u, 1, self.unroll).T
        if self.output_bias:
            y = y + p["b_o"][:, None]
        return y
