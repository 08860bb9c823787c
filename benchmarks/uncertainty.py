"""Are jaxfric's parameter intervals and prediction bands calibrated?

    python benchmarks/uncertainty.py [--emps PATH/DATA_EMPS.mat] [--quick] [--out DIR]

(1) How often the 95 % parameter intervals of each covariance method (``jacobian``, Newey–West
``hac``, moving-block ``block_bootstrap``) hold a known truth: the simulated rig's velocity,
Coulomb+viscous and Stribeck friction, white or AR(1) noise. (2) How often the prediction
bands (covariance, and an 8-member ensemble's min–max) hold held-out samples where the truth is
not in the model class: the rig's seal friction and EMPS, beside EMPS's least-squares baseline.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # not on sys.path under `jaxfric bench`
from _harness import add_output_arguments, emps_file, machine, markdown_table, results_dir, write_report, x64  # noqa: E402

x64()
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from scipy import optimize, stats  # noqa: E402
from tqdm import tqdm  # noqa: E402

import jaxfric  # noqa: E402
from jaxfric import Fit, models, rig  # noqa: E402
from jaxfric.uncertainty import (andrews_bandwidth, block_bootstrap_covariance, coverage,  # noqa: E402
                                 hac_covariance, jacobian_covariance)

N_TRAIN = 1600
LEVEL = 0.95
TRUTHS = {
    "coulomb": (models.Coulomb(), {"Fc": 300.0, "sigma2": 1.5e4}),
    "stribeck": (models.Stribeck(), {"Fc": 300.0, "Fs": 450.0, "vs": 2e-3, "sigma2": 1.5e4}),
}
NOISE_N = 20.0
ALL_PARAMS = ("Fc", "Fs", "vs", "sigma2")


def ar1(rng, reps, n, rho, sd):
    e = rng.standard_normal((reps, n)) * sd * np.sqrt(1 - rho**2)
    out = np.empty_like(e)
    out[:, 0] = rng.standard_normal(reps) * sd
    for t in range(1, n):
        out[:, t] = rho * out[:, t - 1] + e[:, t]
    return out


def replicate_fitter(model, v):
    """Least squares in search coordinates from the truth (MINPACK's LM through scipy),
    compiled once per model: ``fit(theta0, y) -> (theta, residuals, Jacobian)``."""
    pred = jax.jit(lambda th: model.simulate(th, v))
    jac = jax.jit(jax.jacfwd(lambda th: model.simulate(th, v)))

    def fit(theta0, y):
        res = optimize.least_squares(lambda th: np.asarray(pred(jnp.asarray(th))) - y, np.asarray(theta0),
                                     jac=lambda th: np.asarray(jac(jnp.asarray(th))), method="lm",
                                     xtol=1e-12, ftol=1e-12)
        th = jnp.asarray(res.x)
        return np.asarray(th), np.asarray(pred(th)) - y, np.asarray(jac(th))

    return fit


def parameter_coverage(v, reps, rng, methods, boot_reps):
    rows = []
    n = v.size
    for mname, (model, truth) in TRUTHS.items():
        theta_true = np.asarray(model.from_physical(**truth))
        clean = np.asarray(model.simulate(jnp.asarray(theta_true), v))
        fit_replicate = replicate_fitter(model, jnp.asarray(v))
        for rho in (0.0, 0.5, 0.9):
            noise = ar1(rng, reps, n, rho, NOISE_N)
            hits = {m: np.zeros(theta_true.size) for m in methods}
            t = stats.t.ppf(0.5 + LEVEL / 2, n - theta_true.size)
            for r in tqdm(range(reps), desc=f"{mname} rho={rho}", leave=False):
                th, res, jac = fit_replicate(theta_true, clean + noise[r])
                for m in methods:
                    cov = (jacobian_covariance(jac, res)[0] if m == "jacobian" else
                           hac_covariance(jac, res, andrews_bandwidth(jac, res)) if m == "hac" else
                           block_bootstrap_covariance(jac, res, r, int(andrews_bandwidth(jac, res)) + 1, boot_reps))
                    hits[m] += np.abs(th - theta_true) <= t * np.sqrt(np.diag(cov))
            for m in methods:
                cov_frac = hits[m] / reps
                rows.append({"truth": mname, "noise": "white" if rho == 0 else f"AR(1) rho={rho}",
                             "method": m, "replicates": reps, **{f"cover_{k}": "" for k in ALL_PARAMS},
                             **{f"cover_{k}": round(float(c), 3) for k, c in zip(truth, cov_frac)},
                             "cover_min": round(float(cov_frac.min()), 3),
                             "cover_max": round(float(cov_frac.max()), 3)})
    return rows


def band_row(label, fit, data, split, **extra):
    n, f, inputs = data.n_train, np.asarray(data.friction), fit.model.inputs_from(data, data.n_samples)
    out = {"data": label, "model": type(fit.model).__name__ + extra.pop("suffix", ""), "split": split}
    for method in ("hac", "jacobian"):
        y, lo, hi = fit.prediction_interval(data.velocity, LEVEL, inputs=inputs, method=method)
        out[f"train_{method}"] = round(coverage(f[:n], lo[:n], hi[:n]), 4)
        out[f"valid_{method}"] = round(coverage(f[n:], lo[n:], hi[n:]), 4)
        out[f"half_width_N_{method}"] = round(float(np.mean(hi - lo) / 2), 3)
    e = (f - y)[n:]
    out["valid_rmse_N"] = round(float(np.sqrt(np.mean(e**2))), 3)
    out["valid_mse_percent"] = round(float(100 * np.mean(e**2) / np.var(f[n:])), 4)
    out["implausible"] = "; ".join(f"{d['name']} ({d['rule']})" for d in fit.diagnostics.get("implausible", []))
    out.update(extra)
    return out


def interval_rows(label, fit):
    return [{"data": label, "model": type(fit.model).__name__, "param": r["name"], "estimate": f"{r['estimate']:.5g}",
             "se_hac": f"{r['se_hac']:.3g}", "se_jacobian": f"{r['se_jacobian']:.3g}",
             "interval_95": f"[{r['low']:.4g}, {r['high']:.4g}]", "not_determined": "yes" if r["covers_box"] else ""}
            for r in fit.uncertainty.table(LEVEL)]


def ls_baseline_fit(data):
    """EMPS's Coulomb+viscous+offset least-squares fit (asymmetric levels), as a Fit."""
    model = models.Coulomb(asymmetric=True, offset=True)
    n = data.n_train
    p = model.fit_least_squares(data.velocity[:n], data.friction[:n])
    fit = Fit(model=model, theta=np.asarray(model.from_physical(**p)), velocity_scaler=None,
              friction_scaler=None, dt=data.dt, n_train=n, n_samples=data.n_samples, metrics={})
    return jaxfric.uncertainty.assess_fit(fit, data)  # a new fit: fits are immutable


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--emps", default=None, help="DATA_EMPS.mat (default: _harness.emps_file; skipped when absent)")
    ap.add_argument("--replicates", type=int, default=None)
    add_output_arguments(ap, "fewer replicates, no ensemble (smoke test)")
    args = ap.parse_args(argv)
    out = results_dir(args.out, quick=args.quick)
    reps = args.replicates or (40 if args.quick else 200)
    boot = 100 if args.quick else 200
    t0 = time.perf_counter()
    warnings.simplefilter("ignore")  # bound/plausibility warnings are reported in the tables

    rec = rig.simulate(rig.Rig(), jax.random.key(0))
    v = np.asarray(rec.velocity, np.float64)[:N_TRAIN]
    cov_rows = parameter_coverage(v, reps, np.random.default_rng(0), ("jacobian", "hac", "block_bootstrap"), boot)

    band_rows, iv_rows = [], []
    data = rig.synthetic_friction_data(jax.random.key(1))
    for name in ("coulomb", "stribeck", "lugre"):
        fit = jaxfric.identify(name, data, key=0)
        band_rows.append(band_row("rig (seal friction)", fit, data, "train 1600 / valid 400"))
        iv_rows += interval_rows("rig", fit)
    ens_text = "not run (--quick)"
    if not args.quick:
        lo, hi = jaxfric.identify("lugre", data, key=0, keys=8).predict_band(data.velocity)
        f, n = np.asarray(data.friction), data.n_train
        ens_text = (f"LuGre, keys=8 on the rig: the members' min–max band (mean half-width "
                    f"{float(np.mean(hi - lo) / 2):.3g} N) holds {coverage(f[:n], lo[:n], hi[:n]):.1%} of the "
                    f"training and {coverage(f[n:], lo[n:], hi[n:]):.1%} of the validation samples")

    emps_note = "EMPS: skipped (no file at --emps)."
    args.emps = emps_file(args.emps)
    if args.emps is not None:
        data = rig.emps_friction_data(rig.load_emps(args.emps))
        split = f"estimation {data.n_train} / held-back {data.n_samples - data.n_train}"
        base = ls_baseline_fit(data)
        band_rows.append(band_row("EMPS", base, data, split, suffix=" (LS baseline, asym+offset)"))
        iv_rows += interval_rows("EMPS", base)
        for name, opts in [("stribeck", {}), ("lugre", dict(asymmetric=True, offset=True))][:1 if args.quick else 2]:
            fit = jaxfric.identify(name, data, key=0, **opts)
            band_rows.append(band_row("EMPS", fit, data, split, suffix=" (asym+offset)" if opts else ""))
            iv_rows += interval_rows("EMPS", fit)
        emps_note = f"EMPS: {args.emps.name}, {data.n_samples} samples at {1 / data.dt:.4g} Hz, {split}."

    md = ["# Parameter intervals and prediction bands: measured coverage", "",
          f"`python benchmarks/uncertainty.py{' --quick' if args.quick else ''}` — jaxfric "
          f"{jaxfric.__version__ if hasattr(jaxfric, '__version__') else ''}, float64, "
          f"{machine()}, {time.perf_counter() - t0:.0f} s in all.", "",
          "## 1. Parameter coverage (known truth, rig velocity, noise 20 N)", "",
          f"Fraction of {reps} noisy replicates whose 95 % interval holds the true parameter (nominal 0.95; the "
          f"test asks 0.85–0.99). `block_bootstrap`: {boot} resamples per replicate.", "", markdown_table(cov_rows), "",
          "## 2. Prediction-band coverage of held-out samples", "",
          "95 % band ŷ ± t·sqrt(j Σ jᵀ + s²) with Σ from the Newey–West (`hac`) or the independent-residual "
          "(`jacobian`) covariance and s² the training residual variance. The truth is not in the model class here "
          "(seal friction on the rig; real EMPS data), so the band's width is set by model error.", "", markdown_table(band_rows), "",
          f"Ensemble min–max band: {ens_text}.", "", emps_note, "",
          "## 3. Intervals of the fits above", "", markdown_table(iv_rows), ""]
    write_report(out, "uncertainty", md, cov_rows + band_rows)


if __name__ == "__main__":
    main()
