"""How much of new motion does a motion fit's position band hold?

    python benchmarks/motion_band.py [--proxy emps-blocked,rig] [--keys 0,1] [--models coulomb,...]
                                     [--data DIR] [--quick] [--out DIR]

``MotionFit.prediction_interval(record)`` (docs/uncertainty.md, "Position band") on records the
fit never saw, by the proxies of ``benchmarks/motion_judge.py``: ``emps-blocked`` trains on one
of DATA_EMPS.mat's three blocks (its first 80 %, ``mass=(50, 200)``) and bands the two others;
``rig`` trains on one excitation family of the rig simulator (the rig's mass) and bands the
three others. Key ``k`` trains on block / family ``k mod n``; every fit is ``identify_motion``'s
default with ``fit_offset=True`` in float64. Each record is free-run from its first 20 samples.
Per (fit, record): the free-run RMSE [mm], the band's RMS half-width at 95 % [mm] and the share
of measured positions inside it, for the Newey–West covariance with and without the training
residual variance s² and for the i.i.d. Jacobian covariance with s².
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import (about, add_output_arguments, cell, command, emps_file, machine, markdown_table,  # noqa: E402
                      results_dir, skipped, write_report, x64)

INIT, LEVEL = 20, 0.95
MODELS = ("coulomb", "stribeck", "lugre", "gms")
BANDS = {"hac": ("hac", True), "hac_no_s2": ("hac", False), "jacobian": ("jacobian", True)}


def measure(proxy, key, models, emps, quick) -> list[dict]:
    import numpy as np

    from jaxfric.motion import identify_motion
    from motion_judge import setup

    recs, train, _, opts = setup(proxy, key, quick, emps)
    rows = []
    for name in models:
        fit = identify_motion(name, recs[train], key=key, train=0.8, progress=False, **opts)
        for rname, rec in recs.items():
            x = np.asarray(rec.position)
            row = {"proxy": proxy, "key": key, "model": name, "train": train, "record": rname,
                   "seen": rname == train, "rmse_mm": fit.score(rec, INIT)["rmse_mm"]}
            for label, (method, noise) in BANDS.items():
                _, lo, hi = fit.prediction_interval(rec, LEVEL, init_window=INIT, method=method, noise=noise)
                row[f"half_{label}_mm"] = 1e3 * float(np.sqrt(np.mean(((hi - lo) / 2)[INIT:] ** 2)))
                row[f"held_{label}"] = float(np.mean(((x >= lo) & (x <= hi))[INIT:]))
            rows.append(row)
            print({k: cell()(v) for k, v in row.items()}, flush=True)
    return rows


def summary(rows) -> list[dict]:
    """Per proxy and model, over the unseen records: the shares held (median, min–max) and how
    the RMS half-width compares with the free-run error (median of RMSE / (half / 1.96))."""
    import numpy as np
    from scipy.stats import spearmanr

    out = []
    for proxy in dict.fromkeys(r["proxy"] for r in rows):
        for model in [*dict.fromkeys(r["model"] for r in rows), "all"]:
            sel = [r for r in rows if r["proxy"] == proxy and not r["seen"] and model in ("all", r["model"])]
            if not sel:
                continue
            row = {"proxy": proxy, "model": model, "records": len(sel)}
            for label in BANDS:
                held = np.array([r[f"held_{label}"] for r in sel])
                row[f"held_{label}"] = f"{np.median(held):.2f} ({held.min():.2f}–{held.max():.2f})"
            ratio = np.array([r["rmse_mm"] / max(r["half_hac_mm"] / 1.96, 1e-300) for r in sel])
            row["rmse_over_sigma"] = f"{np.median(ratio):.2f} ({ratio.min():.2f}–{ratio.max():.2f})"
            rho = spearmanr([r["half_hac_mm"] for r in sel], [r["rmse_mm"] for r in sel])[0] if len(sel) > 2 else np.nan
            row["rank_corr"] = f"{rho:.2f}"
            out.append(row)
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=about(__doc__))
    p.add_argument("--proxy", default="emps-blocked,rig")
    p.add_argument("--keys", default="0,1,2")
    p.add_argument("--models", default=",".join(MODELS))
    p.add_argument("--data", default=None, help="folder or DATA_EMPS.mat (default: JAXFRIC_DATA, ../shared/data)")
    add_output_arguments(p, "a tiny search, key 0, Coulomb only (smoke test)")
    a = p.parse_args(argv)
    x64()
    warnings.simplefilter("ignore")
    proxies = a.proxy.split(",")
    emps = emps_file(a.data) if "emps-blocked" in proxies else None
    if "emps-blocked" in proxies and emps is None:
        if proxies == ["emps-blocked"]:
            return skipped("motion_band", "DATA_EMPS.mat not found")
        print("motion_band: DATA_EMPS.mat not found; the emps-blocked proxy is left out", file=sys.stderr)
        proxies.remove("emps-blocked")
    keys = [0] if a.quick else [int(k) for k in a.keys.split(",")]
    models = ["coulomb"] if a.quick else a.models.split(",")
    rows = [r for proxy in proxies for k in keys for r in measure(proxy, k, models, emps, a.quick)]
    summ = summary(rows)
    text = ["# Position band of a motion fit on new motion", "",
            f"`{command('motion_band.py', argv)}`; {machine()}. {about(__doc__)}", "",
            "Summary over the records each fit never saw: `held_*` the share of samples inside the 95 % band "
            "(median, min–max), `rmse_over_sigma` the free-run RMSE over the band's RMS half-width / 1.96 "
            "(1: the band's width matches the error), `rank_corr` Spearman's correlation of the Newey–West "
            "band's width with the RMSE over the (fit, record) pairs (does a wider band flag a worse prediction?).",
            "", markdown_table(summ), "", "Every (fit, record), `seen`: the training record:", "",
            markdown_table(rows, fmt=cell(".3g"))]
    write_report(results_dir(a.out, quick=a.quick), "motion_band", text, rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
