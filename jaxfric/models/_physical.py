"""Shared machinery of the physical (SI-unit) friction models: search coordinates,
the search box they span (defaults and data-centred boxes, `._box`), and a
least-squares initial guess.

Search coordinates (docs/algorithms.md §8.5): stiffnesses, damping and the Stribeck
velocity span decades, so they are searched as log10; forces are linear; the
static force is searched as the ratio ``Fs / Fc`` in [1, 3], which keeps
``Fs >= Fc`` inside the box without a penalty (a linear ratio rather than
``Fc (1 + e^xi)`` so that uniform sampling covers the ratio evenly).

Physical units: sigma0 [N/m], sigma1 and sigma2 [N s/m], Fc and Fs [N],
vs [m/s], delta [-].
"""

from __future__ import annotations

import abc
from typing import ClassVar

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike

from ._base import AbstractFrictionModel, Unidentifiable, friction_scales, record_velocity
from ._box import DEFAULT_RANGES, SearchBox, data_ranges

#: Suffixes of direction-dependent parameters (docs/algorithms.md §13.1): ``Fc_pos``
#: acts for v > 0, ``Fc_neg`` for v < 0; both share the range of ``Fc``.
DIRECTIONS = ("_pos", "_neg")

def base_name(phys: str) -> str:
    """``Fc_pos`` -> ``Fc``: the range key of a direction-dependent parameter."""
    for suffix in DIRECTIONS:
        if phys.endswith(suffix):
            return phys[: -len(suffix)]
    return phys


#: Parameters that get a ``_pos`` / ``_neg`` pair when a model is asymmetric (§13.1).
_DIRECTIONAL = ("Fc", "Fs", "sigma2")


def directional_coords(coords, asymmetric: bool, offset: bool) -> tuple:
    """docs/algorithms.md §13.1: the symmetric ``coords`` with ``Fc``, ``Fs`` and
    ``sigma2`` split into ``_pos`` (v > 0) and ``_neg`` (v < 0) levels when
    ``asymmetric``, and an output offset ``F_off`` [N] appended when ``offset``.
    With both off the symmetric layout is returned unchanged (saved fits load)."""
    out = []
    for search, phys, kind in coords:
        if asymmetric and phys in _DIRECTIONAL:
            out += [(search + sfx, phys + sfx, kind) for sfx in DIRECTIONS]
        else:
            out.append((search, phys, kind))
    if offset:
        out.append(("F_off", "F_off", "linear"))
    return tuple(out)


def by_direction(p: dict, name: str, v: Array) -> Array:
    """``p[name]`` for a symmetric model, else ``p[name_pos]`` where v > 0 and
    ``p[name_neg]`` elsewhere (§13.1)."""
    if name in p:
        return p[name]
    return jnp.where(v > 0, p[name + "_pos"], p[name + "_neg"])


def signed_level(t: Array, p: dict, name: str, level_pos: Array, level_neg: Array) -> Array:
    """``t * level`` for a smoothed sign ``t`` in [-1, 1] (symmetric), else
    ``max(t, 0) level_pos - max(-t, 0) level_neg`` (§13.1): the EMPS form
    ``Fc+ [v>0] - Fc- [v<0]`` with the model's smoothed sign. ``name`` tells which."""
    if name in p:
        return t * level_pos
    return jnp.maximum(t, 0.0) * level_pos - jnp.maximum(-t, 0.0) * level_neg


def add_offset(f: Array, p: dict) -> Array:
    """``f + F_off`` when the model has an output offset (§13.1)."""
    return f + p["F_off"] if "F_off" in p else f


def _ratio_base(phys: str) -> str:
    """The level a ``ratio`` coordinate multiplies: ``Fs`` -> ``Fc``, ``Fs_neg`` -> ``Fc_neg``."""
    return "Fc" + phys[len(base_name(phys)):]


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


#: Below this fraction of max |v| a sample counts as low speed (pre-sliding or the
#: Stribeck dip) for `AbstractPhysicalModel.unidentifiable` [D]. A sine sweeps
#: through it in 1.3 % of its samples and the EMPS recording in 1.5 %: both are
#: flagged, as the EMPS data description says its pre-sliding is weakly excited;
#: records with slow reversals or small-amplitude (pre-sliding) segments pass.
LOW_SPEED = 0.02
#: Fewer low-speed samples than this fraction of the record, and the parameters
#: that only low speeds excite are reported as not determined by the data.
MIN_LOW_SPEED_FRACTION = 0.02
#: Sliding samples (|v| > 0.2 max|v|) of one direction whose speeds span less than this
#: ((95th - 5th percentile) / median) are "one speed" [D]: the pneumatic O-ring records
#: (triangular strokes) span 22-24 %, the EMPS trapezoids several-fold.
ONE_SPEED_SPREAD = 0.3


