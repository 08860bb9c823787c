"""Friction identification on the simulated rig: the paper's neuron study and ENN-vs-LuGre table.

Usage::

    python benchmarks/friction.py [--seeds 3] [--out benchmarks/results] [--x64] [--quick]

Data: ``jaxfric.rig.synthetic_friction_data`` at its default noise (2000 samples at
128 Hz, 5 Hz Butterworth, 1600 training / 400 validation samples; ALGORITHMS.md §7).
Each configuration runs ``--seeds`` independent optimiser keys on the *same* record.

What it measures (ALGORITHMS.md §12):

1. one full default ENN identification (``identify("elman", data, key=...)``), compile
   time apart, and the same call again (served from the jit cache);
2. the optimiser stages for the 30-neuron ENN: MAPSO only, MAPSO–NMDS (the paper),
   MAPSO–NMDS + BFGS, MAPSO + BFGS (gradient instead of Nelder–Mead);
3. the Elman context-weight box |r| <= 1, 2 and the spec's 5;
4. the neuron study N = 20, 30, 40 (paper: 0.3277 %, 0.2632 %, 0.2377 %);
5. ENN against LuGre (MSE %, MAX, FIT %, #params; paper: ENN MSE 95.6 % below
   LuGre's, LuGre above 5 %), for the paper's optimiser and the gradient-refined one;
6. the MAPSO generation budget (the default against ``--budgets``, 500 and 1000).

Writes ``friction.md``, ``friction.csv`` and ``friction_*.png`` into ``--out``.
Metric definitions: ``jaxfric.metrics`` (MSE % = 100·mean(e²)/var(F), §6).
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import sys
import time
from pathlib import Path

try:
    import jaxfric  # noqa: F401
except ImportError:  # running from a source checkout without installing
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import jax
import numpy as np


# ----------------------------------------------------------------- options
def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, default=3, help="optimiser keys per configuration")
    p.add_argument("--data-seed", type=int, default=0, help="key of the simulated record")
    p.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    p.add_argument("--x64", action="store_true", help="search in float64 (default: float32)")
    p.add_argument("--quick", action="store_true", help="tiny budgets: a smoke test of the script")
    p.add_argument("--budgets", default="500,1000",
                   help="other MAPSO generation budgets to compare with the default ('' = none)")
    return p.parse_args(argv)


PAPER_NEURONS = {20: 0.3277, 30: 0.2632, 40: 0.2377}


# ------------------------------------------------------------------ helpers
def stats(values):
    a = np.asarray([v for v in values if v is not None], float)
    if a.size == 0:
        return float("nan"), float("nan"), float("nan")
    return float(np.mean(a)), float(np.min(a)), float(np.max(a))


def fmt(values, digits=3):
    mean, lo, hi = stats(values)
    if not np.isfinite(mean):
        return "–"
    if len(values) == 1:
        return f"{mean:.{digits}f}"
    return f"{mean:.{digits}f} ({lo:.{digits}f}–{hi:.{digits}f})"


def stage(fit, name):
    for s in fit.stages:
        if s["stage"] == name:
            return s
    raise KeyError(name)


def row(config, method, seed, fit, st, *, time_run, time_compile):
    """One CSV row: a method's numbers for one seed (``st``: the stage dict)."""
    r = {"config": config, "method": method, "seed": seed, "model": type(fit.model).__name__,
         "neurons": getattr(fit.model, "neurons", ""),
         "context_weight_bound": getattr(fit.model, "context_weight_bound", ""),
         "num_params": fit.num_params, "J": st["J"],
         "time_run_s": time_run, "time_compile_s": time_compile}
    for k in ("mse_percent", "max_abs", "fit_percent"):
        for w in ("train", "valid", "all"):
            r[f"{k}_{w}"] = st.get(f"{k}_{w}")
    return r


