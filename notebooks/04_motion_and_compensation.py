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
# # 04 — Friction from motion alone, friction compensation, and export
#
# Three things beyond the paper (`docs/algorithms.md §13.2–13.3`):
#
# 1. **Motion identification**: the friction model sits inside the mechanics
#    `m dv/dt = F_act − F_f − F_load`, `dx/dt = v`, and its parameters are fitted to the
#    measured *position* — no friction signal, no twice-differentiated position.
# 2. **Compensation**: a position loop on the rig simulator with friction feed-forward from
#    an identified fit, against no compensation, the least-squares baseline and the true friction.
# 3. **Export**: the fitted model as a NumPy step function and a C header for a controller.
#
# Every number in the text is computed in the cell that shows it.
# `JAXFRIC_NOTEBOOK_BUDGET=small` (set by the tests) shrinks every budget.

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
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Markdown, display

jax.config.update("jax_enable_x64", True)  # notebooks choose; the library never does

import jaxfric as jf
from jaxfric import compensation, models, plot, rig
from jaxfric.cli.fitting import physical_form
from jaxfric.cli.spec import FitSpec
from jaxfric.identification import GradientRefinement
from jaxfric.motion import MotionData, friction_step, identify_motion, simulate_motion
from jaxfric.optim import MAPSO, MAPSONMDS, NelderMead
from jaxfric.rig.emps import idim_ls

# %% [markdown]
# Helpers (each notebook has its own copy, so that it runs alone). `say` prints a sentence made
# from measured numbers, `show` draws a figure; both keep a record (`CLAIMS`) that
# tests/test_notebooks.py checks against the outputs, with every comparison's models and the
# form the data need. Warnings print as one line, `Category: message`.

# %%
NAME = "04_motion_and_compensation"
warnings.formatwarning = lambda message, category, *args, **kwargs: f"{category.__name__}: {message}\n"
#: numbers quoted in the text that are not measured here (the paper's, and fixed settings)
CONSTANTS = [0, 2.5, 3, 12, 60, 20]
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
# ## 1. A known axis, simulated: 2.5 kg, Coulomb + viscous friction and a 3 N offset
#
# The forward model is one `lax.scan`: friction at the end of each step, solved by one Newton
# step (stable for stiff friction and a near-hard sign). The true friction is symmetric
# (Fc = 12 N, viscous 60 N·s/m) and the actuator force carries a constant 3 N offset, so the form
# these data need is a symmetric model with a fitted offset (`fit_offset=True`). The measured
# position carries sensor noise (its standard deviation is printed below); a record without
# noise would flatter every model.

# %%
true = models.Coulomb(v_eps=1e-3)
box = {"Fc": (2.0, 40.0), "sigma2": (5.0, 500.0)}  # the search box: data for identify_motion
theta_true = true.from_physical(Fc=12.0, sigma2=60.0)
dt, n = 1e-3, 2000
t = np.arange(n) * dt
NOISE = 2e-6  # position sensor noise, standard deviation [m]
noise = np.random.default_rng(0)


def measured(force, x0=0.0):
    """Position of the true axis under ``force`` (offset included), with sensor noise."""
    x = np.asarray(simulate_motion(friction_step(true), theta_true, 2.5, force - 3.0, dt, x0, 0.0)["x"])
    return x + NOISE * noise.standard_normal(x.size)


force = 30 * np.sin(2 * np.pi * 1.3 * t) + 12 * np.sin(2 * np.pi * 3.1 * t + 1.0)
data = MotionData.from_arrays(force, measured(force), dt)
say("Position noise: standard deviation {s:.4f} mm, against a motion of {r:.2f} mm peak to peak.",
    s=NOISE * 1e3, r=1e3 * np.ptp(data.position))

fig, ax = plt.subplots(2, 1, figsize=(8, 5), sharex=True, layout="constrained")
ax[0].plot(t, force, color="0.15")
ax[0].set_ylabel("actuator force [N]")
ax[1].plot(t, 1e3 * data.position, color="0.15")
ax[1].set_ylabel("measured position [mm]")
ax[1].set_xlabel("time [s]")
show(fig)

