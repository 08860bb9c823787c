"""jaxfric's Nelder–Mead against SciPy's adaptive Nelder–Mead on random starts.

Shifted sphere ``Σ(x − s)²`` and Rosenbrock ``rosen(x − s + 1)``, n = 4, 8, 12; the shift
``s ~ U(−2, 2)^n`` and ``--starts`` starts ``x0 ~ s + U(−3, 3)^n`` from fixed seeds. Both solvers
get the same start, first simplex (fminsearch's rule), evaluation budget (``--budget`` × n) and
stopping rule (every vertex within ``xatol``, every value within ``fatol`` of the best); a run
is *solved* below ``--solved``. SciPy's ``adaptive=True`` against ``jaxfric.NelderMead`` as
shipped, with ``adaptive=True`` and with restarts. ``tests/test_nelder_mead_vs_scipy.py`` runs
:func:`compare` with fewer starts.

    python benchmarks/nm_vs_scipy.py [--quick]    # 30 starts per case; --quick: 5, n = 4
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # not on sys.path under `jaxfric bench`
from _harness import add_output_arguments, machine, markdown_table, results_dir, write_report  # noqa: E402

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optimistix as optx  # noqa: E402
import scipy  # noqa: E402
import scipy.optimize  # noqa: E402

import jaxfric as jf  # noqa: E402

FUNCTIONS = ("sphere", "rosenbrock")


def objective(name):
    """``fn(y, shift)`` for jaxfric and ``f(x, shift)`` (NumPy) for SciPy."""
    return {"sphere": ((lambda y, s: jnp.sum((y - s) ** 2)), (lambda x, s: float(np.sum((x - s) ** 2)))),
            "rosenbrock": ((lambda y, s: jf.functions.rosenbrock(y - s + 1.0)),
                           (lambda x, s: float(scipy.optimize.rosen(x - s + 1.0))))}[name]


def problem_set(name, n, starts, seed=0):
    rng = np.random.default_rng([seed, n, FUNCTIONS.index(name)])
    shift = rng.uniform(-2, 2, n)
    return shift, shift + rng.uniform(-3, 3, (starts, n))


def run_scipy(name, n, shift, x0s, budget, tol):
    opts = dict(adaptive=True, xatol=tol, fatol=tol, maxfev=budget, maxiter=budget)
    runs = [scipy.optimize.minimize(objective(name)[1], x0, args=(shift,), method="Nelder-Mead", options=opts)
            for x0 in x0s]
    return np.array([(float(r.fun), int(r.nfev)) for r in runs])


def run_jaxfric(name, n, shift, x0s, budget, tol, **solver_kw):
    fn, _ = objective(name)
    solver = jf.NelderMead(rtol=0.0, atol=tol, initial_simplex="fminsearch", max_evals=budget, **solver_kw)

    @jax.jit
    @jax.vmap
    def run(x0):
        sol = optx.minimise(fn, solver, x0, jnp.asarray(shift), max_steps=budget, throw=False)
        return sol.state.f_simplex[0], sol.state.num_evals

    with jax.enable_x64(True):
        f, ev = run(jnp.asarray(x0s))
        return np.stack([np.asarray(f, np.float64), np.asarray(ev, np.float64)], axis=1)


VARIANTS = {"jaxfric NelderMead()": {}, "jaxfric NelderMead(adaptive=True)": {"adaptive": True},
            "jaxfric NelderMead(restarts=3)": {"restarts": 3}}


def compare(name, n, starts, budget, tol, solved, variants=VARIANTS, seed=0):
    """Rows ``{solver: (number solved, median evaluations, all final values)}``."""
    shift, x0s = problem_set(name, n, starts, seed)
    res = {"scipy adaptive": run_scipy(name, n, shift, x0s, budget, tol)}
    for label, kw in variants.items():
        res[label] = run_jaxfric(name, n, shift, x0s, budget, tol, **kw)
    return {label: (int(np.sum(r[:, 0] < solved)), float(np.median(r[:, 1])), r[:, 0]) for label, r in res.items()}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--starts", type=int, default=30)
    p.add_argument("--budget", type=int, default=2000, help="evaluations per run = budget × n")
    p.add_argument("--tol", type=float, default=1e-10, help="xatol = fatol")
    p.add_argument("--solved", type=float, default=1e-8)
    p.add_argument("--dims", default="4,8,12")
    add_output_arguments(p, "5 starts, n = 4 (smoke test)")
    a = p.parse_args(argv)
    if a.quick:
        a.starts, a.dims = 5, "4"
    rows = []
    for name in FUNCTIONS:
        for n in (int(d) for d in a.dims.split(",")):
            res = compare(name, n, a.starts, a.budget * n, a.tol, a.solved)
            for label, (ok, med_ev, f) in res.items():
                rows.append({"function": name, "n": n, "solver": label, "solved": ok, "starts": a.starts,
                             "median_evals": med_ev, "median_f": float(np.median(f)), "worst_f": float(np.max(f))})
                print(f"{name:10s} n={n:2d} {label:36s} solved {ok:2d}/{a.starts}  median evals {med_ev:8.0f}  "
                      f"median f {np.median(f):.1e}", flush=True)
    table = [{"function": r["function"], "n": r["n"], "solver": r["solver"], "solved": f"{r['solved']}/{r['starts']}",
              "median evaluations": f"{r['median_evals']:.0f}", "median f": f"{r['median_f']:.1e}",
              "worst f": f"{r['worst_f']:.1e}"} for r in rows]
    lines = [
        "# Nelder–Mead: jaxfric against SciPy's adaptive Nelder–Mead", "",
        f"{a.starts} random starts per case (fixed seeds), budget {a.budget}·n evaluations, "
        f"xatol = fatol = {a.tol:g} (absolute), solved: f < {a.solved:g}; first simplex: fminsearch's "
        f"rule for both; float64. SciPy {scipy.__version__}, jaxfric {jf.__version__}; {machine()}. Re-run: `python benchmarks/nm_vs_scipy.py`.",
        "", markdown_table(table)]
    write_report(results_dir(a.out, quick=a.quick), "nm_vs_scipy", lines, rows, float_format="", echo=False)


if __name__ == "__main__":
    main()
