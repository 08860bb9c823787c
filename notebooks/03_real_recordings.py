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
# # 03 — Real recordings: pneumatic piston seals and the EMPS axis
#
# Two public recordings, both fetched by `jaxfric.datasets`:
#
# * **pneumatic seals** (TU Delft, Zillen 2021, CC0): 3D-printed pneumatic cylinders with five
#   piston seals at 1, 3, 5 and 7 bar. Not the paper's hydraulic press, but real cylinder friction
#   recorded the same way: position, chamber pressure and load-cell force, from which friction
#   follows by a force balance;
# * **EMPS** (Janot, Gautier & Brunot 2019): a ball-screw positioning axis under a PD position
#   loop, published as a system-identification benchmark with reference friction values.
#
# **Data.** `jaxfric.datasets` looks for each file in the folder `$JAXFRIC_DATA` names (the
# README's setup) or, when that variable is not set, in its cache (`~/.cache/jaxfric/data`);
# a file that is not there is downloaded once into that folder, and every file is checked
# against its SHA-256. Offline and without the files, each section prints one `SKIPPED` line
# saying what is missing and where to put it.
#
# **Fair comparisons.** Every physical model is fitted in the form the data need, decided as
# `jaxfric identify --form auto` decides it, and every comparison includes the least-squares
# baseline (asymmetric Coulomb + viscous + offset by `numpy.linalg.lstsq`). Every number in the
# text is computed in the cell that shows it.

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
from jaxfric import datasets, plot, rig
from jaxfric.cli.fitting import physical_form
from jaxfric.cli.spec import FitSpec
from jaxfric.identification import GradientRefinement

# %% [markdown]
# Helpers (each notebook has its own copy, so that it runs alone). `say` prints a sentence made
# from measured numbers, `show` draws a figure; both keep a record (`CLAIMS`) that
# tests/test_notebooks.py checks against the outputs, with every comparison's models and the
# form the data need. Warnings print as one line, `Category: message`.

# %%
NAME = "03_real_recordings"
warnings.formatwarning = lambda message, category, *args, **kwargs: f"{category.__name__}: {message}\n"
#: numbers quoted in the text that are not measured here (the paper's, and fixed settings)
CONSTANTS = [1, 3, 5, 7, 15, 20, 30, 80, 95, 95.6]
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
# ## Pneumatic seals: the data
#
# `datasets.pneumatic(seal, bar)` reads a raw file (time [ms], position [mm], chamber pressure
# [bar] and load-cell force [N]; the first 15 rows dropped, as the authors do), resamples the
# irregular stamps (about 100 Hz with gaps) to a uniform grid, low-pass filters every channel
# (zero-phase Butterworth, 5 Hz), differentiates the position and applies the force balance of
# docs/algorithms.md §7 with one pressurised chamber and no inertia: `F_f = F_loadcell − p·A`.

# %%
SEALS, BARS = datasets.PNEUMATIC_SEALS, datasets.PNEUMATIC_BARS
records = {}
try:
    for seal in SEALS:
        for bar in BARS:
            records[seal, bar] = datasets.pneumatic(seal, bar)[1]
except datasets.DatasetUnavailable as err:
    records = {}
    print(f"SKIPPED: no pneumatic_seal_friction data ({err})")
HAVE_DATA = bool(records)
if HAVE_DATA:
    say("{n} records, e.g. O-ring at 3 bar: {k} samples at {fs:.0f} Hz.", n=len(records),
        k=records["O-ring", 3].n_samples, fs=1 / records["O-ring", 3].dt)

# %% [markdown]
# ## Coulomb level against pressure, checked two ways
#
# The Coulomb level is half the difference between the mean friction while extending and while
# retracting (faster than 3 mm/s). jaxfric's value (filtered, resampled pipeline) is checked
# against one computed here independently from the raw file: raw time stamps, `np.gradient` for
# the velocity, no filter (the recipe of the data folder's `make_summary.py`, a script written
# for this project, not the authors').

# %%
def raw_levels(seal, bar):
    """Mean friction while extending / retracting from the raw file: no resampling, no filter."""
    raw = np.loadtxt(datasets.pneumatic_path(seal, bar))[datasets.PNEUMATIC_DROP_ROWS:]
    t, x, p, load = raw[:, 0] / 1e3, raw[:, 4] / 1e3, raw[:, 5] * 1e5, raw[:, 6]
    bore = 0.0257 if "257" in seal else 0.025
    f = load - p * np.pi * (bore / 2) ** 2
    v = np.gradient(x, t)
    return f[v > 3e-3].mean(), f[v < -3e-3].mean()


