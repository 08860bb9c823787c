# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Friction from motion alone, friction compensation, and export
#
# Three things beyond the paper (`docs/algorithms.md §13.2–13.3`):
#
# 1. **Motion identification**: the friction model sits inside the mechanics
#    `m dv/dt = F_act − F_f − F_load`, `dx/dt = v`, and its parameters are fitted to the
#    measured *position* — no friction signal, no twice-differentiated position.
# 2. **Compensation**: a position loop on the rig simulator with friction feed-forward from
#    an identified fit, against no compensation and the true friction.
# 3. **Export**: the fitted model as a NumPy step function and a C header for a controller.
#
# `JAXFRIC_NOTEBOOK_BUDGET=small` (set by the tests) shrinks every budget.

# %%
import os

import jax
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np

jax.config.update("jax_enable_x64", True)  # notebooks choose; the library never does

import jaxfric
from jaxfric import compensation, models
from jaxfric.motion import MotionData, friction_step, identify_motion, simulate_motion
from jaxfric.optim import MAPSO, MAPSONMDS, NelderMead

SMALL = os.environ.get("JAXFRIC_NOTEBOOK_BUDGET") == "small"
print(f"budget: {'small' if SMALL else 'full'}")

# %% [markdown]
# ## 1. A known axis, simulated: 2.5 kg, Coulomb + viscous friction and a 3 N offset
# The forward model is one `lax.scan`: friction at the end of each step, solved by one Newton
# step (stable for stiff friction and a near-hard sign).

# %%
true = models.Coulomb(v_eps=1e-3)
box = {"Fc": (2.0, 40.0), "sigma2": (5.0, 500.0)}  # the search box: data for identify_motion
theta_true = true.from_physical(Fc=12.0, sigma2=60.0)
dt, n = 1e-3, 2000
t = np.arange(n) * dt
force = 30 * np.sin(2 * np.pi * 1.3 * t) + 12 * np.sin(2 * np.pi * 3.1 * t + 1.0)
sim = simulate_motion(friction_step(true), theta_true, 2.5, force - 3.0, dt, 0.0, 0.0)
data = MotionData.from_arrays(force, np.asarray(sim["x"]), dt)

fig, ax = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
ax[0].plot(t, force)
ax[0].set_ylabel("actuator force [N]")
ax[1].plot(t, 1e3 * np.asarray(sim["x"]))
ax[1].set_ylabel("position [mm]")
ax[1].set_xlabel("time [s]");

# %% [markdown]
# ## 2. Identify friction, mass and offset from force and position
# The default search (`docs/motion.md`): a short PSO on windows of the record, then
# Levenberg–Marquardt on multiple-shooting segments, then on the free run. `max_time` /
# `max_evals` bound it; `progress=True` shows a bar per stage.

# %%
search = jaxfric.motion.MotionSearch(particles=10, generations=8, global_window=150, horizons=(300, None),
                                      steps=(15, 25)) \
    if SMALL else None  # None: the defaults
fit = identify_motion(true, data, key=0, mass=(0.5, 10.0), fit_offset=True, box=box,
                      data_bounds=False, dtype=jnp.float64, search=search, max_time=120)
print(fit.summary())
print("truth: Fc=12, sigma2=60, mass=2.5, offset=3")
print("stages:", [(s["stage"], s["num_steps"], f"{s['J']:.3g}") for s in fit.stages])

# %% [markdown]
# Free run on the held-back 20 %, started from the state estimated there (measured
# position, filtered velocity). A new recording is scored the benchmark's way instead:
# `fit.simulate(record, init_window=20)` estimates the state from its first 20 samples only.

# %%
valid = fit.simulate_from(data, fit.n_train)
new_force = 25 * np.sin(2 * np.pi * 0.9 * t + 0.5) + 10 * np.sin(2 * np.pi * 2.3 * t)
new_x = simulate_motion(friction_step(true), theta_true, 2.5, new_force - 3.0, dt, 0.01, 0.0)["x"]
new = MotionData.from_arrays(new_force, np.asarray(new_x), dt)
print("new recording, state from its first 20 samples:", fit.score(new, init_window=20))
fig, ax = plt.subplots(1, 2, figsize=(10, 3))
ax[0].plot(t[fit.n_train:], 1e3 * data.position[fit.n_train:], "k", lw=2, label="measured")
ax[0].plot(t[fit.n_train:], 1e3 * valid["x"], label="identified model, free run")
ax[0].set_title("held-back 20 %")
ax[1].plot(t, 1e3 * new.position, "k", lw=2, label="measured")
ax[1].plot(t, 1e3 * fit.simulate(new, init_window=20)["x"], label="free run from 20 samples")
ax[1].set_title("a new recording")
for a in ax:
    a.set_xlabel("time [s]")
    a.set_ylabel("position [mm]")
    a.legend();

# %% [markdown]
# ### Choosing a model by validation
# `compare_motion` fits several models on the same data and ranks them by the held-back
# error; a richer model that predicts worse than a simpler one raises an `OverfitWarning`.

# %%
import warnings

with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always", jaxfric.motion.OverfitWarning)
    ranked = jaxfric.motion.compare_motion(
        {"coulomb": true, "stribeck": models.Stribeck(v_eps=1e-3)}, data, key=0, mass=(0.5, 10.0),
        fit_offset=True, dtype=jnp.float64,
        search=search if SMALL else jaxfric.motion.MotionSearch(generations=10))
print(ranked.table())
for w in caught:
    print("warning:", w.message)

# %% [markdown]
# ## 3. Friction compensation on the rig simulator
# A force-balance fit (static Stribeck here; ENN and LuGre in `benchmarks/motion.py`) gives
# the feed-forward along the reference velocity. The compensator sees only the fit.

# %%
from jaxfric import identify, rig

rig_data = rig.synthetic_friction_data(jax.random.key(0))
small_solver = MAPSONMDS(mapso=MAPSO(lattice_size=4, num_generations=10 if SMALL else 100),
                         nelder_mead=NelderMead(max_steps=300, max_evals=300))
stribeck = identify("stribeck", rig_data, key=0, solver=small_solver)
ref = (compensation.reference(fs=250.0, amplitude=3e-3, period=3.0, ramp_time=1.0, hold=0.2) if SMALL
       else compensation.reference())
rows, runs = compensation.compensation_study({"static (Stribeck)": stribeck}, ref=ref,
                                             substeps=2 if SMALL else 4)
print(compensation.compensation_table(rows))
compensation.plot_tracking(runs, ref);

# %% [markdown]
# ## 4. Export for a controller
# `Fit.to_numpy()` gives a pure-NumPy `f, state = step(v, state)`; `Fit.to_c_header()` the
# same step in C99 with the weights inlined.

# %%
step = stribeck.to_numpy()
state = None
for v in (0.0, 0.002, 0.004):
    f, state = step.step(v, state)
    print(f"v = {v:.3f} m/s -> F = {f:.2f} N")
print(np.max(np.abs(step.run(rig_data.velocity) - np.asarray(stribeck.predict(rig_data.velocity)))))
print(stribeck.to_c_header()[:600])
