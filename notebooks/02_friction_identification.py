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
# compares it with a LuGre model fitted the same way (docs/algorithms.md §1, §11). It reports the
# ENN's error 95.6 % below LuGre's. Its rig data are not public, so jaxfric simulates a press
# cylinder whose seal friction is richer than LuGre (§7), measures it with noisy sensors, and
# runs the pipeline:
#
# 1. rig data: piston position, two chamber pressures and the load, 2000 samples at 128 Hz;
# 2. friction from the force balance after a 5 Hz zero-phase Butterworth filter (paper eq. 31);
# 3. which form the physical models need (the data's friction is not symmetric);
# 4. the neuron study (N = 20, 30, 40 in the paper);
# 5. ENN against LuGre **and** against the least-squares baseline, on the held-back tail of the
#    record (its last 400 samples, never used to fit);
# 6. all three on motion they have never seen: the same rig driven by two other excitations.
#
# **Methods as run.** jaxfric's default pipeline is not the paper's: the ENN is fitted by a
# short MAPSO on the first part of the training window, then BFGS on all of it; LuGre by
# MAPSO then Nelder–Mead (the paper's MAPSO–NMDS). The stages each fit actually ran are printed
# below from the fit itself. `identify(..., method="paper")` runs the paper's MAPSO–NMDS for
# both. Every number in the text below is computed in the cell above it.
#
# `jaxfric demo` on the command line does steps 1, 2, 3 and 5 and writes a report.

# %%
import os

# "small" (set by the test suite) runs in seconds with tiny budgets; anything else gives
# a budget worth looking at (a few minutes on a laptop).
BUDGET = os.environ.get("JAXFRIC_NOTEBOOK_BUDGET", "full").strip().lower()
SMALL = BUDGET == "small"
print(f"budget: {BUDGET}")

# %%
# %matplotlib inline
import json
import warnings
from pathlib import Path

import jax

# float32 (JAX's default), as the command line uses: the rollouts are twice as fast and
# float32 LuGre/ENN rollouts track float64 to about 1e-6 (tests/test_models_lugre.py).

import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Markdown, display

import jaxfric as jf
from jaxfric import plot, report, rig
from jaxfric.cli.fitting import physical_form
from jaxfric.cli.spec import FitSpec
from jaxfric.identification import GradientRefinement

# %% [markdown]
# Helpers (each notebook has its own copy, so that it runs alone). `say` prints a sentence made
# from measured numbers, `show` draws a figure; both keep a record (`CLAIMS`) that
# tests/test_notebooks.py checks against the outputs, with every comparison's models and the
# form the data need. Warnings print as one line, `Category: message`.

# %%
NAME = "02_friction_identification"
warnings.formatwarning = lambda message, category, *args, **kwargs: f"{category.__name__}: {message}\n"
#: numbers quoted in the text that are not measured here (the paper's, and fixed settings)
CONSTANTS = [95.6, 0.3277, 0.2632, 0.2377, 180, 2000, 128, 400, 1600, 1, 5, 10, 20, 30, 40]
CLAIMS = {"notebook": NAME, "budget": BUDGET, "constants": CONSTANTS, "sentences": [], "comparisons": [],
          "figures": []}


def say(template, **values):
    """Show ``template.format(**values)`` and record it with its values."""
    values = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in values.items()}
    text = template.format(**values)
    CLAIMS["sentences"].append({"text": text, "values": {k: v for k, v in values.items()
                                                         if isinstance(v, (int, float)) and not isinstance(v, bool)}})
    display(Markdown(text))


def show(fig, comparison=None):
    """Display a figure (pyplot or not) and record its legend entries."""
    labels = [t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().get_texts()]
    CLAIMS["figures"].append({"comparison": comparison, "labels": labels})
    display(fig)
    plt.close(fig)


def form_of(data):
    """The form `jaxfric identify --form auto` gives the physical models for ``data``."""
    asym, reason = physical_form(data)
    v, f = np.asarray(data.velocity[:data.n_train]), np.asarray(data.friction[:data.n_train])
    lev = rig.coulomb_levels(v, f, 0.1 * float(np.max(np.abs(v))))
    return {"asymmetric": asym, "offset": asym, "reason": reason, "mean_pos": lev.mean_pos, "mean_neg": lev.mean_neg,
            "apart": 100 * abs(lev.offset) / abs(lev.halfrange)}


