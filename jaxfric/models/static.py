"""Static (memoryless) friction maps: Coulomb + viscous and the Stribeck curve.

docs/algorithms.md §8.1 (the steady state of LuGre is the Stribeck map) and §8.3
background. The sign function is smoothed as tanh(v / v_eps): a hard sign
makes the friction at v = 0 arbitrary and the output discontinuous in the
data, which derivative-free and gradient fits both dislike. ``v_eps`` is a
hyperparameter in m/s, small against the record's speeds.

Static maps ignore ``dt`` (``uses_dt = False``). Units: velocity m/s,
friction N.

Real drives (docs/algorithms.md §13.1): ``asymmetric=True`` gives every level
(``Fc``, ``Fs``, ``sigma2``) a ``_pos`` value for v > 0 and a ``_neg`` value for
v < 0, ``offset=True`` adds a constant ``F_off`` to the output. Both default to
``False``, the paper's symmetric form with its unchanged ``theta`` layout.
[`Cylinder`][jaxfric.models.Cylinder] is the Simscape cylinder friction whose Coulomb level grows
with the chamber pressures.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._physical import (AbstractPhysicalModel, Unidentifiable, add_offset, by_direction, directional_coords,
                        signed_level, stribeck_curve)

__all__ = ["Coulomb", "Cylinder", "Stribeck"]


def _check_smoothing(v_eps: float, exponent: float = 1.0) -> None:
    """The sign's smoothing ``v_eps`` and the Stribeck exponent must be positive."""
    if not v_eps > 0.0:
        raise ValueError(f"v_eps must be positive (m/s), got {v_eps}")
    if not exponent > 0.0:
        raise ValueError(f"exponent must be positive, got {exponent}")


def _columns(model, thetas, velocity):
    """A static model's inputs for broadcasting: physical parameters as ``(P, 1)``
    columns, the velocity as a ``(1, T)`` row (dtypes promoted by ``_prepare``) and the
    smoothed sign ``t = tanh(v / v_eps)`` of that row. ``dt`` is never needed."""
    thetas, v = model._prepare(thetas, velocity)
    p = {k: x[:, None] for k, x in model.to_physical(thetas).items()}
    vv = v[None, :]
    return p, vv, jnp.tanh(vv / jnp.asarray(model.v_eps, vv.dtype))


class Coulomb(AbstractPhysicalModel):
    """Coulomb + viscous friction ``F = Fc tanh(v / v_eps) + sigma2 v``.

    Search coordinates ``Fc`` (+ ``log10_sigma2`` when ``viscous=True``, the
    default). Physical parameters: ``Fc`` [N], ``sigma2`` [N s/m].
    Hyperparameters: ``v_eps`` [m/s] (default 1e-4) and ``viscous``; the search box
    (entries ``Fc``, ``sigma2``) is data given to [`jaxfric.identify`][jaxfric.identification.identify] (see
    [`LuGre`][jaxfric.models.LuGre]).

    ``asymmetric=True`` / ``offset=True`` (docs/algorithms.md §13.1, the EMPS
    reference model of Janot et al. 2019 with a smoothed sign t = tanh(v / v_eps))::

        F = Fc_pos max(t, 0) - Fc_neg max(-t, 0) + sigma2_pos v [v > 0] + sigma2_neg v [v < 0] + F_off

    with search coordinates ``Fc_pos``, ``Fc_neg``, ``log10_sigma2_pos``,
    ``log10_sigma2_neg``, ``F_off`` (box entry ``F_off``, default data-centred
    +-0.5 F). Linear in its physical parameters: [`fit_least_squares`][jaxfric.models.Coulomb.fit_least_squares]
    solves it exactly.
    """

    v_eps: float = eqx.field(default=1e-4, static=True, converter=float)
    viscous: bool = eqx.field(default=True, static=True)
    asymmetric: bool = eqx.field(default=False, static=True)
    offset: bool = eqx.field(default=False, static=True)

    uses_dt = False

    def __check_init__(self):
        _check_smoothing(self.v_eps)

    @property
    def _coords(self):
        coords = (("Fc", "Fc", "linear"),)
        if self.viscous:
            coords += (("log10_sigma2", "sigma2", "log10"),)
        return directional_coords(coords, self.asymmetric, self.offset)

    def _simulate_batch(self, thetas, velocity, dt=None) -> Float[Array, "P T"]:
        p, vv, t = _columns(self, thetas, velocity)
        if self.asymmetric:
            f = signed_level(t, p, "Fc", p["Fc_pos"], p["Fc_neg"])
        else:
            f = p["Fc"] * t
        if self.viscous:
            f = f + by_direction(p, "sigma2", vv) * vv
        return add_offset(f, p)

    def fit_least_squares(self, velocity: ArrayLike, friction: ArrayLike) -> dict[str, float]:
        """Exact least-squares fit of the physical parameters (the model is linear in
        them, docs/algorithms.md §13.1): ``{name: value}`` for [`from_physical`][jaxfric.models.AbstractPhysicalModel.from_physical].

        Solved unconstrained on every sample with the model's own smoothed sign; a
        negative viscous coefficient (which the log10 search coordinate cannot
        hold) is returned as it is, so check it before ``from_physical``.
        """
        v = np.asarray(velocity, dtype=float).ravel()
        f = np.asarray(friction, dtype=float).ravel()
        if v.shape != f.shape or v.size < self.num_params:
            raise ValueError(f"velocity and friction must have the same length, at least {self.num_params}; "
                             f"got {v.shape} and {f.shape}")
        if not (np.all(np.isfinite(v)) and np.all(np.isfinite(f))):
            raise ValueError("velocity and friction must be finite (no NaN or inf)")
        cols = self.regressors(v)
        names = list(cols)
        coef, *_ = np.linalg.lstsq(np.stack([cols[n] for n in names], axis=1), f, rcond=None)
        return {n: float(c) for n, c in zip(names, coef)}

    def regressors(self, velocity: ArrayLike) -> dict[str, np.ndarray]:
        """The columns of the model's linear form, ``F = sum_i params[i] * columns[i]``
        (NumPy, float64, the model's own smoothed sign ``t = tanh(v / v_eps)``): the
        regressors [`fit_least_squares`][jaxfric.models.Coulomb.fit_least_squares] solves for, and
        with its solution the least-squares prediction itself (a negative viscous slope
        included)."""
        v = np.asarray(velocity, dtype=float).ravel()
        t = np.tanh(v / self.v_eps)
        cols: dict[str, np.ndarray] = {}
        if self.asymmetric:
            cols["Fc_pos"], cols["Fc_neg"] = np.maximum(t, 0.0), -np.maximum(-t, 0.0)
        else:
            cols["Fc"] = t
        if self.viscous:
            if self.asymmetric:
                cols["sigma2_pos"], cols["sigma2_neg"] = v * (v > 0), v * (v <= 0)
            else:
                cols["sigma2"] = v
        if self.offset:
            cols["F_off"] = np.ones_like(v)
        return cols


