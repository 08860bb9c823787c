"""The EMPS benchmark recording: loader, the benchmark's own friction recipe, IDIM-LS.

EMPS (Electro-Mechanical Positioning System; Janot, Gautier & Brunot, "Data Set and
Reference Models of EMPS", Nonlinear System Identification Benchmarks, 2019) is a
ball-screw prismatic axis under a PD position loop. Its estimation file
``DATA_EMPS.mat`` holds ``t`` [s], ``qm`` (measured position) [m], ``qg`` (reference)
[m], ``vir`` (drive voltage) [V] and the constants ``gtau`` [N/V], ``kp``, ``kv``.

The benchmark's recipe (used by [`emps_states`][jaxfric.rig.emps.emps_states] and [`emps_friction_data`][jaxfric.rig.emps_friction_data]):

1. 4th-order Butterworth low-pass at 100 Hz on ``qm``, run forward–backward
   (``scipy.signal.sosfiltfilt``, [`jaxfric.rig.lowpass`][jaxfric.rig.lowpass]);
2. velocity and acceleration by central differences ([`jaxfric.rig.differentiate`][jaxfric.rig.differentiate]);
3. drop ``drop`` samples (default 50) at each end, where the filter's edge
   transients live;
4. rigid-body inverse model (IDIM)::

       gtau·vir = M·a + Fv·v + Fc·sign(v) + offset                    (symmetric)
       gtau·vir = M·a + Fv±·v + Fc+·[v > 0] − Fc−·[v < 0]              (asymmetric)

   solved by linear least squares ([`idim_ls`][jaxfric.rig.idim_ls], IDIM-LS), and the friction
   record ``friction = gtau·vir − M·a`` with a given or IDIM-LS-estimated ``M``
   (this signal also holds the constant offset).

The data are not part of jaxfric: pass the path of your copy of ``DATA_EMPS.mat``.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from ._checks import as_channel, check_increasing, check_positive
from .data import FrictionData
from .pipeline import differentiate, lowpass

__all__ = ["EMPSRecording", "IDIMResult", "emps_friction_data", "emps_states", "idim_ls", "load_emps"]

#: The benchmark's filter: order 4, 100 Hz (forward–backward), and samples dropped at each end.
EMPS_CUTOFF_HZ = 100.0
EMPS_ORDER = 4
EMPS_DROP = 50

_SIGNALS = ("t", "qm", "qg", "vir")
_CONSTANTS = ("gtau", "kp", "kv")


@dataclasses.dataclass(frozen=True)
class EMPSRecording:
    """The raw signals of an EMPS ``.mat`` file (NumPy float64, SI units, unchanged).

    ``t`` [s], ``qm`` measured position [m], ``qg`` reference position [m], ``vir``
    drive voltage [V]; constants ``gtau`` [N/V] (actuator force = ``gtau·vir``),
    ``kp`` [1/s] and ``kv`` [V/(m/s)] of the loop ``vir = kv·(kp·(qg − qm) − dqm)``.
    """

    t: np.ndarray
    qm: np.ndarray
    qg: np.ndarray
    vir: np.ndarray
    gtau: float
    kp: float
    kv: float

    @property
    def n_samples(self) -> int:
        return int(self.t.shape[0])

    @property
    def dt(self) -> float:
        """Sample time [s]: the median step of ``t`` (1 ms for the benchmark file)."""
        return float(np.median(np.diff(self.t)))

    @property
    def force(self) -> np.ndarray:
        """Actuator force ``gtau·vir`` [N]."""
        return self.gtau * self.vir


def load_emps(path) -> EMPSRecording:
    """Read an EMPS ``.mat`` file (``scipy.io.loadmat``) into an [`EMPSRecording`][jaxfric.rig.EMPSRecording].

    Raises:
        FileNotFoundError: no file at ``path``.
        ValueError: a signal or constant is missing, not finite, of another length,
            or ``t`` is not strictly increasing.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"no EMPS file at {path!r} (expected DATA_EMPS.mat)")
    import scipy.io  # here, not at import: scipy is slow to import

    try:
        mat = scipy.io.loadmat(path)
    except Exception as err:  # scipy raises several types for a non-MAT file
        raise ValueError(f"{path!r} is not a readable MATLAB .mat file: {err}") from None
    missing = [k for k in _SIGNALS + _CONSTANTS if k not in mat]
    if missing:
        raise ValueError(f"{path!r} lacks the EMPS variable(s) {', '.join(missing)}")
    t = as_channel("t", np.ravel(mat["t"]))
    check_increasing(t)
    n = t.shape[0]
    signals = {k: as_channel(k, np.ravel(mat[k]), n) for k in _SIGNALS[1:]}
    consts = {}
    for k in _CONSTANTS:
        value = np.ravel(mat[k])
        if value.size != 1 or not np.isfinite(value[0]):
            raise ValueError(f"EMPS constant {k!r} must be one finite number, got {mat[k]!r}")
        consts[k] = float(value[0])
    check_positive("gtau [N/V]", consts["gtau"])
    return EMPSRecording(t=t, **signals, **consts)


