# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
#       jupytext_version: 1.19.6
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 03 — Real recordings: pneumatic piston-seal friction
#
# Measured friction of 3D-printed pneumatic cylinders with five piston seals at 1, 3, 5 and
# 7 bar (TU Delft, Zillen 2021, CC0; see `SOURCE.md` next to the data). It is not the paper's
# hydraulic press, but it is real cylinder friction recorded the same way: position, chamber
# pressure and load-cell force, from which friction follows by a force balance.
#
# The data stay outside the repository. Set `JAXFRIC_PNEUMATIC_DATA` to the
# `pneumatic_seal_friction` folder; otherwise the notebook looks in
# `../../shared/data/pneumatic_seal_friction` relative to itself, and skips (with a message)
# when the data are not there.

# %%
import os

# "small" (set by the test suite) runs in seconds with tiny budgets; anything else gives
# a budget worth looking at (a few minutes on a laptop).
BUDGET = os.environ.get("JAXFRIC_NOTEBOOK_BUDGET", "full").strip().lower()
SMALL = BUDGET == "small"
print(f"budget: {BUDGET}")

# %%
# %matplotlib inline
import time

import jax

# float32 (JAX's default), as the command line uses: the rollouts are twice as fast and
# float32 LuGre/ENN rollouts track float64 to about 1e-6 (tests/test_models_lugre.py).

import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Markdown, display

import jaxfric as jf
from jaxfric.cli.spec import FitSpec
from jaxfric import plot
import csv
import glob
import warnings
from pathlib import Path

from jaxfric import rig

# %%
DATA = Path(os.environ.get("JAXFRIC_PNEUMATIC_DATA", "../../shared/data/pneumatic_seal_friction"))
HAVE_DATA = (DATA / "raw").is_dir()
if HAVE_DATA:
    print(f"data: {DATA.resolve()}")
else:
    print(f"SKIPPED: no pneumatic_seal_friction data at {DATA.resolve()}; "
          "set JAXFRIC_PNEUMATIC_DATA to the folder to run this notebook.")

# %% [markdown]
# ## From raw channels to friction
#
# Raw files are whitespace-separated: time [ms], position [mm], chamber pressure [bar] and
# load-cell force [N] in columns 0, 4, 5 and 6. The time stamps are irregular (about 100 Hz
# with gaps), so `load_measurements` resamples them to a uniform grid. The pipeline then
# low-pass filters every channel (zero-phase Butterworth, 5 Hz), differentiates the position and
# applies the force balance of docs/algorithms.md §7 with one pressurised chamber and no inertia:
# `F_f = F_loadcell − p·A` (the load cell pushes towards +x, hence `load` scale −1).

# %%
COLUMNS = {"t": 0, "x": 4, "p2": 5, "load": 6}
SCALE = {"t": 1e-3, "x": 1e-3, "p2": 1e5, "load": -1.0}   # ms, mm, bar -> SI; load-cell sign


def bore_of(seal):
    return 0.0257 if "257" in seal else 0.025   # SOURCE.md


def load_record(path):
    seal = Path(path).stem.rsplit("_", 1)[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rig.IrregularSamplingWarning)
        meas = rig.load_measurements(path, COLUMNS, scale=SCALE, fill={"p1": 0.0}, delimiter=None,
                                     skip_rows=15, on_irregular="resample")
    return rig.estimate_friction(meas, bore=bore_of(seal), rod=0.0, mass=0.0, cutoff=5.0)


records = {}
if HAVE_DATA:
    for path in sorted(glob.glob(str(DATA / "raw" / "*.csv"))):
        records[Path(path).name] = load_record(path)
    print(f"{len(records)} records, e.g. {next(iter(records))}: "
          f"{next(iter(records.values())).n_samples} samples")

# %% [markdown]
# ## Coulomb level against pressure
#
# The Coulomb level is half the difference between the mean friction while extending and while
# retracting (faster than 3 mm/s). It should grow with pressure and agree with the authors'
# `friction_summary.csv` to within a few percent.