def model_options(form):
    return {"asymmetric": True, "offset": True} if form["asymmetric"] else {}


def record_comparison(name, split, form, fits, values, metric="MSE %", physical=None):
    """Keep a comparison: its models (with their form) and ``metric`` per model on ``split``.
    A jaxfric ``Fit`` is a network or a physical model by its model; anything else is the
    baseline, unless ``physical`` gives its form (``{label: {"asymmetric": ..., "offset": ...}}``)."""
    models = []
    for label, fit in fits.items():
        if isinstance(fit, jf.Fit):
            kind = "network" if fit.model.needs_scaling else "physical"
            models.append({"label": label, "kind": kind, "asymmetric": bool(getattr(fit.model, "asymmetric", False)),
                           "offset": bool(getattr(fit.model, "offset", False))})
        elif physical and label in physical:
            models.append({"label": label, "kind": "physical", **physical[label]})
        else:
            models.append({"label": label, "kind": "baseline", "asymmetric": True, "offset": True})
    CLAIMS["comparisons"].append({"name": name, "split": split, "form": form, "models": models, "metric": metric,
                                  "values": {k: float(v) for k, v in values.items()}, "leads": []})


def lead(name, model, over):
    """How far ``model``'s MSE % lies below ``over``'s in comparison ``name`` [%], recorded."""
    comp = next(c for c in CLAIMS["comparisons"] if c["name"] == name)
    pct = 100 * (1 - comp["values"][model] / comp["values"][over])
    comp["leads"].append({"model": model, "over": over, "percent": pct})
    return pct


def save_claims():
    folder = os.environ.get("JAXFRIC_NOTEBOOK_CLAIMS")
    if folder:
        Path(folder).mkdir(parents=True, exist_ok=True)
        Path(folder, f"{NAME}.json").write_text(json.dumps(CLAIMS, indent=1, default=float))


class LSBaseline:
    """The least-squares baseline: asymmetric Coulomb + viscous + offset, five numbers by
    ``numpy.linalg.lstsq`` on the training window (a static map: no state, no optimiser)."""

    def __init__(self, velocity, friction):
        self.coef, *_ = np.linalg.lstsq(self.columns(velocity), np.asarray(friction, float), rcond=None)

    @staticmethod
    def columns(v):
        v = np.asarray(v, float)
        pos, neg = (v > 0).astype(float), (v < 0).astype(float)
        return np.stack([v * pos, v * neg, pos, -neg, np.ones_like(v)], axis=1)

    def predict(self, velocity, dt=None):
        return self.columns(velocity) @ self.coef


def below(pct):
    """``(|pct|, "below" or "above")`` for a sentence."""
    return abs(pct), ("below" if pct >= 0 else "above")


def nmse(y, y_hat):
    y, y_hat = np.asarray(y, float), np.asarray(y_hat, float)
    return 100 * np.mean((y - y_hat) ** 2) / np.var(y)


def stages_text(fit):
    return " → ".join(plot.STAGE_NAMES.get(s["stage"], s["stage"]) for s in fit.stages)


def budget(name, form=None, *, lm=False):
    """`identify` keywords: with SMALL, `jaxfric --quick`'s solver (the library's default for
    the model cut to 3 generations and 200 Nelder-Mead evaluations; MAPSO then 20 BFGS steps
    for the networks); otherwise the library's defaults. ``lm``: a physical model gets a short
    swarm, then Levenberg-Marquardt (as benchmarks/emps.py fits EMPS)."""
    asym = bool(form and form["asymmetric"])
    if name == "elman":
        return ({"solver": FitSpec(name, solver="mapso", generations=3).build_solver(),
                 "refine": GradientRefinement(method="bfgs", max_steps=20)} if SMALL else {})
    if lm:
        return {"solver": jf.MAPSO(lattice_size=3 if SMALL else 5, num_generations=2 if SMALL else 30),
                "refine": "lm"}
    return {"solver": FitSpec(name, generations=3, nm_evals=200, asymmetric=asym).build_solver()} if SMALL else {}


