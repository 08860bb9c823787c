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
# # 05 — Your own CSV file: load, compare, export
#
# The path from a recording of your own to a model a controller can use:
#
# 1. **load** the raw channels from a CSV file (position, chamber pressures, load; any units);
# 2. **friction** from the force balance, with your cylinder's bore, rod and moving mass;
# 3. **form**: whether the physical models need direction-dependent levels and an offset;
# 4. **compare** on the held-back tail: the least-squares baseline, physical models in the
#    data's form, the Elman network;
# 5. **export** the chosen model: a saved fit, a NumPy step function and a C header;
# 6. the same from the command line, `jaxfric identify`.
#
# The example input is written by the rig simulator into a temporary folder, in the units a
# data logger might use (ms, mm, bar, kN). Point `CSV` at your own file (and change `COLUMNS`,
# `SCALE` and the cylinder below) to run it on yours. Every number in the text is computed in
# the cell that shows it.

# %%
import os

BUDGET = os.environ.get("JAXFRIC_NOTEBOOK_BUDGET", "full").strip().lower()
SMALL = BUDGET == "small"
print(f"budget: {BUDGET}")

# %%
# %matplotlib inline
import json
import warnings
from pathlib import Path

import jax
import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Markdown, display

import jaxfric as jf
from jaxfric import plot, rig
from jaxfric.cli.fitting import physical_form
from jaxfric.cli.spec import FitSpec
from jaxfric.identification import GradientRefinement

# %% [markdown]
# Helpers (each notebook has its own copy, so that it runs alone). `say` prints a sentence made
# from measured numbers, `show` draws a figure; both keep a record (`CLAIMS`) that
# tests/test_notebooks.py checks against the outputs, with every comparison's models and the
# form the data need. Warnings print as one line, `Category: message`.

# %%
NAME = "05_your_own_csv"
warnings.formatwarning = lambda message, category, *args, **kwargs: f"{category.__name__}: {message}\n"
#: numbers quoted in the text that are not measured here (the paper's, and fixed settings)
CONSTANTS = [80, 20, 5, 30]
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
# ## The example file
#
# A simulated press cylinder (`rig.Rig()`), driven by its default excitation, recorded at
# 128 Hz and written as a CSV file with a header: time in ms, position in mm, pressures in bar,
# load in kN. Replace this cell by `CSV = Path("your_file.csv")`.

# %%
import tempfile

folder = Path(tempfile.mkdtemp(prefix="jaxfric-csv-"))
CSV = folder / "my_cylinder.csv"
r = rig.Rig()
rec = rig.simulate(r, jax.random.key(7))
table = np.column_stack([np.asarray(rec.t) * 1e3, np.asarray(rec.x) * 1e3, np.asarray(rec.p1) / 1e5,
                         np.asarray(rec.p2) / 1e5, np.asarray(rec.load) / 1e3])
np.savetxt(CSV, table, delimiter=",", header="time_ms,pos_mm,p_cap_bar,p_rod_bar,load_kN", comments="",
           fmt="%.10g")
print(CSV.name, "first lines:")
print("\n".join(CSV.read_text().splitlines()[:4]))

# %% [markdown]
# ## 1–2. Load the channels, compute the friction
#
# `rig.load_measurements` maps your columns (by header name or 0-based index) to the channels
# `t, x, p1, p2, load` and scales them to SI units; irregular time stamps are resampled (with a
# warning). `rig.estimate_friction` filters (zero-phase Butterworth, 5 Hz), differentiates the
# position and solves the force balance `F_f = p1·A1 − p2·A2 − F_L − m·a` with your cylinder's
# bore, rod and moving mass. The first 80 % train, the last 20 % are held back.

# %%
COLUMNS = {"t": "time_ms", "x": "pos_mm", "p1": "p_cap_bar", "p2": "p_rod_bar", "load": "load_kN"}
SCALE = {"t": 1e-3, "x": 1e-3, "p1": 1e5, "p2": 1e5, "load": 1e3}      # ms, mm, bar, kN -> SI
CYLINDER = {"bore": r.cylinder.bore, "rod": r.cylinder.rod, "mass": r.cylinder.mass}  # [m], [m], [kg]

meas = rig.load_measurements(CSV, COLUMNS, scale=SCALE)
data = rig.estimate_friction(meas, **CYLINDER)
say("Loaded {n} samples at {fs:.0f} Hz; {tr} train, {va} held back.", n=data.n_samples, fs=1 / data.dt,
    tr=data.n_train, va=data.n_samples - data.n_train)
show(plot.plot_data(data, title=f"{CSV.name}: velocity and friction"))

# %% [markdown]
# ## 3. Which form?
#
# `jaxfric identify --form auto` compares the mean friction while sliding in each direction;
# when they differ by more than 5 % of the level, every physical model gets direction-dependent
# levels and an offset (`asymmetric=True, offset=True`).

# %%
FORM = form_of(data)
say("Form: {reason}.", **FORM)

# %% [markdown]
# ## 4. Compare on the held-back tail
#
# The least-squares baseline (asymmetric Coulomb + viscous + offset by `numpy.linalg.lstsq`),
# LuGre in the data's form and the Elman network, each fitted on the training window with
# jaxfric's default pipeline (the small budget cuts every search short). Add any model of
# `jf.models.available()` to the loop.

