"""Static (memoryless) friction maps: Coulomb + viscous and the Stribeck curve.

ALGORITHMS.md §8.1 (the steady state of LuGre is the Stribeck map) and §8.3
background. The sign function is smoothed as tanh(v / v_eps): a hard sign
makes the friction at v = 0 arbitrary and the output discontinuous in the
data, which derivative-free and gradient fits both dislike. ``v_eps`` is a
hyperparameter in m/s, small against the record's speeds.

Static maps ignore ``dt`` (``uses_dt = False``). Units: velocity m/s,
friction N.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._physical import AbstractPhysicalModel, as_range, stribeck_curve

__all__ = ["Coulomb", "Stribeck"]


def _check_v_eps(v_eps: float) -> None:
    if not v_eps > 0.0:
        raise ValueError(f"v_eps must be positive (m/s), got {v_eps}")


def _columns(model, thetas, velocity):
    """A static model's inputs for broadcasting: physical parameters as ``(P, 1)``
    columns and the velocity as a ``(1, T)`` row (dtypes promoted by ``_prepare``)."""
    thetas, v = model._prepare(thetas, velocity)
    p = {k: x[:, None] for k, x in model.to_physical(thetas).items()}
    return p, v[None, :]


class Coulomb(AbstractPhysicalModel):
    """Coulomb + viscous friction ``F = Fc tanh(v / v_eps) + sigma2 v``.

    Search coordinates ``Fc`` (+ ``log10_sigma2`` when ``viscous=True``, the
    default). Physical parameters: ``Fc`` [N], ``sigma2`` [N s/m].
    Hyperparameters: ``v_eps`` [m/s] (default 1e-4), ``viscous``, and the
    ``Fc_range`` / ``sigma2_range`` search ranges (see :class:`LuGre`).
    """

    v_eps: float = eqx.field(default=1e-4, static=True, converter=float)
    viscous: bool = eqx.field(default=True, static=True)
    Fc_range: tuple[float, float] | None = eqx.field(default=None, static=True, converter=as_range)
    sigma2_range: tuple[float, float] | None = eqx.field(default=None, static=True, converter=as_range)

    uses_dt = False

    def __check_init__(self):
        _check_v_eps(self.v_eps)
        self._check_ranges()

    @property
    def _coords(self):
        coords = (("Fc", "Fc", "linear"),)
        if self.viscous:
            coords += (("log10_sigma2", "sigma2", "log10"),)
        return coords

    def _simulate_batch(
        self, thetas: Float[ArrayLike, "P n"], velocity: Float[ArrayLike, " T"], dt=None
    ) -> Float[Array, "P T"]:
        """Friction [N] for velocity [m/s]; ``dt`` is ignored."""
        del dt
        p, vv = _columns(self, thetas, velocity)
        f = p["Fc"] * jnp.tanh(vv / jnp.asarray(self.v_eps, vv.dtype))
        if self.viscous:
            f = f + p["sigma2"] * vv
        return f


class Stribeck(AbstractPhysicalModel):
    """Stribeck curve + viscous friction (the LuGre steady state, §8.1)::

        F = tanh(v / v_eps) (Fc + (Fs - Fc) exp(-|v / vs|^delta)) + sigma2 v

    Search coordinates ``Fc``, ``Fs_over_Fc``, ``log10_vs``, ``log10_sigma2``
    and, with ``fit_exponent=True``, ``delta`` (linear, ``delta_range``
    default [0.5, 3]). Physical parameters: ``Fc`` [N], ``Fs`` [N], ``vs``
    [m/s], ``sigma2`` [N s/m] (+ ``delta`` [-]). Hyperparameters: ``v_eps``
    [m/s] (default 1e-4), ``exponent`` (the fixed delta, default 2),
    ``fit_exponent`` and the ``*_range`` fields (see :class:`LuGre`).
    """

    v_eps: float = eqx.field(default=1e-4, static=True, converter=float)
    exponent: float = eqx.field(default=2.0, static=True, converter=float)
    fit_exponent: bool = eqx.field(default=False, static=True)
    Fc_range: tuple[float, float] | None = eqx.field(default=None, static=True, converter=as_range)
    Fs_ratio_range: tuple[float, float] | None = eqx.field(default=None, static=True, converter=as_range)
    vs_range: tuple[float, float] | None = eqx.field(default=None, static=True, converter=as_range)
    sigma2_range: tuple[float, float] | None = eqx.field(default=None, static=True, converter=as_range)
    delta_range: tuple[float, float] | None = eqx.field(default=None, static=True, converter=as_range)

    uses_dt = False

    def __check_init__(self):
        _check_v_eps(self.v_eps)
        if not self.exponent > 0.0:
            raise ValueError(f"exponent must be positive, got {self.exponent}")
        self._check_ranges()
        if self.fit_exponent and self.physical_range("delta")[0] <= 0.0:
            raise ValueError("delta_range must be positive")

    @property
    def _coords(self):
        coords = (
            ("Fc", "Fc", "linear"),
            ("Fs_over_Fc", "Fs", "ratio"),
            ("log10_vs", "vs", "log10"),
            ("log10_sigma2", "sigma2", "log10"),
        )
        if self.fit_exponent:
            coords += (("delta", "delta", "linear"),)
        return coords

    def _simulate_batch(
        self, thetas: Float[ArrayLike, "P n"], velocity: Float[ArrayLike, " T"], dt=None
    ) -> Float[Array, "P T"]:
        """Friction [N] for velocity [m/s]; ``dt`` is ignored."""
        del dt
        p, vv = _columns(self, thetas, velocity)
        delta = p["delta"] if self.fit_exponent else self.exponent
        g = stribeck_curve(vv, p["Fc"], p["Fs"], p["vs"], delta)
        return jnp.tanh(vv / jnp.asarray(self.v_eps, vv.dtype)) * g + p["sigma2"] * vv