class Runner:
    """Runs identifications and turns each fit's stages into CSV rows."""

    def __init__(self, data, args):
        from jaxfric.identify import GradientRefinement, default_solver, identify

        self.identify, self.default_solver = identify, default_solver
        self.GradientRefinement = GradientRefinement
        self.data, self.args = data, args
        self.rows = []
        self.fits = {}
        self.dtype = np.float64 if args.x64 else np.float32

    def solver(self, model, generations=None, mapso_only=False):
        import jaxfric

        s = self.default_solver(model)
        if self.args.quick:
            s = jaxfric.mapso_nmds(lattice_size=3, num_generations=5, sl_generations=2,
                                   nm_max_steps=200, nm_max_evals=200)
        elif generations is not None:
            s = jaxfric.MAPSONMDS(mapso=jaxfric.MAPSO(lattice_size=s.mapso.lattice_size,
                                                      num_generations=generations),
                                  nelder_mead=s.nelder_mead)
        return s.mapso if mapso_only else s

    def refinement(self, model):
        steps = 50 if self.args.quick else 2000
        method = "bfgs" if model.num_params > 20 else "lm"
        return self.GradientRefinement(method=method, max_steps=steps if method == "bfgs" else 200)

    def run(self, config, model, seed, *, generations=None, mapso_only=False, label_prefix=""):
        solver = self.solver(model, generations, mapso_only)
        ref = self.refinement(model)
        fit = self.identify(model, self.data, key=jax.random.key(seed), solver=solver,
                            refine=ref, dtype=self.dtype)
        t = fit.timings
        first = fit.stages[0]["stage"]
        grad = ref.method.upper() if ref.method == "lm" else ref.method.upper()
        if mapso_only:
            self.rows.append(row(config, f"{label_prefix}MAPSO only", seed, fit, stage(fit, first),
                                 time_run=t["run_s"], time_compile=t["compile_s"]))
            self.rows.append(row(config, f"{label_prefix}MAPSO + {grad}", seed, fit, fit.stages[-1],
                                 time_run=t["run_s"] + t["refine_run_s"],
                                 time_compile=t["compile_s"] + t["refine_compile_s"]))
        else:
            self.rows.append(row(config, f"{label_prefix}MAPSO–NMDS", seed, fit,
                                 stage(fit, "nelder_mead"),
                                 time_run=t["run_s"], time_compile=t["compile_s"]))
            self.rows.append(row(config, f"{label_prefix}MAPSO–NMDS + {grad}", seed, fit,
                                 fit.stages[-1], time_run=t["run_s"] + t["refine_run_s"],
                                 time_compile=t["compile_s"] + t["refine_compile_s"]))
        self.fits[(config, mapso_only, seed)] = fit
        m = fit.stages
        print(f"  {config:<22} seed {seed} {'MAPSO' if mapso_only else 'MAPSO-NMDS'}: "
              + " -> ".join(f"{s['stage']} J={s['J']:.3g}" for s in m)
              + f" | valid {fit.metrics['valid']['mse_percent']:.3f} % "
              f"| run {t['run_s'] + t.get('refine_run_s', 0):.1f} s, compile "
              f"{t['compile_s'] + t.get('refine_compile_s', 0):.1f} s", flush=True)
        return fit

    def select(self, config, method):
        return [r for r in self.rows if r["config"] == config and r["method"] == method]


# -------------------------------------------------------------------- report
def table(runner, configs_methods, columns, header):
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for label, config, method, extra in configs_methods:
        rs = runner.select(config, method)
        if not rs:
            continue
        cells = [label]
        for key, digits in columns:
            if key == "num_params":
                cells.append(str(rs[0]["num_params"]))
            else:
                cells.append(fmt([r[key] for r in rs], digits))
        cells += extra
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_csv(rows, path):
    keys = list(rows[0])
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})


def paper_fit(fit):
    """The Nelder–Mead result of a refined fit, as its own Fit (for figures)."""
    from jaxfric.fit import Fit

    return Fit(model=fit.model, theta=np.asarray(fit.solution.value),
               velocity_scaler=fit.velocity_scaler, friction_scaler=fit.friction_scaler,
               dt=fit.dt, n_train=fit.n_train, n_samples=fit.n_samples, metrics={})