def emps_states(rec: EMPSRecording, *, cutoff: float = EMPS_CUTOFF_HZ, order: int = EMPS_ORDER,
                drop: int = EMPS_DROP) -> dict[str, np.ndarray]:
    """Steps 1–3 of the recipe: ``t``, filtered ``q``, ``v``, ``a`` and ``force`` with
    ``drop`` samples removed at each end (all float64 NumPy arrays of one length)."""
    if not isinstance(rec, EMPSRecording):
        raise ValueError(f"rec must be an EMPSRecording (load_emps), got {type(rec).__name__}")
    if isinstance(drop, bool) or int(drop) != drop or drop < 0:
        raise ValueError(f"drop must be a non-negative integer, got {drop!r}")
    drop = int(drop)
    if rec.n_samples <= 2 * drop + 2:
        raise ValueError(f"the recording has {rec.n_samples} samples; dropping {drop} at each end "
                         "leaves fewer than 3")
    dt = rec.dt
    q = lowpass(rec.qm, 1.0 / dt, cutoff, order)
    v, a = differentiate(q, dt)
    keep = slice(drop, rec.n_samples - drop)
    return {"t": rec.t[keep], "q": q[keep], "v": v[keep], "a": a[keep], "force": rec.force[keep]}


@dataclasses.dataclass(frozen=True)
class IDIMResult:
    """IDIM-LS estimate [SI]: ``M`` [kg]; symmetric ``Fv`` [N·s/m], ``Fc`` [N], ``offset`` [N]
    or asymmetric ``Fv_pos``, ``Fv_neg``, ``Fc_pos``, ``Fc_neg`` (the others ``None``);
    ``relative_error`` = ‖residual‖ / ‖force‖."""

    asymmetric: bool
    M: float
    relative_error: float
    Fv: float | None = None
    Fc: float | None = None
    offset: float | None = None
    Fv_pos: float | None = None
    Fv_neg: float | None = None
    Fc_pos: float | None = None
    Fc_neg: float | None = None

    def friction(self, v) -> np.ndarray:
        """The fitted friction law at velocity ``v`` [m/s] (step 4 without ``M·a``)."""
        v = np.asarray(v, np.float64)
        if self.asymmetric:
            pos, neg = v > 0, v < 0
            return (np.where(pos, self.Fv_pos * v + self.Fc_pos, 0.0)
                    + np.where(neg, self.Fv_neg * v - self.Fc_neg, 0.0))
        return self.Fv * v + self.Fc * np.sign(v) + self.offset


def idim_ls(v, a, force, *, asymmetric: bool = False, mass: float | None = None) -> IDIMResult:
    """IDIM-LS: least squares on step 4 of the module docstring (``numpy.linalg.lstsq``).

    ``mass`` given: ``M`` is fixed and only the friction terms are fitted to
    ``force − M·a``; otherwise ``M`` is estimated with them.
    """
    v, a, force = (np.asarray(x, np.float64) for x in (v, a, force))
    if not (v.shape == a.shape == force.shape and v.ndim == 1):
        raise ValueError(f"v, a and force must be 1-D of one length, got {v.shape}, {a.shape}, {force.shape}")
    if asymmetric:
        pos, neg = (v > 0).astype(float), (v < 0).astype(float)
        cols, names = [v * pos, v * neg, pos, -neg], ["Fv_pos", "Fv_neg", "Fc_pos", "Fc_neg"]
    else:
        cols, names = [v, np.sign(v), np.ones_like(v)], ["Fv", "Fc", "offset"]
    target = force
    if mass is None:
        cols, names = [a] + cols, ["M"] + names
    else:
        target = force - float(mass) * a
    A = np.stack(cols, axis=1)
    x, *_ = np.linalg.lstsq(A, target, rcond=None)
    rel = float(np.linalg.norm(target - A @ x) / np.linalg.norm(force))
    est = dict(zip(names, (float(xi) for xi in x)))
    if mass is not None:
        est["M"] = float(mass)
    return IDIMResult(asymmetric=asymmetric, relative_error=rel, **est)


def emps_friction_data(rec: EMPSRecording, *, mass: float | None = None, asymmetric: bool = False,
                       cutoff: float = EMPS_CUTOFF_HZ, order: int = EMPS_ORDER, drop: int = EMPS_DROP,
                       train_fraction: float = 0.8) -> FrictionData:
    """The EMPS friction record: ``friction = gtau·vir − M·a`` against the filtered velocity.

    ``M`` is ``mass`` [kg] when given, else the IDIM-LS estimate ([`idim_ls`][jaxfric.rig.idim_ls] with
    ``asymmetric``) on the whole kept recording. Returns [`FrictionData`][jaxfric.rig.FrictionData] with
    the acceleration, the first ``train_fraction`` of the samples for training and
    the rest (the last 20 % by default) for validation.
    """
    if mass is not None:
        check_positive("mass [kg]", mass, allow_zero=True)
    s = emps_states(rec, cutoff=cutoff, order=order, drop=drop)
    if mass is None:
        mass = idim_ls(s["v"], s["a"], s["force"], asymmetric=asymmetric).M
    friction = s["force"] - float(mass) * s["a"]
    return FrictionData.from_arrays(s["v"], friction, s["t"], train_fraction, acceleration=s["a"])
