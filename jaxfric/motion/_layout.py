"""Where a motion fit's mechanics sit in its search vector: shared by the fit's cost
(`jaxfric.motion._api`) and its uncertainty's residuals (`jaxfric.motion._residuals`)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp


class Layout(eqx.Module):
    """Where the mechanics' unknowns sit after the friction parameters in the search vector."""

    n_friction: int = eqx.field(static=True)
    fit_mass: bool = eqx.field(static=True)
    fit_offset: bool = eqx.field(static=True)
    fit_v0: bool = eqx.field(static=True)

    def unpack(self, y, args):
        i = self.n_friction
        theta = y[:i]
        mass, offset, dv0 = args["mass"], jnp.zeros((), y.dtype), jnp.zeros((), y.dtype)
        if self.fit_mass:
            mass, i = 10.0 ** y[i], i + 1
        if self.fit_offset:
            offset, i = y[i], i + 1
        if self.fit_v0:
            dv0 = y[i]
        return theta, mass, offset, dv0

    def names(self):
        return (("log10_mass",) if self.fit_mass else ()) + (("offset",) if self.fit_offset else ()) \
            + (("v0",) if self.fit_v0 else ())