def parameter_table(fit):
    """Estimate and 95 % interval of each parameter; none for a parameter the fit flags."""
    loose = {str(s).split(": ", 1)[0]: str(s).split(": ", 1)[1] for s in fit.diagnostics.get("unidentifiable", [])}
    for d in fit.diagnostics.get("implausible", []):
        loose.setdefault(d["name"], d["message"])
    on_bound = {d["name"]: d for d in fit.diagnostics.get("on_bound", [])}
    rows = ["| parameter | estimate | 95 % interval | note |", "|---|---|---|---|"]
    for row in fit.uncertainty.table():
        name = row["name"]
        ok = row.get("identifiable", True) and name not in loose and not row.get("covers_box")
        note = loose.get(name, "the interval covers the search box" if row.get("covers_box") else "")
        if name in on_bound:
            note = f"ON A BOUND of its search box: {on_bound[name]['message']}. " + note
        interval = f"[{row['low']:.4g}, {row['high']:.4g}]" if ok else "— (not identifiable)"
        rows.append(f"| {name} | {row['estimate']:.4g} | {interval} | {note} |")
    display(Markdown("\n".join(rows)))


def curves(models, d):
    """``{label: Fit or prediction array}`` on record ``d`` for the figures (the baseline's
    predictions computed here)."""
    return {k: (f if isinstance(f, jf.Fit) else f.predict(d.velocity)) for k, f in models.items()}


# %% [markdown]
# ## 1. Rig data
#
# `rig.simulate` integrates the cylinder, valve, PI position controller and seal friction at
# 4 kHz and samples the sensors at 128 Hz, with noise and quantisation. Besides the measured
# channels the record holds the ground truth (true velocity and friction), which a real rig
# never gives; we use it only to check the pipeline. The excitation is the default one: a
# position loop following the sum of two sines (0.2 and 0.53 Hz).

# %%
data_key, fit_key, test_key = jax.random.split(jax.random.key(0), 3)
r = rig.Rig()
record = rig.simulate(r, data_key)
t = np.asarray(record.t)
fig, ax = plt.subplots(3, 1, figsize=(9, 7), sharex=True, layout="constrained")
ax[0].plot(t, np.asarray(record.x) * 1e3, color="0.15")
ax[0].set_ylabel("position x [mm]")
ax[1].plot(t, np.asarray(record.p1) / 1e5, label="p1 (cap side)")
ax[1].plot(t, np.asarray(record.p2) / 1e5, ls="--", label="p2 (rod side)")
ax[1].set_ylabel("pressure [bar]")
ax[1].legend(fontsize=8)
ax[2].plot(t, np.asarray(record.load) / 1e3, color="0.15")
ax[2].set_ylabel("load [kN]")
ax[2].set_xlabel("time [s]")
for a in ax:
    a.grid(alpha=0.3)
fig.suptitle(f"Measured channels (bore {r.cylinder.bore * 1e3:g} mm, rod {r.cylinder.rod * 1e3:g} mm, "
             f"moving mass {r.cylinder.mass:g} kg)")
show(fig)

# %% [markdown]
# ## 2. Friction from the force balance
#
# `estimate_friction` filters every channel (Butterworth, 4th order, 5 Hz, zero phase),
# differentiates the position twice and solves the force balance
# `F_f = p1·A1 − p2·A2 − F_L − m·a`. The first 1600 samples are for estimation, the last 400
# are held back for validation (the paper's split; below: "the held-back tail"). The second
# figure shows what the pipeline gets wrong against the true friction: the measured friction is
# drawn as dots so that the truth stays visible under it.

# %%
data = rig.estimate_friction(record.measurements(), r.cylinder)
show(plot.plot_data(data, title="Velocity (Fig. 9) and computed friction (Fig. 10)"))
true_f = np.asarray(record.friction)
fig, ax = plt.subplots(figsize=(9, 3.5), layout="constrained")
ax.plot(t, true_f, color="goldenrod", lw=2.5, label="true friction (simulator)")
ax.plot(t, np.asarray(data.friction), ".", ms=2, color="0.15", label="computed by the pipeline")
ax.set_xlabel("time [s]")
ax.set_ylabel("friction force [N]")
ax.legend(fontsize=8)
ax.grid(alpha=0.3)
pipeline_mse = nmse(true_f, data.friction)
ax.set_title("Pipeline against the truth")
show(fig)
say("The friction the pipeline computes differs from the simulator's true friction by a normalised "
    "MSE of {mse:.2f} %, mostly filter lag at the reversals. Every error below is measured against the "
    "computed friction (a real rig has no other), not against the truth.", mse=pipeline_mse)

