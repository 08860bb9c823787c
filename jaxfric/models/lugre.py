"""Bristle (LuGre, Dahl) friction models with an exact zero-order-hold update.

docs/algorithms.md §8.1-8.3. Both models share the internal state equation

    dz/dt = v - a(v) z,      a(v) = sigma0 |v| / g(v) >= 0,

which is stiff at hydraulic stiffnesses: with sigma0 = 1e7 N/m, g = 200 N,
|v| = 10 mm/s and h = 1/128 s, a h = 3.9 > 2 and explicit Euler diverges
(§8.2). With v held constant over each sample (zero-order hold, the natural
reading of sampled data) the equation is linear, so it is integrated exactly:

    z_{k+1} = z_k exp(-a_k h) + v_k h phi(a_k h),     phi(x) = -expm1(-x) / x,  phi(0) = 1.

This is unconditionally stable and, under the hold assumption, free of
discretisation error. Everything that depends on v only (a_k, the decay and
the gain) is computed vectorised before a ``lax.scan`` whose body is one
multiply-add per candidate (on a GPU an associative scan of the same
recurrence, ``jaxfric.models._scan.linear_recurrence``).

Units: velocity in m/s, friction in N, ``dt`` in s; parameters in SI units
(sigma0 N/m, sigma1 and sigma2 N s/m, Fc and Fs N, vs m/s).

Real drives (docs/algorithms.md §13.1): ``asymmetric=True`` makes the levels
direction-dependent, g(v) = g_pos(v) for v > 0 and g_neg(v) for v <= 0 (Fc, Fs and
sigma2 each with a ``_pos`` / ``_neg`` value), so the steady state is
F_ss = g_pos(v) + sigma2_pos v sliding forwards and -g_neg(v) + sigma2_neg v
backwards; ``offset=True`` adds ``F_off`` to the output. The exact update is
unchanged (g still depends on v_k only). Both default to ``False``.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._physical import AbstractPhysicalModel, add_offset, by_direction, directional_coords, stribeck_curve
from ._scan import linear_recurrence

__all__ = ["LuGre", "Dahl", "bristle_friction", "bristle_phi"]

_PHI_SWITCH = 1e-8


def _sample_time(dt, dtype) -> Array:
    if dt is None:
        raise ValueError("bristle models integrate in time: pass the sample time dt in seconds")
    dt = jnp.asarray(dt, dtype)
    if dt.ndim != 0:
        raise ValueError(f"dt must be a scalar sample time in seconds, got shape {dt.shape}")
    return dt


def _bristle_columns(model, thetas, velocity, dt):
    """A bristle model's inputs: physical parameters as ``(P, 1)`` columns, the velocity
    ``(T,)`` and the checked sample time, in the dtype ``_prepare`` promotes to."""
    thetas, v = model._prepare(thetas, velocity)
    p = {k: x[:, None] for k, x in model.to_physical(thetas).items()}
    return p, v, _sample_time(dt, v.dtype)


def bristle_phi(x: Array) -> Array:
    """phi(x) = (1 - e^{-x}) / x with the double-``where`` guard (§8.2).

    The series 1 - x/2 is used below the switch; the inner ``where`` keeps the
    unused branch from producing 0/0, whose NaN would otherwise leak into the
    gradient at v = 0.
    """
    small = x < jnp.asarray(_PHI_SWITCH, x.dtype)
    x_safe = jnp.where(small, jnp.ones_like(x), x)
    return jnp.where(small, 1.0 - 0.5 * x, -jnp.expm1(-x_safe) / x_safe)


def bristle_friction(sigma0: Array, sigma1: Array, sigma2: Array, g: Array, velocity: Array, dt) -> Float[Array, "P T"]:
    """Exact-ZOH rollout of the LuGre bristle state and friction output, §8.2.

    ``sigma0``, ``sigma1``: shape ``(P, 1)``; ``sigma2``: ``(P, 1)`` or
    ``(P, T)`` (direction-dependent, §13.1); ``g``: Stribeck
    curve g(v_k), shape ``(P, T)`` (``g = Fc`` for Dahl); ``velocity``:
    ``(T,)``. The output at sample k uses the state before the update,

        F_k = sigma0 z_k + sigma1 (v_k - a_k z_k) + sigma2 v_k,

    with z_0 = sgn(v_0) g(v_0) / sigma0, the steady state of §8.1, so a
    record that starts while sliding has no start-up transient.
    """
    v = velocity[None, :]
    a = sigma0 * jnp.abs(v) / g
    x = a * dt
    decay = jnp.exp(-x)
    gain = v * dt * bristle_phi(x)
    z0 = jnp.sign(v[:, 0]) * g[:, 0] / sigma0[:, 0]

    z = linear_recurrence(decay, gain, z0)
    return sigma0 * z + sigma1 * (v - a * z) + sigma2 * v


class LuGre(AbstractPhysicalModel):
    """LuGre friction model (Canudas de Wit et al. 1995), docs/algorithms.md §8.1-8.2, §8.5.

    ::

        dz/dt = v - sigma0 |v| / g(v) z
        g(v)  = Fc + (Fs - Fc) exp(-|v / vs|^delta)
        F     = sigma0 z + sigma1 dz/dt + sigma2 v

    Six search coordinates (§8.5): ``log10_sigma0``, ``log10_sigma1``,
    ``log10_sigma2``, ``Fc``, ``Fs_over_Fc`` (so Fs >= Fc), ``log10_vs``.
    Physical parameters ([`to_physical`][jaxfric.models.AbstractPhysicalModel.to_physical]): ``sigma0`` [N/m], ``sigma1``
    [N s/m], ``sigma2`` [N s/m], ``Fc`` [N], ``Fs`` [N], ``vs`` [m/s].

    Hyperparameters (static): ``stribeck_exponent`` delta (default 2, the
    original model). The search box is data, not a field ([`SearchBox`][jaxfric.models.SearchBox]).

    ``asymmetric=True`` (docs/algorithms.md §13.1, module docstring) replaces
    ``log10_sigma2``, ``Fc``, ``Fs_over_Fc`` by their ``_pos`` / ``_neg`` pairs
    (9 coordinates); ``offset=True`` appends ``F_off`` [N].
    """

    stribeck_exponent: float = eqx.field(default=2.0, static=True, converter=float)
    asymmetric: bool = eqx.field(default=False, static=True)
    offset: bool = eqx.field(default=False, static=True)

    _checks_dt = True
    _presliding = ("sigma0", "sigma1")

    def __check_init__(self):
        if not self.stribeck_exponent > 0.0:
            raise ValueError(f"stribeck_exponent must be positive, got {self.stribeck_exponent}")

    @property
    def _coords(self):
        coords = (("log10_sigma0", "sigma0", "log10"),
                  ("log10_sigma1", "sigma1", "log10"),
                  ("log10_sigma2", "sigma2", "log10"),
                  ("Fc", "Fc", "linear"),
                  ("Fs_over_Fc", "Fs", "ratio"),
                  ("log10_vs", "vs", "log10"))
        return directional_coords(coords, self.asymmetric, self.offset)

    def _simulate_batch(self, thetas, velocity, dt) -> Float[Array, "P T"]:
        p, v, dt = _bristle_columns(self, thetas, velocity, dt)
        vv = v[None, :]
        if self.asymmetric:
            g_pos = stribeck_curve(vv, p["Fc_pos"], p["Fs_pos"], p["vs"], self.stribeck_exponent)
            g_neg = stribeck_curve(vv, p["Fc_neg"], p["Fs_neg"], p["vs"], self.stribeck_exponent)
            g = jnp.where(vv > 0, g_pos, g_neg)
        else:
            g = stribeck_curve(vv, p["Fc"], p["Fs"], p["vs"], self.stribeck_exponent)
        sigma2 = by_direction(p, "sigma2", vv)
        return add_offset(bristle_friction(p["sigma0"], p["sigma1"], sigma2, g, v, dt), p)


class Dahl(AbstractPhysicalModel):
    """Dahl friction model, docs/algorithms.md §8.3 (exponent i = 1)::

        dF/dt = sigma0 v - sigma0 |v| F / Fc     (+ sigma2 v if viscous)

    i.e. LuGre with g = Fc and sigma1 = 0, F = sigma0 z; integrated with the
    same exact zero-order-hold update. Search coordinates ``log10_sigma0``,
    ``Fc`` (+ ``log10_sigma2`` when ``viscous=True``). Physical parameters:
    ``sigma0`` [N/m], ``Fc`` [N], ``sigma2`` [N s/m].

    ``asymmetric=True`` (docs/algorithms.md §13.1): g = Fc_pos for v > 0 and
    Fc_neg for v <= 0 (and sigma2_pos/neg when viscous); ``offset=True``
    appends ``F_off`` [N] to the output.
    """

    viscous: bool = eqx.field(default=False, static=True)
    asymmetric: bool = eqx.field(default=False, static=True)
    offset: bool = eqx.field(default=False, static=True)

    _checks_dt = True
    _presliding = ("sigma0",)

    @property
    def _coords(self):
        coords = (("log10_sigma0", "sigma0", "log10"), ("Fc", "Fc", "linear"))
        if self.viscous:
            coords += (("log10_sigma2", "sigma2", "log10"),)
        return directional_coords(coords, self.asymmetric, self.offset)

    def _simulate_batch(self, thetas, velocity, dt) -> Float[Array, "P T"]:
        p, v, dt = _bristle_columns(self, thetas, velocity, dt)
        zero = jnp.zeros_like(p["sigma0"])
        vv = v[None, :]
        sigma2 = by_direction(p, "sigma2", vv) if self.viscous else zero
        g = jnp.broadcast_to(by_direction(p, "Fc", vv), (zero.shape[0], v.shape[0]))
        return add_offset(bristle_friction(p["sigma0"], zero, sigma2, g, v, dt), p)
