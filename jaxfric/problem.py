"""What an identification problem is: its records, search coordinates and box, residuals
and score ([`AbstractProblem`][jaxfric.problem.AbstractProblem]; docs/architecture.md, "Problems").

Two final implementations: [`ForceBalanceProblem`][jaxfric.problem.ForceBalanceProblem] here (a measured friction
signal, §2.4: the prediction minus the measured friction) and
[`jaxfric.motion.MotionProblem`][jaxfric.motion.MotionProblem] with the motion code (force and position only,
§13.2: the simulated minus the measured position). A fit names its problem
([`Fit.problem`][jaxfric.fit.Fit.problem], overridden by [`jaxfric.motion.MotionFit`][jaxfric.motion.MotionFit]), so code
that reads a fit of either kind ([`jaxfric.uncertainty`][jaxfric.uncertainty]) asks the fit and imports
neither ``identification`` nor ``motion``. A collection of records that knows which of them
trained a fit ([`jaxfric.identification.RecordSet`][jaxfric.identification.RecordSet]) is a
[`TrainingRecords`][jaxfric.problem.TrainingRecords].

The force-balance residual function is a pytree (`_ForceBalance`, an ``eqx.Module``):
the records are its array leaves, traced inputs of the uncertainty's compiled
linearisation, and only the model's configuration, the training lengths and the dtypes
are static, so a second fit of the same model on records of the same lengths reuses the
compiled program.
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .metrics import friction_metrics
from .models import AbstractFrictionModel
from .records import FrictionData, as_channel, check_sample_time

__all__ = ["AbstractProblem", "ForceBalanceProblem", "Residuals", "SearchCoordinates", "TrainingRecords",
           "rollout"]


@dataclasses.dataclass(frozen=True)
class SearchCoordinates:
    """A fit's search vector ``y`` (NumPy) and, per coordinate, its physical
    ``names``, ``kinds`` (``"log10"``, ``"linear"``, ...) and search box ``[lower, upper]``:
    the model's coordinates, then any the problem adds (a motion fit's mechanics)."""

    y: np.ndarray
    names: tuple[str, ...]
    kinds: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray


@dataclasses.dataclass(frozen=True)
class Residuals:
    """A fit's training residuals r(y) (``fn``: ``(p,) -> (n,)``) in its search
    coordinates ``y`` (linearised at ``y``), the lengths of the independent ``segments``
    r is made of (no Newey–West lag crosses one), the ``unit`` of r, and per coordinate
    its physical ``names``, ``kinds`` (``"log10"``, ``"linear"``, ...) and search box.

    ``fn`` is best a pytree callable (an ``eqx.Module`` or ``jax.tree_util.Partial``)
    holding the records as array leaves: its compiled linearisation is then shared by
    every fit with equal static parts (model configuration, lengths) and array shapes.
    A plain closure works too, compiled afresh on each call (its captured arrays are
    constants of the program, and the closure is not kept alive by a cache)."""

    fn: Callable
    y: Any
    segments: tuple[int, ...]
    unit: str
    names: tuple[str, ...]
    kinds: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray

    @classmethod
    def at(cls, coords: SearchCoordinates, fn: Callable, segments, unit: str) -> "Residuals":
        """Residuals ``fn`` in the coordinates ``coords`` (linearised at ``coords.y``)."""
        return cls(fn=fn, y=coords.y, segments=tuple(segments), unit=unit, names=coords.names,
                   kinds=coords.kinds, lower=coords.lower, upper=coords.upper)


class TrainingRecords(abc.ABC):
    """Records of one identification that know which of them trained the fit:
    ``train_records``, each a [`jaxfric.FrictionData`][jaxfric.rig.FrictionData] whose first ``n_train``
    samples were training samples."""

    @property
    @abc.abstractmethod
    def train_records(self) -> tuple:
        """The records that trained the fit (each with its ``n_train``)."""


class AbstractProblem(eqx.Module):
    """One kind of identification problem: how a fit of it reads its data.

    Every method takes the fit first; ``data`` is what the fit was trained on (the record
    given to the identification, or its records). The methods are pure: they read the fit
    and the data and return new values.

    * [`coordinates`][jaxfric.problem.AbstractProblem.coordinates]: the parameter layout and box of the fit's search vector;
    * [`training_records`][jaxfric.problem.AbstractProblem.training_records]: the records (windows) the fit was trained on;
    * [`residuals`][jaxfric.problem.AbstractProblem.residuals]: r(y) over those training windows, the quantity the search
      minimised the squares of (the parameter uncertainty linearises it);
    * [`train_velocity`][jaxfric.problem.AbstractProblem.train_velocity]: the training velocity (the plausibility rules read it);
    * [`score`][jaxfric.problem.AbstractProblem.score]: the problem's metrics of the fit on one record; ``metric`` names
      the headline entry, lower is better.
    """

    #: The key of [`score`][jaxfric.problem.AbstractProblem.score]'s headline entry (lower is better).
    metric: ClassVar[str]
    #: How that entry is named in a message, and its unit.
    metric_label: ClassVar[str]
    metric_unit: ClassVar[str]

    @abc.abstractmethod
    def coordinates(self, fit) -> SearchCoordinates:
        """The fit's search vector with the names, kinds and box of its coordinates."""

    @abc.abstractmethod
    def training_records(self, fit, data) -> tuple:
        """The records of ``data`` that trained ``fit``, each cut to its training window."""

    @abc.abstractmethod
    def residuals(self, fit, data) -> Residuals:
        """The training residuals r(y) at the fit's search vector."""

    @abc.abstractmethod
    def train_velocity(self, fit, data) -> np.ndarray:
        """The velocity [m/s] of the training samples, concatenated."""

    @abc.abstractmethod
    def score(self, fit, record) -> dict:
        """The problem's metrics of ``fit`` on ``record`` (a dict holding ``metric``)."""