if HAVE_DATA:
    levels, checks = {}, {}
    lines = ["| seal | bar | Coulomb, jaxfric [N] | Coulomb, raw recipe [N] | difference |", "|---|---|---|---|---|"]
    for (seal, bar), d in records.items():
        lev = rig.coulomb_levels(np.asarray(d.velocity), np.asarray(d.friction), 3e-3)
        pos, neg = raw_levels(seal, bar)
        ref = 0.5 * (pos - neg)
        levels[seal, bar], checks[seal, bar] = lev.halfrange, 100 * (lev.halfrange / ref - 1)
        lines.append(f"| {seal} | {bar} | {lev.halfrange:.2f} | {ref:.2f} | {checks[seal, bar]:+.1f} % |")
    display(Markdown("\n".join(lines)))
    worst = max(checks, key=lambda k: abs(checks[k]))
    say("The two agree within {d:.1f} % on every record (largest difference: {seal} at {bar} bar).",
        d=abs(checks[worst]), seal=worst[0], bar=worst[1])

    fig, ax = plt.subplots(figsize=(7, 4.5), layout="constrained")
    for i, seal in enumerate(SEALS):
        # seals are not models: shades of one colour map, so no seal wears a model's colour
        ax.plot(BARS, [levels[seal, b] for b in BARS], marker="osD^v"[i], ls="-", label=seal,
                color=plt.cm.viridis(i / len(SEALS)))
    ax.set_xlabel("nominal chamber pressure [bar]")
    ax.set_ylabel("Coulomb level [N]")
    ax.set_title("Seal friction grows with pressure")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    show(fig)

# %% [markdown]
# ## One record up close: O-ring at 3 bar
#
# Friction flips sign at each reversal, but not symmetrically: the two sliding levels differ
# (the cell measures them), so a model with one Coulomb level for both directions is biased in
# each. The transitions are where dynamic models (LuGre, the Elman network) differ from a static
# map.

# %%
if HAVE_DATA:
    full = records["O-ring", 3]
    show(plot.plot_data(full, title="O-ring at 3 bar: velocity and friction"))
    show(plot.plot_friction_velocity(full, title="O-ring at 3 bar: friction against velocity"))
    lev = rig.coulomb_levels(np.asarray(full.velocity), np.asarray(full.friction), 3e-3)
    say("While sliding, the friction averages {p:+.1f} N extending and {n:+.1f} N retracting: a Coulomb level "
        "of {h:.2f} N around an offset of {o:+.2f} N.", p=lev.mean_pos, n=lev.mean_neg, h=lev.halfrange, o=lev.offset)

# %% [markdown]
# ## Identifying the seal friction at a pressure it was not trained on
#
# Train on the O-ring at 1, 5 and 7 bar (each record used whole), test on the O-ring at 3 bar,
# a pressure none of the models saw. The models take velocity only, so they learn one friction
# law for all training pressures; the test asks how well that law carries over. Three
# contenders: the least-squares baseline, LuGre in the form the training data need, and the
# Elman network (N = 30), each fitted with jaxfric's default pipeline.