def figures(runner, data, out, enn_key, lugre_key):
    from jaxfric import plot

    enn = runner.fits[enn_key]
    lug = runner.fits[lugre_key]
    files = []
    for name, fit, label in (
        ("friction_fit_enn.png", enn, "ENN (N = 30), MAPSO–NMDS + BFGS"),
        ("friction_fit_enn_paper.png", paper_fit(enn), "ENN (N = 30), MAPSO–NMDS (paper)"),
        ("friction_fit_lugre.png", paper_fit(lug), "LuGre, MAPSO–NMDS"),
    ):
        fig = plot.plot_fit(fit, data, label=label)
        fig.savefig(out / name, dpi=110)
        files.append(name)
    fig = plot.plot_error({"ENN, MAPSO–NMDS + BFGS": enn, "ENN, MAPSO–NMDS": paper_fit(enn),
                           "LuGre, MAPSO–NMDS": paper_fit(lug)}, data)
    fig.savefig(out / "friction_error.png", dpi=110)
    files.append("friction_error.png")
    fig = plot.plot_convergence({"ENN N = 30": enn, "LuGre": lug},
                                title="MAPSO–NMDS convergence (best J against evaluations)")
    fig.savefig(out / "friction_convergence.png", dpi=110)
    files.append("friction_convergence.png")
    return files