# ----------------------------------------------------------------------- force balance
def rollout(model: AbstractFrictionModel, theta, scalers, velocity, dt, inputs=None) -> jax.Array:
    """[`jaxfric.fit.predict`][jaxfric.fit.predict] without its checks of the velocity and ``dt``, so that
    both may be traced (the parameter uncertainty's compiled linearisation calls it): the
    force balance's forward map, friction of ``model`` at ``theta`` along ``velocity`` (§2.4)."""
    dtype = theta.dtype
    v = jnp.asarray(velocity, dtype)
    dt = jnp.asarray(dt, dtype)
    if inputs is not None and model.input_names:
        inputs = jnp.asarray(inputs, dtype)
    if model.needs_scaling:
        sv, sf = scalers
        return sf.unscale(model.simulate(theta, sv.scale(v), dt, inputs))
    return model.simulate(theta, v, dt, inputs)


class ForceBalanceProblem(AbstractProblem):
    """Friction identified from a measured friction signal (the force balance, §2.4, §11):
    a [`jaxfric.Fit`][jaxfric.fit.Fit]'s search vector is its model's θ, its residuals the free-run
    friction prediction minus the measured friction, each training record run from its own
    initial state, its score [`jaxfric.metrics.friction_metrics`][jaxfric.metrics.friction_metrics] of the free run over a
    whole record (headline: MSE %).

    ``data``: the fit's training record (a [`jaxfric.FrictionData`][jaxfric.rig.FrictionData] or a
    ``(velocity, friction, dt)`` tuple, its first ``fit.n_train`` samples), a list of
    training records (each trained on whole), or a [`TrainingRecords`][jaxfric.problem.TrainingRecords]."""

    metric: ClassVar[str] = "mse_percent"
    metric_label: ClassVar[str] = "free-run MSE"
    metric_unit: ClassVar[str] = "%"

    def coordinates(self, fit) -> SearchCoordinates:
        model = fit.model
        coords = tuple(model._coords)
        lower, upper = (np.asarray(b, np.float64) for b in model.bounds(fit.box))
        return SearchCoordinates(y=fit.theta, names=tuple(c[1] for c in coords),
                                 kinds=tuple(c[2] for c in coords), lower=lower, upper=upper)

    def training_records(self, fit, data) -> tuple:
        if isinstance(data, TrainingRecords):
            return tuple(data.train_records)
        if isinstance(data, (list, tuple)) and data and not _is_triplet(data):
            return tuple(_one_record(d) for d in data)  # a list of records, each trained on whole
        return (_one_record(data, fit.n_train),)

    def residuals(self, fit, data) -> Residuals:
        """Prediction minus measured friction over the training samples the fit was made
        on, each record run from its own initial state (`_ForceBalance`)."""
        if not isinstance(fit.problem(), ForceBalanceProblem):
            raise ValueError(f"a {type(fit).__name__} solves {type(fit.problem()).__name__}, not the force "
                             "balance: ask fit.problem() for its residuals")
        model = fit.model
        records = []
        for r in self.training_records(fit, data):
            x = model.inputs_from(r, r.velocity.shape[0])
            records.append((as_channel("velocity", r.velocity), np.asarray(r.friction)[: r.n_train],
                            None if x is None else np.asarray(x)))
        resid = _ForceBalance(model=model, scalers=(fit.velocity_scaler, fit.friction_scaler),
                              dt=np.asarray(check_sample_time(fit.dt), np.float64), records=tuple(records),
                              n_train=tuple(int(r[1].shape[0]) for r in records))
        return Residuals.at(self.coordinates(fit), resid, resid.n_train, "friction [N]")

    def train_velocity(self, fit, data) -> np.ndarray:
        return np.concatenate([np.asarray(r.velocity)[: r.n_train] for r in self.training_records(fit, data)])

    def score(self, fit, record) -> dict:
        """[`jaxfric.metrics.friction_metrics`][jaxfric.metrics.friction_metrics] [N] of
        [`Fit.predict`][jaxfric.fit.Fit.predict] over the whole ``record`` (a FrictionData or a
        ``(velocity, friction, dt)`` tuple), run from the model's initial state."""
        r = _one_record(record)
        dt = record[2] if _is_triplet(record) else record.dt
        inputs = fit.model.inputs_from(r, r.velocity.shape[0])
        return friction_metrics(r.friction, fit.predict(r.velocity, dt=dt, inputs=inputs))


