"""Friction models for jaxfric (docs/algorithms.md §2, §8 and §13.1).

Every model implements [`AbstractFrictionModel`][jaxfric.models.AbstractFrictionModel]: a flat search vector
``theta`` with [`bounds`][jaxfric.models.AbstractFrictionModel.bounds] (of a [`SearchBox`][jaxfric.models.SearchBox], for
the physical models: data given to ``identify``, not a model field), named physical
parameters via ``to_physical`` / ``from_physical``, and a pure-JAX free-run
rollout ``simulate(theta, velocity, dt)`` / ``simulate_batch(thetas, velocity, dt)``.

Black-box models (``needs_scaling = True``: [`Elman`][jaxfric.models.Elman], [`ElmanFull`][jaxfric.models.ElmanFull])
are fitted on data scaled with [`Scaler`][jaxfric.models.Scaler]; physical models ([`LuGre`][jaxfric.models.LuGre],
[`Dahl`][jaxfric.models.Dahl], [`Coulomb`][jaxfric.models.Coulomb], [`Stribeck`][jaxfric.models.Stribeck], [`GMS`][jaxfric.models.GMS],
[`Cylinder`][jaxfric.models.Cylinder]) work in SI units, as does
[`GreyBox`][jaxfric.models.GreyBox] (a physical model plus a bounded, contractive network
correction). ``asymmetric=True`` / ``offset=True`` give
Coulomb, Stribeck, LuGre and Dahl direction-dependent levels and an output offset
(§13.1); [`Cylinder`][jaxfric.models.Cylinder] needs the chamber pressures as ``inputs``
(``model.input_names``). ``model.unidentifiable(record)`` names the parameters a
record may not determine.
"""

from __future__ import annotations

from ._base import AbstractFrictionModel, Unidentifiable, check_theta, friction_scales
from ._box import DEFAULT_RANGES, RANGE_FLOORS, SearchBox, data_ranges, widened
from ._physical import AbstractPhysicalModel, add_offset, by_direction, stribeck_curve
from ._scaling import Scaler
from ._scan import ACCELERATOR_UNROLL, time_loop, time_scan
from .elman import Elman, ElmanFull, elman_full_hidden, elman_hidden
from .gms import GMS
from .greybox import GreyBox
from .lugre import Dahl, LuGre, bristle_friction, bristle_phi
from .static import Coulomb, Cylinder, Stribeck

__all__ = ["AbstractFrictionModel", "AbstractPhysicalModel", "Coulomb", "Cylinder", "DEFAULT_RANGES", "Dahl",
           "Elman", "ElmanFull", "GMS", "GreyBox", "LuGre", "Scaler", "SearchBox", "Stribeck",
           "Unidentifiable", "available", "bristle_friction", "bristle_phi", "elman_full_hidden", "elman_hidden",
           "ACCELERATOR_UNROLL", "RANGE_FLOORS", "add_offset", "by_direction", "time_loop", "time_scan",
           "widened", "check_theta", "data_ranges", "friction_scales", "get", "stribeck_curve"]

_REGISTRY: dict[str, type[AbstractFrictionModel]] = {
    "elman": Elman,
    "elman_full": ElmanFull,
    "lugre": LuGre,
    "dahl": Dahl,
    "coulomb": Coulomb,
    "stribeck": Stribeck,
    "gms": GMS,
    "cylinder": Cylinder,
    "greybox": GreyBox,
}


def available() -> tuple[str, ...]:
    """Names accepted by [`get`][jaxfric.models.get]."""
    return tuple(_REGISTRY)


def get(name: str, **kwargs) -> AbstractFrictionModel:
    """Build a model by name, e.g. ``get("elman", neurons=20)`` or ``get("lugre")``.

    Names are case-insensitive and ``-`` may stand for ``_``. Keyword arguments
    go to the model's constructor. Unknown names raise ``ValueError`` listing
    the valid ones.
    """
    if not isinstance(name, str):
        raise ValueError(f"model name must be a string, one of {available()}, got {name!r}")
    key = name.strip().lower().replace("-", "_")
    try:
        cls = _REGISTRY[key]
    except KeyError:
        raise ValueError(f"unknown friction model {name!r}; valid names: {', '.join(available())}") from None
    return cls(**kwargs)