# %% [markdown]
# ## 2. Identify friction, mass and offset from force and position
#
# The default search (`docs/motion.md`): a short PSO on windows of the record, then
# Levenberg–Marquardt on multiple-shooting segments, then on the free run. `max_time` /
# `max_evals` bound it; `progress=True` shows a bar per stage.
#
# Beside it, the **least-squares baseline** of motion identification: inverse dynamics
# `F_act = M·a + Fc·sign(v) + Fv·v + F_off` solved by `numpy.linalg.lstsq` on the filtered
# velocity and its derivative (IDIM-LS, the EMPS benchmark's method, `jaxfric.rig.emps.idim_ls`),
# then simulated by the same forward model.

# %%
search = jf.motion.MotionSearch(particles=10, generations=8, global_window=150, horizons=(300, None),
                                steps=(15, 25)) if SMALL else None  # None: the defaults
fit = identify_motion(true, data, key=0, mass=(0.5, 10.0), fit_offset=True, box=box,
                      data_bounds=False, dtype=jnp.float64, search=search, max_time=120)
print(fit.summary())
p = fit.params
say("Identified: Fc = {fc:.3f} N, viscous {s2:.2f} N·s/m, mass {m:.4f} kg, offset {o:.3f} N "
    "(truth: 12, 60, 2.5 and 3).", fc=float(p["Fc"]), s2=float(p["sigma2"]), m=fit.mass, o=fit.offset)


class LSMotion:
    """The least-squares baseline in the mechanics: IDIM-LS on the training block, simulated.
    ``identify_motion`` computes the same baseline for its summary; its numbers are used
    when the fit carries them, so that the notebook and the fit's table agree."""

    def __init__(self, d, n_train, fit=None):
        got = fit.mechanics.baseline if fit is not None else None
        if got:
            self.M, self.Fc, self.Fv, self.offset = (float(got[k]) for k in ("M", "Fc", "Fv", "offset"))
        else:
            v = d.velocity[20:n_train - 20]
            a = np.gradient(d.velocity, d.dt, edge_order=2)[20:n_train - 20]
            est = idim_ls(v, a, d.net_force[20:n_train - 20])
            self.M, self.Fc, self.Fv, self.offset = est.M, est.Fc, est.Fv, est.offset
        self.model = models.Coulomb(v_eps=1e-4)
        self.theta = self.model.from_physical(Fc=self.Fc, sigma2=self.Fv)

    def run(self, force, x0, v0):
        return np.asarray(simulate_motion(friction_step(self.model), self.theta, self.M, force - self.offset, dt,
                                          x0, v0)["x"])

    def from_block(self, d, start):
        """Free run from sample ``start``, started at the measured position and filtered velocity."""
        return self.run(d.force[start:], d.position[start], d.velocity[start])

    def from_first(self, d, k=20):
        """Free run with the state from a quadratic fit of the first ``k`` positions only."""
        c = np.polyfit(np.arange(k) * dt, d.position[:k], 2)
        tk = (k - 1) * dt
        x = self.run(d.force[k - 1:], np.polyval(c, tk), np.polyval(np.polyder(c), tk))
        return np.concatenate([np.full(k - 1, np.nan), x])


ls = LSMotion(data, fit.n_train, fit)
say("Least-squares baseline: Fc = {fc:.3f} N, viscous {s2:.2f} N·s/m, mass {m:.4f} kg, offset {o:.3f} N.",
    fc=ls.Fc, s2=ls.Fv, m=ls.M, o=ls.offset)

# %% [markdown]
# Two tests: the **held-back tail** (the last 20 % of the record, free run from the state
# measured there), and **a new recording**: another force signal (0.9 and 2.3 Hz instead of 1.3
# and 3.1 Hz) with fresh noise, scored as a benchmark scores a test file —
# `fit.score(record, init_window=20)` estimates the state from its first 20 samples only. The
# figures draw the measurement as dots under the models and each model's error below; the
# last one (`jaxfric.plot.plot_position_band`) draws the motion fit's run of the new recording
# and its error inside its position band: where the error stays inside it, the fit's
# parameters and the sensor noise explain the miss. It does not hold a wrong model form, a force offset that drifts on a real drive, nor
# a start the initial-state rule gets wrong (docs/uncertainty.md, "Position band of a motion
# fit"); the cell below measures the last on this recording.