def main(argv=None):
    args = parse(argv)
    if args.x64:
        jax.config.update("jax_enable_x64", True)
    from jaxfric import rig
    from jaxfric.identify import DEFAULT_GENERATIONS_BLACK_BOX, NAMED_MODEL_DEFAULTS, identify
    from jaxfric.models import Elman, LuGre

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    seeds = list(range(args.seeds))
    rb_default = NAMED_MODEL_DEFAULTS["elman"]["context_weight_bound"]
    load_before = os.getloadavg()
    t_start = time.perf_counter()

    print("simulating the rig ...", flush=True)
    data = rig.synthetic_friction_data(jax.random.key(args.data_seed))
    f = np.asarray(data.friction, np.float64)
    print(f"  {data.n_samples} samples, {data.n_train} training, friction {f.min():.0f}..{f.max():.0f} N")
    runner = Runner(data, args)
    dtype = runner.dtype

    # 1. one full default identification, timed (compile apart), then again from the cache
    timing = []
    if not args.quick:
        print("default ENN identification (timing) ...", flush=True)
        for k in (100, 101):
            fit = identify("elman", data, key=k, dtype=dtype)
            timing.append(("paper default", fit.timings, fit.metrics["valid"]["mse_percent"]))
        fit = identify("elman", data, key=100, dtype=dtype, refine="bfgs")
        timing.append(("default + refine='bfgs'", fit.timings, fit.metrics["valid"]["mse_percent"]))

    # 2.-4. ENN configurations
    neurons = (4,) if args.quick else (20, 30, 40)
    n_main = neurons[-1] if args.quick else 30
    boxes = (1.0, 2.0, 5.0)
    print("ENN runs ...", flush=True)
    for rb in boxes:
        for s in seeds:
            model = Elman(neurons=n_main, context_weight_bound=rb)
            runner.run(f"N={n_main} r<={rb:g}", model, s)
            runner.run(f"N={n_main} r<={rb:g}", model, s, mapso_only=True)
    for n in neurons:
        if n == n_main:
            continue
        for s in seeds:
            runner.run(f"N={n} r<={rb_default:g}", Elman(neurons=n, context_weight_bound=rb_default), s)
    budgets = [] if args.quick or not args.budgets else [int(g) for g in args.budgets.split(",")]
    for g in budgets:
        for s in seeds:
            runner.run(f"N=30 r<={rb_default:g} G={g}",
                       Elman(neurons=30, context_weight_bound=rb_default), s, generations=g)

    # 5. LuGre
    print("LuGre runs ...", flush=True)
    for s in seeds:
        runner.run("LuGre", LuGre(), s)
    rows = runner.rows
    write_csv(rows, out / "friction.csv")

    main_cfg = f"N={n_main} r<={rb_default:g}"
    files = figures(runner, data, out, (main_cfg, False, 0), ("LuGre", False, 0))

    # ------------------------------------------------------------- markdown
    L = []
    add = L.append
    add("# Friction identification on the simulated rig (`benchmarks/friction.py`)\n")
    add(f"Data: `jaxfric.rig.synthetic_friction_data(jax.random.key({args.data_seed}))` at the "
        f"default sensor noise: {data.n_samples} samples at {1 / float(data.dt):.0f} Hz, "
        f"{data.n_train} training / {data.n_samples - data.n_train} validation samples "
        f"(ALGORITHMS.md §7). The rig's seal friction is richer than LuGre (Maxwell-slip "
        f"elements plus unmodelled effects), so LuGre cannot fit it exactly.\n")
    add(f"Search dtype {np.dtype(dtype).name}; {len(seeds)} optimiser key(s) per configuration "
        f"(numbers are mean (min–max) over keys). MSE % = 100·mean(e²)/var(F) over the stated "
        f"window (§6); MAX = max|e| [N]; FIT % = 100·(1 − ‖e‖/‖F − mean F‖).")
    add(f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPU cores, "
        f"load average {load_before[0]:.1f} at the start (other jobs share the machine, so "
        f"times are upper bounds). jax {jax.__version__}.\n")
    default_desc = ("identify's default solver: MAPSO 8×8 lattice (64 agents, §3.5), "
                    f"G = {DEFAULT_GENERATIONS_BLACK_BOX} generations (162 evaluations each), then "
                    "Nelder–Mead with fminsearch's budget of 200·n iterations and 200·n "
                    "evaluations (36 000 for N = 30).")
    add(f"ENN solver: {default_desc} Gradient stage (not in the paper): BFGS on J, 2000 "
        "steps, box kept by the sine reparametrisation. LuGre: MAPSO 5×5, G = 200, "
        "Nelder–Mead 1200 iterations, then Levenberg–Marquardt (200 steps); data-centred "
        "bounds (`with_data_bounds`).\n")

    if timing:
        add("## Timing of one full default ENN identification (N = 30)\n")
        add("`identify(\"elman\", data, key=...)` with every default (float32 unless "
            "`--x64`). Compile time is measured from JAX's compile events, apart from the run.\n")
        add("| call | compile [s] | optimiser run [s] | gradient run [s] | total wall [s] | valid MSE % |")
        add("|---|---|---|---|---|---|")
        for i, (name, t, mse) in enumerate(timing):
            tag = name + (" (first call)" if i == 0 else " (cached)" if i == 1 else "")
            comp = t["compile_s"] + t.get("refine_compile_s", 0.0)
            add(f"| {tag} | {comp:.1f} | {t['run_s']:.1f} | {t.get('refine_run_s', 0.0):.1f} | "
                f"{t['total_s']:.1f} | {mse:.3f} |")
        add("")

    mse_cols = [("mse_percent_train", 3), ("mse_percent_valid", 3), ("num_params", 0),
                ("time_run_s", 1)]
    hdr = ["method", "MSE % train", "MSE % valid", "#params", "run time [s]"]

    add(f"## Optimiser stages (ENN N = {n_main}, |r| ≤ {rb_default:g})\n")
    add(table(runner, [
        ("MAPSO only", main_cfg, "MAPSO only", []),
        ("MAPSO–NMDS (paper)", main_cfg, "MAPSO–NMDS", []),
        ("MAPSO–NMDS + BFGS", main_cfg, "MAPSO–NMDS + BFGS", []),
        ("MAPSO + BFGS (no Nelder–Mead)", main_cfg, "MAPSO + BFGS", []),
    ], mse_cols, hdr))
    add("")

    add(f"## Elman context-weight box (N = {n_main})\n")
    add("|r| ≤ 5 is the spec's box (§2.4); with it about 98 % of random networks are chaotic "
        "over 1600 samples (models/elman.py).\n")
    add(table(runner, [(f"\\|r\\| ≤ {rb:g}, {m}", f"N={n_main} r<={rb:g}", meth, [])
                       for rb in boxes for m, meth in (("MAPSO–NMDS", "MAPSO–NMDS"),
                                                       ("+ BFGS", "MAPSO–NMDS + BFGS"))],
                mse_cols, ["box, method"] + hdr[1:]))
    add("")

    add(f"## Neuron study (|r| ≤ {rb_default:g})\n")
    cfg_n = {n: (main_cfg if n == n_main else f"N={n} r<={rb_default:g}") for n in neurons}
    entries = []
    for n in neurons:
        paper = f"{PAPER_NEURONS[n]:.4f}" if n in PAPER_NEURONS else "–"
        entries.append((f"N = {n}, MAPSO–NMDS", cfg_n[n], "MAPSO–NMDS", [paper]))
        entries.append((f"N = {n}, + BFGS", cfg_n[n], "MAPSO–NMDS + BFGS", [paper]))
    add(table(runner, entries, mse_cols, ["N, method"] + hdr[1:] + ["paper MSE %"]))
    add("")

    add("## ENN against LuGre (Table 4 of the paper)\n")
    full_cols = [("mse_percent_valid", 3), ("mse_percent_all", 3), ("max_abs_valid", 1),
                 ("max_abs_all", 1), ("fit_percent_valid", 2), ("num_params", 0)]
    add(table(runner, [
        (f"ENN N = {n_main}, MAPSO–NMDS", main_cfg, "MAPSO–NMDS", []),
        (f"ENN N = {n_main}, MAPSO–NMDS + BFGS", main_cfg, "MAPSO–NMDS + BFGS", []),
        ("LuGre, MAPSO–NMDS", "LuGre", "MAPSO–NMDS", []),
        ("LuGre, MAPSO–NMDS + LM", "LuGre", "MAPSO–NMDS + LM", []),
    ], full_cols, ["model, method", "MSE % valid", "MSE % all", "MAX valid [N]", "MAX all [N]",
                   "FIT % valid", "#params"]))
    add("")
    red = []
    for enn_m, lug_m in (("MAPSO–NMDS", "MAPSO–NMDS"), ("MAPSO–NMDS + BFGS", "MAPSO–NMDS + LM")):
        for w in ("valid", "all"):
            e = stats([r[f"mse_percent_{w}"] for r in runner.select(main_cfg, enn_m)])[0]
            g = stats([r[f"mse_percent_{w}"] for r in runner.select("LuGre", lug_m)])[0]
            red.append((enn_m, w, e, g, 100 * (1 - e / g)))
    add("MSE reduction of the ENN against LuGre (means over keys; paper: 95.6 %, LuGre > 5 %):\n")
    add("| ENN method | window | ENN MSE % | LuGre MSE % | reduction |")
    add("|---|---|---|---|---|")
    for m, w, e, g, r in red:
        add(f"| {m} | {w} | {e:.3f} | {g:.3f} | {r:.1f} % |")
    add("")

    if budgets:
        add(f"## MAPSO generation budget (N = 30, |r| ≤ {rb_default:g})\n")
        cfgs = sorted([(DEFAULT_GENERATIONS_BLACK_BOX, main_cfg)]
                      + [(g, f"N=30 r<={rb_default:g} G={g}") for g in budgets])
        entries = []
        for g, cfg in cfgs:
            tag = " (default)" if g == DEFAULT_GENERATIONS_BLACK_BOX else ""
            entries.append((f"G = {g}{tag}, MAPSO–NMDS", cfg, "MAPSO–NMDS", []))
            entries.append((f"G = {g}{tag}, + BFGS", cfg, "MAPSO–NMDS + BFGS", []))
        add(table(runner, entries, mse_cols, ["budget, method"] + hdr[1:]))
        add("")

    add("## Figures\n")
    for name in files:
        add(f"![{name}]({name})")
    add("")
    add(f"Total benchmark wall time: {time.perf_counter() - t_start:.0f} s. "
        f"Raw numbers per key: `friction.csv`.")
    (out / "friction.md").write_text("\n".join(L) + "\n")
    print(f"wrote {out / 'friction.md'}, friction.csv and {len(files)} figures")


if __name__ == "__main__":
    main()
