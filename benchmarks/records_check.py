"""Train on one real recording, validate on another: per-record metrics (issue 17.4, 17.5).

Usage::

    python benchmarks/records_check.py [--data DIR]

``DIR`` (default ``$JAXFRIC_DATA``, else ``../shared/data`` beside the repository) holds
``pneumatic_seal_friction/raw`` and ``emps/DATA_EMPS.mat``; a data set that is absent is
skipped. Never commit the data.

* Pneumatic O-ring cylinder (TU Delft, CC0): friction = load-cell force − pressure force,
  position differentiated after the §7 pipeline (5 Hz Butterworth, forward-backward),
  resampled at 10 ms. Train on ``O-ring_3bar`` (25 mm bore), validate on
  ``O-ring257_3bar`` (25.7 mm bore, same pressure) and on ``O-ring_5bar``.
* EMPS (the benchmark's recipe: 100 Hz Butterworth forward-backward on position,
  central differences, friction = gtau·vir − M·a with the published M = 95.1089 kg, 50
  samples dropped at each end): the first 80 % train, the last 20 % validate, as two
  records (each rolled out from its own initial state).

Each pair is fitted with ``identify(name, train={...}, valid={...}, key=0)`` (library
defaults) and compared with a least-squares Coulomb + viscous + offset fit on the same
training record. Prints the normalised MSE % (docs/algorithms.md §6) of each record and the
parameters flagged on a bound.
"""

from __future__ import annotations

import argparse
import os
import time
import warnings
from pathlib import Path

import numpy as np


def _default_data() -> Path:
    env = os.environ.get("JAXFRIC_DATA")
    return Path(env) if env else Path(__file__).resolve().parents[2] / "shared" / "data"


def pneumatic(raw: Path, name: str, bore: float):
    from jaxfric import rig

    d = np.loadtxt(raw / name)[15:]  # the authors drop 15 rows of "deviating starting values"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rig.IrregularSamplingWarning)
        meas = rig.load_measurements({"t": d[:, 0] * 1e-3, "x": d[:, 4] * 1e-3, "p2": d[:, 5] * 1e5,
                                      "load": -d[:, 6]}, fill={"p1": 0.0}, dt=0.01)
    data = rig.estimate_friction(meas, bore=bore, rod=0.0, mass=0.0, cutoff=5.0, train_fraction=1.0)
    return np.asarray(data.velocity, np.float64), np.asarray(data.friction, np.float64), 0.01


def emps(path: Path):
    import scipy.io
    import scipy.signal

    m = scipy.io.loadmat(path)
    t, qm, vir = m["t"].ravel(), m["qm"].ravel(), m["vir"].ravel()
    gtau = float(m["gtau"].ravel()[0])
    dt = float(np.median(np.diff(t)))
    b, a = scipy.signal.butter(4, 100.0, fs=1.0 / dt)
    q = scipy.signal.filtfilt(b, a, qm)
    v = np.gradient(q, dt)
    f = gtau * vir - 95.1089 * np.gradient(v, dt)
    v, f = v[50:-50], f[50:-50]
    n = int(round(0.8 * v.size))
    return (v[:n], f[:n], dt), (v[n:], f[n:], dt)


def baseline(train, records: dict) -> tuple[np.ndarray, dict]:
    """Least squares F = Fc·sign(v) + Fv·v + F0 on ``train``; MSE % on each record."""
    from jaxfric.metrics import friction_metrics

    def design(v):
        return np.stack([np.sign(v), v, np.ones_like(v)], 1)

    coef, *_ = np.linalg.lstsq(design(train[0]), train[1], rcond=None)
    return coef, {k: friction_metrics(r[1], design(r[0]) @ coef)["mse_percent"] for k, r in records.items()}


def check(title: str, train: dict, valid: dict, models=("coulomb", "lugre")) -> list[str]:
    from jaxfric.identification import BoundWarning, identify

    lines = [f"### {title}", ""]
    (tname, trec), = train.items()
    coef, base = baseline(trec, {**train, **valid})
    lines += ["| model | " + " | ".join(f"MSE % {k}" for k in base) + " | time [s] | on a bound |",
              "|---|" + "---|" * (len(base) + 2)]
    lines.append("| LS Coulomb+viscous+offset "
                 f"(Fc {coef[0]:.4g} N, Fv {coef[1]:.4g} N s/m, F0 {coef[2]:.4g} N) | "
                 + " | ".join(f"{x:.3f}" for x in base.values()) + " | - | - |")
    for name in models:
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", BoundWarning)  # reported from fit.diagnostics below
            fit = identify(name, train=train, valid=valid, key=0)
        seconds = time.perf_counter() - t0
        per = {r["name"]: r["all"]["mse_percent"] for r in fit.metrics["records"]}
        flags = "; ".join(f"{d['name']} ({d['side']})" for d in fit.diagnostics["on_bound"]) or "-"
        lines.append(f"| {name} | " + " | ".join(f"{per[k]:.3f}" for k in base) + f" | {seconds:.1f} | {flags} |")
    return lines + [""]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", type=Path, default=_default_data())
    args = p.parse_args(argv)
    out = []
    raw = args.data / "pneumatic_seal_friction" / "raw"
    if raw.is_dir():
        a = pneumatic(raw, "O-ring_3bar.csv", 0.025)
        out += check("Pneumatic O-ring: train O-ring_3bar, validate O-ring257_3bar and O-ring_5bar",
                     {"O-ring_3bar": a}, {"O-ring257_3bar": pneumatic(raw, "O-ring257_3bar.csv", 0.0257),
                                          "O-ring_5bar": pneumatic(raw, "O-ring_5bar.csv", 0.025)})
    else:
        out.append(f"(skipped: no {raw})")
    mat = args.data / "emps" / "DATA_EMPS.mat"
    if mat.is_file():
        tr, va = emps(mat)
        out += check("EMPS: first 80 % train, last 20 % validate (two records)",
                     {"first 80 %": tr}, {"last 20 %": va})
    else:
        out.append(f"(skipped: no {mat})")
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
