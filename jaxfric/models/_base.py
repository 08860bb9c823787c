"""The interface every jaxfric friction model implements.

A friction model is a small immutable ``eqx.Module`` that holds only *static
hyperparameters* (number of neurons, which parameters are free). A physical
model's search box is data ([`jaxfric.models.SearchBox`][jaxfric.models.SearchBox]), passed to
[`bounds`][jaxfric.models.AbstractFrictionModel.bounds] and [`jaxfric.identify`][jaxfric.identification.identify].
Measured data -- velocity, friction, sample time -- always arrive as function
arguments, so a new data set never triggers recompilation and data sets can be
vmapped (docs/design.md, "Conventions").

Every model maps a flat search vector ``theta`` (what the optimisers see, in
*search coordinates*, e.g. log10 of a stiffness) to a friction prediction::

    lower, upper = model.bounds(box)         # NumPy, search coordinates
    params = model.to_physical(theta)        # {"sigma0": ..., "Fc": ...}
    theta = model.from_physical(**params)    # the inverse
    F_hat = model.simulate(theta, v, dt)     # free-run rollout, (T,)
    F_hat = model.simulate_batch(thetas, v, dt)  # (P, n) -> (P, T)

``simulate`` is the output-error (free-run) prediction of docs/algorithms.md §2.4 /
§11 step 4: the measured friction is never fed back.

A model that needs measured signals besides the velocity (the cylinder friction
of docs/algorithms.md §13.1 needs the chamber pressures) names them in
[`input_names`][jaxfric.models.AbstractFrictionModel.input_names] and takes them as ``inputs``, a
``(C, T)`` array in that order: ``model.simulate(theta, v, dt, inputs)``. Every
other model has ``input_names == ()`` and ignores ``inputs``.
[`inputs_from`][jaxfric.models.AbstractFrictionModel.inputs_from] reads them from a record.
"""

from __future__ import annotations

import abc
import functools
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .. import _xla

__all__ = ["AbstractFrictionModel", "Unidentifiable", "check_theta", "friction_scales", "record_velocity"]


class Unidentifiable(str):
    """The name of a parameter the data may not determine, with the ``reason``.

    A ``str`` (so ``"sigma0" in model.unidentifiable(record)`` works) that also
    carries a human-readable ``reason`` for reports.
    """

    reason: str

    def __new__(cls, name: str, reason: str) -> "Unidentifiable":
        obj = super().__new__(cls, name)
        obj.reason = str(reason)
        return obj

    def __reduce__(self):
        return (Unidentifiable, (str(self), self.reason))


def record_velocity(data) -> np.ndarray:
    """The velocity [m/s] of a record (anything with ``.velocity``) or of a plain array."""
    v = getattr(data, "velocity", data)
    v = np.asarray(v, dtype=float).ravel()
    if v.size == 0 or not np.all(np.isfinite(v)):
        raise ValueError("velocity must be a non-empty, finite time series")
    return v


def _as_float_dtype(*arrays) -> jnp.dtype:
    """Common floating dtype of the inputs (ints and bools promote to float).

    Constants inside the models are created in this dtype so float32 and float64
    both work without the library touching ``jax_enable_x64``.
    """
    dtype = jnp.result_type(*arrays)
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(dtype, jnp.float32)
    return dtype


def check_theta(theta: ArrayLike, num_params: int, *, name: str = "theta") -> np.ndarray:
    """Validate a parameter vector (or a ``(P, n)`` batch) eagerly, outside jit.

    Returns ``theta`` as a NumPy array. Raises ``ValueError`` when it is not
    1-D/2-D, when its last axis is not ``num_params`` long, or when it holds NaN
    or inf. Use it at API boundaries (user-supplied initial guesses, saved
    fits); inside a jitted objective non-finite values are left to the
    optimiser's NaN-is-worst rule instead.
    """
    arr = np.asarray(theta)
    if arr.ndim not in (1, 2):
        raise ValueError(f"{name} must be a 1-D parameter vector or a 2-D (P, n) batch, got shape {arr.shape}")
    if arr.shape[-1] != num_params:
        raise ValueError(f"{name} has {arr.shape[-1]} entries per candidate but the model has "
                         f"{num_params} parameters")
    if not np.issubdtype(arr.dtype, np.number):
        raise ValueError(f"{name} must be numeric, got dtype {arr.dtype}")
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))
        raise ValueError(f"{name} holds non-finite values (NaN or inf) at index {bad[0].tolist()}")
    return arr