# %%
v, f, n = np.asarray(data.velocity), np.asarray(data.friction), data.n_train
fits = {"LS baseline": LSBaseline(v[:n], f[:n])}
for name in ("lugre", "elman"):
    opts = model_options(FORM) if name != "elman" else {}
    fit = jf.identify(name, data, key=0, model_options=opts or None, **budget(name, FORM))
    widen = {d["box_key"]: tuple(d["widen_to"]) for d in fit.diagnostics["on_bound"] if not d["at_limit"]}
    if widen:  # the box, not the data, stopped these: fit again with the wider ranges identify suggests
        say("The BoundWarning above: {model}'s {names} ended on an edge of the search box, so it is fitted again "
            "with the wider range the warning names.", model=plot.fit_label(fit),
            names=", ".join(d["shown"] for d in fit.diagnostics["on_bound"] if not d["at_limit"]))
        fit = jf.identify(name, data, key=0, model_options=opts or None, box=widen, **budget(name, FORM))
    fits[plot.fit_label(fit)] = fit
mse = {k: nmse(f[n:], plot.predict_on(c, data)[n:]) for k, c in curves(fits, data).items()}
record_comparison("your CSV, held-back tail", f"held-back tail: last {data.n_samples - n} samples", FORM, fits, mse)
rows = ["| model | parameters | fitted by | MSE % held-back tail |", "|---|---|---|---|"]
for k, c in fits.items():
    rows.append(f"| {k} | {c.num_params if isinstance(c, jf.Fit) else 5} | "
                f"{stages_text(c) if isinstance(c, jf.Fit) else 'numpy.linalg.lstsq'} | {mse[k]:.3f} |")
display(Markdown("\n".join(rows)))
physical = {k: c for k, c in fits.items() if isinstance(c, jf.Fit) and not c.model.needs_scaling}
CHOSEN = min(physical, key=mse.get)
best = min(mse, key=mse.get)
pct, word = below(lead("your CSV, held-back tail", CHOSEN, "LS baseline"))
say("Lowest error on the held-back tail: {best} ({m:.3f} %). The best physical model, {chosen}, is {pct:.1f} % "
    "{word} the baseline ({b:.3f} %); it is the one exported below (a physical model exports as a few "
    "numbers and its parameters carry intervals).", best=best, m=mse[best], chosen=CHOSEN, pct=pct, word=word,
    b=mse["LS baseline"])
show(plot.plot_models(curves(fits, data), data, title="Held-back tail: measured and every model"),
     comparison="your CSV, held-back tail")
show(plot.plot_friction_velocity(data, curves(fits, data), title="Friction against velocity, with every model"),
     comparison="your CSV, held-back tail")

# %% [markdown]
# The chosen model's parameters: an interval where the data determine the parameter, none
# where they do not (and why), and what each bound hit means.

# %%
chosen = fits[CHOSEN]
parameter_table(chosen)
for d in chosen.diagnostics["on_bound"]:
    say("{name} = {value:.4g} is on the {side} edge of its search range: {why}", name=d["shown"],
        value=float(d["value"]), side=d["side"],
        why=("the data ask for less than the model can express (for Fs/Fc = 1: no static peak above the sliding "
             "level); the exported model carries that value" if d["at_limit"] else
             "even the widened range did not hold it, so the value is the box's, not a measurement; the exported "
             "model carries it"))
if not chosen.diagnostics["on_bound"]:
    say("No parameter of {chosen} ended on a bound of its search box.", chosen=CHOSEN)

# %% [markdown]
# ## 5. Export
#
# `fit.save` writes a file `jf.load_fit` (and `jaxfric predict`) reads back; `fit.to_numpy()`
# is a dependency-free step function; `fit.to_c_header(path)` writes the same step in C99.

# %%
saved = folder / "friction_model.npz"
chosen.save(saved)
header = folder / "friction_model.h"
chosen.to_c_header(header)
step = jf.load_fit(saved).to_numpy()
gap = np.max(np.abs(step.run(data.velocity) - np.asarray(chosen.predict(data.velocity))))
say("Saved {a} and {b}; the NumPy step function of the reloaded fit matches the fit to {g:.2e} N.",
    a=saved.name, b=header.name, g=gap)
print("\n".join(header.read_text().splitlines()[:14]))

# %% [markdown]
# ## 6. The same from the command line
#
# `jaxfric identify` takes the same file, columns, units and cylinder, chooses the form
# (`--form auto`), fits the models and writes a report (`report.md`, `results.json`, figures and
# the fits in `models/`). `--quick` keeps this example short and `--model coulomb` fits one
# model; leave both out for a real fit of the ENN and LuGre.

# %%
import shlex
import subprocess
import sys

cmd = [sys.executable, "-m", "jaxfric", "identify", CSV.name, "--time-col", "time_ms", "--time-unit", "ms",
       "--x-col", "pos_mm", "--x-unit", "mm", "--p1-col", "p_cap_bar", "--p2-col", "p_rod_bar",
       "--pressure-unit", "bar", "--load-col", "load_kN", "--load-unit", "kN",
       "--bore", f"{CYLINDER['bore']:g}", "--rod", f"{CYLINDER['rod']:g}", "--mass", f"{CYLINDER['mass']:g}",
       "--model", "coulomb", "--quick", "--quiet", "--out", "report"]
print("jaxfric " + " ".join(shlex.quote(c) for c in cmd[3:]))
if SMALL:  # a second process and its compilation: left to tests/test_cli.py under the small budget
    print("(not run with the small budget)")
else:
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=folder)   # in the file's folder
    out = folder / "report"
    print(done.stdout[-1500:] or done.stderr[-1500:])
    say("The command exited with status {rc} and wrote {k} files into the report folder.", rc=done.returncode,
        k=sum(1 for p in out.rglob("*") if p.is_file()))

# %%
save_claims()
