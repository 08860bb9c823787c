"""Write the example notebooks (without outputs) from the cell sources below.

    python notebooks/build_notebooks.py        # rewrites notebooks/*.ipynb

Edit the cells here, not in the .ipynb files, so the notebooks stay reviewable as
plain Python and are committed without outputs. ``tests/test_notebooks.py`` runs
every notebook with ``JAXFRIC_NOTEBOOK_BUDGET=small``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

HERE = Path(__file__).resolve().parent

BUDGET_CELL = '''\
import os

# "small" (set by the test suite) runs in seconds with tiny budgets; anything else gives
# a budget worth looking at (a few minutes on a laptop).
BUDGET = os.environ.get("JAXFRIC_NOTEBOOK_BUDGET", "full").strip().lower()
SMALL = BUDGET == "small"
print(f"budget: {BUDGET}")'''

SETUP_HEAD = '''\
%matplotlib inline
import time

import jax
'''

X64_LINES = '''
# Notebooks (like the CLI and the benchmarks) choose the precision at start-up;
# the library itself never changes JAX's configuration.
jax.config.update("jax_enable_x64", True)
'''

F32_LINES = '''
# float32 (JAX's default), as the command line uses: the rollouts are twice as fast and
# float32 LuGre/ENN rollouts track float64 to about 1e-6 (tests/test_models_lugre.py).
'''

SETUP_TAIL = '''
import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Markdown, display

import jaxfric as jf
from jaxfric import plot'''


def setup(x64: bool) -> str:
    return SETUP_HEAD + (X64_LINES if x64 else F32_LINES) + SETUP_TAIL


SOLVER_CELL = '''
def solver_for(name):
    """The small budget (the same solver as `jaxfric --quick`), else None: the library default
    (MAPSO-NMDS sized for the model, see jaxfric.identify.default_solver)."""
    if SMALL:
        return jf.mapso_nmds(lattice_size=8 if name.startswith("elman") else 5,
                             num_generations=3, nm_max_evals=200)
    return None'''


def md(text: str):
    return new_markdown_cell(text.strip("\n"))


def code(text: str):
    return new_code_cell(text.strip("\n"))


# ------------------------------------------------------------------------- 01
NB01 = [
    md("""
# 01 — MAPSO–NMDS against PSO on the test functions (the paper's Table 1)

The paper first checks its optimiser on five benchmark functions: MAPSO–NMDS (a multi-agent
particle swarm on a torus, then Nelder–Mead from the best agent) against plain PSO. Its claim
(ALGORITHMS.md §12, item 10): MAPSO–NMDS reaches lower means and variances, "mostly equal to
zero", but takes longer.

Here every function gets `RUNS` independent runs per solver in **one vmapped call**
(`jaxfric.minimise_many`), and PSO receives the same number of function evaluations as
MAPSO–NMDS used. The full table with 30 runs at D = 30 is `jaxfric bench table1`
(or `python benchmarks/table1.py`)."""),
    code(BUDGET_CELL),
    code(setup(x64=True) + '''
from jaxfric import functions as F'''),
    md("""
## The test functions

Each is `f(x)` on a 1-D array of any length; `jaxfric.functions.REGISTRY` holds the
standard box and the known minimum. "Schwefel" is Schwefel 2.22 (the paper says every
function but Rosenbrock has its minimum 0 at the origin)."""),
    code('''
rows = ["| function | box (per coordinate) | minimum f | at x_i = |", "|---|---|---|---|"]
for name in F.PAPER_TABLE1:
    t = F.get(name)
    lo, hi = t.bounds(2)
    rows.append(f"| {name} | [{float(lo[0]):g}, {float(hi[0]):g}] | {t.f_min:g} | {t.minimiser_value:g} |")
display(Markdown("\\n".join(rows)))'''),
    md("""
## Budget

`small` is for the test suite: a 5-dimensional problem, 3 runs, 20 MAPSO generations and two
functions, so that compilation dominates. The default budget runs all five functions at
D = 30."""),
    code('''
if SMALL:
    DIM, RUNS, GENERATIONS, FUNCTIONS = 5, 3, 20, ("sphere", "griewank")
else:
    DIM, RUNS, GENERATIONS, FUNCTIONS = 30, 10, 300, F.PAPER_TABLE1
print(f"D = {DIM}, {RUNS} runs, MAPSO generations G = {GENERATIONS}, functions: {', '.join(FUNCTIONS)}")'''),
    md("""
## Run both solvers

