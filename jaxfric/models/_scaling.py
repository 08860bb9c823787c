"""Min/max scaling to [-1, 1] (MATLAB ``mapminmax`` convention, docs/algorithms.md §2.4).

The Elman network is fitted on velocity and friction scaled with the minimum
and maximum of the *training* segment; the same [`Scaler`][jaxfric.models.Scaler] is then applied
to validation data (which may therefore fall slightly outside [-1, 1]) and its
inverse maps predictions back to newtons.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike

__all__ = ["Scaler"]


class Scaler(eqx.Module):
    """Affine map ``x -> 2 (x - lo) / (hi - lo) - 1`` per signal.

    ``lo`` and ``hi`` have the shape of one sample (scalars for a 1-D signal,
    ``(C,)`` for a ``(T, C)`` array of ``C`` signals). Both directions are pure
    JAX and broadcast over the leading (time) axis.
    """

    lo: Array | np.ndarray
    hi: Array | np.ndarray

    @classmethod
    def fit(cls, x: ArrayLike) -> "Scaler":
        """Take ``lo``/``hi`` as the min/max of ``x`` over its first (time) axis.

        Raises ``ValueError`` for empty input, non-finite values, or a constant
        signal (``hi == lo``), for which the scaling is undefined.
        """
        arr = np.asarray(x)
        if arr.ndim == 0 or arr.shape[0] == 0:
            raise ValueError(f"cannot fit a Scaler on an empty or scalar array (shape {arr.shape})")
        if not np.all(np.isfinite(arr)):
            raise ValueError("cannot fit a Scaler on data holding NaN or inf")
        lo = arr.min(axis=0)
        hi = arr.max(axis=0)
        if np.any(hi <= lo):
            raise ValueError("cannot fit a Scaler on a constant signal (max == min); mapminmax scaling is undefined")
        # Kept as float64 NumPy so that a scaler fitted before x64 is switched on
        # does not lose precision; arrays are cast to the data's dtype on use.
        return cls(lo=lo.astype(np.float64), hi=hi.astype(np.float64))

    @property
    def gain(self) -> Array:
        """Scaled units per physical unit, ``2 / (hi - lo)``."""
        return 2.0 / (jnp.asarray(self.hi) - jnp.asarray(self.lo))

    def scale(self, x: ArrayLike) -> Array:
        """Physical -> scaled ([-1, 1] on the fitting data)."""
        x, lo, hi = self._cast(x)
        return 2.0 * (x - lo) / (hi - lo) - 1.0

    def unscale(self, y: ArrayLike) -> Array:
        """Scaled -> physical (inverse of [`scale`][jaxfric.models.Scaler.scale])."""
        y, lo, hi = self._cast(y)
        return (y + 1.0) * (0.5 * (hi - lo)) + lo

    def unscale_difference(self, d: ArrayLike) -> Array:
        """Map a *difference* of scaled values (an error) to physical units (no offset)."""
        d, lo, hi = self._cast(d)
        return d * (0.5 * (hi - lo))

    def _cast(self, x):
        x = jnp.asarray(x)
        dtype = x.dtype if jnp.issubdtype(x.dtype, jnp.floating) else jnp.result_type(float)
        return x.astype(dtype), jnp.asarray(self.lo, dtype), jnp.asarray(self.hi, dtype)