class Stribeck(AbstractPhysicalModel):
    """Stribeck curve + viscous friction (the LuGre steady state, §8.1)::

        F = tanh(v / v_eps) (Fc + (Fs - Fc) exp(-|v / vs|^delta)) + sigma2 v

    Search coordinates ``Fc``, ``Fs_over_Fc``, ``log10_vs``, ``log10_sigma2``
    and, with ``fit_exponent=True``, ``delta`` (linear, box entry ``delta``,
    default [0.5, 3]). Physical parameters: ``Fc`` [N], ``Fs`` [N], ``vs``
    [m/s], ``sigma2`` [N s/m] (+ ``delta`` [-]). Hyperparameters: ``v_eps``
    [m/s] (default 1e-4), ``exponent`` (the fixed delta, default 2),
    ``fit_exponent``; the search box is data (see [`LuGre`][jaxfric.models.LuGre]).

    ``asymmetric=True`` / ``offset=True`` (docs/algorithms.md §13.1): with
    ``g_pos``, ``g_neg`` the Stribeck curves of (``Fc_pos``, ``Fs_pos``) and
    (``Fc_neg``, ``Fs_neg``) (shared ``vs``, ``delta``) and t = tanh(v / v_eps),
    ``F = max(t, 0) g_pos - max(-t, 0) g_neg + sigma2_pos/neg v + F_off``.
    Search coordinates ``Fc_pos``, ``Fc_neg``, ``Fs_over_Fc_pos``,
    ``Fs_over_Fc_neg``, ``log10_vs``, ``log10_sigma2_pos``, ``log10_sigma2_neg``
    (+ ``delta``) + ``F_off``.
    """

    v_eps: float = eqx.field(default=1e-4, static=True, converter=float)
    exponent: float = eqx.field(default=2.0, static=True, converter=float)
    fit_exponent: bool = eqx.field(default=False, static=True)
    asymmetric: bool = eqx.field(default=False, static=True)
    offset: bool = eqx.field(default=False, static=True)

    uses_dt = False

    def __check_init__(self):
        _check_smoothing(self.v_eps, self.exponent)

    @property
    def _coords(self):
        coords = (("Fc", "Fc", "linear"),
                  ("Fs_over_Fc", "Fs", "ratio"),
                  ("log10_vs", "vs", "log10"),
                  ("log10_sigma2", "sigma2", "log10"))
        if self.fit_exponent:
            coords += (("delta", "delta", "linear"),)
        return directional_coords(coords, self.asymmetric, self.offset)

    def _simulate_batch(self, thetas, velocity, dt=None) -> Float[Array, "P T"]:
        p, vv, t = _columns(self, thetas, velocity)
        delta = p["delta"] if self.fit_exponent else self.exponent
        if self.asymmetric:
            g_pos = stribeck_curve(vv, p["Fc_pos"], p["Fs_pos"], p["vs"], delta)
            g_neg = stribeck_curve(vv, p["Fc_neg"], p["Fs_neg"], p["vs"], delta)
            f = signed_level(t, p, "Fc", g_pos, g_neg)
        else:
            f = t * stribeck_curve(vv, p["Fc"], p["Fs"], p["vs"], delta)
        return add_offset(f + by_direction(p, "sigma2", vv) * vv, p)


