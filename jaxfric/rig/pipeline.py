"""Measurement pipeline: raw rig channels -> friction by force balance (docs/algorithms.md §7, paper eq. 31).

1. zero-phase Butterworth low-pass of every channel (order 4, 5 Hz at 128 Hz by
   default; ``scipy.signal.butter(..., output="sos")`` + ``sosfiltfilt``, so the
   magnitude is ``|H|^2`` and the phase is zero);
2. velocity and acceleration from the filtered displacement by central
   differences (``np.gradient``);
3. ``F_f = p1 A1 - p2 A2 - F_L - m a - m g``  with ``A1 = pi D^2/4``,
   ``A2 = pi (D^2 - d^2)/4``; ``g`` is the component of gravity pulling towards
   -x (0 for a horizontal axis, 9.81 for a vertical axis with x pointing up).

This is preprocessing, done once per record in NumPy float64.
"""

from __future__ import annotations

import numpy as np

from ._checks import check_positive, filter_padlen, is_uniform
from .data import FrictionData, Measurements
from .params import _check_geometry


def butterworth_sos(fs: float, cutoff: float = 5.0, order: int = 4) -> np.ndarray:
    """Second-order sections of the Butterworth low-pass (§7: fc = 5 Hz at fs = 128 Hz, Wn = 5/64)."""
    fs = check_positive("sample rate fs [Hz]", fs)
    cutoff = check_positive("cutoff [Hz]", cutoff)
    if cutoff >= fs / 2:
        raise ValueError(f"cutoff {cutoff} Hz must be below the Nyquist frequency {fs / 2} Hz (fs = {fs} Hz)")
    if int(order) != order or order < 1:
        raise ValueError(f"filter order must be a positive integer, got {order!r}")
    import scipy.signal  # here, not at import: it is 1.5 s of every `jaxfric` start-up

    return scipy.signal.butter(int(order), cutoff, btype="low", fs=fs, output="sos")


def lowpass(signal, fs: float, cutoff: float = 5.0, order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth low-pass along the last axis (forward-backward, magnitude ``|H|^2``)."""
    sos = butterworth_sos(fs, cutoff, order)
    signal = np.asarray(signal, dtype=np.float64)
    pad = filter_padlen(sos)
    if signal.shape[-1] <= pad:
        raise ValueError(f"record too short for the order-{order} filter: {signal.shape[-1]} samples, "
                         f"sosfiltfilt needs more than padlen = {pad}")
    import scipy.signal

    return scipy.signal.sosfiltfilt(sos, signal, axis=-1)


def differentiate(x, dt: float):
    """Velocity and acceleration of a (filtered) displacement by central differences (§7 step 2)."""
    v = np.gradient(x, dt, edge_order=2)
    return v, np.gradient(v, dt, edge_order=2)


def force_balance(p1, p2, load, acceleration, *, bore, rod, mass, gravity=0.0):
    """Friction [N] from paper eq. (31): ``p1 A1 - p2 A2 - F_L - m a - m g`` (§7)."""
    _check_geometry(bore, rod)
    check_positive("mass [kg]", mass, allow_zero=True)
    a1 = np.pi * bore**2 / 4.0
    a2 = np.pi * (bore**2 - rod**2) / 4.0
    return p1 * a1 - p2 * a2 - load - mass * acceleration - mass * gravity


def estimate_friction(meas: Measurements, cylinder=None, *, bore: float | None = None, rod: float | None = None,
                      mass: float | None = None, gravity: float | None = None, cutoff: float = 5.0,
                      order: int = 4, train_fraction: float = 0.8, n_train: int | None = None) -> FrictionData:
    """Run the §7 pipeline on uniformly sampled measurements and return [`FrictionData`][jaxfric.rig.FrictionData].

    Geometry comes from ``cylinder`` (anything with ``bore``, ``rod``, ``mass``,
    ``gravity`` attributes, e.g. [`Cylinder`][jaxfric.rig.Cylinder], or a whole
    [`Rig`][jaxfric.rig.Rig]) and/or the
    keywords, which take precedence: bore and rod diameters [m], moving mass
    [kg], gravity along -x [m/s^2] (default 0). ``cutoff`` [Hz] and ``order`` set
    the Butterworth filter; ``train_fraction`` / ``n_train`` the split (default
    80/20, i.e. 1600/400 of 2000 samples).

    Every check (geometry, filter, record length, uniform time stamps) runs
    before any filtering.
    """
    if not isinstance(meas, Measurements):
        raise ValueError(f"meas must be a Measurements record, got {type(meas).__name__}")
    cylinder = getattr(cylinder, "cylinder", cylinder)  # a whole Rig is fine too

    def pick(name, value, default=None):
        if value is not None:
            return float(value)
        if cylinder is not None and hasattr(cylinder, name):
            return float(getattr(cylinder, name))
        if default is not None:
            return default
        raise ValueError(f"'{name}' is required: pass it as a keyword or via cylinder=")

    bore, rod, mass = pick("bore", bore), pick("rod", rod), pick("mass", mass)
    gravity = pick("gravity", gravity, 0.0)
    _check_geometry(bore, rod)
    check_positive("mass [kg]", mass, allow_zero=True)
    t = meas.t
    if not is_uniform(t):
        raise ValueError("time stamps are not uniform; load the record with on_irregular='resample' "
                         "or call jaxfric.rig.io.resample_uniform first")
    dt = float(np.median(np.diff(t)))
    fs = 1.0 / dt
    sos = butterworth_sos(fs, cutoff, order)
    pad = filter_padlen(sos)
    if meas.n_samples <= pad:
        raise ValueError(f"record too short for the order-{order} filter: {meas.n_samples} samples, "
                         f"sosfiltfilt needs more than padlen = {pad}")

    import scipy.signal

    x, p1, p2, load = scipy.signal.sosfiltfilt(sos, np.stack([meas.x, meas.p1, meas.p2, meas.load]), axis=-1)
    v, a = differentiate(x, dt)
    f = force_balance(p1, p2, load, a, bore=bore, rod=rod, mass=mass, gravity=gravity)
    return FrictionData.from_arrays(v, f, t, train_fraction, n_train=n_train, acceleration=a, p1=p1, p2=p2)
