"""Shared machinery of the physical (SI-unit) friction models: search coordinates,
default and data-centred search ranges, and a least-squares initial guess.

Search coordinates (ALGORITHMS.md §8.5): stiffnesses, damping and the Stribeck
velocity span decades, so they are searched as log10; forces are linear; the
static force is searched as the ratio ``Fs / Fc`` in [1, 3], which keeps
``Fs >= Fc`` inside the box without a penalty (a linear ratio rather than
``Fc (1 + e^xi)`` so that uniform sampling covers the ratio evenly).

Physical units: sigma0 [N/m], sigma1 and sigma2 [N s/m], Fc and Fs [N],
vs [m/s], delta [-].
"""

from __future__ import annotations

import abc
import dataclasses
from typing import ClassVar

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike

from ._base import AbstractFrictionModel, friction_scales

DEFAULT_RANGES: dict[str, tuple[float, float]] = {
    # ALGORITHMS.md §8.5 [D]: order-of-magnitude ranges for hydraulic cylinders.
    "sigma0": (1e4, 1e9),
    "sigma1": (1e1, 1e6),
    "sigma2": (1e1, 1e5),
    "Fc": (10.0, 2000.0),
    "Fs_ratio": (1.0, 3.0),
    "vs": (1e-4, 5e-2),
    "delta": (0.5, 3.0),
}

_LOG_RANGED = ("sigma0", "sigma1", "sigma2", "vs")


def as_range(value) -> tuple[float, float] | None:
    """Field converter: ``None`` or a hashable ``(low, high)`` pair of floats."""
    if value is None:
        return None
    try:
        lo, hi = (float(x) for x in value)
    except (TypeError, ValueError):
        raise ValueError(f"a search range must be a (low, high) pair of numbers, got {value!r}") from None
    return (lo, hi)


def data_ranges(velocity: ArrayLike, friction: ArrayLike) -> dict[str, tuple[float, float]]:
    """Search ranges centred on a record's friction level ``F`` and speed ``V``.

    With ``F`` = 95th percentile of |friction| and ``V`` = max |velocity|
    (:func:`friction_scales`), the rules are [D]:

    - Fc in [0.05, 1.2] F (Coulomb level cannot much exceed the observed force);
    - sigma0 in [F / 1e-2, F / 1e-7] N/m (bristle deflection at Fc between
      0.1 um and 10 mm);
    - sigma1 in [1e-3, 1e2] F / V and sigma2 in [1e-3, 2] F / V N s/m
      (damping/viscous force at V between 0.1 % and 100x resp. 200 % of F);
    - vs in [1e-3, 1] V m/s.

    For F = 200 N and V = 14 mm/s these reproduce the §8.5 table to within a
    factor of about 2. Fs/Fc and delta keep their defaults.
    """
    f, v = friction_scales(velocity, friction)
    return {
        "Fc": (0.05 * f, 1.2 * f),
        "sigma0": (f / 1e-2, f / 1e-7),
        "sigma1": (1e-3 * f / v, 1e2 * f / v),
        "sigma2": (1e-3 * f / v, 2.0 * f / v),
        "vs": (1e-3 * v, v),
    }


def coulomb_viscous_ls(velocity: ArrayLike, friction: ArrayLike, *, viscous: bool = True) -> tuple[float, float]:
    """Least-squares fit of ``F = Fc sign(v) + sigma2 v`` on the sliding samples.

    Sliding = |v| > 0.2 max|v|, where pre-sliding and Stribeck effects are
    small. Returns ``(Fc, sigma2)`` (sigma2 = 0 when ``viscous`` is False);
    used only as a starting point, so no statistics are attached.
    """
    v = np.asarray(velocity, dtype=float).ravel()
    f = np.asarray(friction, dtype=float).ravel()
    if v.shape != f.shape:
        raise ValueError(f"velocity and friction must have the same length, got {v.shape} and {f.shape}")
    friction_scales(v, f)  # validates finiteness and non-degeneracy
    mask = np.abs(v) > 0.2 * np.max(np.abs(v))
    cols = [np.sign(v[mask])] + ([v[mask]] if viscous else [])
    coef, *_ = np.linalg.lstsq(np.stack(cols, axis=1), f[mask], rcond=None)
    fc = float(abs(coef[0]))
    s2 = float(coef[1]) if viscous else 0.0
    return fc, s2