# %%
def rmse_mm(x, x_hat):
    ok = np.isfinite(x_hat)
    return 1e3 * np.sqrt(np.mean((x[ok] - x_hat[ok]) ** 2))


valid = fit.simulate_from(data, fit.n_train)["x"]
new_force = 25 * np.sin(2 * np.pi * 0.9 * t + 0.5) + 10 * np.sin(2 * np.pi * 2.3 * t)
new = MotionData.from_arrays(new_force, measured(new_force, 0.01), dt)
motion_x = {"held-back tail": {"LS baseline": ls.from_block(data, fit.n_train), "motion fit (Coulomb)": valid},
            "new recording": {"LS baseline": ls.from_first(new), "motion fit (Coulomb)": fit.simulate(new, init_window=20)["x"]}}
truth_x = {"held-back tail": data.position[fit.n_train:], "new recording": new.position}
err = {k: {m: rmse_mm(truth_x[k], x) for m, x in v.items()} for k, v in motion_x.items()}
score = fit.score(new, init_window=20)
MOTION_FORM = {"asymmetric": False, "offset": True,
               "reason": "the true friction is symmetric and the force carries a constant offset"}
for where in motion_x:
    record_comparison(f"motion, {where}", where, MOTION_FORM, motion_x[where], err[where], metric="RMSE [mm]",
                      physical={"motion fit (Coulomb)": {"asymmetric": bool(getattr(fit.model, "asymmetric", False)),
                                                         "offset": "offset" in fit.uncertainty.names}})
say("Held-back tail: RMSE {a:.4f} mm (motion fit) and {b:.4f} mm (least-squares baseline). New recording, state "
    "from its first 20 samples: {c:.4f} mm and {d:.4f} mm (fit.score: {s:.4f} mm, FIT {f:.2f} %).",
    a=err["held-back tail"]["motion fit (Coulomb)"], b=err["held-back tail"]["LS baseline"],
    c=err["new recording"]["motion fit (Coulomb)"], d=err["new recording"]["LS baseline"],
    s=score["rmse_mm"], f=score["fit_percent"])

_, band_lo, band_hi = fit.prediction_interval(new, 0.95, init_window=20)
held = np.mean(((new.position >= band_lo) & (new.position <= band_hi))[20:])
start = fit.initial_state(new.position[:20], 20)
true_v = np.asarray(simulate_motion(friction_step(true), theta_true, 2.5, new_force - 3.0, dt, 0.01, 0.0)["v"])
settled = t >= 0.1
say("The motion fit's {lvl:.0f} % position band on the new recording (fit.prediction_interval: its parameters' "
    "Newey–West spread, the noise of the 20 positions its start is fitted to, its training residuals) is "
    "{w:.4f} mm wide on average and holds {h:.1f} % of the samples. The start rule's velocity is {v0:.3f} mm/s "
    "where the true axis moves at {vt:.3f} mm/s: a quadratic through 20 positions of an axis breaking away. "
    "From {k} s on the run sits {off:.4f} mm off, a constant the viscous friction left of that start, "
    "which the band does not hold.", lvl=95, w=1e3 * np.mean((band_hi - band_lo)[20:]), h=100 * held,
    v0=1e3 * start["v0"], vt=1e3 * true_v[19], k=0.1,
    off=1e3 * np.mean((new.position - motion_x["new recording"]["motion fit (Coulomb)"])[settled]))