Each batch is run twice: the first call includes compilation, the second is the run alone.
PSO gets 25 particles and as many generations as needed to match the largest evaluation
count of the MAPSO–NMDS runs."""),
    code('''
def timed(fn_name, solver, keys):
    bounds, obj = F.get(fn_name).bounds(DIM), F.objective(fn_name)
    t0 = time.perf_counter()
    jax.block_until_ready(jf.minimise_many(obj, solver, bounds, keys=keys))
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    sol = jax.block_until_ready(jf.minimise_many(obj, solver, bounds, keys=keys))
    run = time.perf_counter() - t0
    return sol, max(first - run, 0.0), run


keys = jax.random.split(jax.random.key(2017), RUNS)
results, table = {}, []
for name in FUNCTIONS:
    hybrid, c1, r1 = timed(name, jf.mapso_nmds(num_generations=GENERATIONS), keys)
    budget = int(np.max(np.asarray(hybrid.stats["num_evals"])))
    pso, c2, r2 = timed(name, jf.PSO(num_particles=25, num_generations=max(1, budget // 25 - 1)), keys)
    results[name] = {"MAPSO-NMDS": hybrid, "PSO": pso}
    for label, sol, c, r in (("MAPSO-NMDS", hybrid, c1, r1), ("PSO", pso, c2, r2)):
        f = np.asarray(sol.f, dtype=float)
        table.append(dict(function=name, solver=label, mean=f.mean(), variance=f.var(ddof=1) if f.size > 1 else 0.0,
                          best=f.min(), worst=f.max(), evals=int(np.mean(np.asarray(sol.stats["num_evals"]))),
                          compile_s=c, run_s=r))
    print(f"{name}: done")'''),
    code('''
lines = ["| function | solver | mean | variance | best | worst | evals/run | compile [s] | batch [s] |",
         "|---|---|---|---|---|---|---|---|---|"]
for r in table:
    lines.append(f"| {r['function']} | {r['solver']} | {r['mean']:.3e} | {r['variance']:.3e} | {r['best']:.3e} | "
                 f"{r['worst']:.3e} | {r['evals']} | {r['compile_s']:.1f} | {r['run_s']:.2f} |")
display(Markdown("\\n".join(lines)))'''),
    code('''
display(plot.plot_table1(table, title=f"Final value after an equal budget (D = {DIM}, {RUNS} runs)"))'''),
    md("""
## Convergence

Best value against function evaluations: the median over the runs, with the band from the
best to the worst run. The dotted line is where Nelder–Mead takes over from the swarm."""),
    code('''
for name, sols in results.items():
    display(plot.plot_convergence(sols, title=f"{name}, D = {DIM}", ylabel="best f"))'''),
    md("""
## What to look for

