"""The EMPS benchmark's official forward task (docs/motion.md; ../shared/spec/ANCHORS.md §4.1).

Usage::

    python benchmarks/emps_official.py --test PATH/DATA_EMPS_PULSES.mat
        [--emps PATH/DATA_EMPS.mat] [--models coulomb,stribeck,lugre,gms] [--out DIR] [--quick]

Protocol (nonlinear_benchmarks' EMPS task): train on the estimation file ``DATA_EMPS.mat``
(input ``gtau*vir`` [N], output ``qm`` [m], every sample), then simulate the test recording
in free run from its input; only the test file's first 20 samples may set the initial state
(:meth:`jaxfric.motion.MotionFit.simulate` with ``init_window=20``: a quadratic fit of
their positions for x and v at sample 19, the friction state tracked along its slope);
score ``RMSE(qm[20:], q̂[20:])`` in mm and FIT %. Every model gets
:func:`jaxfric.identify_motion`'s defaults (mass searched in [50, 200] kg, a constant force
offset identified), chosen on the estimation file only.

Beside them: the least-squares Coulomb + viscous + offset baseline (IDIM-LS on the
estimation file, ``jaxfric.rig.emps.idim_ls``) and the published IDIM-LS parameters, both
simulated by the same forward model and initial-state rule, and the published figures
(IDIM-LS physics open loop 8.44 mm, FIT 89.8 %, computed in ANCHORS.md with another
integrator; dynoNet 2.64 mm, FIT 96.8 %, Forgione & Piga 2021).

The test recording is not part of ../shared/data (never tune on it): without ``--test`` (or
``$JAXFRIC_EMPS_TEST``) the script says so and exits 0 without writing anything.
Writes ``emps_official.md`` and ``emps_official.csv`` into ``--out`` (default
``benchmarks/results``; ``benchmarks/results/quick`` with ``--quick``). x64 is switched on here.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import add_output_arguments, cell, emps_file, markdown_table, results_dir, write_report, x64  # noqa: E402

x64()
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from jaxfric.motion import MotionData, MotionFit, MotionSearch, baseline_motion_fit, identify_motion  # noqa: E402
from jaxfric.rig.emps import EMPS_CUTOFF_HZ, emps_states, idim_ls, load_emps  # noqa: E402

INIT_WINDOW = 20
#: Published IDIM-LS values (SOURCE.md; Janot, Gautier, Brunot 2019).
IDIM = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "offset": -3.1648}
#: Published figures of the official task (ANCHORS.md §4).
PUBLISHED = [("IDIM-LS physics, open loop (published parameters; ANCHORS.md, 0.1 ms Euler)", 8.44, 89.8),
             ("dynoNet (Forgione & Piga 2021)", 2.64, 96.8)]


#: The drive gain of the benchmark files (SOURCE.md), used when a file does not hold ``gtau``.
GTAU = 35.15065188248547


def motion_data(path) -> MotionData:
    """Force ``gtau*vir`` and position ``qm`` of an EMPS ``.mat`` file. The estimation file
    goes through :func:`jaxfric.rig.emps.load_emps`; a file without all of its channels (a
    test recording may lack ``qg`` or the loop gains) is read for ``qm``, ``vir``, ``t`` and
    ``gtau`` only."""
    try:
        rec = load_emps(path)
        return MotionData.from_arrays(rec.force, rec.qm, rec.dt, cutoff=EMPS_CUTOFF_HZ)
    except (KeyError, ValueError):
        from scipy.io import loadmat

        mat = loadmat(path)
        qm, vir = (np.asarray(mat[k], np.float64).ravel() for k in ("qm", "vir"))
        gtau = float(np.asarray(mat["gtau"]).ravel()[0]) if "gtau" in mat else GTAU
        dt = float(np.median(np.diff(np.asarray(mat["t"], np.float64).ravel()))) if "t" in mat else 1e-3
        return MotionData.from_arrays(gtau * vir, qm, dt, cutoff=EMPS_CUTOFF_HZ)


def least_squares_baseline(path, dt) -> MotionFit:
    """IDIM-LS (M, Fv, Fc, offset) on the whole estimation file, the benchmark's own recipe."""
    s = emps_states(load_emps(path))
    est = idim_ls(s["v"], s["a"], s["force"])
    return baseline_motion_fit(est.M, est.Fc, est.Fv, est.offset, dt=dt), est


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--emps", default=None, help="DATA_EMPS.mat (default: _harness.emps_file)")
    ap.add_argument("--test", default=os.environ.get("JAXFRIC_EMPS_TEST"),
                    help="the benchmark's test recording DATA_EMPS_PULSES.mat (not shipped)")
    ap.add_argument("--models", default="coulomb,stribeck,lugre,gms")
    ap.add_argument("--seed", type=int, default=0)
    add_output_arguments(ap, "a tiny search (smoke test)")
    args = ap.parse_args(argv)
    if not args.test or not Path(args.test).exists():
        print(f"EMPS test recording {args.test!r} not given or not found: skipping the official task "
              "(pass --test PATH/DATA_EMPS_PULSES.mat)")
        return 0
    args.emps = emps_file(args.emps)
    if args.emps is None:
        print("EMPS estimation file not found: skipping")
        return 0
    out = results_dir(args.out, quick=args.quick)
    est, test = motion_data(args.emps), motion_data(args.test)
    rows = []

    def row(name, fit, seconds=None, kind="simulated here"):
        tr = fit.score(est, init_window=INIT_WINDOW)
        te = fit.score(test, init_window=INIT_WINDOW)
        rows.append({"model": name, "kind": kind, "mass_kg": fit.mass, "offset_N": fit.offset,
                     "estimation_rmse_mm": tr["rmse_mm"], "estimation_fit_percent": tr["fit_percent"],
                     "test_rmse_mm": te["rmse_mm"], "test_fit_percent": te["fit_percent"],
                     "seconds": seconds})
        print(name, f"test {te['rmse_mm']:.3f} mm, FIT {te['fit_percent']:.2f} %", flush=True)

    ls_fit, ls = least_squares_baseline(args.emps, est.dt)
    row(f"least squares Coulomb+viscous+offset (IDIM-LS here: M {ls.M:.2f}, Fv {ls.Fv:.1f}, "
        f"Fc {ls.Fc:.2f}, offset {ls.offset:.2f})", ls_fit, kind="baseline")
    row("IDIM-LS published parameters", baseline_motion_fit(IDIM["M"], IDIM["Fc"], IDIM["Fv"], IDIM["offset"], dt=est.dt),
        kind="reference")
    search = MotionSearch(particles=6, generations=3, horizons=(None,), steps=(3,)) if args.quick else None
    for name in [m.strip() for m in args.models.split(",") if m.strip()]:
        opts = {"neurons": 10} if name.startswith("elman") else None
        t0 = time.perf_counter()
        fit = identify_motion(name, est, train=1.0, key=args.seed, mass=(50.0, 200.0), fit_offset=True,
                              dtype=jnp.float64, model_options=opts, search=search)
        row(f"{name} + mass + offset (identify_motion defaults, whole estimation file)", fit,
            time.perf_counter() - t0, kind="jaxfric")
    for name, rmse, fitp in PUBLISHED:
        rows.append({"model": name, "kind": "published", "mass_kg": None, "offset_N": None,
                     "estimation_rmse_mm": None, "estimation_fit_percent": None, "test_rmse_mm": rmse,
                     "test_fit_percent": fitp, "seconds": None})
    md = ["# EMPS official forward task (benchmarks/emps_official.py)", "",
          f"Command: `python benchmarks/emps_official.py --test PATH{' --quick' if args.quick else ''} "
          f"--models {args.models}`", "",
          "Train on DATA_EMPS.mat (all samples), free-run simulate DATA_EMPS_PULSES.mat from its input; "
          f"the first {INIT_WINDOW} samples of each file set the initial state (quadratic fit of the "
          "positions, friction state tracked along its slope) and are not scored. RMSE of qm in mm, "
          "FIT = 100 (1 - ||e|| / ||y - mean y||). 'estimation' = the same protocol on the training "
          "file itself. Times: wall seconds of the identify_motion call, compilation included.", "",
          markdown_table(rows, fmt=cell()), ""]
    write_report(out, "emps_official", md, rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
