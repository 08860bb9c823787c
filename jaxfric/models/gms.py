"""Generalised Maxwell-slip (GMS) friction model, docs/algorithms.md §8.4.

Al-Bender, Lampaert, Swevers, "The generalized Maxwell-slip model: a novel model
for friction simulation and compensation", IEEE TAC 50(11), 2005 (and Chaos 14(2),
2004). ``N`` elementary slip blocks in parallel share the velocity ``v``; element
``i`` carries the force ``F_i``::

    stick:  dF_i/dt = k_i v                               while |F_i| < alpha_i s(v)
    slip:   dF_i/dt = sgn(v) C (alpha_i - F_i / s_signed(v))
          = C (alpha_i sgn(v) - F_i / s(v))               until v changes sign
    F = sum_i F_i + sigma2 v,    s(v) = Fc + (Fs - Fc) exp(-|v / vs|^delta),    sum_i alpha_i = 1

The published slip law is written with a signed Stribeck curve
``s_signed(v) = sgn(v) s(v)``; the second line is the same law with ``s > 0``,
which relaxes each slipping element to ``alpha_i s(v) sgn(v)`` at the rate
``C / s(v)`` for either direction of motion (the spec's rendering in §8.4 has the
attraction rate ``C`` where the paper has ``alpha_i C``; this module follows the
paper). An element re-sticks when the velocity changes sign.

Discretisation (exact under a zero-order hold on ``v``, like LuGre's §8.2 update):
over one sample of length ``h`` an element that is slipping the way ``v`` moves,
or that starts the sample beyond its slip level, relaxes exactly,
``F <- target + (F - target) exp(-C h / s)`` with ``target = alpha_i s sgn(v)``;
a sticking element moves by ``k_i v h`` and, if that reaches its slip level,
stops exactly at ``target`` (slipping from the level keeps it there) and slips
from then on. Stable for any ``h``; the stick/slip direction is carried in the
``lax.scan`` state. The output at sample ``k`` uses the state before the update
(as LuGre); the state starts in steady sliding at ``v_0``.
"""

from __future__ import annotations

import re

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._physical import AbstractPhysicalModel, add_offset, by_direction, directional_coords, stribeck_curve
from ._scan import time_scan
from .lugre import _sample_time

__all__ = ["GMS"]

_ELEMENT = re.compile(r"(k|split)\d+$")


def _splits_to_weights(u: Array) -> Array:
    """Stick-breaking: ``(..., N-1)`` fractions in [0, 1] -> ``(..., N)`` weights summing to 1.

    alpha_1 = u_1, alpha_i = u_i prod_{j<i} (1 - u_j), alpha_N = prod_j (1 - u_j):
    every point of the box is a valid weight vector, without a penalty."""
    ones = jnp.ones(u.shape[:-1] + (1,), u.dtype)
    remain = jnp.cumprod(jnp.concatenate([ones, 1.0 - u], axis=-1), axis=-1)
    return remain * jnp.concatenate([u, ones], axis=-1)


def _weights_to_splits(alpha: Array) -> Array:
    """Inverse of `_splits_to_weights` (``(..., N)`` -> ``(..., N-1)``)."""
    used = jnp.cumsum(alpha, axis=-1)[..., :-1]
    remain = jnp.concatenate([jnp.ones_like(used[..., :1]), 1.0 - used[..., :-1]], axis=-1)
    return alpha[..., :-1] / remain


