"""Data containers: raw rig measurements and the velocity/friction record models are fitted to.

``Measurements`` holds what a rig records (docs/algorithms.md §7: x, p1, p2, F_L
against t). ``FrictionData`` holds what identification needs (§1, §2.4, §11):
velocity in, friction out, on a uniform grid, with the train/validation split
of the paper (first 1600 of 2000 samples for estimation, last 400 for validation).
"""

from __future__ import annotations

from typing import Optional

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._checks import as_channel, check_increasing, check_positive, is_uniform


class Measurements(eqx.Module):
    """Raw rig channels in SI units (NumPy float64): time [s], piston position [m],
    cap / rod chamber pressures [Pa], external load from the force sensor [N]
    (opposing +x; see ``params`` for the sign convention)."""

    t: np.ndarray
    x: np.ndarray
    p1: np.ndarray
    p2: np.ndarray
    load: np.ndarray

    @classmethod
    def from_arrays(cls, t, x, p1, p2, load) -> "Measurements":
        """Validate and wrap the five channels (finite, equal length, strictly increasing ``t``)."""
        t = as_channel("t", t)
        check_increasing(t)
        n = t.shape[0]
        return cls(t=t, x=as_channel("x", x, n), p1=as_channel("p1", p1, n),
                   p2=as_channel("p2", p2, n), load=as_channel("load", load, n))

    @property
    def n_samples(self) -> int:
        return int(np.shape(self.t)[0])


def _split_count(n: int, train_fraction, n_train) -> int:
    if n_train is None:
        frac = float(train_fraction)
        if not (0.0 < frac <= 1.0):
            raise ValueError(f"train_fraction must lie in (0, 1], got {train_fraction!r}")
        n_train = int(round(frac * n))
    n_train = int(n_train)
    if not (1 <= n_train <= n):
        raise ValueError(f"n_train must lie in [1, {n}] for {n} samples, got {n_train}")
    return n_train


def _opt(a):
    return None if a is None else jnp.asarray(a)


class FrictionData(eqx.Module):
    """Velocity/friction record on a uniform grid, ready for identification.

    Fields (JAX arrays, SI): ``t`` [s], ``velocity`` [m/s], ``friction`` [N]
    (positive when opposing +x), ``acceleration`` [m/s^2] and chamber pressures
    ``p1``, ``p2`` [Pa] (``None`` when unknown), ``dt`` [s] (0-d array).
    ``n_train`` (static int): the first ``n_train`` samples are the training
    window, the rest the validation window (§1: 1600 / 400). A ``train()`` view
    has ``n_train == len``; a ``valid()`` view has ``n_train == 0``.

    A pytree of arrays: it can travel in ``args`` of a jitted objective and be
    stacked/vmapped over records of equal length.
    """

    t: jax.Array
    velocity: jax.Array
    friction: jax.Array
    acceleration: Optional[jax.Array]
    p1: Optional[jax.Array]
    p2: Optional[jax.Array]
    dt: jax.Array
    n_train: int = eqx.field(static=True)

    @classmethod
    def from_arrays(cls, velocity, friction, dt_or_t, train_fraction: float = 0.8, *,
                    n_train: int | None = None, acceleration=None, p1=None, p2=None,
                    rtol: float = 1e-3) -> "FrictionData":
        """Wrap velocity [m/s] / friction [N] pairs sampled uniformly.

        ``dt_or_t``: the sample interval [s] (scalar) or the time stamps [s]
        (must be uniform within ``rtol``; resample irregular stamps with
        :func:`jaxfric.rig.io.resample_uniform` first). The split is
        ``round(train_fraction * n)`` training samples unless ``n_train`` is given.
        """
        velocity = as_channel("velocity", velocity)
        n = velocity.shape[0]
        if n < 2:
            raise ValueError(f"a friction record needs at least 2 samples, got {n}")
        friction = as_channel("friction", friction, n)
        try:
            stamps = np.asarray(dt_or_t, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError("dt_or_t must be the sample interval [s] (a number) or the time "
                             f"stamps [s] (an array), got {dt_or_t!r}") from None
        if stamps.ndim == 0:
            dt = check_positive("dt", stamps)
            t = np.arange(n) * dt
        else:
            t = as_channel("t", stamps, n)
            check_increasing(t)
            if not is_uniform(t, rtol):
                raise ValueError("time stamps are not uniform; resample them first "
                                 "(jaxfric.rig.io.resample_uniform or on_irregular='resample')")
            dt = float(np.median(np.diff(t)))
        extra = {name: (None if arr is None else as_channel(name, arr, n))
                 for name, arr in (("acceleration", acceleration), ("p1", p1), ("p2", p2))}
        return cls(t=jnp.asarray(t), velocity=jnp.asarray(velocity), friction=jnp.asarray(friction),
                   acceleration=_opt(extra["acceleration"]), p1=_opt(extra["p1"]), p2=_opt(extra["p2"]),
                   dt=jnp.asarray(dt), n_train=_split_count(n, train_fraction, n_train))

    @property
    def n_samples(self) -> int:
        return int(self.velocity.shape[-1])

    @property
    def n_valid(self) -> int:
        return self.n_samples - self.n_train

    def _view(self, sl: slice, n_train: int) -> "FrictionData":
        cut = lambda a: None if a is None else a[..., sl]  # noqa: E731
        return FrictionData(t=cut(self.t), velocity=cut(self.velocity), friction=cut(self.friction),
                            acceleration=cut(self.acceleration), p1=cut(self.p1), p2=cut(self.p2),
                            dt=self.dt, n_train=n_train)

    def train(self) -> "FrictionData":
        """The estimation window: samples ``[0, n_train)``."""
        return self._view(slice(0, self.n_train), self.n_train)

    def valid(self) -> "FrictionData":
        """The validation window: samples ``[n_train, n)`` (its own ``n_train`` is 0)."""
        return self._view(slice(self.n_train, None), 0)

    def with_split(self, train_fraction: float | None = 0.8, *, n_train: int | None = None) -> "FrictionData":
        """Same record, another split (fraction of samples, or a count)."""
        return self._view(slice(None), _split_count(self.n_samples, train_fraction, n_train))
