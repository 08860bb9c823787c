"""The motion residual and the training residuals of an [`jaxfric.identify_motion`][jaxfric.motion.identify_motion] fit.

`motion_residual` is the one definition of what every motion cost compares, §13.2: the
weighted error ``√w_k (x̂_k − x̃_k)`` of a simulated position (or velocity) against the
measurement, and `SumOfSquares` the one scalar cost made of residuals. The
multiple-shooting residuals and the free-run / k-step cost of the search
(``motion/_api.py``), the search's batched costs (``motion/_pipeline.py``) and the
uncertainty's residuals below call them.

For a fit's parameter uncertainty ([`jaxfric.uncertainty`][jaxfric.uncertainty], docs/uncertainty.md):
the fit's own cost's residuals as a function of its search coordinates (the model's,
then the mechanics it identified), so that their Jacobian is that of what the search
minimised. The residual function is an ``eqx.Module`` (`MotionResiduals`) whose arrays are
the record and the constants, so the uncertainty code's one compiled linearisation is
reused by every motion fit of the same model, cost and record length."""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..problem import Residuals, SearchCoordinates
from ._forward import motion_prediction
from ._layout import Layout
from ._step import friction_step

#: A motion fit's mechanics coordinates: search name -> (physical name, kind).
MECHANICS = {"log10_mass": ("mass", "log10"), "offset": ("offset", "linear"), "v0": ("v0", "linear")}


def motion_residual(x_hat, x, weight=None):
    """The motion residual, §13.2: ``r_k = √w_k (x̂_k − x̃_k)``, the simulated minus the
    measured position [m] (or velocity) of each sample, weighted by ``w_k`` (a scalar or
    one per sample; ``None``: unweighted, ``r_k = x̂_k − x̃_k``). The one definition every
    motion cost uses (module docstring): the shooting cost weighs each sample by its
    record's ``1 / (var(x_r) N)`` (0 on forced samples), the free-run cost by
    ``1 / (var(x) T)``, so that ``Σ r²`` is ``1 − R²``."""
    error = x_hat - x
    return error if weight is None else jnp.sqrt(weight) * error


class SumOfSquares(eqx.Module):
    """``J = sum(residuals(y, args)**2)``: the scalar cost of a residual function."""

    residuals: eqx.Module

    def __call__(self, y, args):
        r = self.residuals(y, args)
        return jnp.sum(r * r)


def search_layout(fit) -> tuple[Layout, list]:
    """Where the fit's search vector puts its mechanics, and their search names."""
    mech = fit.mechanics
    names = list(mech.search_names)
    extra = names[fit.model.num_params:]
    layout = Layout(fit.model.num_params, "log10_mass" in extra, "offset" in extra, "v0" in extra)
    if layout.names() != tuple(extra) or len(mech.y) != len(names):
        raise ValueError(f"motion fit with search coordinates {names} not understood by the "
                         f"uncertainty code (mechanics it knows: {sorted(MECHANICS)})")
    return layout, extra


def motion_coordinates(fit) -> SearchCoordinates:
    """A motion fit's search vector (the model's coordinates, then the mechanics it
    identified) with their names, kinds and box (the mechanics' box as searched; unbounded
    when the fit did not record it)."""
    mech = fit.mechanics
    _, extra = search_layout(fit)
    coords = tuple(fit.model._coords)
    lower, upper = (np.asarray(b, np.float64) for b in fit.model.bounds(fit.box))
    if extra:
        sb = mech.search_bounds
        if sb is not None:
            lower, upper = (np.asarray(b, np.float64) for b in sb[:2])
        else:  # bounds of the mechanics were not recorded: treat them as unbounded
            lower = np.concatenate([lower, np.full(len(extra), -np.inf)])
            upper = np.concatenate([upper, np.full(len(extra), np.inf)])
    return SearchCoordinates(y=np.asarray(mech.y, np.float64),
                             names=tuple(c[1] for c in coords) + tuple(MECHANICS[e][0] for e in extra),
                             kinds=tuple(c[2] for c in coords) + tuple(MECHANICS[e][1] for e in extra),
                             lower=lower, upper=upper)


