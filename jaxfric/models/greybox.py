"""Grey-box friction: a physical model plus a bounded, contractive network correction.

An Elman network alone inside the mechanics fits the record it was trained on and does
not carry over to new motion (docs/motion.md): it is unbounded in what it adds and its
recurrence can learn the excitation. [`GreyBox`][jaxfric.models.GreyBox] keeps a
physical model ([`LuGre`][jaxfric.models.LuGre], [`Stribeck`][jaxfric.models.Stribeck], ...)
as the backbone and lets a small recurrent network add a correction that is

* **bounded by construction**: ``|Δ| <= B`` with ``B = bound · Fc`` (a fraction of the
  physical model's Coulomb level, the mean of ``Fc_pos`` and ``Fc_neg`` for an
  asymmetric one), since ``Δ = B tanh(.)``;
* **contractive by construction**: the context update
  ``c' = α c + (1 − α) tanh(w u + r c + b)`` with ``α ∈ [0, α_max]``, ``|r| <= r_max < 1``
  has ``|∂c'/∂c| <= α + (1 − α) r_max < 1``, so two initial contexts forget their
  difference geometrically and no weight choice makes the state chaotic or unbounded
  (``|c| <= max(|c0|, 1)``);
* **regularised toward the physics**: [`penalty`][jaxfric.models.GreyBox.penalty] returns
  ``sqrt(ridge) · v`` (the output weights), rows the motion cost appends to its
  residuals (a ridge term); with the output weights at zero the model *is* its physical
  model, bit for bit.

Units: SI, as the physical model (velocity m/s, friction N, ``dt`` s); the network's
input is the velocity divided by a searched scale ``v_net`` [m/s] (search coordinate
``log10_net_vscale``, box entry ``vs``).
"""

from __future__ import annotations

import ast

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..records import check_int
from ._base import AbstractFrictionModel, Unidentifiable
from ._box import DEFAULT_RANGES, SearchBox, data_ranges
from ._physical import AbstractPhysicalModel
from .elman import elman_hidden
from .lugre import LuGre

__all__ = ["GreyBox"]

#: The network's blocks in ``theta`` after the physical coordinates and ``log10_net_vscale``.
NET_BLOCKS = ("w", "r", "b", "alpha", "c0", "v")
#: The blocks the ridge penalty pulls to zero: the output weights, whose zero *is* the
#: physical model (pulling the input weights to zero as well would only saturate nothing
#: and leave the output weights without a gradient).
RIDGE_BLOCKS = ("v",)


def _as_physical(model):
    """``None`` -> ``LuGre()``; a [`get`][jaxfric.models.get] name, or the repr a saved fit's
    configuration holds (``"LuGre(asymmetric=True)"``: a class of ``jaxfric.models`` and
    literal keyword values, parsed with ``ast``, never evaluated) -> that model."""
    if model is None:
        return LuGre()
    if isinstance(model, str):
        from . import get  # the registry of jaxfric.models (no cycle: called at construction)

        if "(" not in model:
            return get(model)
        return _from_repr(model)
    return model


def _from_repr(text: str):
    from .. import models as _models

    try:
        call = ast.parse(text.strip(), mode="eval").body
        if not (isinstance(call, ast.Call) and isinstance(call.func, ast.Name) and not call.args):
            raise ValueError
        cls = getattr(_models, call.func.id, None)
        kwargs = {kw.arg: ast.literal_eval(kw.value) for kw in call.keywords}
    except (SyntaxError, ValueError):
        raise ValueError(f"GreyBox: cannot read the physical model {text!r}") from None
    if not (isinstance(cls, type) and issubclass(cls, AbstractPhysicalModel)):
        raise ValueError(f"GreyBox: {call.func.id!r} is not a physical model of jaxfric.models")
    return cls(**kwargs)


def _coulomb_level(p: dict) -> Array:
    """The Coulomb level [N] of a physical model's parameters: ``Fc`` or the mean of
    ``|Fc_pos|`` and ``|Fc_neg|``."""
    if "Fc" in p:
        return jnp.abs(p["Fc"])
    return 0.5 * (jnp.abs(p["Fc_pos"]) + jnp.abs(p["Fc_neg"]))