class _ForceBalance(eqx.Module):
    """r(θ) of a force-balance fit: [`jaxfric.fit.predict`][jaxfric.fit.predict] of each record minus its
    measured friction over the first ``n_train`` samples, concatenated. The records
    (velocity, friction, input channels), the scalers and ``dt`` are array leaves, so
    traced inputs of the compiled linearisation; the model (its static configuration)
    and the lengths are its static part."""

    model: Any
    scalers: tuple
    dt: np.ndarray
    records: tuple  # ((velocity, training friction, inputs or None), ...)
    n_train: tuple[int, ...] = eqx.field(static=True)

    def __call__(self, theta):
        out = [rollout(self.model, theta, self.scalers, v, self.dt, x)[:n] - jnp.asarray(f, theta.dtype)
               for (v, f, x), n in zip(self.records, self.n_train)]
        return jnp.concatenate(out)


def _one_record(data, n_train: int | None = None):
    """A record a force-balance fit was trained on (a ``(velocity, friction, dt)`` tuple or
    a FrictionData), with its first ``n_train`` samples (default: all) as the training
    window."""
    if _is_triplet(data):
        v, f, _ = data
        rec = None
    elif isinstance(data, FrictionData):
        v, f, rec = data.velocity, data.friction, data
    else:
        raise ValueError("data must be the fit's training record (FrictionData or (velocity, friction, dt)), "
                         f"a list of training records, or a RecordSet; got {type(data).__name__}")
    v, f = as_channel("velocity", v), as_channel("friction", f)
    n_train = v.shape[0] if n_train is None else n_train
    if v.shape != f.shape or v.shape[0] < n_train:
        raise ValueError(f"the record ({v.shape[0]} velocity, {f.shape[0]} friction samples) does not hold "
                         f"the fit's {n_train} training samples")

    return _Window(v, f, int(n_train), rec)


@dataclasses.dataclass(frozen=True)
class _Window:
    """A record's velocity, friction and training length; other attributes (a Cylinder's
    chamber pressures) come from the record it was read from, if any."""

    velocity: np.ndarray
    friction: np.ndarray
    n_train: int
    source: Any = None

    def __getattr__(self, name):
        if name == "source":  # not set yet (copying): no recursion
            raise AttributeError(name)
        return getattr(self.source, name)


def _is_triplet(data) -> bool:
    return isinstance(data, tuple) and len(data) == 3 and np.ndim(data[2]) == 0