# %% [markdown]
# ## 3. Which form do the physical models need?
#
# The seal friction of this rig is larger moving out than moving in. A symmetric model (one
# Coulomb level for both directions, the paper's LuGre) cannot follow that: its error is a steady
# bias in each direction, and a lead measured against it says more about the form than about the
# network. jaxfric decides the form from the training data exactly as `jaxfric identify --form
# auto` does, and every physical model below is fitted in that form.

# %%
FORM = form_of(data)
say("Form: {reason}.", **FORM)
show(plot.plot_friction_velocity(data, title="Friction against velocity: two different levels"))

# %% [markdown]
# ## 4. How many neurons?
#
# The paper tried N = 20, 30 and 40 hidden neurons (normalised MSE 0.3277 %, 0.2632 % and
# 0.2377 %) and kept 30, "with 180 internal connections" (6 parameters per neuron). Every fit
# below uses the same data and the same optimiser key; `jf.identify` returns a `Fit` with
# metrics on the training and validation windows (`fit.summary()` prints them). The small budget
# fits N = 30 only.

# %%
NEURONS = (30,) if SMALL else (20, 30, 40)
study = {}
for n in NEURONS:
    study[n] = jf.identify("elman", data, key=fit_key, model_options={"neurons": n}, **budget("elman"))
    m = study[n].metrics
    say("N = {n}: {p} parameters, MSE % training {tr:.4f}, held-back tail {va:.4f} ({sec:.1f} s).",
        n=n, p=study[n].num_params, tr=m["train"]["mse_percent"], va=m["valid"]["mse_percent"],
        sec=study[n].timings["total_s"])

# %%
fig, ax = plt.subplots(figsize=(6.5, 4), layout="constrained")
for window, marker, ls in (("train", "o", "-"), ("valid", "s", "--")):
    ax.plot(NEURONS, [study[n].metrics[window]["mse_percent"] for n in NEURONS], marker=marker, ls=ls,
            color="tab:blue", label=f"jaxfric ENN, {'training' if window == 'train' else 'held-back tail'}")
ax.plot([20, 30, 40], [0.3277, 0.2632, 0.2377], "k^:", label="paper (its rig)")
ax.set_xticks([20, 30, 40])
ax.set_xlabel("hidden neurons N")
ax.set_ylabel("normalised MSE [%]")
ax.set_yscale("log")
ax.set_title("Neuron study")
ax.grid(alpha=0.3, which="both")
ax.legend(fontsize=8)
show(fig)

# %% [markdown]
# ## 5. ENN against LuGre and the least-squares baseline, on the held-back tail
#
# Three contenders, all fitted on the first 1600 samples and scored on the last 400:
#
# * the **least-squares baseline**: asymmetric Coulomb + viscous + offset, five numbers by
#   `numpy.linalg.lstsq` (a static map, no optimiser): what any model has to beat;
# * **LuGre** in the form the data need (direction-dependent levels and an offset), its ten
#   parameters searched in log-space where they span decades, in ranges centred on the data;
# * the **ENN** with N = 30.

# %%
enn = study[30]
lugre = jf.identify("lugre", data, key=fit_key, model_options=model_options(FORM), **budget("lugre", FORM))
n_tr = data.n_train
v_all, f_all = np.asarray(data.velocity), np.asarray(data.friction)
baseline = LSBaseline(v_all[:n_tr], f_all[:n_tr])
LABELS = {"LS baseline": baseline, plot.fit_label(lugre): lugre, plot.fit_label(enn): enn}
L_LUGRE, L_ENN = plot.fit_label(lugre), plot.fit_label(enn)
preds = {k: plot.predict_on(f, data) for k, f in curves(LABELS, data).items()}
mse_tail = {k: nmse(f_all[n_tr:], y[n_tr:]) for k, y in preds.items()}
mse_train = {k: nmse(f_all[:n_tr], y[:n_tr]) for k, y in preds.items()}
record_comparison("rig, held-back tail", "held-back tail (last 400 of 2000 samples)", FORM, LABELS, mse_tail)
rows = ["| model | parameters | fitted by | MSE % training | MSE % held-back tail |", "|---|---|---|---|---|"]
for k, f in LABELS.items():
    how = stages_text(f) if isinstance(f, jf.Fit) else "numpy.linalg.lstsq"
    npar = f.num_params if isinstance(f, jf.Fit) else 5
    rows.append(f"| {k} | {npar} | {how} | {mse_train[k]:.4f} | {mse_tail[k]:.4f} |")