# %%
if HAVE_DATA:
    summary = {r["file"]: r for r in csv.DictReader(open(DATA / "friction_summary.csv"))}
    levels = {}
    lines = ["| file | Coulomb, jaxfric [N] | Coulomb, summary [N] | difference |", "|---|---|---|---|"]
    for name, data in records.items():
        lev = rig.coulomb_levels(np.asarray(data.velocity), np.asarray(data.friction), 3e-3)
        ref = float(summary[name]["coulomb_halfrange_N"])
        levels[name] = lev.halfrange
        lines.append(f"| {name} | {lev.halfrange:.2f} | {ref:.2f} | {100 * (lev.halfrange / ref - 1):+.1f} % |")
    display(Markdown("\n".join(lines)))

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for i, seal in enumerate(sorted({n.rsplit("_", 1)[0] for n in records})):
        names = sorted((n for n in records if n.rsplit("_", 1)[0] == seal),
                       key=lambda n: int(n.rsplit("_", 1)[1][:-7]))
        ax.plot([int(n.rsplit("_", 1)[1][:-7]) for n in names], [levels[n] for n in names], "o-",
                color=f"C{i}", label=seal)
    ax.set_xlabel("nominal chamber pressure [bar]")
    ax.set_ylabel("Coulomb level [N]")
    ax.set_title("Seal friction grows with pressure")
    ax.grid(alpha=0.3)
    ax.legend()
    plt.show()

# %% [markdown]
# ## One record up close
#
# O-ring at 3 bar: the figures the command line also draws. Friction flips sign at each
# reversal and sits near ±F_c while sliding; the transitions are where dynamic models (LuGre,
# the Elman network) differ from a static map.

# %%
if HAVE_DATA:
    name = "O-ring_3bar.csv" if "O-ring_3bar.csv" in records else next(iter(records))
    full = records[name]
    display(plot.plot_data(full, title=f"{name}: velocity and friction"))
    display(plot.plot_friction_velocity(full, title=f"{name}: friction against velocity"))


# %% [markdown]
# ## Identifying the seal friction
#
# A 20 s stretch (2000 samples, like the paper's record) of O-ring at 3 bar: the first 1600
# samples train, the last 400 validate. The Elman network and LuGre are fitted exactly as on the
# simulated rig.

# %%
def solver_for(name):
    """`jaxfric --quick`'s solver (the library's default for the model, budget cut to 3
    generations and 200 Nelder-Mead evaluations) when SMALL, else None: the default itself."""
    return FitSpec(name, generations=3, nm_evals=200).build_solver() if SMALL else None


# %%
if HAVE_DATA:
    seg = slice(500, 2500)
    v, f = np.asarray(full.velocity)[seg], np.asarray(full.friction)[seg]
    data = rig.FrictionData.from_arrays(v, f, float(full.dt), n_train=1600)
    fits = {}
    for model, opts in (("lugre", None), ("elman", {"neurons": 30})):
        fits[model] = jf.identify(model, data, solver=solver_for(model), key=jax.random.key(0),
                                  model_options=opts)
        print(fits[model].summary(), "\n")
    from jaxfric import report
    display(Markdown(report.markdown_table(report.comparison_rows(fits, data))))
    for fit in fits.values():
        display(plot.plot_fit(fit, data))
    display(plot.plot_error(fits, data))


# %% [markdown]
# ## A second real recording: the EMPS positioning axis
#
# EMPS (Janot, Gautier & Brunot 2019) is a ball-screw axis under a PD position loop, published as
# a system-identification benchmark with reference friction values. `jaxfric.rig.emps` follows
# the benchmark's own recipe: 4th-order Butterworth at 100 Hz forward–backward on the measured
# position, central differences for velocity and acceleration, 50 samples dropped at each end,
# and the rigid-body inverse model `gtau·vir = M·a + Fv·v + Fc·sign(v) + offset` solved by
# least squares (IDIM-LS). The friction record is `gtau·vir − M·a` with the IDIM-LS mass.
#
# Set `JAXFRIC_EMPS` to your `DATA_EMPS.mat`; otherwise the notebook looks in
# `../../shared/data/emps/` and skips this section when the file is not there.
# `benchmarks/emps.py` runs every model on the same split (`benchmarks/results/emps.md`).