* MAPSO–NMDS should end lower than PSO on every function at the same number of evaluations;
  on Sphere, Schwefel 2.22 and Ackley it typically reaches 1e-8 or below (the paper's "mostly
  equal to zero"), Griewank sometimes stalls in a side basin.
* PSO is cheaper per evaluation: the paper's "MAPSO–NMDS is slower" is about wall time.
* With the small budget the numbers are only a smoke test."""),
]

# ------------------------------------------------------------------------- 02
NB02 = [
    md("""
# 02 — Friction identification, end to end (the paper on the simulated rig)

The paper identifies the friction of a low-speed hydraulic cylinder with an Elman recurrent
network (ENN) whose 180 weights are found by MAPSO followed by Nelder–Mead (MAPSO–NMDS), and
compares it with a LuGre model fitted the same way (ALGORITHMS.md §1, §11). Its rig data are
not public, so jaxfric simulates a press cylinder whose seal friction is richer than LuGre
(§7), measures it with noisy sensors, and runs the paper's pipeline:

1. rig data: piston position, two chamber pressures and the load, 2000 samples at 128 Hz;
2. friction from the force balance after a 5 Hz zero-phase Butterworth filter (paper eq. 31);
3. the neuron study (N = 20, 30, 40 in the paper);
4. ENN (N = 30) against LuGre: MSE %, MAX and number of parameters (Table 4), figures like the
   paper's 11 and 12.

`jaxfric demo` on the command line does steps 1, 2 and 4 and writes a report."""),
    code(BUDGET_CELL),
    code(setup(x64=False) + """
from jaxfric import report, rig"""),
    code(SOLVER_CELL),
    md("""
## 1. Rig data

`rig.simulate` integrates the cylinder, valve, PI position controller and seal friction at
4 kHz and samples the sensors at 128 Hz, with noise and quantisation. Besides the measured
channels the record holds the ground truth (true velocity and friction), which a real rig
never gives; we use it only to check the pipeline."""),
    code("""
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
plt.show()"""),
    md("""
## 2. Friction from the force balance

`estimate_friction` filters every channel (Butterworth, 4th order, 5 Hz, zero phase),
differentiates the position twice and solves the force balance
`F_f = p1·A1 − p2·A2 − F_L − m·a`. The first 1600 samples are for estimation, the last 400
for validation (the paper's split). Left: the paper's Figs 9 and 10. Right: what the
pipeline gets wrong against the true friction (filter lag at the reversals)."""),
    code("""
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
display(plot.plot_friction_velocity(data))"""),
    md("""
## 3. How many neurons?

The paper tried N = 20, 30 and 40 hidden neurons (normalised MSE 0.3277 %, 0.2632 % and
0.2377 %) and kept 30, "with 180 internal connections" (6 parameters per neuron). Every fit
below uses the same data and the same optimiser key; `jf.identify` returns a `Fit` with
metrics on the training and validation windows (`fit.summary()` prints them)."""),
    code("""
NEURONS = (5, 30) if SMALL else (20, 30, 40)
study = {}
for n in NEURONS:
    study[n] = jf.identify("elman", data, solver=solver_for("elman"), key=fit_key, model_options={"neurons": n})
    m = study[n].metrics
    print(f"N = {n:2d}: {study[n].num_params:3d} parameters, MSE % train {m['train']['mse_percent']:.4f}, "
          f"valid {m['valid']['mse_percent']:.4f}  ({study[n].timings['total_s']:.1f} s)")"""),
    code("""
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
plt.show()"""),
    md("""
## 4. ENN against LuGre

LuGre has six parameters (σ0, σ1, σ2, Fc, Fs, vs), searched in log-space where they span
decades, in ranges centred on the data's friction level and speed. The paper reports LuGre
above 5 % MSE and the ENN 95.6 % lower."""),
    code("""
enn = study[30]
lugre = jf.identify("lugre", data, solver=solver_for("lugre"), key=fit_key)
print(lugre.summary())
fits = {"elman": enn, "lugre": lugre}
rows = report.comparison_rows(fits, data)
display(Markdown(report.markdown_table(rows)))
reduction = 100 * (1 - enn.metrics["valid"]["mse_percent"] / lugre.metrics["valid"]["mse_percent"])
word = "below" if reduction >= 0 else "above"
print(f"ENN validation MSE is {abs(reduction):.1f} % {word} LuGre's (paper: 95.6 % below)")"""),
    md("""
Measured against estimated friction (the paper's Figs 11 and 12), the error curves, and the
optimiser's progress: MAPSO's generations, then Nelder–Mead from the best agent (dotted
line)."""),
    code("""
display(plot.plot_fit(enn, data, title="ENN (30 neurons): measured and estimated friction (Fig. 11)"))
display(plot.plot_fit(lugre, data, title="LuGre: measured and estimated friction (Fig. 12)"))
display(plot.plot_error({"ENN (30 neurons)": enn, "LuGre": lugre}, data))
display(plot.plot_convergence({"ENN (30 neurons)": enn, "LuGre": lugre},
                              ylabel="best objective J (each model's own cost)"))"""),
    md("""
## 5. A fresh record, a saved model

A fit is a file: `fit.save(path)` and `jf.load_fit(path)` (or `jaxfric predict` on the
command line). Here the saved ENN predicts friction on a new simulated record (another noise
key) that it has never seen."""),
    code("""
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
assert np.array_equal(np.asarray(loaded.predict(data.velocity)), np.asarray(enn.predict(data.velocity)))"""),
]


# ------------------------------------------------------------------------- 03
NB03 = [
    md("""
# 03 — Real recordings: pneumatic piston-seal friction

Measured friction of 3D-printed pneumatic cylinders with five piston seals at 1, 3, 5 and
7 bar (TU Delft, Zillen 2021, CC0; see `SOURCE.md` next to the data). It is not the paper's
hydraulic press, but it is real cylinder friction recorded the same way: position, chamber
pressure and load-cell force, from which friction follows by a force balance.

The data stay outside the repository. Set `JAXFRIC_PNEUMATIC_DATA` to the
`pneumatic_seal_friction` folder; otherwise the notebook looks in
`../../shared/data/pneumatic_seal_friction` relative to itself, and skips (with a message)
when the data are not there."""),
    code(BUDGET_CELL),
    code(setup(x64=False) + '''
import csv
import glob
import warnings
from pathlib import Path

from jaxfric import rig'''),
    code('''
DATA = Path(os.environ.get("JAXFRIC_PNEUMATIC_DATA", "../../shared/data/pneumatic_seal_friction"))
HAVE_DATA = (DATA / "raw").is_dir()
if HAVE_DATA:
    print(f"data: {DATA.resolve()}")
else:
    print(f"SKIPPED: no pneumatic_seal_friction data at {DATA.resolve()}; "
          "set JAXFRIC_PNEUMATIC_DATA to the folder to run this notebook.")'''),
    md("""
## From raw channels to friction

Raw files are whitespace-separated: time [ms], position [mm], chamber pressure [bar] and
load-cell force [N] in columns 0, 4, 5 and 6. The time stamps are irregular (about 100 Hz
with gaps), so `load_measurements` resamples them to a uniform grid. The pipeline then
low-pass filters every channel (zero-phase Butterworth, 5 Hz), differentiates the position and
applies the force balance of ALGORITHMS.md §7 with one pressurised chamber and no inertia:
`F_f = F_loadcell − p·A` (the load cell pushes towards +x, hence `load` scale −1)."""),
    code('''
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
          f"{next(iter(records.values())).n_samples} samples")'''),
    md("""
## Coulomb level against pressure

The Coulomb level is half the difference between the mean friction while extending and while
retracting (faster than 3 mm/s). It should grow with pressure and agree with the authors'
`friction_summary.csv` to within a few percent."""),
    code('''
if HAVE_DATA:
    summary = {r["file"]: r for r in csv.DictReader(open(DATA / "friction_summary.csv"))}
    levels = {}
    lines = ["| file | Coulomb, jaxfric [N] | Coulomb, summary [N] | difference |", "|---|---|---|---|"]
    for name, data in records.items():
        lev = rig.coulomb_levels(np.asarray(data.velocity), np.asarray(data.friction), 3e-3)
        ref = float(summary[name]["coulomb_halfrange_N"])
        levels[name] = lev.halfrange
        lines.append(f"| {name} | {lev.halfrange:.2f} | {ref:.2f} | {100 * (lev.halfrange / ref - 1):+.1f} % |")
    display(Markdown("\\n".join(lines)))

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
    plt.show()'''),
    md("""
## One record up close

O-ring at 3 bar: the figures the command line also draws. Friction flips sign at each
reversal and sits near ±F_c while sliding; the transitions are where dynamic models (LuGre,
the Elman network) differ from a static map."""),
    code('''
if HAVE_DATA:
    name = "O-ring_3bar.csv" if "O-ring_3bar.csv" in records else next(iter(records))
    full = records[name]
    display(plot.plot_data(full, title=f"{name}: velocity and friction"))
    display(plot.plot_friction_velocity(full, title=f"{name}: friction against velocity"))'''),
    md("""
## Identifying the seal friction

A 20 s stretch (2000 samples, like the paper's record) of O-ring at 3 bar: the first 1600
samples train, the last 400 validate. The Elman network and LuGre are fitted exactly as on the
simulated rig."""),
    code(SOLVER_CELL),
    code("""
if HAVE_DATA:
    seg = slice(500, 2500)
    v, f = np.asarray(full.velocity)[seg], np.asarray(full.friction)[seg]
    data = rig.FrictionData.from_arrays(v, f, float(full.dt), n_train=1600)
    fits = {}
    for model, opts in (("lugre", None), ("elman", {"neurons": 30})):
        fits[model] = jf.identify(model, data, solver=solver_for(model), key=jax.random.key(0),
                                  model_options=opts)
        print(fits[model].summary(), "\\n")
    from jaxfric import report
    display(Markdown(report.markdown_table(report.comparison_rows(fits, data))))
    for fit in fits.values():
        display(plot.plot_fit(fit, data))
    display(plot.plot_error(fits, data))"""),
]


NOTEBOOKS = {
    "01_test_functions.ipynb": NB01,
    "02_friction_identification.ipynb": NB02,
    "03_real_recordings.ipynb": NB03,
}


def build(names=None) -> list[Path]:
    """Write the notebooks (all, or those named) and return their paths."""
    written = []
    for name, cells in NOTEBOOKS.items():
        if names and name not in names:
            continue
        nb = new_notebook(cells=cells, metadata={
            "kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"},
            "language_info": {"name": "python"},
        })
        nbformat.validate(nb)
        path = HERE / name
        nbformat.write(nb, path)
        written.append(path)
    return written


if __name__ == "__main__":
    for p in build(sys.argv[1:]):
        print(f"wrote {p}")
