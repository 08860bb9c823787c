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
