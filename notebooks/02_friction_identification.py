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
# # 02 — Friction identification, end to end (the paper on the simulated rig)
#
# The paper identifies the friction of a low-speed hydraulic cylinder with an Elman recurrent
# network (ENN) whose 180 weights are found by MAPSO followed by Nelder–Mead (MAPSO–NMDS), and
# compares it with a LuGre model fitted the same way (docs/algorithms.md §1, §11). Its rig data are
# not public, so jaxfric simulates a press cylinder whose seal friction is richer than LuGre
# (§7), measures it with noisy sensors, and runs the paper's pipeline:
#
# 1. rig data: piston position, two chamber pressures and the load, 2000 samples at 128 Hz;
# 2. friction from the force balance after a 5 Hz zero-phase Butterworth filter (paper eq. 31);
# 3. the neuron study (N = 20, 30, 40 in the paper);
# 4. ENN (N = 30) against LuGre: MSE %, MAX and number of parameters (Table 4), figures like the
#    paper's 11 and 12.
#
# `jaxfric demo` on the command line does steps 1, 2 and 4 and writes a report.

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
from jaxfric import report, rig


# %%
def solver_for(name):
    """`jaxfric --quick`'s solver (the library's default for the model, budget cut to 3
    generations and 200 Nelder-Mead evaluations) when SMALL, else None: the default itself."""
    return FitSpec(name, generations=3, nm_evals=200).build_solver() if SMALL else None


# %% [markdown]
# ## 1. Rig data
#
# `rig.simulate` integrates the cylinder, valve, PI position controller and seal friction at
# 4 kHz and samples the sensors at 128 Hz, with noise and quantisation. Besides the measured
# channels the record holds the ground truth (true velocity and friction), which a real rig
# never gives; we use it only to check the pipeline.

# %%
data_key, fit_key, test_key = jax.random.split(jax.random.key(0), 3)
r = rig.Rig()
record = rig.simulate(r, data_key)
t = np.asarray(record.t)
fig, ax = plt.subplots(3, 1, figsize=(9, 7), sharex=True, layout="constrained")
ax[0].plot(t, np.asarray(record.x) * 1e3)
ax[0].set_ylabel("position x [mm]")
ax[1].plot(t, np.asarray(record.p1) / 1e5, label="p1 (cap side)")
ax[1].plot(t, np.asarray(record.p2) / 1e5, label="p2 (rod side)")
ax[1].set_ylabel("pressure [bar]")
ax[1].legend(fontsize=8)
ax[2].plot(t, np.asarray(record.load) / 1e3)
ax[2].set_ylabel("load [kN]")
ax[2].set_xlabel("time [s]")
for a in ax:
    a.grid(alpha=0.3)
fig.suptitle(f"Measured channels (bore {r.cylinder.bore * 1e3:g} mm, rod {r.cylinder.rod * 1e3:g} mm, "
             f"moving mass {r.cylinder.mass:g} kg)")
plt.show()

# %% [markdown]
# ## 2. Friction from the force balance
#
# `estimate_friction` filters every channel (Butterworth, 4th order, 5 Hz, zero phase),
# differentiates the position twice and solves the force balance
# `F_f = p1·A1 − p2·A2 − F_L − m·a`. The first 1600 samples are for estimation, the last 400
# for validation (the paper's split). Left: the paper's Figs 9 and 10. Right: what the
# pipeline gets wrong against the true friction (filter lag at the reversals).

# %%
data = rig.estimate_friction(record.measurements(), r.cylinder)
display(plot.plot_data(data, title="Velocity (Fig. 9) and computed friction (Fig. 10)"))
true_f = np.asarray(record.friction)
fig, ax = plt.subplots(figsize=(9, 3.5), layout="constrained")
ax.plot(t, true_f, color="0.6", lw=2.5, label="true friction (simulator)")
ax.plot(t, np.asarray(data.friction), color="k", lw=0.9, label="computed by the pipeline")
ax.set_xlabel("time [s]")
ax.set_ylabel("friction force [N]")
ax.legend(fontsize=8)
ax.grid(alpha=0.3)
pipeline_mse = 100 * np.mean((true_f - np.asarray(data.friction)) ** 2) / np.var(true_f)
ax.set_title(f"Pipeline against the truth: normalised MSE {pipeline_mse:.2f} %")
plt.show()
display(plot.plot_friction_velocity(data))