# %%
EMPS_FILE = Path(os.environ.get("JAXFRIC_EMPS", "../../shared/data/emps/DATA_EMPS.mat"))
HAVE_EMPS = EMPS_FILE.is_file()
if HAVE_EMPS:
    emps_rec = rig.load_emps(EMPS_FILE)
    print(f"EMPS: {emps_rec.n_samples} samples at {1 / emps_rec.dt:.0f} Hz from {EMPS_FILE.resolve()}")
else:
    print(f"SKIPPED: no EMPS file at {EMPS_FILE.resolve()}; set JAXFRIC_EMPS to DATA_EMPS.mat "
          "to run this section.")

# %% [markdown]
# ### IDIM-LS against the published values
#
# The mass, viscous and Coulomb coefficients, symmetric and direction-dependent, estimated on the
# whole recording as the benchmark does; they agree with the published IDIM-LS values to within
# about 1 %.

# %%
PUBLISHED = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935,
             "Fv_pos": 166.71, "Fc_pos": 20.14, "Fv_neg": 240.42, "Fc_neg": 20.63}
if HAVE_EMPS:
    from jaxfric.rig.emps import emps_states, idim_ls

    states = emps_states(emps_rec)
    lines = ["| form | parameter | jaxfric | published | difference |", "|---|---|---|---|---|"]
    for asym in (False, True):
        est = idim_ls(states["v"], states["a"], states["force"], asymmetric=asym)
        for k in (("M", "Fv_pos", "Fv_neg", "Fc_pos", "Fc_neg") if asym else ("M", "Fv", "Fc")):
            ours = getattr(est, k)
            lines.append(f"| {'asymmetric' if asym else 'symmetric'} | {k} | {ours:.4g} | {PUBLISHED[k]:.4g} "
                         f"| {100 * (ours / PUBLISHED[k] - 1):+.2f} % |")
    display(Markdown("\n".join(lines)))

# %% [markdown]
# ### Identify on the first 80 %, validate on the last 20 %
#
# The held-back 20 % is never used to choose anything. Three contenders: a four-level
# least-squares map (asymmetric Coulomb + viscous + offset, five numbers by `numpy.linalg.lstsq`,
# the baseline to beat), jaxfric's asymmetric Coulomb + viscous + offset model (a short swarm,
# then Levenberg–Marquardt) and the Elman network with `identify`'s defaults. With the small
# budget the searches are cut to a few generations and steps, so only the plumbing is shown.