def motion_residuals(fit, data) -> Residuals:
    """Simulation residuals of a motion fit over its training window of ``data`` (a
    [`jaxfric.motion.MotionData`][jaxfric.motion.MotionData]): free-run position and/or velocity, each divided
    by its standard deviation for ``error="both"``; k-step positions for a k-step fit;
    each training record run from its own start for a fit on whole records."""
    mech = fit.mechanics
    n = fit.n_train
    layout, _ = search_layout(fit)
    # a fit on whole records (identify_motion(train=[...])) attaches them concatenated
    records = training_lengths(fit)
    error, horizon = mech.error or "position", mech.horizon
    if records is not None and (sum(records) != n or error != "position" or horizon is not None):
        raise ValueError("motion fit on several records with a velocity or k-step cost: no uncertainty")
    x, v = np.asarray(data.position[:n]), np.asarray(data.velocity[:n])
    resid = MotionResiduals(
        step=friction_step(fit.model, (fit.velocity_scaler, fit.friction_scaler)),
        layout=layout, error=error,
        horizon=None if horizon is None else int(horizon),
        records=records,
        mass=np.asarray(mech.mass, np.float64), dt=np.asarray(float(fit.dt), np.float64),
        force=np.asarray(data.net_force[:n]), x=x, v=v,
        scale=np.asarray([np.std(x), max(np.std(v), 1e-300)], np.float64))
    unit = {"position": "position [m]", "velocity": "velocity [m/s]"}.get(error, "scaled position+velocity")
    if horizon is not None:
        unit = f"{int(horizon)}-step position [m]"
    segs = (n,) if error != "both" or horizon is not None else (n, n)
    if records is not None:
        segs = tuple(records)
    return Residuals.at(motion_coordinates(fit), resid, segs, unit)


def training_lengths(fit) -> tuple[int, ...] | None:
    """The lengths of the whole training records a fit on several records
    (``identify_motion(train=[...])``) was made on, concatenated in its data; ``None`` for
    a fit on one split record."""
    records = (fit.mechanics.records or {}).get("train")
    return None if records is None else tuple(int(r) for r in records)


class MotionResiduals(eqx.Module):
    """r(y) of a motion fit (`motion_residuals`) for search coordinates ``y`` (the
    model's, then the mechanics where ``layout`` puts them, as in the fit's own cost).
    The record (net force, position, velocity), the fixed mass and ``dt`` are array
    leaves, traced inputs of the compiled linearisation; the friction step's model, the
    cost (``error``, ``horizon``, ``records``) and the layout are its static part."""

    step: Any
    mass: np.ndarray  # used unless "log10_mass" is searched
    dt: np.ndarray
    force: np.ndarray
    x: np.ndarray
    v: np.ndarray
    scale: np.ndarray  # std of x and of v: error="both" divides by them, as the fit's cost
    layout: Layout
    error: str = eqx.field(static=True)
    horizon: int | None = eqx.field(static=True)
    records: tuple[int, ...] | None = eqx.field(static=True)

    def __call__(self, y):
        theta, mass, off, dv0 = self.layout.unpack(y, {"mass": jnp.asarray(self.mass, y.dtype)})
        step, dt = self.step, jnp.asarray(self.dt, y.dtype)
        u = jnp.asarray(self.force, y.dtype) - off
        xs, vs = jnp.asarray(self.x, y.dtype), jnp.asarray(self.v, y.dtype)
        if self.records is not None and self.horizon is None:  # whole records, each from its own start
            cuts = np.cumsum((0,) + self.records)
            return jnp.concatenate([
                motion_residual(motion_prediction(step, theta, mass, u[a:b], dt, xs[a:b], vs[a:b], dv0, None)[0],
                                xs[a:b])
                for a, b in zip(cuts[:-1], cuts[1:])])
        x_hat, v_hat, x, v = motion_prediction(step, theta, mass, u, dt, xs, vs, dv0, self.horizon)
        if self.horizon is not None or self.error == "position":
            return motion_residual(x_hat, x)
        if self.error == "velocity":
            return motion_residual(v_hat, v)
        sx, sv = jnp.asarray(self.scale[0], y.dtype), jnp.asarray(self.scale[1], y.dtype)
        return jnp.concatenate([motion_residual(x_hat, x) / sx, motion_residual(v_hat, v) / sv])


def motion_train_velocity(fit, data) -> np.ndarray:
    """The training window's velocity of ``data`` (a [`jaxfric.motion.MotionData`][jaxfric.motion.MotionData])."""
    return np.asarray(data.velocity)[: fit.n_train]