display(Markdown("\n".join(rows)))
lead_lugre, word_lugre = below(lead("rig, held-back tail", L_ENN, L_LUGRE))
lead_ls, word_ls = below(lead("rig, held-back tail", L_ENN, "LS baseline"))
say("On the held-back tail the ENN's MSE ({enn:.3f} %) is {lead:.1f} % {w1} that of LuGre in the form the "
    "data need ({lug:.3f} %), and {lead_ls:.1f} % {w2} the least-squares baseline's ({ls:.3f} %). "
    "The paper reports its ENN 95.6 % below LuGre, against a symmetric LuGre on its own rig.",
    enn=mse_tail[L_ENN], lug=mse_tail[L_LUGRE], ls=mse_tail["LS baseline"],
    lead=lead_lugre, w1=word_lugre, lead_ls=lead_ls, w2=word_ls)
say("Methods as run: ENN {enn_st}; LuGre {lug_st}.", enn_st=stages_text(enn), lug_st=stages_text(lugre))

# %% [markdown]
# Measured and estimated friction on the held-back tail, with each model's error below
# (the measured samples are the grey dots; the baseline is the dashed black line), and the
# same against velocity.

# %%
show(plot.plot_models(curves(LABELS, data), data, title="Held-back tail (last 400 samples): measured and the three models"),
     comparison="rig, held-back tail")
show(plot.plot_friction_velocity(data, curves(LABELS, data), title="Friction against velocity, with the three models"),
     comparison="rig, held-back tail")

# %% [markdown]
# ### What LuGre's parameters mean here
#
# The ten numbers are not all determined by these data: the record holds almost no standstill
# or pre-sliding, so the bristle stiffness, damping and Stribeck parameters are set by the search,
# not by the data. The table withholds the interval of every parameter jaxfric flags as not
# identifiable, and says why; the warnings `identify` printed above are explained here too.

# %%
parameter_table(lugre)
flagged = sorted({str(s).split(": ", 1)[0] for s in lugre.diagnostics["unidentifiable"]})
say("LuGre: {k} of its {p} parameters are not determined by these data ({names}); {b} ended on a bound of "
    "the search box. Its predictions are what the comparison uses; its parameter values are not "
    "physical measurements.", k=len(flagged), p=lugre.num_params, names=", ".join(flagged) or "none",
    b=len(lugre.diagnostics["on_bound"]))

# %% [markdown]
# ### The optimisers' progress
#
# Best cost against function evaluations, per model (each model's own cost: the ENN's on
# [−1, 1]-scaled data, LuGre's normalised by the friction variance). The ENN's MAPSO stage runs on
# the first part of the training window only, and BFGS on the whole window continues from its
# best point. The cell measures where MAPSO's best cost stopped moving and what BFGS added.

# %%
show(plot.plot_convergence({L_ENN: enn, L_LUGRE: lugre}, ylabel="best objective J (each model's own cost)"))
evals, best = np.asarray(enn.history["evals"]), np.asarray(enn.history["f"])
within10, within1 = (int(evals[np.argmax(best <= best[-1] * (1 + tol))]) for tol in (0.10, 0.01))
grad = [s for s in enn.stages if "num_evals" not in s]
say("ENN: MAPSO's best cost ({j_g:.3g} at the end) was within 10 % of that after {k10} of its {n} evaluations "
    "and within 1 % after {k1}. {gname} then took the cost from there to {j_b:.3g} in {steps} steps: the "
    "network's fit comes from the gradient stage, not from the swarm.",
    j_g=float(best[-1]), k10=within10, k1=within1, n=int(evals[-1]),
    gname=plot.STAGE_NAMES.get(grad[-1]["stage"], grad[-1]["stage"]) if grad else "No gradient stage",
    j_b=float(grad[-1]["J"]) if grad else float(best[-1]), steps=int(grad[-1].get("num_steps", 0)) if grad else 0)