class GMS(AbstractPhysicalModel):
    """Generalised Maxwell-slip friction, docs/algorithms.md §8.4 (module docstring).

    Search coordinates: ``log10_k1 .. log10_kN`` (element stiffness [N/m],
    box entry ``k``), ``split1 .. split{N-1}`` (stick-breaking fractions in
    [0, 1] that give the weights alpha_i, see `_splits_to_weights`),
    ``log10_C`` (attraction rate [N/s]), ``Fc``, ``Fs_over_Fc``, ``log10_vs``,
    ``log10_sigma2``: 2N + 4 in all. Physical parameters ([`to_physical`][jaxfric.models.GMS.to_physical]):
    ``k1 .. kN``, ``alpha1 .. alphaN`` (sum 1), ``C``, ``Fc``, ``Fs``, ``vs``,
    ``sigma2``. Hyperparameters: ``num_elements`` N (default 3),
    ``stribeck_exponent`` delta (default 2); the search box is data (as
    [`LuGre`][jaxfric.models.LuGre]; ``k`` and ``C`` are data-centred by [`search_box`][jaxfric.models.AbstractPhysicalModel.search_box]).

    ``asymmetric=True`` / ``offset=True`` (docs/algorithms.md §13.1): the slip
    level is s_pos(v) (``Fc_pos``, ``Fs_pos``) for v > 0 and s_neg(v) for v <= 0,
    the viscous term ``sigma2_pos`` / ``sigma2_neg``, and ``F_off`` is added to
    the output; an element stuck after a reversal slips again at
    -alpha_i s_neg (the rig simulator's Maxwell-slip truth is of this kind).
    """

    num_elements: int = eqx.field(default=3, static=True, converter=int)
    stribeck_exponent: float = eqx.field(default=2.0, static=True, converter=float)
    asymmetric: bool = eqx.field(default=False, static=True)
    offset: bool = eqx.field(default=False, static=True)

    _checks_dt = True
    _presliding = ("k", "C", "alpha")
    _fixed_ranges = {"split": (0.0, 1.0)}

    def __check_init__(self):
        if self.num_elements < 1:
            raise ValueError(f"num_elements must be at least 1, got {self.num_elements}")
        if not self.stribeck_exponent > 0.0:
            raise ValueError(f"stribeck_exponent must be positive, got {self.stribeck_exponent}")

    # ------------------------------------------------------------ coordinates
    @property
    def _coords(self):
        n = self.num_elements
        coords = tuple((f"log10_k{i}", f"k{i}", "log10") for i in range(1, n + 1))
        coords += tuple((f"split{i}", f"split{i}", "linear") for i in range(1, n))
        return coords + directional_coords((
            ("log10_C", "C", "log10"),
            ("Fc", "Fc", "linear"),
            ("Fs_over_Fc", "Fs", "ratio"),
            ("log10_vs", "vs", "log10"),
            ("log10_sigma2", "sigma2", "log10"),
        ), self.asymmetric, self.offset)

    @property
    def slow_coordinates(self) -> dict[str, tuple[int, ...]]:
        """Indices in ``theta`` of the coordinates that set how slowly the model relaxes
        (``"k"``: every ``log10_k*``; ``"C"``: ``log10_C`` (both directions when asymmetric);
        ``"Fs_over_Fc"``): the coordinates `jaxfric.motion`'s slow-attraction starts vary."""
        names = self.param_names
        return {"k": tuple(range(self.num_elements)),
                "C": tuple(i for i, n in enumerate(names) if n.startswith("log10_C")),
                "Fs_over_Fc": tuple(i for i, n in enumerate(names) if n.startswith("Fs_over_Fc"))}

    def _range_key(self, phys: str, kind: str) -> str:
        match = _ELEMENT.match(phys)
        return match.group(1) if match else super()._range_key(phys, kind)

    def _group(self, phys: str) -> str:
        match = re.match(r"(k|alpha)\d+$", phys)
        return match.group(1) if match else super()._group(phys)

    @property
    def physical_names(self) -> tuple[str, ...]:
        n = self.num_elements
        tail = tuple(c[1] for c in self._coords[2 * n - 1:])
        return tuple(f"k{i}" for i in range(1, n + 1)) + tuple(f"alpha{i}" for i in range(1, n + 1)) + tail

    def to_physical(self, theta: ArrayLike) -> dict[str, Array]:
        """Search coordinates -> physical parameters (weights from the splits)."""
        out = self._coord_values(theta)
        n = self.num_elements
        splits = jnp.stack([jnp.asarray(theta)[..., n + i] for i in range(n - 1)], axis=-1)
        alpha = _splits_to_weights(splits)
        out.update({f"alpha{i + 1}": alpha[..., i] for i in range(n)})
        return {name: out[name] for name in self.physical_names}

    def from_physical(self, **params) -> Array:
        """Physical parameters ([`physical_names`][jaxfric.models.GMS.physical_names]; the alphas must sum to 1) -> ``theta``."""
        self._check_physical_names(params)
        n = self.num_elements
        alpha = jnp.stack(jnp.broadcast_arrays(*(jnp.asarray(params[f"alpha{i}"]) for i in range(1, n + 1))), axis=-1)
        if not isinstance(alpha, jax.core.Tracer):
            total = np.asarray(jnp.sum(alpha, axis=-1))
            if not np.allclose(total, 1.0, rtol=1e-5, atol=1e-6):
                raise ValueError(f"GMS weights alpha1..alpha{n} must sum to 1, got {total}")
        splits = _weights_to_splits(alpha)
        values = dict(params)
        values.update({f"split{i + 1}": splits[..., i] for i in range(n - 1)})
        return self._theta_from(values)

    # ---------------------------------------------------------------- rollout
    def _simulate_batch(self, thetas, velocity, dt) -> Float[Array, "P T"]:
        thetas, v = self._prepare(thetas, velocity)
        dt = _sample_time(dt, v.dtype)
        p = self.to_physical(thetas)
        n = self.num_elements
        k = jnp.stack([p[f"k{i}"] for i in range(1, n + 1)], axis=-1)  # (P, N)
        alpha = jnp.stack([p[f"alpha{i}"] for i in range(1, n + 1)], axis=-1)
        col = {name: x[:, None] for name, x in p.items()}
        vv = v[None, :]
        if self.asymmetric:
            s = jnp.where(vv > 0,
                          stribeck_curve(vv, col["Fc_pos"], col["Fs_pos"], col["vs"], self.stribeck_exponent),
                          stribeck_curve(vv, col["Fc_neg"], col["Fs_neg"], col["vs"], self.stribeck_exponent))
        else:
            s = stribeck_curve(vv, col["Fc"], col["Fs"], col["vs"], self.stribeck_exponent)  # (P, T)
        sv = jnp.sign(v)  # (T,)
        decay = jnp.exp(-p["C"][:, None] * dt / s)  # (P, T)

        def step(carry, x):
            force, direction = carry  # (P, N) each; direction in {-1, 0, +1}
            v_k, sv_k, s_k, decay_k = x  # scalars and (P,)
            level = alpha * s_k[:, None]
            target = level * sv_k
            relaxed = target + (force - target) * decay_k[:, None]
            stuck = force + k * (v_k * dt)
            moving = sv_k != 0
            keeps_slipping = moving & (direction == sv_k)
            beyond = moving & (sv_k * force >= level)
            reaches = moving & (sv_k * stuck >= level)
            slips = keeps_slipping | beyond
            new_force = jnp.where(slips, relaxed, jnp.where(reaches, target, stuck))
            new_direction = jnp.where(slips | reaches, sv_k, jnp.zeros_like(direction))
            return (new_force, new_direction), jnp.sum(force, axis=-1)

        force0 = alpha * (s[:, :1] * sv[0])
        direction0 = jnp.broadcast_to(sv[0], force0.shape).astype(force0.dtype)
        elements = time_scan(step, (force0, direction0), (v, sv, s.T, decay.T), cpu_unroll=1)
        return add_offset(elements.T + by_direction(col, "sigma2", vv) * vv, col)
