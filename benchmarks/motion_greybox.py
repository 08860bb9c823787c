"""Does the grey-box correction earn its place on motion it was not fitted on (issue 45 item 5)?

    python benchmarks/motion_greybox.py [--emps PATH/DATA_EMPS.mat] [--folds A,B]
                                        [--models lugre,greybox_lugre,...] [--quick] [--out DIR]

A proxy of new motion on the EMPS estimation file (its test recording is not shipped): fold
``A`` trains on the first 70 %, fold ``B`` on the last 70 % (``train=1.0``); each fit is scored on
the other 30 %, in two blocks and whole, each free-run from its own first 20 samples
(``fit.score(record, init_window=20)``; ``train_mm``: the training record the same way), by its
free-run position RMSE [mm]. The held-out part shares the file's excitation: a weaker test
than a new recording. Candidates: the
least-squares baseline, LuGre and Stribeck with an offset, the grey-box of each
(``GreyBox(physical, hidden=4, bound=0.25)``) and an Elman(10) network inside the mechanics;
every fit is ``identify_motion``'s default with ``mass=(50, 200)``, ``fit_offset=True``, key 0.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import (about, add_output_arguments, cell, command, emps_file, emps_motion, machine,  # noqa: E402
                      markdown_table, results_dir, skipped, write_report, x64)

INIT = 20
TRAIN = 0.7
#: candidate -> its row's label
CANDIDATES = {"lugre": "LuGre+offset", "greybox_lugre": "GreyBox(LuGre, 4, 0.25)+offset", "stribeck": "Stribeck+offset",
              "greybox_stribeck": "GreyBox(Stribeck, 4, 0.25)+offset", "elman": "Elman(10)+offset"}


def build(name, grey=None):
    """The model of candidate ``name``; ``grey``: GreyBox options (default hidden=4, bound=0.25)."""
    from jaxfric import models

    if name == "elman":
        return models.Elman(neurons=10)
    phys = models.LuGre() if name.endswith("lugre") else models.Stribeck()
    return models.GreyBox(phys, **{"hidden": 4, "bound": 0.25, **(grey or {})}) if name.startswith("greybox") else phys


def label(name, grey=None) -> str:
    if not name.startswith("greybox") or not grey:
        return CANDIDATES[name]
    options = ", ".join(f"{k}={v}" for k, v in grey.items())
    return f"GreyBox({'LuGre' if name.endswith('lugre') else 'Stribeck'}, {options})+offset"


def fold_data(data, fold: str):
    """``(train record, held-out record, label)``: fold A trains on the first 70 %, B on
    the last 70 % (the held-out 30 % is the other end)."""
    n = data.n_samples
    cut = int(round(TRAIN * n))
    if fold == "A":
        return data.window(0, cut), data.window(cut, n), f"train [0, {cut}), held out [{cut}, {n})"
    lo = n - cut
    return data.window(lo, n), data.window(0, lo), f"train [{lo}, {n}), held out [0, {lo})"


def baseline_fit(train):
    """The least-squares baseline (IDIM-LS on the training record) as a MotionFit."""
    from jaxfric.motion import baseline_motion_fit
    from jaxfric.motion._baseline import least_squares

    est = least_squares([train])
    return baseline_motion_fit(est.M, est.Fc, est.Fv, est.offset, dt=train.dt, n_train=train.n_samples)


def score_row(fit, train, held):
    import numpy as np

    n = held.n_samples
    score = lambda rec: fit.score(rec, init_window=INIT)["rmse_mm"]  # noqa: E731
    scores = [score(held.window(0, round(n / 2))), score(held.window(round(n / 2), n))]
    return {"block1_mm": scores[0], "block2_mm": scores[1], "blocks_mean_mm": float(np.mean(scores)),
            "held_out_mm": score(held), "train_mm": score(train)}


def run(path, folds, names, quick, on_row, grey=None):
    import jax.numpy as jnp

    from jaxfric.motion import MotionSearch, identify_motion

    data = emps_motion(path)
    rows = []
    for fold in folds:
        train, held, where = fold_data(data, fold)
        rows.append({"fold": fold, "split": where, "model": "least squares Coulomb+viscous+offset",
                     "num_params": 4, "seconds": 0.0, **score_row(baseline_fit(train), train, held)})
        on_row(rows)
        for name in names:
            search = MotionSearch(particles=8, generations=4, horizons=(2000, None), steps=(5, 5),
                                  polish=0) if quick else None
            t0 = time.perf_counter()
            with warnings.catch_warnings(action="ignore"):
                fit = identify_motion(build(name, grey), train, key=0, mass=(50.0, 200.0), train=1.0,
                                      fit_offset=True, dtype=jnp.float64, search=search)
            secs = time.perf_counter() - t0
            extra = {"bound_N": float(fit.model.correction_bound(fit.theta)), "net_v_norm": float(
                sum(abs(float(v)) for k, v in fit.params.items() if k.startswith("net_v[")))} \
                if name.startswith("greybox") else {}
            rows.append({"fold": fold, "split": where, "model": label(name, grey),
                         "num_params": int(fit.metrics["num_params"]), "seconds": secs,
                         **score_row(fit, train, held), **extra})
            on_row(rows)
    return rows


COLUMNS = ["fold", "model", "num_params", "train_mm", "block1_mm", "block2_mm", "blocks_mean_mm",
           "held_out_mm", "seconds", "bound_N", "net_v_norm"]


def table(rows, command, split_lines) -> str:
    head = ["# Grey-box friction on EMPS motion it was not fitted on (benchmarks/motion_greybox.py)", "",
            f"Command: `{command}`", "", f"Machine: {machine()}", "", about(__doc__), "", *split_lines, ""]
    return "\n".join(head) + "\n" + markdown_table(rows, COLUMNS, fmt=cell(".4g")) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--emps", default=None)
    ap.add_argument("--folds", default="A,B")
    ap.add_argument("--models", default=",".join(CANDIDATES))
    for name, kind, what in (("hidden", int, "hidden units (4)"), ("bound", float, "bound, fraction of Fc (0.25)"),
                             ("ridge", float, "ridge (1e-6)")):
        ap.add_argument(f"--{name}", type=kind, default=None, help=f"GreyBox {what}")
    add_output_arguments(ap, "tiny search budgets (smoke test)")
    args = ap.parse_args(argv)
    x64()
    path = emps_file(args.emps)
    if path is None:
        return skipped("motion_greybox", "DATA_EMPS.mat not found (set JAXFRIC_DATA or pass --emps)")
    out = results_dir(args.out, quick=args.quick)
    folds = [f.strip().upper() for f in args.folds.split(",") if f.strip()]
    names = [m.strip() for m in args.models.split(",") if m.strip()]
    if not set(folds) <= {"A", "B"} or not set(names) <= set(CANDIDATES):
        raise SystemExit(f"--folds takes A and/or B, --models of {', '.join(CANDIDATES)}; got "
                         f"{args.folds!r}, {args.models!r}")

    def write(rows):
        splits = sorted({f"Fold {r['fold']}: {r['split']}." for r in rows})
        write_report(out, "motion_greybox", table(rows, command("motion_greybox.py", argv), splits), rows, echo=False)

    grey = {k: getattr(args, k) for k in ("hidden", "bound", "ridge") if getattr(args, k) is not None}
    run(path, folds, names, args.quick, write, grey)
    print((out / "motion_greybox.md").read_text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