class GreyBox(AbstractFrictionModel):
    """Physical friction plus a bounded, contractive recurrent correction (module docstring)::

        u_k   = v_k / v_net
        h_k   = tanh(w u_k + r c_k + b)                        (N hidden units, elementwise)
        c_k+1 = α c_k + (1 − α) h_k,        c_0 learned
        F_k   = F_phys(v, s)_k + B tanh(Σ_j v_j h_k,j),     B = bound · Fc

    ``theta`` = the physical model's coordinates, then ``log10_net_vscale``, then the
    blocks ``w, r, b, alpha, c0, v`` of ``hidden`` entries each: ``n_phys + 1 + 6N``.

    Hyperparameters (static): ``physical`` (a physical model with a Coulomb level ``Fc``
    or ``Fc_pos``/``Fc_neg``, or its [`get`][jaxfric.models.get] name; default
    ``LuGre()``); ``hidden`` N (default 4); ``bound`` (B as a fraction of the Coulomb
    level, default 0.25); ``ridge`` (weight of the ridge penalty on the network weights,
    on the output weights, in units of the motion cost ``1 − R²``, default 1e-6); ``weight_bound`` (|w|, |b|,
    |v| <= it, default 3); ``context_bound`` r_max (|r| <= it, in (0, 1), default 0.9);
    ``alpha_max`` (default 0.99); ``c0_bound`` (|c0| <= it, default 1).

    Not a network on scaled data: ``needs_scaling`` is ``False`` and the search box is
    the physical model's ([`search_box`][jaxfric.models.GreyBox.search_box]) plus ``vs``
    for the network's velocity scale.
    """

    physical: AbstractFrictionModel = eqx.field(default=None, static=True, converter=_as_physical)
    hidden: int = eqx.field(default=4, static=True)
    bound: float = eqx.field(default=0.25, static=True, converter=float)
    ridge: float = eqx.field(default=1e-6, static=True, converter=float)
    weight_bound: float = eqx.field(default=3.0, static=True, converter=float)
    context_bound: float = eqx.field(default=0.9, static=True, converter=float)
    alpha_max: float = eqx.field(default=0.99, static=True, converter=float)
    c0_bound: float = eqx.field(default=1.0, static=True, converter=float)

    def __check_init__(self):
        if not isinstance(self.physical, AbstractPhysicalModel):
            raise ValueError(f"GreyBox needs a physical model (LuGre, Stribeck, Coulomb, Dahl, GMS), "
                             f"got {type(self.physical).__name__}")
        names = self.physical.physical_names
        if "Fc" not in names and not {"Fc_pos", "Fc_neg"} <= set(names):
            raise ValueError(f"GreyBox bounds its correction by the Coulomb level Fc, which "
                             f"{type(self.physical).__name__} does not have")
        if self.physical.input_names:
            raise ValueError("GreyBox takes physical models driven by the velocity alone")
        check_int("hidden", self.hidden)
        for name in ("bound", "weight_bound", "c0_bound"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be positive and finite, got {value!r}")
        if not (np.isfinite(self.ridge) and self.ridge >= 0.0):
            raise ValueError(f"ridge must be >= 0, got {self.ridge!r}")
        for name in ("context_bound", "alpha_max"):
            value = getattr(self, name)
            if not 0.0 < value < 1.0:
                raise ValueError(f"{name} must lie in (0, 1) so that the context is contractive, got {value!r}")

    # ------------------------------------------------------------ description
    @property
    def n_physical(self) -> int:
        """Entries of ``theta`` that belong to the physical model (its search coordinates)."""
        return self.physical.num_params

    @property
    def param_names(self) -> tuple[str, ...]:
        net = tuple(f"net_{blk}[{j}]" for blk in NET_BLOCKS for j in range(self.hidden))
        return self.physical.param_names + ("log10_net_vscale",) + net

    @property
    def num_params(self) -> int:
        return self.n_physical + 1 + len(NET_BLOCKS) * self.hidden

    @property
    def box_keys(self) -> tuple[str, ...]:
        """The physical model's box entries and ``vs`` (the network's velocity scale)."""
        return tuple(dict.fromkeys(self.physical.box_keys + ("vs",)))

    def unidentifiable(self, data) -> tuple[Unidentifiable, ...]:
        """The physical model's (the network's weights are regularised, not identified)."""
        return self.physical.unidentifiable(data)

    # ------------------------------------------------------------ search box
    def search_box(self, box=None, velocity: ArrayLike | None = None, friction: ArrayLike | None = None,
                   inputs: ArrayLike | None = None) -> SearchBox:
        """The physical model's complete box
        ([`AbstractPhysicalModel.search_box`][jaxfric.models.AbstractPhysicalModel.search_box]) with a
        ``vs`` entry for the network's velocity scale: the given one, else the physical
        model's, else data-centred ([`data_ranges`][jaxfric.models.data_ranges]) or the default."""
        given = box if isinstance(box, SearchBox) else SearchBox(box)
        unknown = [k for k in given if k not in self.box_keys]
        if unknown:
            raise ValueError(f"search box: GreyBox has no parameter {', '.join(map(repr, unknown))}; "
                             f"its box entries are {', '.join(self.box_keys)}")
        own = {k: r for k, r in given.items() if k in self.physical.box_keys}
        phys = self.physical.search_box(own, velocity, friction, inputs)
        if "vs" in given:
            vs = given["vs"]
        elif "vs" in phys:
            vs = phys["vs"]
        elif velocity is not None:
            vs = data_ranges(velocity, friction)["vs"]
        else:
            vs = DEFAULT_RANGES["vs"]
        return phys | {"vs": vs}

    def bounds(self, box=None) -> tuple[np.ndarray, np.ndarray]:
        """The physical model's bounds, ``log10`` of the ``vs`` range, then the network's:
        ``|w|, |b|, |v| <= weight_bound``, ``|r| <= context_bound``,
        ``α ∈ [0, alpha_max]``, ``|c0| <= c0_bound``."""
        box = self.search_box(box)
        lo_p, hi_p = self.physical.bounds({k: box[k] for k in self.physical.box_keys})
        n = self.hidden
        half = {"w": self.weight_bound, "r": self.context_bound, "b": self.weight_bound,
                "c0": self.c0_bound, "v": self.weight_bound}
        lo = [lo_p, [np.log10(box["vs"][0])]]
        hi = [hi_p, [np.log10(box["vs"][1])]]
        for blk in NET_BLOCKS:
            if blk == "alpha":
                lo.append(np.zeros(n))
                hi.append(np.full(n, self.alpha_max))
            else:
                lo.append(np.full(n, -half[blk]))
                hi.append(np.full(n, half[blk]))
        return np.concatenate(lo).astype(np.float64), np.concatenate(hi).astype(np.float64)

    def initial_guess(self, velocity: ArrayLike, friction: ArrayLike, box=None) -> np.ndarray:
        """The physical model's initial guess with the network *off*: output weights ``v = 0``
        (so the friction is exactly the physical model's), input weights spread over
        ``[-1, 1]·weight_bound/2`` and biases ``0.5`` (so the gradient in ``v`` is not zero and
        no two units mirror each other), ``r = c0 = 0``,
        ``α = alpha_max / 2``, the velocity scale at the top of its range (with a data-centred
        box the record's top speed, so the units start unsaturated)."""
        box = self.search_box(box, velocity, friction)
        theta_p = self.physical.initial_guess(velocity, friction, {k: box[k] for k in self.physical.box_keys})
        return np.concatenate([theta_p, self.network_start(box)])

    def network_start(self, box=None) -> np.ndarray:
        """The network's part of [`initial_guess`][jaxfric.models.GreyBox.initial_guess]
        (``log10_net_vscale`` first): a correction of exactly zero."""
        box = self.search_box(box)
        n = self.hidden
        spread = np.linspace(-1.0, 1.0, n) if n > 1 else np.ones(1)
        # b the same for all units: with b_j = -b_{N-1-j} the units j and N-1-j would be each
        # other's negatives (tanh is odd) and stay so under the gradient, halving the network
        blocks = {"w": 0.5 * self.weight_bound * spread, "r": np.zeros(n), "b": np.full(n, 0.5), "alpha": np.full(n, 0.5 * self.alpha_max),
                  "c0": np.zeros(n), "v": np.zeros(n)}
        vscale = np.log10(box["vs"][1])  # the box's top: the record's top speed when data-centred
        return np.concatenate([[vscale]] + [np.asarray(blocks[k], np.float64) for k in NET_BLOCKS])

    # ------------------------------------------------------------ parameters
    def _split(self, theta) -> tuple[Array, dict[str, Array]]:
        theta = jnp.asarray(theta)
        if theta.shape[-1:] != (self.num_params,):
            raise ValueError(f"theta must have last axis {self.num_params}, got shape {theta.shape}")
        k = self.n_physical
        n = self.hidden
        net = {"vscale": 10.0 ** theta[..., k]}
        for i, blk in enumerate(NET_BLOCKS):
            net[blk] = theta[..., k + 1 + i * n: k + 1 + (i + 1) * n]
        return theta[..., :k], net

    def to_physical(self, theta: Float[ArrayLike, "... n"]) -> dict[str, Array]:
        """The physical model's parameters (SI), ``net_vscale`` [m/s] and every network
        weight by name (``net_w[0]``, ..., ``net_v[N-1]``; dimensionless), each of shape
        ``theta.shape[:-1]``: the `_coords` entries."""
        return {c[1]: x for c, x in zip(self._coords, self._ordered(self._coord_values(theta)))}

    def _ordered(self, values: dict) -> list:
        return [values[c[1]] for c in self._coords]

    def from_physical(self, **params) -> Array:
        """Inverse of [`to_physical`][jaxfric.models.GreyBox.to_physical] (the same keywords)."""
        names = [c[1] for c in self._coords]
        missing = [k for k in names if k not in params]
        extra = [k for k in params if k not in names]
        if missing or extra:
            raise ValueError(f"GreyBox.from_physical needs exactly the names of to_physical; "
                             f"missing {missing[:4]}{'...' if len(missing) > 4 else ''}, unexpected {extra}")
        theta_p = self.physical.from_physical(**{k: params[k] for k in self.physical.physical_names})
        cols = [theta_p, jnp.log10(jnp.asarray(params["net_vscale"]))[..., None]]
        cols += [jnp.asarray(params[k])[..., None] for k in names[len(self.physical._coords) + 1:]]
        cols = [jnp.asarray(c) for c in cols]
        dtype = jnp.result_type(*cols, jnp.float32)
        shape = jnp.broadcast_shapes(*(c.shape[:-1] for c in cols))
        return jnp.concatenate([jnp.broadcast_to(c.astype(dtype), shape + c.shape[-1:]) for c in cols], axis=-1)

    @property
    def _coords(self) -> tuple[tuple[str, str, str], ...]:
        """``(search name, physical name, kind)`` of every entry of ``theta``, as the physical
        models list them (for the uncertainty code): the physical model's, ``net_vscale``
        (log10) and one linear entry per network weight (``net_w[0]``, ...)."""
        net = tuple((f"net_{blk}[{j}]", f"net_{blk}[{j}]", "linear")
                    for blk in NET_BLOCKS for j in range(self.hidden))
        return tuple(self.physical._coords) + (("log10_net_vscale", "net_vscale", "log10"),) + net

    def _coord_values(self, theta: ArrayLike) -> dict[str, Array]:
        """The physical value of every `_coords` entry, keyed by its physical name."""
        theta_p, net = self._split(theta)
        out = dict(self.physical._coord_values(theta_p))
        out["net_vscale"] = net["vscale"]
        for blk in NET_BLOCKS:
            for j in range(self.hidden):
                out[f"net_{blk}[{j}]"] = net[blk][..., j]
        return out

    def correction_bound(self, theta: ArrayLike) -> Array:
        """B [N] = ``bound`` times the Coulomb level of ``theta``'s physical part: the
        largest ``|Δ|`` the network can add (leading axes kept)."""
        theta_p, _ = self._split(theta)
        return self.bound * _coulomb_level(self.physical.to_physical(theta_p))

    def penalty(self, theta: ArrayLike) -> Array:
        """``sqrt(ridge)`` times the network's output weights ``v``, the rows of the ridge
        term the motion cost appends to its residuals (their sum of squares is
        ``ridge · ||v||²``). Zero exactly where the grey-box is its physical model."""
        _, net = self._split(theta)
        weights = jnp.concatenate([net[k] for k in RIDGE_BLOCKS], axis=-1)
        return jnp.sqrt(jnp.asarray(self.ridge, weights.dtype)) * weights

    # ------------------------------------------------------------ rollouts
    def _check_dt(self, dt) -> None:
        self.physical._check_dt(dt)

    def network_step(self, net: dict, c: Array, u: Array) -> tuple[Array, Array]:
        """One sample of the network: ``(h_k, c_k+1)`` from context ``c_k`` and scaled input
        ``u_k`` (broadcasting over leading axes)."""
        h = elman_hidden(u, c, net["w"], net["r"], net["b"])  # §2.2's hidden layer
        return h, net["alpha"] * c + (1.0 - net["alpha"]) * h

    def correction(self, level: Array, net: dict, h: Array) -> Array:
        """Δ = B tanh(Σ_j v_j h_j) [N], B = ``bound`` · ``level``."""
        return self.bound * level * jnp.tanh(jnp.sum(net["v"] * h, axis=-1))

    def _simulate_batch(self, thetas, velocity, dt) -> Float[Array, "P T"]:
        """Physical rollout plus the bounded correction of a ``lax.scan`` over samples."""
        thetas, v = self._prepare(thetas, velocity)
        theta_p, net = self._split(thetas)
        phys = self.physical._simulate_batch(theta_p, v, dt)
        level = _coulomb_level(self.physical.to_physical(theta_p))  # (P,)
        u = v[:, None] / net["vscale"][None, :]  # (T, P)
        cols = {k: x for k, x in net.items() if k != "vscale"}

        def body(c, uk):
            h, c_next = self.network_step(cols, c, uk[:, None])
            return c_next, jnp.sum(cols["v"] * h, axis=-1)

        _, s = jax.lax.scan(body, cols["c0"], u)
        return phys + (self.bound * level)[:, None] * jnp.tanh(s.T)