def friction_scales(velocity: ArrayLike, friction: ArrayLike) -> tuple[float, float]:
    """Characteristic friction level and speed of a record, for data-centred bounds.

    Returns ``(F_level, v_max)``: the 95th percentile of ``|friction|`` (robust
    to filter spikes at reversals) and ``max |velocity|``. Raises
    ``ValueError`` if either is zero or the data are not finite.
    """
    v = np.asarray(velocity, dtype=float).ravel()
    f = np.asarray(friction, dtype=float).ravel()
    if v.size == 0 or f.size == 0:
        raise ValueError("velocity and friction must not be empty")
    if not (np.all(np.isfinite(v)) and np.all(np.isfinite(f))):
        raise ValueError("velocity and friction must be finite (no NaN or inf)")
    f_level = float(np.percentile(np.abs(f), 95.0))
    v_max = float(np.max(np.abs(v)))
    if f_level <= 0.0:
        raise ValueError("friction is (almost) identically zero; cannot centre bounds on it")
    if v_max <= 0.0:
        raise ValueError("velocity is identically zero; cannot centre bounds on it")
    return f_level, v_max


class AbstractFrictionModel(eqx.Module):
    """Base class of all friction models (Elman, LuGre, Dahl, static maps).

    Subclasses are immutable and hold only static hyperparameters. They must
    provide [`param_names`][jaxfric.models.AbstractFrictionModel.param_names], [`bounds`][jaxfric.models.AbstractFrictionModel.bounds], [`to_physical`][jaxfric.models.AbstractFrictionModel.to_physical],
    [`from_physical`][jaxfric.models.AbstractFrictionModel.from_physical] and ``_simulate_batch``; the rest has defaults.

    Class attributes:

    - ``needs_scaling``: ``True`` for black-box models fitted on data scaled
      to [-1, 1] (the Elman network, docs/algorithms.md §2.4). Physical models work
      in SI units (velocity in m/s, friction in N) and leave it ``False``.
    - ``uses_dt``: ``False`` for static maps, whose output ignores ``dt``.
    """

    needs_scaling: ClassVar[bool] = False
    uses_dt: ClassVar[bool] = True

    # ------------------------------------------------------------ description
    @property
    def input_names(self) -> tuple[str, ...]:
        """Measured channels the model needs besides the velocity, in the row order
        of ``inputs`` (e.g. ``("p1", "p2")``, chamber pressures in Pa); ``()`` for
        models driven by the velocity alone."""
        return ()

    def inputs_from(self, data, length: int | None = None) -> np.ndarray | None:
        """The ``(C, T)`` ``inputs`` array read from ``data``'s attributes named in
        [`input_names`][jaxfric.models.AbstractFrictionModel.input_names] (a [`jaxfric.FrictionData`][jaxfric.rig.FrictionData], the record type of the
        loaders and of [`jaxfric.identify`][jaxfric.identification.identify]), or ``None`` for a model that needs none.

        Raises ``ValueError`` naming the missing channels when ``data`` lacks them,
        and when a channel is not ``length`` samples long.
        """
        if not self.input_names:
            return None
        missing = [n for n in self.input_names if getattr(data, n, None) is None]
        if missing:
            raise ValueError(f"{type(self).__name__} needs the measured channel(s) {', '.join(missing)} "
                             f"(of {self.input_names}) but the data have none; pass a record that holds "
                             "them (e.g. FrictionData.from_arrays(..., p1=..., p2=...))")
        rows = [np.asarray(getattr(data, n), dtype=np.float64).ravel() for n in self.input_names]
        for name, row in zip(self.input_names, rows):
            if length is not None and row.shape[0] != length:
                raise ValueError(f"channel {name} has {row.shape[0]} samples, expected {length}")
            if not np.all(np.isfinite(row)):
                raise ValueError(f"channel {name} holds NaN or inf")
        return np.stack(rows)

    def unidentifiable(self, data) -> tuple[Unidentifiable, ...]:
        """Parameters that ``data`` (a record or a velocity array) may not determine,
        each with its reason ([`Unidentifiable`][jaxfric.models.Unidentifiable]); ``()`` by default."""
        del data
        return ()

    @property
    def box_keys(self) -> tuple[str, ...]:
        """The [`SearchBox`][jaxfric.models.SearchBox] entries this model searches; ``()`` for
        the networks, whose box is a model option (docs/algorithms.md §8.5)."""
        return ()

    @property
    @abc.abstractmethod
    def param_names(self) -> tuple[str, ...]:
        """Names of the search coordinates, in ``theta`` order."""

    @property
    def num_params(self) -> int:
        """Length of the flat search vector ``theta``."""
        return len(self.param_names)

    @abc.abstractmethod
    def bounds(self, box=None) -> tuple[np.ndarray, np.ndarray]:
        """Search box ``(lower, upper)`` in search coordinates (1-D float64 NumPy), for
        the search box ``box`` of a physical model (``None``: its defaults)."""

    @abc.abstractmethod
    def to_physical(self, theta: Float[ArrayLike, "... n"]) -> dict[str, Array]:
        """Map search coordinates to named physical parameters (leading axes kept)."""

    @abc.abstractmethod
    def from_physical(self, **params) -> Array:
        """Inverse of [`to_physical`][jaxfric.models.AbstractFrictionModel.to_physical]: named physical parameters -> ``theta``."""

    # -------------------------------------------------------------- rollouts
    @abc.abstractmethod
    def _simulate_batch(self, thetas: Array, velocity: Array, dt) -> Array:
        """Model-specific rollout; called traced, through [`simulate_batch`][jaxfric.models.AbstractFrictionModel.simulate_batch].

        Models with [`input_names`][jaxfric.models.AbstractFrictionModel.input_names] take a fourth argument, the ``(C, T)``
        ``inputs``; the others are called with three."""

    def _check_inputs(self, inputs):
        """``None`` for models that ignore ``inputs``; else the array, after an
        eager (trace-time) check that it is there and has ``C`` rows."""
        if not self.input_names:
            return None
        if inputs is None:
            raise ValueError(f"{type(self).__name__} needs inputs={self.input_names} (a (C, T) array of "
                             "measured channels, e.g. chamber pressures in Pa); none were given")
        inputs = jnp.asarray(inputs)
        if inputs.ndim != 2 or inputs.shape[0] != len(self.input_names):
            raise ValueError(f"inputs must be a ({len(self.input_names)}, T) array holding {self.input_names}, "
                             f"got shape {inputs.shape}")
        return inputs

    def simulate_batch(
        self, thetas: Float[ArrayLike, "P n"], velocity: Float[ArrayLike, " T"], dt=None,
        inputs: Float[ArrayLike, "C T"] | None = None,
    ) -> Float[Array, "P T"]:
        """Free-run friction of ``P`` candidates on one velocity record, ``(P, T)``.

        The rollout is wrapped in ``jax.jit`` (a no-op inside a caller's own
        jit), so eager calls compile once per model configuration and input
        shape; ``dt`` is traced, so a new sample time does not recompile. On CPU
        it compiles with [`jaxfric.compiler_options`][jaxfric._xla.compiler_options] ``("rollout")``
        (512-bit vectors where the CPU has them).
        """
        self._check_dt(dt)
        inputs = self._check_inputs(inputs)
        rollout = _xla.jit(_jit_rollout, _xla.resolve(_xla.AUTO, "rollout"))
        return rollout(self, thetas, velocity, dt, inputs)

    def simulate(
        self, theta: Float[ArrayLike, " n"], velocity: Float[ArrayLike, " T"], dt=None,
        inputs: Float[ArrayLike, "C T"] | None = None,
    ) -> Float[Array, " T"]:
        """Free-run friction prediction for one parameter vector.

        Pure JAX: jittable, differentiable (any order, forward and reverse), and
        vmappable. ``vmap`` over ``theta`` alone is routed to
        [`simulate_batch`][jaxfric.models.AbstractFrictionModel.simulate_batch] by a custom batching rule, so an optimiser that
        vmaps a per-candidate objective gets the fast batched rollout (docs/algorithms.md
        §2.2, "measured"); other vmaps (over data, or nested) fall back to ordinary batching. ``velocity`` and the returned friction are in the
        model's working units (see ``needs_scaling``); ``dt`` is the sample time
        in s (ignored by static maps and the Elman networks). ``inputs``: the
        ``(C, T)`` measured channels named by [`input_names`][jaxfric.models.AbstractFrictionModel.input_names] (ignored by
        models that need none).
        """
        theta = jnp.asarray(theta)
        if theta.ndim != 1:
            raise ValueError(f"theta must be 1-D, got shape {theta.shape}; use simulate_batch")
        self._check_dt(dt)
        inputs = self._check_inputs(inputs)
        return _single_rollout(self)(theta, velocity, dt, inputs)

    # ---------------------------------------------------------------- helpers
    #: Models whose rollout integrates in time reject a concrete non-positive or
    #: non-finite ``dt`` eagerly (inside a jit it is traced and cannot be checked).
    _checks_dt: ClassVar[bool] = False

    def _check_dt(self, dt) -> None:
        if not self._checks_dt or dt is None or isinstance(dt, jax.core.Tracer):
            return
        arr = np.asarray(dt)
        if arr.ndim == 0 and np.issubdtype(arr.dtype, np.number):
            value = float(arr)
            if not (np.isfinite(value) and value > 0.0):
                raise ValueError(f"dt must be a positive, finite sample time in seconds, got {value!r}")

    def check_theta(self, theta: ArrayLike) -> np.ndarray:
        """Eager validation of ``theta`` (shape, length, finiteness); see [`check_theta`][jaxfric.models.AbstractFrictionModel.check_theta]."""
        return check_theta(theta, self.num_params)

    def penalty(self, theta: ArrayLike) -> Array:
        """Extra residual rows a motion fit appends to its cost (its sum of squares is added
        to J): a regularisation term of the model's own. Empty (no penalty) by default;
        [`GreyBox`][jaxfric.models.GreyBox] returns its ridge rows."""
        theta = jnp.asarray(theta)
        return jnp.zeros(theta.shape[:-1] + (0,), _as_float_dtype(theta))

    def initial_guess(self, velocity: ArrayLike, friction: ArrayLike, box=None) -> np.ndarray:
        """A starting point inside [`bounds`][jaxfric.models.AbstractFrictionModel.bounds]; the default is the box centre."""
        lower, upper = self.bounds(box)
        return 0.5 * (lower + upper)

    def search_box(self, box=None, velocity: ArrayLike | None = None, friction: ArrayLike | None = None,
                   inputs: ArrayLike | None = None):
        """The search box to give [`bounds`][jaxfric.models.AbstractFrictionModel.bounds]: ``None`` for a model whose box is
        part of its configuration (the Elman networks' weight bounds, fitted on
        scaled data); a given non-empty ``box`` is then refused (``ValueError``).
        Physical models complete ``box`` from their defaults and the data
        ([`jaxfric.models.AbstractPhysicalModel.search_box`][jaxfric.models.AbstractPhysicalModel.search_box])."""
        del velocity, friction, inputs
        if box:
            raise ValueError(
                f"{type(self).__name__} takes no search box: its box is set by its own options "
                "(e.g. the Elman networks' weight_bound, context_weight_bound)")
        return None

    # ------------------------------------------------------------- internals
    def _prepare(self, thetas, velocity) -> tuple[Array, Array]:
        """Shape checks (trace-time, so they also work under jit) and dtype promotion."""
        thetas = jnp.asarray(thetas)
        velocity = jnp.asarray(velocity)
        if thetas.ndim != 2:
            raise ValueError(f"thetas must be a 2-D (P, n) batch, got shape {thetas.shape}")
        if thetas.shape[-1] != self.num_params:
            raise ValueError(f"theta has {thetas.shape[-1]} entries but {type(self).__name__} has "
                             f"{self.num_params} parameters")
        if velocity.ndim != 1:
            raise ValueError(f"velocity must be a 1-D time series, got shape {velocity.shape}")
        if velocity.shape[0] == 0:
            raise ValueError("velocity is empty: a rollout needs at least one sample")
        dtype = _as_float_dtype(thetas, velocity)
        return thetas.astype(dtype), velocity.astype(dtype)