fig, ax = plt.subplots(2, 2, figsize=(12, 5.5), sharex="col", height_ratios=[1.5, 1], layout="constrained")
for j, (where, xs) in enumerate(motion_x.items()):
    tt = t[fit.n_train:] if where == "held-back tail" else t
    x = truth_x[where]
    ax[0, j].plot(tt[::10], 1e3 * x[::10], ".", ms=3, color="0.3", label="measured (every 10th sample)")
    for label, xh in xs.items():
        look = {"ls": "-", **plot.style(label)}
        ax[0, j].plot(tt, 1e3 * xh, lw=1.0, label=label, **look)
        ax[1, j].plot(tt, 1e3 * (x - xh), lw=0.8, label=label, **look)
    ax[0, j].set_title(where)
    ax[0, j].set_ylabel("position [mm]")
    ax[1, j].set_ylabel("error [mm]")
    ax[1, j].set_xlabel("time [s]")
    for a in ax[:, j]:
        a.grid(alpha=0.3)
ax[0, 1].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0))
show(fig, comparison="motion, held-back tail")

show(plot.plot_position_band(fit, new, label="motion fit (Coulomb)"))

# %% [markdown]
# ### Choosing a model by validation
#
# `compare_motion` fits several models on the same data and ranks them by a judge, here the
# error on the held-back tail (`judge="tail"`; the default, `"gated"`, judges many short free runs of
# the models whose blocked folds beat least squares'); a
# richer model that predicts worse than a simpler one raises an `OverfitWarning`. The tail shares
# the record's excitation: it ranks the models on motion like the training part, not on new
# motion (docs/motion.md measures the judges on new excitation). Both models
# here are symmetric with a fitted offset, the form these data need. A difference smaller than the position noise cannot be told apart from it, so the cell
# picks the simplest model within that margin of the best, and says which.

# %%
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always", jf.motion.OverfitWarning)
    ranked = jf.motion.compare_motion(
        {"Coulomb": true, "Stribeck": models.Stribeck(v_eps=1e-3)}, data, key=0, mass=(0.5, 10.0),
        fit_offset=True, dtype=jnp.float64, judge="tail",
        search=search if SMALL else jf.motion.MotionSearch(generations=10))
display(Markdown(ranked.table()))
for w in caught:
    print(f"{w.category.__name__}: {w.message}")
rm = {k: ranked.fits[k].metrics["valid"]["rmse_mm"] for k in ranked.fits}
npar = {k: ranked.fits[k].metrics["num_params"] for k in ranked.fits}
best = min(rm, key=rm.get)
tied = [k for k in rm if rm[k] - rm[best] <= NOISE * 1e3]
pick = min(tied, key=lambda k: (npar[k], rm[k]))
say("Validation RMSE on the held-back tail: " + "; ".join(f"{k} {{rm_{i}:.6f}} mm" for i, k in enumerate(rm))
    + ". Lowest: {best}. Within the position noise ({s:.4f} mm) of it: {tied}. Chosen, the simplest of those: "
    "{pick}.", best=best, s=NOISE * 1e3, tied=", ".join(tied), pick=pick,
    **{f"rm_{i}": v for i, v in enumerate(rm.values())})

# %% [markdown]
# ## 3. Friction compensation on the rig simulator
#
# A force-balance fit gives the feed-forward along the reference velocity; the compensator sees
# only the fit. The rig's friction is not symmetric, so the static model is fitted in the form the
# data need (`--form auto`), and the least-squares baseline compensates beside it. ENN and
# LuGre compensators are in `benchmarks/motion.py`.

# %%
rig_data = rig.synthetic_friction_data(jax.random.key(0))
FORM_R = form_of(rig_data)
say("Form: {reason}.", **FORM_R)
small_solver = MAPSONMDS(mapso=MAPSO(lattice_size=4, num_generations=10 if SMALL else 100),
                         nelder_mead=NelderMead(max_steps=300, max_evals=300))
stribeck_model = models.Stribeck(**model_options(FORM_R))
stribeck = jf.identify(stribeck_model, rig_data, key=0, solver=small_solver)
widen = {d["box_key"]: tuple(d["widen_to"]) for d in stribeck.diagnostics["on_bound"] if not d["at_limit"]}
if widen:  # the box, not the data, stopped these: fit again with the wider ranges identify suggests
    say("The BoundWarning above: Stribeck's {names} ended on an edge of the search box, so it is fitted again "
        "with the wider range the warning names.",
        names=", ".join(d["shown"] for d in stribeck.diagnostics["on_bound"] if not d["at_limit"]))
    stribeck = jf.identify(stribeck_model, rig_data, key=0, solver=small_solver, box=widen)