# %%
if HAVE_EMPS:
    emps = rig.emps_friction_data(emps_rec)            # first 80 % train, last 20 % validate
    v_e, f_e, n_e = np.asarray(emps.velocity), np.asarray(emps.friction), emps.n_train
    pos, neg = (v_e > 0).astype(float), (v_e < 0).astype(float)
    A = np.stack([v_e * pos, v_e * neg, pos, -neg, np.ones_like(v_e)], axis=1)
    coef, *_ = np.linalg.lstsq(A[:n_e], f_e[:n_e], rcond=None)
    emps_pred = {"LS baseline": A @ coef}
    emps_time = {"LS baseline": 0.0}

    phys_solver = jf.MAPSO(lattice_size=3 if SMALL else 5, num_generations=2 if SMALL else 30)
    from jaxfric.identification import GradientRefinement

    enn_opts = ({"solver": jf.MAPSO(lattice_size=8, num_generations=3),
                 "refine": GradientRefinement(method="bfgs", max_steps=5)} if SMALL else {})
    emps_fits = {
        "Coulomb asym. + offset": (jf.models.Coulomb(asymmetric=True, offset=True),
                                   {"solver": phys_solver, "refine": "lm", "data_bounds": True}),
        "ENN (N = 30)": ("elman", enn_opts),
    }
    for label, (model, opts) in emps_fits.items():
        t0 = time.perf_counter()
        fit = jf.identify(model, emps, key=0, **opts)
        emps_time[label] = time.perf_counter() - t0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")   # a few samples lie a hair outside the training range
            emps_pred[label] = np.asarray(fit.predict(emps.velocity))
        print(f"{label}: {fit.summary()}\n")

    def nmse(y, sl):
        return 100 * np.mean((f_e[sl] - y[sl]) ** 2) / np.var(f_e[sl])

    rows = ["| model | MSE % train | MSE % valid (last 20 %) | time [s] |", "|---|---|---|---|"]
    for label, y in emps_pred.items():
        rows.append(f"| {label} | {nmse(y, slice(None, n_e)):.3f} | {nmse(y, slice(n_e, None)):.3f} "
                    f"| {emps_time[label]:.1f} |")
    display(Markdown("\n".join(rows)))

    t_e = np.asarray(emps.t)
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.2), constrained_layout=True)
    ax[0].plot(t_e[n_e:], f_e[n_e:], color="0.6", lw=0.8, label="measured")
    for label, y in emps_pred.items():
        ax[0].plot(t_e[n_e:], y[n_e:], lw=0.8, label=label)
        ax[1].plot(v_e[n_e:], y[n_e:], ".", ms=0.8, label=label)
    ax[1].plot(v_e[n_e:], f_e[n_e:], ".", ms=0.8, color="0.6", zorder=0, label="measured")
    ax[0].set(xlabel="t [s]", ylabel="friction [N]", title="EMPS: held-back last 20 %")
    ax[1].set(xlabel="v [m/s]", ylabel="friction [N]", title="friction against velocity")
    ax[0].legend(fontsize=8)
    plt.show()

# %% [markdown]
# ### How sure is the fit? Intervals, correlation and a band with its measured coverage
#
# Every physical fit carries the uncertainty of its parameters (docs/uncertainty.md):
# `fit.stderr`, `fit.intervals(level)` and `fit.correlation`, from the Jacobian of the
# residuals at the optimum with a Newey–West covariance, because friction residuals are
# strongly correlated in time. A correlation near ±1 says the data fix a combination, not
# the parts: here the offset against the two Coulomb levels, which sliding data cannot
# separate (the plausibility check warns about it too). The 95 % prediction band
# `fit.prediction_interval` is checked on the held-back 20 %, which it never saw.

# %%
if HAVE_EMPS:
    model, opts = emps_fits["Coulomb asym. + offset"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")           # the plausibility warning is in the summary below
        coul = jf.identify(model, emps, key=0, **opts)
    u = coul.uncertainty
    rows = ["| parameter | estimate | se (Newey–West) | se (independent) | 95 % interval |", "|---|---|---|---|---|"]
    for r in u.table():
        rows.append(f"| {r['name']} | {r['estimate']:.4g} | {r['se_hac']:.3g} | {r['se_jacobian']:.3g} "
                    f"| [{r['low']:.4g}, {r['high']:.4g}] |")
    display(Markdown("\n".join(rows)))
    print("correlation (order", u.names, "):\n", np.round(coul.correlation, 3))
    for d in coul.diagnostics["implausible"]:
        print("implausible:", d["message"])

    y, lo, hi = coul.prediction_interval(emps.velocity, 0.95)
    inside = (f_e >= lo) & (f_e <= hi)
    print(f"95 % band holds {inside[:n_e].mean():.1%} of the training and {inside[n_e:].mean():.1%} "
          f"of the held-back samples (mean half-width {np.mean(hi - lo) / 2:.2f} N)")
    fig, ax = plt.subplots(figsize=(12, 3.5), constrained_layout=True)
    sl = slice(n_e, None)
    ax.fill_between(t_e[sl], lo[sl], hi[sl], color="C0", alpha=0.25, lw=0, label="95 % band")
    ax.plot(t_e[sl], f_e[sl], color="0.4", lw=0.6, label="measured")
    ax.plot(t_e[sl], y[sl], color="C0", lw=0.8, label="Coulomb asym. + offset")
    ax.set(xlabel="t [s]", ylabel="friction [N]", title="EMPS held-back block with the 95 % band")
    ax.legend(fontsize=8)
    plt.show()
