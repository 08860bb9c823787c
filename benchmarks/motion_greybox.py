"""Does the grey-box correction earn its place on motion it was not fitted on (issue 45 item 5)?

Usage::

    python benchmarks/motion_greybox.py [--emps PATH/DATA_EMPS.mat] [--folds A,B]
                                        [--models lugre,greybox_lugre,...] [--quick] [--out DIR]

A proxy of new motion on the EMPS estimation file (the benchmark's separate test recording
is not shipped): fold ``A`` trains on the first 70 % of the file, fold ``B`` on the last
70 %; each fit is scored on the other 30 % cut into two blocks, every block free-run from
its own first 20 samples (``MotionFit.score(record, init_window=20)``: only those samples
set the state), and on the whole held-out 30 % the same way. The held-out blocks share the
file's excitation (trapezoidal strokes), so this is a weaker test than a new excitation; it
is still motion the fit never saw, started from a window, not from the training state.

Candidates: the least-squares Coulomb + viscous + offset baseline (IDIM-LS on the training
part, simulated the same way), LuGre and Stribeck with an offset, the grey-box of each
(``GreyBox(physical, hidden=4, bound=0.25)``, started from that physical fit) and an
Elman(10) network inside the mechanics; every fit is ``identify_motion``'s default with
``mass=(50, 200)``, ``fit_offset=True``, key 0, float64. Rows go to ``motion_greybox.csv``
as they come; the table to ``motion_greybox.md``.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import (add_output_arguments, cell, command, emps_file, emps_motion, machine,  # noqa: E402
                      markdown_table, results_dir, skipped, write_report, x64)

INIT = 20
TRAIN = 0.7
#: label -> (model factory, model options) of identify_motion
CANDIDATES = {
    "lugre": "LuGre+offset",
    "greybox_lugre": "GreyBox(LuGre, 4, 0.25)+offset",
    "stribeck": "Stribeck+offset",
    "greybox_stribeck": "GreyBox(Stribeck, 4, 0.25)+offset",
    "elman": "Elman(10)+offset",
}


def build(name, grey=None):
    """The model of candidate ``name``; ``grey``: GreyBox options (default hidden=4, bound=0.25)."""
    from jaxfric import models

    grey = {"hidden": 4, "bound": 0.25, **(grey or {})}
    return {"lugre": lambda: models.LuGre(), "stribeck": lambda: models.Stribeck(),
            "greybox_lugre": lambda: models.GreyBox(models.LuGre(), **grey),
            "greybox_stribeck": lambda: models.GreyBox(models.Stribeck(), **grey),
            "elman": lambda: models.Elman(neurons=10)}[name]()


def label(name, grey=None) -> str:
    if not name.startswith("greybox") or not grey:
        return CANDIDATES[name]
    phys = "LuGre" if name.endswith("lugre") else "Stribeck"
    return f"GreyBox({phys}, {', '.join(f'{k}={v}' for k, v in grey.items())})+offset"


def fold_data(data, fold: str):
    """``(train record, held-out record, label)``: fold A trains on the first 70 %, B on
    the last 70 % (the held-out 30 % is the other end)."""
    n = data.n_samples
    cut = int(round(TRAIN * n))
    if fold == "A":
        return data.window(0, cut), data.window(cut, n), f"train [0, {cut}), held out [{cut}, {n})"
    lo = n - cut
    return data.window(lo, n), data.window(0, lo), f"train [{lo}, {n}), held out [0, {lo})"


def blocks(record, count=2):
    n = record.n_samples
    edges = [round(i * n / count) for i in range(count + 1)]
    return [record.window(a, b) for a, b in zip(edges[:-1], edges[1:])]


def baseline_fit(train):
    """The least-squares baseline (IDIM-LS on the training record) as a MotionFit."""
    from jaxfric.motion import baseline_motion_fit
    from jaxfric.motion._baseline import least_squares

    est = least_squares([train])
    return baseline_motion_fit(est.M, est.Fc, est.Fv, est.offset, dt=train.dt, n_train=train.n_samples)


def score_row(fit, train, held):
    import numpy as np

    parts = blocks(held)
    scores = [fit.score(b, init_window=INIT)["rmse_mm"] for b in parts]
    whole = fit.score(held, init_window=INIT)["rmse_mm"]
    train_rmse = fit.score(train, init_window=INIT)["rmse_mm"]
    return {"block1_mm": scores[0], "block2_mm": scores[1], "blocks_mean_mm": float(np.mean(scores)),
            "held_out_mm": whole, "train_mm": train_rmse}


def run(path, folds, names, quick, on_row, grey=None):
    import jax.numpy as jnp

    from jaxfric.motion import MotionSearch, identify_motion

    data = emps_motion(path)
    rows = []
    for fold in folds:
        train, held, where = fold_data(data, fold)
        row = {"fold": fold, "split": where, "model": "least squares Coulomb+viscous+offset",
               "num_params": 4, "seconds": 0.0, **score_row(baseline_fit(train), train, held)}
        rows.append(row)
        on_row(rows)
        for name in names:
            search = MotionSearch(particles=8, generations=4, horizons=(2000, None), steps=(5, 5),
                                  polish=0) if quick else None
            t0 = time.perf_counter()
            with warnings.catch_warnings(action="ignore"):
                fit = identify_motion(build(name, grey), train, key=0, mass=(50.0, 200.0), train=1.0,
                                      fit_offset=True, dtype=jnp.float64, search=search)
            secs = time.perf_counter() - t0
            extra = {}
            if name.startswith("greybox"):
                b = float(fit.model.correction_bound(fit.theta))
                extra = {"bound_N": b, "net_v_norm": float(
                    sum(abs(float(v)) for k, v in fit.params.items() if k.startswith("net_v[")))}
            rows.append({"fold": fold, "split": where, "model": label(name, grey),
                         "num_params": int(fit.metrics["num_params"]), "seconds": secs,
                         **score_row(fit, train, held), **extra})
            on_row(rows)
    return rows


COLUMNS = ["fold", "model", "num_params", "train_mm", "block1_mm", "block2_mm", "blocks_mean_mm",
           "held_out_mm", "seconds", "bound_N", "net_v_norm"]


def table(rows, command, split_lines) -> str:
    head = [
        "# Grey-box friction on EMPS motion it was not fitted on (benchmarks/motion_greybox.py)", "",
        f"Command: `{command}`", "", f"Machine: {machine()}", "",
        "Proxy of new motion: the EMPS estimation file (the benchmark's test recording is not "
        "shipped). Each fold trains on 70 % of the file (the whole training record, "
        "`identify_motion(model, train_record, key=0, mass=(50, 200), train=1.0, fit_offset=True)`, "
        "defaults otherwise) and scores the other 30 %: two blocks and the whole 30 %, each "
        f"free-run from its own first {INIT} samples (`fit.score(record, init_window={INIT})`). "
        "`train_mm` scores the training record the same way. Free-run position RMSE [mm]. "
        "The held-out part shares the file's excitation: a weaker test than a new recording.", "",
        *split_lines, "",
    ]
    return "\n".join(head) + "\n" + markdown_table(rows, COLUMNS, fmt=cell(".4g")) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--emps", default=None)
    ap.add_argument("--folds", default="A,B")
    ap.add_argument("--models", default=",".join(CANDIDATES))
    ap.add_argument("--hidden", type=int, default=None, help="GreyBox hidden units (default 4)")
    ap.add_argument("--bound", type=float, default=None, help="GreyBox bound, fraction of Fc (default 0.25)")
    ap.add_argument("--ridge", type=float, default=None, help="GreyBox ridge (default 1e-6)")
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
        write_report(out, "motion_greybox", table(rows, command("motion_greybox.py", argv), splits), rows,
                     echo=False)

    grey = {k: getattr(args, k) for k in ("hidden", "bound", "ridge") if getattr(args, k) is not None}
    run(path, folds, names, args.quick, write, grey)
    print((out / "motion_greybox.md").read_text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