# %% [markdown]
# ## 6. Motion it has never seen
#
# The held-back tail is the end of the same excitation. A harder test drives the same rig with
# other excitation families (`rig.simulate(..., velocity_reference=...)`) and new sensor noise:
#
# * **strokes**: trapezoidal velocity, constant speed with dwells at standstill between strokes;
# * **chirp**: one sine sweeping from 0.1 to 1 Hz.
#
# No model sees any of these samples before it predicts them. A fit is a file: the ENN is saved
# with `fit.save(path)` and loaded with `jf.load_fit(path)` (or used by `jaxfric predict`).

# %%
import tempfile

path = Path(tempfile.mkdtemp()) / "enn.npz"
enn.save(path)
loaded = jf.load_fit(path)
assert np.array_equal(np.asarray(loaded.predict(data.velocity)), np.asarray(enn.predict(data.velocity)))
NEW = {k: (loaded if f is enn else f) for k, f in LABELS.items()}

fs, N = 128.0, 2000
tt = np.arange(N) / fs


def strokes(t, period=6.0, peak=0.009, ramp=0.6, dwell=0.4):
    half = period / 2
    tau, sign = np.mod(t, half), np.where(np.mod(t, period) < half, 1.0, -1.0)
    return sign * peak * np.minimum(np.clip(tau / ramp, 0, 1), np.clip((half - dwell - tau) / ramp, 0, 1))


EXCITATIONS = {"strokes": strokes(tt),
               "chirp": 0.010 * np.sin(2 * np.pi * (0.1 * tt + 0.5 * (1.0 - 0.1) / tt[-1] * tt ** 2))}
new_data, new_mse = {}, {}
for i, (name, vref) in enumerate(EXCITATIONS.items()):
    rec_new = rig.simulate(r, jax.random.fold_in(test_key, i), velocity_reference=vref)
    d = rig.estimate_friction(rec_new.measurements(), r.cylinder, train_fraction=1.0)
    new_data[name] = d
    v_new, f_new = np.asarray(d.velocity), np.asarray(d.friction)
    new_mse[name] = {k: nmse(f_new, plot.predict_on(f, d)) for k, f in curves(NEW, d).items()}
    record_comparison(f"rig, new excitation: {name}", f"new record, {name} excitation (all {N} samples)", FORM, NEW,
                      new_mse[name])
rows = ["| model | " + " | ".join(f"MSE % {k}" for k in EXCITATIONS) + " |", "|---" * (1 + len(EXCITATIONS)) + "|"]
for k in NEW:
    rows.append(f"| {k} | " + " | ".join(f"{new_mse[e][k]:.3f}" for e in EXCITATIONS) + " |")
display(Markdown("\n".join(rows)))
for name in EXCITATIONS:
    best_k = min(new_mse[name], key=new_mse[name].get)
    pct, word = below(lead(f"rig, new excitation: {name}", L_ENN, L_LUGRE))
    say("New excitation '{exc}': the ENN's MSE is {enn:.3f} %, LuGre's {lug:.3f} %, the baseline's {ls:.3f} %; "
        "the ENN's is {lead:.1f} % {word} LuGre's. Lowest here: {best}.",
        exc=name, enn=new_mse[name][L_ENN], lug=new_mse[name][L_LUGRE], ls=new_mse[name]["LS baseline"],
        lead=pct, word=word, best=best_k)

# %%
for name, d in new_data.items():
    show(plot.plot_models(curves(NEW, d), d, window="all", title=f"New excitation '{name}': measured and the three models"),
         comparison=f"rig, new excitation: {name}")

# %% [markdown]
# ## What this shows
#
# The summary below is computed from this run: the ENN's lead over LuGre in the form the data
# need, on each test, next to the paper's claim. Which model wins depends on the motion; the
# least-squares baseline shows how much of the friction a five-number static map already
# explains.

# %%
for comp in CLAIMS["comparisons"]:
    pct, word = below(next(l["percent"] for l in comp["leads"] if l["over"] == L_LUGRE))
    say("{split}: the ENN's MSE is {pct:.1f} % {word} that of {lugre} (the paper: 95.6 % below a symmetric "
        "LuGre).", split=comp["split"][0].upper() + comp["split"][1:], pct=pct, word=word, lugre=L_LUGRE)
save_claims()