def _jit_rollout(model: AbstractFrictionModel, thetas, velocity, dt, inputs=None):
    # The model has only static fields, so it is an empty pytree whose treedef
    # (hence the jit cache key) is its configuration.
    if model.input_names:
        return model._simulate_batch(thetas, velocity, dt, inputs)
    return model._simulate_batch(thetas, velocity, dt)


def _any_batched(flags) -> bool:
    return any(jax.tree_util.tree_leaves(flags))


@functools.lru_cache(maxsize=128)
def _single_rollout(model: AbstractFrictionModel):
    """``(theta, velocity, dt, inputs) -> (T,)`` for ``model`` with a batching rule
    that sends ``vmap`` over ``theta`` to ``simulate_batch``.

    ``custom_vmap`` alone does not support reverse-mode differentiation, so it
    sits under a ``custom_jvp`` whose rule differentiates the plain rollout:
    values take the fast path, derivatives the ordinary one. Cached per model
    configuration (models are hashable static configs).
    """

    def plain(theta, velocity, dt, inputs):
        return model.simulate_batch(theta[None, :], velocity, dt, inputs)[0]

    batched = jax.custom_batching.custom_vmap(plain)

    @batched.def_vmap
    def _rule(axis_size, in_batched, theta, velocity, dt, inputs):
        theta_b, velocity_b, dt_b, inputs_b = in_batched
        if theta_b and not velocity_b and not _any_batched(dt_b) and not _any_batched(inputs_b):
            return model.simulate_batch(theta, velocity, dt, inputs), True
        axes = tuple(0 if _any_batched(b) else None for b in in_batched)
        return jax.vmap(plain, in_axes=axes, axis_size=axis_size)(theta, velocity, dt, inputs), True

    @jax.custom_jvp
    def rollout(theta, velocity, dt, inputs):
        return batched(theta, velocity, dt, inputs)

    @rollout.defjvp
    def _rollout_jvp(primals, tangents):
        return jax.jvp(plain, primals, tangents)

    return rollout