# %%
TRAIN_BARS, TEST_BAR = (1, 5, 7), 3
if HAVE_DATA:
    cut = slice(0, 1500) if SMALL else slice(None)   # the small budget: the first 15 s of each record


    def window(d):
        return jf.FrictionData.from_arrays(np.asarray(d.velocity)[cut], np.asarray(d.friction)[cut], d.dt,
                                           train_fraction=1.0)


    train = {f"{b} bar": window(records["O-ring", b]) for b in TRAIN_BARS}
    test = window(records["O-ring", TEST_BAR])
    v_tr = np.concatenate([np.asarray(d.velocity) for d in train.values()])
    f_tr = np.concatenate([np.asarray(d.friction) for d in train.values()])
    FORM_P = form_of(jf.FrictionData.from_arrays(v_tr, f_tr, test.dt, train_fraction=1.0))
    say("Form: {reason}.", **FORM_P)
    lugre_p = jf.identify("lugre", train=train, valid={f"{TEST_BAR} bar": test}, key=0,
                          model_options=model_options(FORM_P), **budget("lugre", FORM_P))
    widen = {d["box_key"]: tuple(d["widen_to"]) for d in lugre_p.diagnostics["on_bound"] if not d["at_limit"]}
    if widen:  # the box, not the data, stopped these: fit again with the wider ranges identify suggests
        say("The BoundWarning above: LuGre's {names} ended on an edge of the search box, so it is fitted again "
            "with the wider range the warning names (the box is data: no new compilation).",
            names=", ".join(d["shown"] for d in lugre_p.diagnostics["on_bound"] if not d["at_limit"]))
        lugre_p = jf.identify("lugre", train=train, valid={f"{TEST_BAR} bar": test}, key=0, box=widen,
                              model_options=model_options(FORM_P), **budget("lugre", FORM_P))
    enn_p = jf.identify("elman", train=train, valid={f"{TEST_BAR} bar": test}, key=0, **budget("elman"))
    PNEU = {"LS baseline": LSBaseline(v_tr, f_tr), plot.fit_label(lugre_p): lugre_p, plot.fit_label(enn_p): enn_p}
    f_te = np.asarray(test.friction)
    mse_p = {k: nmse(f_te, plot.predict_on(f, test)) for k, f in curves(PNEU, test).items()}
    mse_p_train = {k: nmse(f_tr, np.concatenate([plot.predict_on(f, d) for d in train.values()]))
                   for k, f in PNEU.items() if isinstance(f, jf.Fit)}
    mse_p_train["LS baseline"] = nmse(f_tr, PNEU["LS baseline"].predict(v_tr))
    split_p = f"trained on 1, 5 and 7 bar; tested on the whole 3 bar record ({test.n_samples} samples)"
    record_comparison("pneumatic O-ring, new pressure", split_p, FORM_P, PNEU, mse_p)
    rows = ["| model | parameters | fitted by | MSE % training (1, 5, 7 bar) | MSE % test (3 bar) |",
            "|---|---|---|---|---|"]
    for k, f in PNEU.items():
        how = stages_text(f) if isinstance(f, jf.Fit) else "numpy.linalg.lstsq"
        rows.append(f"| {k} | {f.num_params if isinstance(f, jf.Fit) else 5} | {how} | {mse_p_train[k]:.3f} "
                    f"| {mse_p[k]:.3f} |")
    display(Markdown("\n".join(rows)))
    L_LUG_P, L_ENN_P = plot.fit_label(lugre_p), plot.fit_label(enn_p)
    pct, word = below(lead("pneumatic O-ring, new pressure", L_ENN_P, L_LUG_P))
    pct_ls, word_ls = below(lead("pneumatic O-ring, new pressure", L_ENN_P, "LS baseline"))
    best_p = min(mse_p, key=mse_p.get)
    say("At 3 bar, which no model saw, the ENN's MSE ({enn:.3f} %) is {lead:.1f} % {w1} LuGre's ({lug:.3f} %) and "
        "{lead_ls:.1f} % {w2} the least-squares baseline's ({ls:.3f} %). Lowest: {best}.",
        enn=mse_p[L_ENN_P], lug=mse_p[L_LUG_P], ls=mse_p["LS baseline"], lead=pct, w1=word, lead_ls=pct_ls,
        w2=word_ls, best=best_p)
    if mse_p[L_ENN_P] > 3 * mse_p_train[L_ENN_P]:
        say("The RuntimeWarning above says the same: the ENN's error at 3 bar ({te:.2f} %) is {ratio:.0f} times its "
            "error on the training pressures ({tr:.2f} %). With velocity as its only input it has learnt the "
            "training records, not how the friction depends on pressure.", te=mse_p[L_ENN_P],
            ratio=mse_p[L_ENN_P] / mse_p_train[L_ENN_P], tr=mse_p_train[L_ENN_P])

# %% [markdown]
# The 3 bar record with the three models (measured samples as grey dots, the baseline dashed
# black) and each model's error; then the same against velocity.

# %%
if HAVE_DATA:
    show(plot.plot_models(curves(PNEU, test), test, window="all",
                          title="O-ring at 3 bar (not trained on): measured and the three models"),
         comparison="pneumatic O-ring, new pressure")
    show(plot.plot_friction_velocity(test, curves(PNEU, test), title="O-ring at 3 bar: friction against velocity"),
         comparison="pneumatic O-ring, new pressure")