class Cylinder(AbstractPhysicalModel):
    """Pressure-dependent cylinder friction (Simscape "Cylinder Friction"),
    docs/algorithms.md §13.1::

        F_C = F_pr + f_cfr (p1 + p2),        F_brk = K_brk F_C
        F   = tanh(v / v_eps) F_C (1 + (K_brk - 1) exp(-|v / vs|^delta)) + sigma2 v (+ F_off)

    Simscape writes the Stribeck term as exp(-c_v |v|): ``delta = 1`` (the
    default ``exponent``) and c_v = 1 / vs. Inputs (``input_names``):
    ``("p1", "p2")``, the cap- and rod-chamber pressures [Pa]; pass them as
    ``inputs`` (a ``(2, T)`` array) or identify from a record that holds them.

    Search coordinates ``F_pr`` [N], ``f_cfr`` [N/Pa] (both linear, >= 0),
    ``K_brk`` [-] (linear, box entry default [1, 3]), ``log10_vs``, ``log10_sigma2``
    (+ ``F_off`` with ``offset=True``); with ``breakaway=False`` the Stribeck
    term and ``K_brk``, ``vs`` are dropped and the model is linear in
    ``F_pr``, ``f_cfr``, ``sigma2``. ``f_cfr``'s data-centred range is
    [0, 1.2 F / median(p1 + p2)], which needs the pressures
    (``search_box(None, v, F, inputs)``).
    """

    v_eps: float = eqx.field(default=1e-4, static=True, converter=float)
    exponent: float = eqx.field(default=1.0, static=True, converter=float)
    breakaway: bool = eqx.field(default=True, static=True)
    offset: bool = eqx.field(default=False, static=True)

    uses_dt = False
    _low_speed = ("K_brk", "vs")

    def __check_init__(self):
        _check_smoothing(self.v_eps, self.exponent)

    @property
    def input_names(self) -> tuple[str, ...]:
        return ("p1", "p2")

    @property
    def _coords(self):
        coords = (("F_pr", "F_pr", "linear"), ("f_cfr", "f_cfr", "linear"))
        if self.breakaway:
            coords += (("K_brk", "K_brk", "linear"), ("log10_vs", "vs", "log10"))
        coords += (("log10_sigma2", "sigma2", "log10"),)
        return directional_coords(coords, False, self.offset)

    def _input_ranges(self, friction_level, inputs):
        p_sum = np.asarray(inputs, dtype=float)[0] + np.asarray(inputs, dtype=float)[1]
        level = float(np.median(np.abs(p_sum)))
        if not level > 0.0:
            return {}
        return {"f_cfr": (0.0, 1.2 * friction_level / level)}

    def unidentifiable(self, data, **kwargs) -> tuple[Unidentifiable, ...]:
        """As [`AbstractPhysicalModel.unidentifiable`][jaxfric.models.AbstractPhysicalModel.unidentifiable], plus ``F_pr`` and ``f_cfr``
        when the record's pressure sum varies by less than 5 % of its level (the
        two then only determine their sum ``F_C``)."""
        out = list(super().unidentifiable(data, **kwargs))
        p1, p2 = getattr(data, "p1", None), getattr(data, "p2", None)
        if p1 is not None and p2 is not None:
            p_sum = np.asarray(p1, dtype=float) + np.asarray(p2, dtype=float)
            level = float(np.median(np.abs(p_sum)))
            if not np.ptp(p_sum) > 0.05 * level:
                why = (f"p1 + p2 varies by {np.ptp(p_sum):.3g} Pa around {level:.3g} Pa (< 5 %): "
                       "the data fix only F_pr + f_cfr (p1 + p2), not the two apart")
                out += [Unidentifiable("F_pr", why), Unidentifiable("f_cfr", why)]
        return tuple(out)

    def _simulate_batch(self, thetas, velocity, dt, inputs) -> Float[Array, "P T"]:
        p, vv, t = _columns(self, thetas, velocity)
        inputs = jnp.asarray(inputs, vv.dtype)
        if inputs.shape[-1] != vv.shape[-1]:
            raise ValueError(f"inputs have {inputs.shape[-1]} samples but velocity has {vv.shape[-1]}")
        f_c = p["F_pr"] + p["f_cfr"] * (inputs[0] + inputs[1])[None, :]
        level = f_c
        if self.breakaway:
            level = stribeck_curve(vv, f_c, p["K_brk"] * f_c, p["vs"], self.exponent)
        return add_offset(t * level + p["sigma2"] * vv, p)