parameter_table(stribeck)
for d in stribeck.diagnostics["on_bound"]:
    say("Stribeck's {name} = {value:.4g} is on the {side} edge of its search range: {why}", name=d["shown"],
        value=float(d["value"]), side=d["side"],
        why=("the data ask for no static peak above the sliding level (Fs/Fc = 1 is the least the model allows); "
             "the exported step function below carries that value" if d["at_limit"] else
             "the widened range did not hold it either; the value is the box's, and the exported step function "
             "below carries it"))
if not stribeck.diagnostics["on_bound"]:
    say("No Stribeck parameter ended on a bound of its search box.")

# %%
v_r, f_r, n_r = np.asarray(rig_data.velocity), np.asarray(rig_data.friction), rig_data.n_train
baseline = LSBaseline(v_r[:n_r], f_r[:n_r])
baseline.dt = rig_data.dt  # the compensator reads the fit's sample time
COMP = {"LS baseline": baseline, plot.fit_label(stribeck): stribeck}
ref = (compensation.reference(fs=250.0, amplitude=3e-3, period=3.0, ramp_time=1.0, hold=0.2) if SMALL
       else compensation.reference())
rows, runs = compensation.compensation_study(COMP, ref=ref, substeps=2 if SMALL else 4)
display(Markdown(compensation.compensation_table(rows)))
rms = {r["compensation"]: r["rms_mm"] for r in rows}
record_comparison("compensation", "tracking on the rig simulator, reference of compensation.reference()", FORM_R,
                  COMP, {k: rms[k] for k in COMP}, metric="tracking RMS [mm]")
say("Tracking RMS error: {none:.4f} mm without compensation, {ls:.4f} mm with the least-squares baseline, "
    "{st:.4f} mm with the Stribeck fit, {ideal:.4f} mm with the true friction.", none=rms["none"],
    ls=rms["LS baseline"], st=rms[plot.fit_label(stribeck)], ideal=rms["ideal (true friction)"])

fig, ax = plt.subplots(2, 1, figsize=(10, 6), sharex=True, layout="constrained")
first = next(iter(runs.values()))
ax[0].plot(first["t"], 1e3 * ref.v, color="0.15")
ax[0].set_ylabel("reference velocity [mm/s]")
for label, run in runs.items():
    look = {"ls": "-", **plot.style("no compensation" if label == "none" else label)}
    ax[1].plot(run["t"], 1e3 * run["error"], lw=1.0, label="no compensation" if label == "none" else label, **look)
ax[1].set_ylabel("tracking error [mm]")
ax[1].set_xlabel("time [s]")
ax[1].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0))
for a in ax:
    a.grid(alpha=0.3)
show(fig, comparison="compensation")

# %% [markdown]
# ## 4. Export for a controller
#
# `Fit.to_numpy()` gives a pure-NumPy `f, state = step(v, state)`; `Fit.to_c_header()` the
# same step in C99 with the parameters inlined. The exported Stribeck fit carries the values in
# the table above, bound hits included (the cells above say which).

# %%
step = stribeck.to_numpy()
state = None
for v in (0.0, 0.002, 0.004):
    f, state = step.step(v, state)
    print(f"v = {v:.3f} m/s -> F = {f:.2f} N")
gap = np.max(np.abs(step.run(rig_data.velocity) - np.asarray(stribeck.predict(rig_data.velocity))))
say("The NumPy step function matches the fit's own prediction on the record to {g:.2e} N.", g=gap)
if "F_off" in stribeck.params:
    say("At standstill (v = 0) the step returns the offset alone, F_off = {o:.2f} N, a value these data do not "
        "determine (the table above): a controller should not trust this feed-forward near zero velocity.",
        o=float(stribeck.params["F_off"]))
print(stribeck.to_c_header()[:600])

# %%
save_claims()