# %% [markdown]
# ### LuGre's parameters, its bound hits and the warnings above
#
# A parameter that ends on an edge of its search box is reported by `identify` with a
# `BoundWarning`: where the box stopped it, the cell above fitted again with the wider range;
# where the range already starts at the least the model allows (Fs/Fc = 1), the data ask for
# less than LuGre can express. A parameter the data cannot determine is flagged not
# identifiable (a `PlausibilityWarning` names a physically doubtful split). The table withholds
# the interval of every such parameter, and the cell says what each remaining bound hit means.

# %%
if HAVE_DATA:
    parameter_table(lugre_p)
    for d in lugre_p.diagnostics["on_bound"]:
        say("LuGre's {name} = {value:.4g} ended on the {side} edge of its search range: {why}",
            name=d["shown"], side=d["side"], value=float(d["value"]),
            why=("the data show no static peak above the sliding level in that direction, and Fs/Fc = 1 is the "
                 "least LuGre allows: its Stribeck term is switched off there" if d["at_limit"] and "Fs" in d["name"]
                 else
                 "the data ask for less than the model can express" if d["at_limit"] else
                 "even the widened range did not hold it; its value is the box's, not a measurement"))
    if not lugre_p.diagnostics["on_bound"]:
        say("No LuGre parameter ended on a bound of its search box.")


# %% [markdown]
# ## A second real recording: the EMPS positioning axis
#
# `datasets.emps()` loads the benchmark's estimation file `DATA_EMPS.mat`;
# `rig.emps_friction_data` follows the benchmark's own recipe: 4th-order Butterworth at 100 Hz
# forward–backward on the measured position, central differences for velocity and acceleration,
# 50 samples dropped at each end, and the rigid-body inverse model
# `gtau·vir = M·a + Fv·v + Fc·sign(v) + offset` solved by least squares (IDIM-LS). The friction
# record is `gtau·vir − M·a` with the IDIM-LS mass. `benchmarks/emps.py` runs every model on the
# same split (`benchmarks/results/emps.md`).

# %%
try:
    emps_rec = datasets.emps()
except datasets.DatasetUnavailable as err:
    emps_rec = None
    print(f"SKIPPED: no EMPS file ({err})")
HAVE_EMPS = emps_rec is not None
if HAVE_EMPS:
    say("EMPS: {n} samples at {fs:.0f} Hz.", n=emps_rec.n_samples, fs=1 / emps_rec.dt)

# %% [markdown]
# ### IDIM-LS against the published values
#
# The mass, viscous and Coulomb coefficients, symmetric and direction-dependent, estimated on the
# whole recording as the benchmark does.

# %%
PUBLISHED = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935,
             "Fv_pos": 166.71, "Fc_pos": 20.14, "Fv_neg": 240.42, "Fc_neg": 20.63}
if HAVE_EMPS:
    from jaxfric.rig.emps import emps_states, idim_ls

    states = emps_states(emps_rec)
    lines = ["| form | parameter | jaxfric | published | difference |", "|---|---|---|---|---|"]
    diffs = []
    for asym in (False, True):
        est = idim_ls(states["v"], states["a"], states["force"], asymmetric=asym)
        for k in (("M", "Fv_pos", "Fv_neg", "Fc_pos", "Fc_neg") if asym else ("M", "Fv", "Fc")):
            ours = getattr(est, k)
            diffs.append(100 * (ours / PUBLISHED[k] - 1))
            lines.append(f"| {'asymmetric' if asym else 'symmetric'} | {k} | {ours:.4g} | {PUBLISHED[k]:.4g} "
                         f"| {diffs[-1]:+.2f} % |")
    display(Markdown("\n".join(lines)))
    say("Every coefficient agrees with the published IDIM-LS value within {d:.2f} %.",
        d=max(abs(x) for x in diffs))

# %% [markdown]
# ### Identify on the first 80 %, test on the held-back tail
#
# The last 20 % of the estimation recording (the **held-back tail**) is never used to choose
# anything. It is the end of the same recording, not a new motion: the benchmark's separate
# test recording is scored further below. Three contenders: the least-squares baseline, LuGre in
# the form the data need (a short swarm, then Levenberg–Marquardt, as `benchmarks/emps.py`), and
# the Elman network with `identify`'s defaults. The small budget cuts every search to a few
# generations and steps and the record to its first 5000 samples, so only the plumbing is shown.

