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

SETUP_CELL = '''\
%matplotlib inline
import time

import jax

# Notebooks (like the CLI and the benchmarks) choose the precision at start-up;
# the library itself never changes JAX's configuration.
jax.config.update("jax_enable_x64", True)

import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Markdown, display

import jaxfric as jf
from jaxfric import plot'''


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
    code(SETUP_CELL + '''
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
    code(SETUP_CELL + '''
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
]


NOTEBOOKS = {
    "01_test_functions.ipynb": NB01,
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