class AbstractPhysicalModel(AbstractFrictionModel):
    """A model whose search coordinates are transforms of named physical parameters.

    Subclasses list ``_coords``: ``(search_name, physical_name, kind)`` with
    kind ``"log10"`` (theta = log10 p), ``"linear"`` (theta = p) or
    ``"ratio"`` (theta = Fs / Fc, physical_name ``"Fs"``). The search box is not
    part of the model: it is a [`SearchBox`][jaxfric.models.SearchBox] (physical name -> (low, high) in
    physical units; the ratio's entry is ``Fs_ratio``) given to [`bounds`][jaxfric.models.AbstractPhysicalModel.bounds] and
    [`jaxfric.identify`][jaxfric.identification.identify], completed by [`search_box`][jaxfric.models.AbstractPhysicalModel.search_box] from the defaults of
    docs/algorithms.md §8.5 and, for a record, the data-centred ranges. Units: see
    the module docstring.
    """

    needs_scaling: ClassVar[bool] = False
    #: Physical parameters set by pre-sliding (bristle / element stiffness, micro-damping).
    _presliding: ClassVar[tuple[str, ...]] = ()
    #: Physical parameters set by low-speed sliding (the Stribeck dip).
    _low_speed: ClassVar[tuple[str, ...]] = ("Fs", "vs", "delta")

    @property
    @abc.abstractmethod
    def _coords(self) -> tuple[tuple[str, str, str], ...]:
        """``(search_name, physical_name, kind)`` per entry of ``theta``."""

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(c[0] for c in self._coords)

    @property
    def physical_names(self) -> tuple[str, ...]:
        """Keys of [`to_physical`][jaxfric.models.AbstractPhysicalModel.to_physical] (and arguments of [`from_physical`][jaxfric.models.AbstractPhysicalModel.from_physical])."""
        return tuple(c[1] for c in self._coords)

    #: Search coordinates whose range is fixed by the model, not by the box (GMS's
    #: stick-breaking fractions live in [0, 1]).
    _fixed_ranges: ClassVar[dict[str, tuple[float, float]]] = {}

    def _range_key(self, phys: str, kind: str) -> str:
        return "Fs_ratio" if kind == "ratio" else base_name(phys)

    @property
    def box_keys(self) -> tuple[str, ...]:
        """The [`SearchBox`][jaxfric.models.SearchBox] entries this model's search coordinates use, in order."""
        keys = (self._range_key(phys, kind) for _, phys, kind in self._coords)
        return tuple(dict.fromkeys(k for k in keys if k not in self._fixed_ranges))

    def search_box(self, box=None, velocity: ArrayLike | None = None, friction: ArrayLike | None = None,
                   inputs: ArrayLike | None = None) -> SearchBox:
        """The complete box of this model: [`DEFAULT_RANGES`][jaxfric.models.DEFAULT_RANGES] (docs/algorithms.md §8.5),
        then, when a record's ``velocity`` [m/s] and ``friction`` [N] are given, the
        data-centred entries ([`data_ranges`][jaxfric.models.data_ranges]; with ``inputs``, the entries that
        scale with the measured channels), then the entries of the user's partial
        ``box`` (a mapping name -> (low, high) or a [`SearchBox`][jaxfric.models.SearchBox]).

        Raises ``ValueError`` naming the entry for an invalid range or a name this
        model does not search (listing the ones it does), before any computation.
        """
        given = box if isinstance(box, SearchBox) else SearchBox(box)
        keys = self.box_keys
        unknown = [k for k in given if k not in keys]
        if unknown:
            raise ValueError(f"search box: {type(self).__name__} has no parameter "
                             f"{', '.join(map(repr, unknown))}; its box entries are {', '.join(keys)}")
        ranges = {k: DEFAULT_RANGES[k] for k in keys}
        if velocity is not None:
            suggested = data_ranges(velocity, friction)
            if inputs is not None and self.input_names:
                suggested.update(self._input_ranges(friction_scales(velocity, friction)[0], inputs))
            ranges.update({k: r for k, r in suggested.items() if k in keys})
        ranges.update(given)
        return SearchBox(ranges)

    def bounds(self, box=None) -> tuple[np.ndarray, np.ndarray]:
        """Search-coordinate bounds of ``box`` (completed by [`search_box`][jaxfric.models.AbstractPhysicalModel.search_box]; log10
        for the ``log10`` coordinates)."""
        box = self.search_box(box)
        lower, upper = [], []
        for _, phys, kind in self._coords:
            key = self._range_key(phys, kind)
            lo, hi = self._fixed_ranges.get(key) or box[key]
            if kind == "log10":
                lo, hi = np.log10(lo), np.log10(hi)
            lower.append(lo)
            upper.append(hi)
        return np.asarray(lower, np.float64), np.asarray(upper, np.float64)

    def to_physical(self, theta: ArrayLike) -> dict[str, Array]:
        """Search coordinates -> physical parameters (SI units, leading axes kept)."""
        out = self._coord_values(theta)
        return {name: out[name] for name in self.physical_names}

    def _coord_values(self, theta: ArrayLike) -> dict[str, Array]:
        """Every ``_coords`` entry's physical value, keyed by its physical name."""
        theta = jnp.asarray(theta)
        if theta.shape[-1:] != (self.num_params,):
            raise ValueError(f"theta must have last axis {self.num_params}, got shape {theta.shape}")
        out: dict[str, Array] = {}
        ratios = []
        for i, (_, phys, kind) in enumerate(self._coords):
            x = theta[..., i]
            if kind == "log10":
                out[phys] = 10.0**x
            elif kind == "linear":
                out[phys] = x
            else:
                ratios.append((phys, x))
        for phys, x in ratios:
            out[phys] = out[_ratio_base(phys)] * x
        return out

    def _check_physical_names(self, params: dict) -> None:
        missing = set(self.physical_names) - set(params)
        extra = set(params) - set(self.physical_names)
        if missing or extra:
            raise ValueError(f"{type(self).__name__}.from_physical needs exactly {self.physical_names}; "
                             f"missing {sorted(missing)}, unexpected {sorted(extra)}")

    def from_physical(self, **params) -> Array:
        """Physical parameters (keywords [`physical_names`][jaxfric.models.AbstractPhysicalModel.physical_names]) -> ``theta``."""
        self._check_physical_names(params)
        return self._theta_from(params)

    def _theta_from(self, params: dict) -> Array:
        """``theta`` from the physical value of every ``_coords`` entry."""
        cols = []
        for _, phys, kind in self._coords:
            p = jnp.asarray(params[phys])
            if kind == "log10":
                cols.append(jnp.log10(p))
            elif kind == "linear":
                cols.append(p)
            else:
                cols.append(p / jnp.asarray(params[_ratio_base(phys)]))
        cols = jnp.broadcast_arrays(*cols)
        dtype = jnp.result_type(*cols, jnp.float32)
        return jnp.stack([c.astype(dtype) for c in cols], axis=-1)

    def unidentifiable(
        self, data, *, low_speed: float = LOW_SPEED, min_fraction: float = MIN_LOW_SPEED_FRACTION
    ) -> tuple[Unidentifiable, ...]:
        """Physical parameters the record may not determine, with reasons.

        ``data``: a record (anything with ``.velocity``) or a velocity array [m/s].
        Rules [D]: with fewer than ``min_fraction`` of the samples at
        ``0 < |v| < low_speed * max|v|``, the pre-sliding parameters (LuGre's
        sigma0, sigma1; Dahl's sigma0; GMS's k_i, C) and the Stribeck-dip ones
        (Fs, vs, delta) are reported; a ``_pos`` (``_neg``) level is reported
        when no sample moves faster than that threshold in the positive
        (negative) direction; viscous coefficients are reported when the record
        slides at one speed (relative spread of |v| below ``ONE_SPEED_SPREAD``) in
        the direction they act in (asymmetric), or in both directions with an
        offset (symmetric: then 2 levels fix 3 unknowns); ``F_off`` is reported whenever the model has both an
        offset and direction-dependent Coulomb levels (the three are not separable
        from sliding data). The fit may still return values for them: they
        are then set by the search box or by effects they were not meant for.
        """
        v = record_velocity(data)
        speed = np.abs(v)
        thr = low_speed * float(speed.max())
        frac = float(np.mean((speed > 0.0) & (speed < thr)))
        out = []
        if frac < min_fraction:
            why = (f"only {frac:.2%} of the samples have 0 < |v| < {thr:.3g} m/s ({low_speed:.0%} of "
                   f"max |v|; needed {min_fraction:.0%})")
            for name in self.physical_names:
                if self._group(name) in self._presliding:
                    out.append(Unidentifiable(name, why + ": the record holds almost no pre-sliding, "
                                              "so this stiffness/damping is not determined by it"))
                elif self._group(name) in self._low_speed:
                    out.append(Unidentifiable(name, why + ": the Stribeck dip is not excited"))
        names = self.physical_names
        if "F_off" in names and "Fc_pos" in names and "Fc_neg" in names:
            out.append(Unidentifiable(
                "F_off", "with direction-dependent Coulomb levels a constant offset shifts "
                "Fc_pos up and Fc_neg down alike: sliding data fix only Fc_pos + F_off and "
                "Fc_neg - F_off (the split comes from standstill samples and the search box)"))
        out += self._one_speed(v)
        for sfx, sign in (("_pos", 1.0), ("_neg", -1.0)):
            if not np.any(sign * v > thr):
                for name in self.physical_names:
                    if name.endswith(sfx) and name not in out:
                        direction = "positive" if sign > 0 else "negative"
                        out.append(Unidentifiable(name, f"no sample moves in the {direction} direction "
                                                  f"faster than {thr:.3g} m/s"))
        return tuple(out)

    def _one_speed(self, v: np.ndarray) -> list[Unidentifiable]:
        speed = np.abs(v)
        sliding = speed > 0.2 * speed.max()
        spread = {}
        for sfx, sign in (("_pos", 1.0), ("_neg", -1.0)):
            s = speed[sliding & (sign * v > 0)]
            if s.size:
                lo, mid, hi = np.percentile(s, [5.0, 50.0, 95.0])
                spread[sfx] = (hi - lo) / mid
        names = [n for n in self.physical_names if self._group(n) == "sigma2"]
        out = []
        for name in names:
            sfx = name[len("sigma2"):]
            if sfx:
                flagged = sfx in spread and spread[sfx] < ONE_SPEED_SPREAD
            else:
                flagged = ("F_off" in self.physical_names and bool(spread)
                           and max(spread.values()) < ONE_SPEED_SPREAD)
            if flagged:
                worst = spread[sfx] if sfx else max(spread.values())
                out.append(Unidentifiable(name, (
                    f"the record slides at one speed (|v| spans {worst:.0%} of its median, "
                    f"< {ONE_SPEED_SPREAD:.0%}): a viscous slope and a Coulomb level fit it alike")))
        return out

    def _group(self, phys: str) -> str:
        """The family of a physical parameter for [`unidentifiable`][jaxfric.models.AbstractPhysicalModel.unidentifiable] (``Fc_pos`` -> ``Fc``)."""
        return base_name(phys)

    def _input_ranges(self, friction_level: float, inputs) -> dict[str, tuple[float, float]]:
        """Data-centred ranges that depend on the measured ``inputs``; none by default."""
        del friction_level, inputs
        return {}

    def initial_guess(self, velocity: ArrayLike, friction: ArrayLike, box=None) -> np.ndarray:
        """Centre of ``box`` ([`bounds`][jaxfric.models.AbstractPhysicalModel.bounds]), with Fc and sigma2 from
        `coulomb_viscous_ls` (clipped to the box)."""
        lower, upper = self.bounds(box)
        theta = 0.5 * (lower + upper)
        viscous = any(base_name(p) == "sigma2" for p in self.physical_names)
        fc, s2 = coulomb_viscous_ls(velocity, friction, viscous=viscous)
        for i, (_, phys, kind) in enumerate(self._coords):
            if base_name(phys) == "Fc":
                theta[i] = fc
            elif base_name(phys) == "sigma2" and s2 > 0.0:
                theta[i] = np.log10(s2) if kind == "log10" else s2
        return np.clip(theta, lower, upper)


def stribeck_curve(v: Array, Fc: Array, Fs: Array, vs: Array, exponent) -> Array:
    """g(v) = Fc + (Fs - Fc) exp(-|v / vs|^delta), docs/algorithms.md §8.1 (delta = 2 there).

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