# %% [markdown]
# ## 3. How many neurons?
#
# The paper tried N = 20, 30 and 40 hidden neurons (normalised MSE 0.3277 %, 0.2632 % and
# 0.2377 %) and kept 30, "with 180 internal connections" (6 parameters per neuron). Every fit
# below uses the same data and the same optimiser key; `jf.identify` returns a `Fit` with
# metrics on the training and validation windows (`fit.summary()` prints them).

# %%
NEURONS = (30,) if SMALL else (20, 30, 40)
study = {}
for n in NEURONS:
    study[n] = jf.identify("elman", data, solver=solver_for("elman"), key=fit_key, model_options={"neurons": n})
    m = study[n].metrics
    print(f"N = {n:2d}: {study[n].num_params:3d} parameters, MSE % train {m['train']['mse_percent']:.4f}, "
          f"valid {m['valid']['mse_percent']:.4f}  ({study[n].timings['total_s']:.1f} s)")

# %%
fig, ax = plt.subplots(figsize=(6, 4), layout="constrained")
for window, marker in (("train", "o-"), ("valid", "s--")):
    ax.plot(NEURONS, [study[n].metrics[window]["mse_percent"] for n in NEURONS], marker, label=window)
ax.plot([20, 30, 40], [0.3277, 0.2632, 0.2377], "k^:", label="paper")
ax.set_xticks(sorted(set(NEURONS) | {20, 30, 40}))
ax.set_xlabel("hidden neurons N")
ax.set_ylabel("normalised MSE [%]")
ax.set_yscale("log")
ax.set_title("Neuron study")
ax.grid(alpha=0.3, which="both")
ax.legend()
plt.show()

# %% [markdown]
# ## 4. ENN against LuGre
#
# LuGre has six parameters (σ0, σ1, σ2, Fc, Fs, vs), searched in log-space where they span
# decades, in ranges centred on the data's friction level and speed. The paper reports LuGre
# above 5 % MSE and the ENN 95.6 % lower.

# %%
enn = study[30]
lugre = jf.identify("lugre", data, solver=solver_for("lugre"), key=fit_key)
print(lugre.summary())
fits = {"elman": enn, "lugre": lugre}
rows = report.comparison_rows(fits, data)
display(Markdown(report.markdown_table(rows)))
reduction = 100 * (1 - enn.metrics["valid"]["mse_percent"] / lugre.metrics["valid"]["mse_percent"])
word = "below" if reduction >= 0 else "above"
print(f"ENN validation MSE is {abs(reduction):.1f} % {word} LuGre's (paper: 95.6 % below)")

# %% [markdown]
# Measured against estimated friction (the paper's Figs 11 and 12), the error curves, and the
# optimiser's progress: MAPSO's generations, then Nelder–Mead from the best agent (dotted
# line).

# %%
display(plot.plot_fit(enn, data, title="ENN (30 neurons): measured and estimated friction (Fig. 11)"))
display(plot.plot_fit(lugre, data, title="LuGre: measured and estimated friction (Fig. 12)"))
display(plot.plot_error({"ENN (30 neurons)": enn, "LuGre": lugre}, data))
display(plot.plot_convergence({"ENN (30 neurons)": enn, "LuGre": lugre},
                              ylabel="best objective J (each model's own cost)"))

# %% [markdown]
# ## 5. A fresh record, a saved model
#
# A fit is a file: `fit.save(path)` and `jf.load_fit(path)` (or `jaxfric predict` on the
# command line). Here the saved ENN predicts friction on a new simulated record (another noise
# key) that it has never seen.

# %%
import tempfile
from pathlib import Path

path = Path(tempfile.mkdtemp()) / "enn.npz"
enn.save(path)
loaded = jf.load_fit(path)
new = rig.estimate_friction(rig.simulate(r, test_key).measurements(), r.cylinder)
for name, fit in (("ENN, loaded from disk", loaded), ("LuGre", lugre)):
    pred = np.asarray(fit.predict(new.velocity, float(new.dt)))
    m = jf.metrics.friction_metrics(np.asarray(new.friction), pred)
    print(f"{name:22s} new record: MSE {m['mse_percent']:.3f} %, MAX {m['max_abs']:.1f} N, FIT {m['fit_percent']:.1f} %")
assert np.array_equal(np.asarray(loaded.predict(data.velocity)), np.asarray(enn.predict(data.velocity)))