class AbstractPhysicalModel(AbstractFrictionModel):
    """A model whose search coordinates are transforms of named physical parameters.

    Subclasses list ``_coords``: ``(search_name, physical_name, kind)`` with
    kind ``"log10"`` (theta = log10 p), ``"linear"`` (theta = p) or
    ``"ratio"`` (theta = Fs / Fc, physical_name ``"Fs"``). Each physical
    parameter ``p`` has an optional ``p_range`` field ((low, high) in
    physical units, ``None`` = default of ALGORITHMS.md §8.5); the ratio uses
    ``Fs_ratio_range``. Units: see the module docstring.
    """

    needs_scaling: ClassVar[bool] = False

    @property
    @abc.abstractmethod
    def _coords(self) -> tuple[tuple[str, str, str], ...]:
        """``(search_name, physical_name, kind)`` per entry of ``theta``."""

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(c[0] for c in self._coords)

    @property
    def physical_names(self) -> tuple[str, ...]:
        """Keys of :meth:`to_physical` (and arguments of :meth:`from_physical`)."""
        return tuple(c[1] for c in self._coords)

    def _range_key(self, phys: str, kind: str) -> str:
        return "Fs_ratio" if kind == "ratio" else phys

    def physical_range(self, key: str) -> tuple[float, float]:
        """Range of physical parameter ``key`` (or ``"Fs_ratio"``) in use."""
        value = getattr(self, f"{key}_range", None)
        return DEFAULT_RANGES[key] if value is None else value

    def _check_ranges(self) -> None:
        for _, phys, kind in self._coords:
            key = self._range_key(phys, kind)
            lo, hi = self.physical_range(key)
            if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
                raise ValueError(f"{key}_range must satisfy low < high (finite), got {(lo, hi)}")
            if (key in _LOG_RANGED or key == "Fc") and lo <= 0.0:
                raise ValueError(f"{key}_range must be positive, got {(lo, hi)}")
            if key == "Fs_ratio" and lo < 1.0:
                raise ValueError(f"Fs_ratio_range must start at >= 1 so that Fs >= Fc, got {(lo, hi)}")

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Search box from the physical ranges (log10 for the ``log10`` coordinates)."""
        lower, upper = [], []
        for _, phys, kind in self._coords:
            lo, hi = self.physical_range(self._range_key(phys, kind))
            if kind == "log10":
                lo, hi = np.log10(lo), np.log10(hi)
            lower.append(lo)
            upper.append(hi)
        return np.asarray(lower, np.float64), np.asarray(upper, np.float64)

    def to_physical(self, theta: ArrayLike) -> dict[str, Array]:
        """Search coordinates -> physical parameters (SI units, leading axes kept)."""
        theta = jnp.asarray(theta)
        if theta.shape[-1:] != (self.num_params,):
            raise ValueError(f"theta must have last axis {self.num_params}, got shape {theta.shape}")
        out: dict[str, Array] = {}
        ratio = None
        for i, (_, phys, kind) in enumerate(self._coords):
            x = theta[..., i]
            if kind == "log10":
                out[phys] = 10.0**x
            elif kind == "linear":
                out[phys] = x
            else:
                ratio = (phys, x)
        if ratio is not None:
            out[ratio[0]] = out["Fc"] * ratio[1]
        return {name: out[name] for name in self.physical_names}

    def from_physical(self, **params) -> Array:
        """Physical parameters (keywords :attr:`physical_names`) -> ``theta``."""
        missing = set(self.physical_names) - set(params)
        extra = set(params) - set(self.physical_names)
        if missing or extra:
            raise ValueError(
                f"{type(self).__name__}.from_physical needs exactly {self.physical_names}; "
                f"missing {sorted(missing)}, unexpected {sorted(extra)}"
            )
        cols = []
        for _, phys, kind in self._coords:
            p = jnp.asarray(params[phys])
            if kind == "log10":
                cols.append(jnp.log10(p))
            elif kind == "linear":
                cols.append(p)
            else:
                cols.append(p / jnp.asarray(params["Fc"]))
        cols = jnp.broadcast_arrays(*cols)
        dtype = jnp.result_type(*cols, jnp.float32)
        return jnp.stack([c.astype(dtype) for c in cols], axis=-1)

    def with_data_bounds(self, velocity: ArrayLike, friction: ArrayLike) -> "AbstractPhysicalModel":
        """Copy with every *unset* range centred on the data (:func:`data_ranges`).

        Ranges given explicitly to the constructor are kept.
        """
        suggested = data_ranges(velocity, friction)
        updates = {}
        for field in dataclasses.fields(self):
            if field.name.endswith("_range") and getattr(self, field.name) is None:
                key = field.name[: -len("_range")]
                if key in suggested:
                    updates[field.name] = suggested[key]
        return dataclasses.replace(self, **updates)

    @classmethod
    def for_data(cls, velocity: ArrayLike, friction: ArrayLike, **kwargs) -> "AbstractPhysicalModel":
        """``cls(**kwargs).with_data_bounds(velocity, friction)``."""
        return cls(**kwargs).with_data_bounds(velocity, friction)

    def initial_guess(self, velocity: ArrayLike, friction: ArrayLike) -> np.ndarray:
        """Box centre, with Fc and sigma2 from :func:`coulomb_viscous_ls` (clipped to the box)."""
        lower, upper = self.bounds()
        theta = 0.5 * (lower + upper)
        viscous = "sigma2" in self.physical_names
        fc, s2 = coulomb_viscous_ls(velocity, friction, viscous=viscous)
        for i, (_, phys, kind) in enumerate(self._coords):
            if phys == "Fc":
                theta[i] = fc
            elif phys == "sigma2" and s2 > 0.0:
                theta[i] = np.log10(s2) if kind == "log10" else s2
        return np.clip(theta, lower, upper)


def stribeck_curve(v: Array, Fc: Array, Fs: Array, vs: Array, exponent) -> Array:
    """g(v) = Fc + (Fs - Fc) exp(-|v / vs|^delta), ALGORITHMS.md §8.1 (delta = 2 there).

    For a non-integer or traced ``exponent`` the power is guarded with the
    double-``where`` trick so gradients stay finite at v = 0.
    """
    ratio = jnp.abs(v) / vs
    if isinstance(exponent, (int, float)) and float(exponent) == 2.0:
        shape = ratio * ratio
    else:
        nonzero = ratio > 0
        safe = jnp.where(nonzero, ratio, jnp.ones_like(ratio))
        shape = jnp.where(nonzero, safe**exponent, jnp.zeros_like(ratio))
    return Fc + (Fs - Fc) * jnp.exp(-shape)