# %%
if HAVE_EMPS:
    emps = rig.emps_friction_data(emps_rec)            # first 80 % train, last 20 % held back
    if SMALL:  # the small budget: the first 5000 samples only, split the same way
        emps = jf.FrictionData.from_arrays(np.asarray(emps.velocity)[:5000], np.asarray(emps.friction)[:5000],
                                           emps.dt, train_fraction=0.8)
    v_e, f_e, n_e = np.asarray(emps.velocity), np.asarray(emps.friction), emps.n_train
    FORM_E = form_of(emps)
    say("Form: {reason}.", **FORM_E)
    with warnings.catch_warnings():
        # a few held-back samples lie a hair outside the training velocity range; the
        # ExtrapolationWarning says so once per prediction, which adds nothing here
        warnings.simplefilter("ignore", jf.fit.ExtrapolationWarning)
        lugre_e = jf.identify("lugre", emps, key=0, model_options=model_options(FORM_E),
                              **budget("lugre", FORM_E, lm=True))
        enn_e = jf.identify("elman", emps, key=0, **budget("elman"))
    EMPS = {"LS baseline": LSBaseline(v_e[:n_e], f_e[:n_e]), plot.fit_label(lugre_e): lugre_e,
            plot.fit_label(enn_e): enn_e}
    pred_e = {k: plot.predict_on(f, emps) for k, f in curves(EMPS, emps).items()}
    mse_e = {k: nmse(f_e[n_e:], y[n_e:]) for k, y in pred_e.items()}
    split_e = f"held-back tail (last {emps.n_samples - n_e} of {emps.n_samples} samples)"
    record_comparison("EMPS, held-back tail", split_e, FORM_E, EMPS, mse_e)
    rows = ["| model | parameters | fitted by | MSE % training | MSE % held-back tail |", "|---|---|---|---|---|"]
    for k, f in EMPS.items():
        how = stages_text(f) if isinstance(f, jf.Fit) else "numpy.linalg.lstsq"
        rows.append(f"| {k} | {f.num_params if isinstance(f, jf.Fit) else 5} | {how} "
                    f"| {nmse(f_e[:n_e], pred_e[k][:n_e]):.3f} | {mse_e[k]:.3f} |")
    display(Markdown("\n".join(rows)))
    L_LUG_E, L_ENN_E = plot.fit_label(lugre_e), plot.fit_label(enn_e)
    pct, word = below(lead("EMPS, held-back tail", L_ENN_E, L_LUG_E))
    pct_ls, word_ls = below(lead("EMPS, held-back tail", L_ENN_E, "LS baseline"))
    say("On the EMPS held-back tail the ENN's MSE ({enn:.3f} %) is {lead:.1f} % {w1} LuGre's ({lug:.3f} %) and "
        "{lead_ls:.1f} % {w2} the least-squares baseline's ({ls:.3f} %).", enn=mse_e[L_ENN_E], lug=mse_e[L_LUG_E],
        ls=mse_e["LS baseline"], lead=pct, w1=word, lead_ls=pct_ls, w2=word_ls)
    flagged = sorted({str(x).split(": ", 1)[0] for x in lugre_e.diagnostics["unidentifiable"]}
                     | {d["name"] for d in lugre_e.diagnostics.get("implausible", [])})
    say("The warnings above: {k} of LuGre's {p} parameters are not determined by these data ({names}), because "
        "few samples lie near zero velocity; {b} ended on a bound of the search box. Its predictions are "
        "compared here; those parameter values are not physical measurements.", k=len(flagged),
        p=lugre_e.num_params, names=", ".join(flagged) or "none", b=len(lugre_e.diagnostics["on_bound"]))
    show(plot.plot_models(curves(EMPS, emps), emps, title="EMPS held-back tail: measured and the three models"),
         comparison="EMPS, held-back tail")
    show(plot.plot_friction_velocity(emps, curves(EMPS, emps), title="EMPS: friction against velocity"),
         comparison="EMPS, held-back tail")

# %% [markdown]
# ### How sure is the fit? Intervals and a band with its measured coverage
#
# Every physical fit carries the uncertainty of its parameters (docs/uncertainty.md):
# `fit.stderr`, `fit.intervals(level)` and `fit.correlation`, from the Jacobian of the
# residuals at the optimum with a Newey–West covariance, because friction residuals are
# strongly correlated in time. Here it is shown for the least-squares model itself, fitted as a
# jaxfric `Coulomb` model in the data's form (so that it has intervals). With direction-dependent
# levels, sliding data fix only `Fc_pos + F_off` and `Fc_neg − F_off`, not the parts: the offset
# is flagged not identifiable (the `PlausibilityWarning` printed by this cell says the same) and
# its interval is withheld. The 95 % prediction band `fit.prediction_interval` is checked on the
# held-back tail, which it never saw.

