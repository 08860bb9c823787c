"""The least-squares baseline of motion identification, and the start it gives (§13.1, §13.2).

Inverse dynamics of the training records, ``F_act − F_load = M·a + Fc·sign(v) + Fv·v + F_off``,
is linear in ``(M, Fc, Fv, F_off)``: with ``v`` the records' zero-phase filtered velocity and
``a`` its central difference, one least-squares solve gives them
([`jaxfric.rig.emps.idim_ls`][jaxfric.rig.idim_ls], the EMPS benchmark's IDIM-LS). The same parameters
simulated in free run are the baseline every motion fit is shown beside: a model that does
not beat it has not earned its extra parameters. Mapped into a richer model (its Coulomb
level and viscous slope, the mass and the offset; the rest at the box centre), they are a
start of the search that does not depend on the key.
"""

from __future__ import annotations

import numpy as np

from ..models import GMS, AbstractPhysicalModel, Coulomb
from ..pipeline import BASELINE_LABEL
from ..rig.emps import IDIMResult, idim_ls

__all__ = ["BASELINE_LABEL", "baseline_model", "least_squares", "least_squares_start", "slow_attraction_grid"]

#: Samples dropped at each end of a record: the zero-phase filter's edges.
EDGE = 20


def baseline_model() -> Coulomb:
    """The baseline's friction model in the mechanics: ``Fc tanh(v / 1e-4) + Fv v``."""
    return Coulomb(v_eps=1e-4)


def least_squares(records, mass: float | None = None) -> IDIMResult:
    """IDIM-LS on ``records`` (module docstring), pooled; ``mass`` given [kg]: fixed."""
    v, a, u = [], [], []
    for r in records:
        keep = slice(EDGE, r.n_samples - EDGE) if r.n_samples > 4 * EDGE else slice(None)
        v.append(r.velocity[keep])
        a.append(np.gradient(r.velocity, r.dt, edge_order=2)[keep])
        u.append(r.net_force[keep])
    return idim_ls(np.concatenate(v), np.concatenate(a), np.concatenate(u), mass=mass)


def least_squares_start(model, est: IDIMResult, velocity, box, layout, lower, upper) -> np.ndarray | None:
    """The search vector of ``model`` (with ``layout``'s mechanics) closest to ``est``:
    Coulomb level and viscous slope by ``model.initial_guess`` on the fitted friction law
    along the training ``velocity``,
    ``log10 M`` and the offset where searched; ``None`` for a model with no physical
    parameters to map (a network). Clipped into ``[lower, upper]``."""
    if not isinstance(model, AbstractPhysicalModel) or not np.isfinite(est.M) or est.M <= 0:
        return None
    v = np.asarray(velocity, np.float64)
    friction = est.Fc * np.sign(v) + est.Fv * v
    y = list(model.initial_guess(v, friction, box))
    if layout.fit_mass:
        y.append(np.log10(est.M))
    if layout.fit_offset:
        y.append(est.offset)
    if layout.fit_v0:
        y.append(0.0)
    return np.clip(np.asarray(y, np.float64), lower, upper)


#: The grid of `slow_attraction_grid`, as fractions of each coordinate's search range: the
#: element stiffnesses (all alike), the attraction rate ``log10 C``, and ``Fs/Fc``.
SLOW_GRID = {"k": (0.1, 0.2, 0.3), "C": (0.002, 0.02, 0.1), "Fs_over_Fc": (0.05, 0.25, 0.5)}


def slow_attraction_grid(model, start, lower, upper) -> list:
    """Variants of the least-squares start ``start`` (a search vector) for a model with
    Maxwell-slip elements and an attraction rate ([`GMS`][jaxfric.models.GMS]: its
    [`slow_coordinates`][jaxfric.models.GMS.slow_coordinates]): every element stiffness, ``log10 C`` and ``Fs/Fc`` set on the
    grid `SLOW_GRID` (fractions of their ranges in ``[lower, upper]``: soft elements, slow
    attraction near the floor of ``C``, a weak Stribeck peak), 27 points; ``[]`` for any other
    model. The swarm's short windows cannot see a slow attraction (its time constant is
    seconds at the floor of ``C``), and Levenberg-Marquardt on 5 000-sample shooting segments
    pulls a point out of that basin (docs/motion.md): these starts run on the free run only."""
    if start is None or not isinstance(model, GMS):
        return []
    k, c, r = (list(i) for i in model.slow_coordinates.values())
    start = np.asarray(start, np.float64)
    lo, hi = np.asarray(lower, np.float64), np.asarray(upper, np.float64)
    out = []
    for qk in SLOW_GRID["k"]:
        for qc in SLOW_GRID["C"]:
            for qr in SLOW_GRID["Fs_over_Fc"] if r else (None,):
                y = start.copy()
                y[k] = lo[k] + qk * (hi[k] - lo[k])
                y[c] = lo[c] + qc * (hi[c] - lo[c])
                if qr is not None:
                    y[r] = lo[r] + qr * (hi[r] - lo[r])
                out.append(y)
    return out