# %%
if HAVE_EMPS:
    coul = jf.identify(jf.models.Coulomb(**model_options(FORM_E)), emps, key=0, **budget("coulomb", FORM_E, lm=True))
    parameter_table(coul)
    y, lo, hi = coul.prediction_interval(emps.velocity, 0.95)
    inside = (f_e >= lo) & (f_e <= hi)
    say("The 95 % band holds {tr:.1f} % of the training samples and {va:.1f} % of the held-back tail "
        "(mean half-width {w:.2f} N).", tr=100 * inside[:n_e].mean(), va=100 * inside[n_e:].mean(),
        w=np.mean(hi - lo) / 2)
    t_e = np.asarray(emps.t)
    fig, ax = plt.subplots(figsize=(12, 3.5), layout="constrained")
    sl = slice(n_e, None)
    look = plot.style("Coulomb")
    ax.fill_between(t_e[sl], lo[sl], hi[sl], color=look["color"], alpha=0.25, lw=0, label="95 % band")
    ax.plot(t_e[sl], f_e[sl], ".", ms=1.5, color="0.3", label="measured")
    ax.plot(t_e[sl], y[sl], lw=0.8, label=plot.fit_label(coul), **look)
    ax.set(xlabel="t [s]", ylabel="friction [N]", title="EMPS held-back tail with the 95 % band")
    ax.legend(fontsize=8)
    show(fig)

# %% [markdown]
# ### Scoring a separate EMPS test recording (the benchmark's protocol)
#
# The held-back tail is the same recording; the benchmark's own test is a separate file
# (`DATA_EMPS_PULSES.mat`, not shipped with jaxfric's data: never tune on it). Its protocol
# is a motion task: fit friction inside the mechanics on the estimation file
# (`jf.identify_motion`, force in, position out), then simulate the test file from its force,
# with only its first 20 samples setting the initial state: `fit.score(record, init_window=20)`
# gives RMSE in mm and FIT %. Give the file's path in `JAXFRIC_EMPS_TEST` to run it
# (`benchmarks/emps_official.py` does the same for every model).

# %%
EMPS_TEST = os.environ.get("JAXFRIC_EMPS_TEST")
if not (HAVE_EMPS and EMPS_TEST and Path(EMPS_TEST).is_file()):
    print("Not scored: no EMPS test recording given; set JAXFRIC_EMPS_TEST to the path of DATA_EMPS_PULSES.mat "
          "to score it" + ("" if HAVE_EMPS else " (and the estimation file is missing too)"))
else:
    from scipy.io import loadmat

    from jaxfric.motion import MotionData, baseline_fit, identify_motion
    from jaxfric.rig.emps import EMPS_CUTOFF_HZ

    def emps_motion(path):
        """Force gtau·vir [N] and motor position qm [m] of an EMPS .mat file."""
        mat = loadmat(path)
        qm, vir = (np.asarray(mat[k], np.float64).ravel() for k in ("qm", "vir"))
        gtau = float(np.asarray(mat["gtau"]).ravel()[0]) if "gtau" in mat else 35.15065188248547
        dt = float(np.median(np.diff(np.asarray(mat["t"], np.float64).ravel()))) if "t" in mat else 1e-3
        return MotionData.from_arrays(gtau * vir, qm, dt, cutoff=EMPS_CUTOFF_HZ)

    motion_fit = identify_motion(jf.models.Coulomb(**model_options(FORM_E)), emps_motion(datasets.emps_path()),
                                 key=0, mass=(50.0, 200.0), fit_offset=True, train=1.0)
    test_record = emps_motion(EMPS_TEST)
    score = motion_fit.score(test_record, init_window=20)
    base = baseline_fit(motion_fit).score(test_record, init_window=20)  # least squares, scored the same way
    say("Separate test recording, free run from its first 20 samples: RMSE {rmse:.3f} mm, FIT {fit:.1f} % "
        "(least-squares Coulomb + viscous + offset: {base:.3f} mm).",
        rmse=score["rmse_mm"], fit=score["fit_percent"], base=base["rmse_mm"])

# %%
save_claims()
