"""Friction identification on the simulated rig: the paper's neuron study and ENN-vs-LuGre table.

Usage::

    python benchmarks/friction.py [--seeds 3] [--out benchmarks/results] [--x64] [--quick]

Data: ``jaxfric.rig.synthetic_friction_data`` at its default noise (2000 samples at
128 Hz, 5 Hz Butterworth, 1600 training / 400 validation samples; docs/algorithms.md §7).
Each configuration runs ``--seeds`` independent optimiser keys on the *same* record.

What it measures (docs/algorithms.md §12):

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
import json
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

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/ is not on sys.path under `jaxfric bench`
from _harness import results_dir, write_csv  # noqa: E402


# ----------------------------------------------------------------- options
def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, default=3, help="optimiser keys per configuration")
    p.add_argument("--data-seed", type=int, default=0, help="key of the simulated record")
    p.add_argument("--out", default=None,
                   help="output folder (default benchmarks/results; benchmarks/results/quick with --quick, "
                   "so a smoke run never overwrites the committed results)")
    p.add_argument("--x64", action="store_true", help="search in float64 (default: float32)")
    p.add_argument("--quick", action="store_true", help="tiny budgets: a smoke test of the script")
    p.add_argument("--report-only", action="store_true",
                   help="rewrite friction.md from an existing friction.csv (no identification)")
    p.add_argument("--budgets", default="500,1000",
                   help="other MAPSO generation budgets to compare with the default ('' = none)")
    return p.parse_args(argv)


PAPER_NEURONS = {20: 0.3277, 30: 0.2632, 40: 0.2377}
#: Timing row of identify's default pipeline (method="jaxfric"); the "paper ..." rows
#: run method="paper" (the paper's MAPSO–NMDS, identify's default before 0.7).
JAXFRIC_LABEL = "jaxfric default (MAPSO G=50 -> BFGS 500)"


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
        from jaxfric.identification import GradientRefinement, identify, paper_solver

        self.identify, self.paper_solver = identify, paper_solver
        self.GradientRefinement = GradientRefinement
        self.data, self.args = data, args
        self.rows = []
        self.fits = {}
        self.dtype = np.float64 if args.x64 else np.float32

    def solver(self, model, generations=None, mapso_only=False):
        import jaxfric

        s = self.paper_solver(model)
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
                cells.append(str(int(rs[0]["num_params"])))
            else:
                cells.append(fmt([r[key] for r in rs], digits))
        cells += extra
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


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


TIMING_CONFIG = "default timing"


def run_benchmark(args, data, out):
    """All identifications; returns (rows, figure files)."""
    from jaxfric.identification import NAMED_MODEL_DEFAULTS, identify
    from jaxfric.models import Elman, LuGre

    seeds = list(range(args.seeds))
    rb_default = NAMED_MODEL_DEFAULTS["elman"]["context_weight_bound"]
    runner = Runner(data, args)
    dtype = runner.dtype

    # 1. one full default identification, timed (compile apart), then again from the cache
    if not args.quick:
        print("default ENN identification (timing) ...", flush=True)
        for k, method, refine, label in ((100, "paper", None, "paper default (first call)"),
                                         (101, "paper", None, "paper default (cached)"),
                                         (100, "paper", "bfgs", "default + refine='bfgs'"),
                                         (100, "jaxfric", None, JAXFRIC_LABEL),
                                         (101, "jaxfric", None, JAXFRIC_LABEL + " (cached)")):
            fit = identify("elman", data, key=k, dtype=dtype, refine=refine, method=method)
            t = fit.timings
            runner.rows.append(row(TIMING_CONFIG, label, k, fit, fit.stages[-1],
                                   time_run=t["run_s"] + t.get("refine_run_s", 0.0),
                                   time_compile=t["compile_s"] + t.get("refine_compile_s", 0.0)))
            runner.rows[-1]["time_total_s"] = t["total_s"]
            print(f"  {label}: {t}", flush=True)

    # 2.-4. ENN configurations
    neurons = (4,) if args.quick else (20, 30, 40)
    n_main = neurons[-1] if args.quick else 30
    print("ENN runs ...", flush=True)
    for rb in BOXES:
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
    main_cfg = f"N={n_main} r<={rb_default:g}"
    files = figures(runner, data, out, (main_cfg, False, 0), ("LuGre", False, 0))
    return runner.rows, files


BOXES = (1.0, 2.0, 5.0)


def read_csv(path):
    rows = []
    with open(path) as fh:
        for r in csv.DictReader(fh):
            for k, v in r.items():
                if k in ("config", "method", "model"):
                    continue
                try:
                    r[k] = float(v) if v not in ("", "None") else None
                except ValueError:
                    pass
            rows.append(r)
    return rows


class Rows:
    """``select(config, method)`` over CSV-like rows (the report's only data source)."""

    def __init__(self, rows):
        self.rows = rows

    def select(self, config, method):
        return [r for r in self.rows if r["config"] == config and r["method"] == method]

    def configs(self):
        return sorted({r["config"] for r in self.rows})


def write_markdown(out, rows, files, meta):
    from jaxfric.identification import DEFAULT_GENERATIONS_BLACK_BOX, NAMED_MODEL_DEFAULTS
    from jaxfric.identification._api import (FAST_GENERATIONS_BLACK_BOX, FAST_REFINE_STEPS,
                                             GLOBAL_STAGE_SAMPLES)

    R = Rows(rows)
    rb_default = NAMED_MODEL_DEFAULTS["elman"]["context_weight_bound"]
    neurons = sorted({int(r["neurons"]) for r in rows if r["model"] == "Elman" and r["neurons"]})
    n_main = 30 if 30 in neurons else neurons[-1]
    main_cfg = f"N={n_main} r<={rb_default:g}"
    n_keys = len({r["seed"] for r in R.select(main_cfg, "MAPSO–NMDS")})
    L = []
    add = L.append
    add("# Friction identification on the simulated rig (`benchmarks/friction.py`)\n")
    add(f"Data: `jaxfric.rig.synthetic_friction_data(jax.random.key({meta['data_seed']}))` at the "
        f"default sensor noise: {meta['n_samples']} samples at {meta['fs']:.0f} Hz, "
        f"{meta['n_train']} training / {meta['n_samples'] - meta['n_train']} validation samples "
        "(docs/algorithms.md §7). The rig's seal friction is a pressure-dependent, asymmetric "
        "Maxwell-slip model (Coulomb level 270 N extending, 150 N retracting), richer than "
        "LuGre on purpose.\n")
    add(f"Search dtype {meta['dtype']}; {n_keys} optimiser keys per configuration on the same "
        "record; cells are mean (min–max) over keys. MSE % = 100·mean(e²)/var(F) over the "
        "stated window (§6); MAX = max|e| [N]; FIT % = 100·(1 − ‖e‖/‖F − mean F‖). "
        f"Machine: {meta['machine']}, {meta['cores']} CPU cores, load average "
        f"{meta['load']:.1f} at the start: other jobs shared the machine, so times are upper "
        f"bounds. jax {meta['jax']}, "
        + (f"jaxfric {meta['jaxfric']}" if "jaxfric" in meta else
           "jaxfric version not recorded (a run before 0.7: its default rows predate the 0.7 "
           "pipeline described below)")
        + ".\n")
    add("`identify`'s default pipeline for the networks (`method=\"jaxfric\"`, 0.7): MAPSO on an 8×8 "
        f"lattice for G = {FAST_GENERATIONS_BLACK_BOX} generations on the first "
        f"{GLOBAL_STAGE_SAMPLES} training samples (all {meta['n_train']} here), then "
        f"{FAST_REFINE_STEPS} BFGS steps on the whole training window "
        "(jaxfric/identification/_api.py); it appears in the timing table. Every other ENN row "
        "uses the paper's solver.\n")
    add(f"Paper's ENN solver (`identify(..., method=\"paper\")`, `paper_solver`): MAPSO on an 8×8 lattice (64 agents, §3.5) for "
        f"G = {DEFAULT_GENERATIONS_BLACK_BOX} generations (162 evaluations each), then "
        "Nelder–Mead with fminsearch's budget, 200·n iterations and 200·n evaluations "
        "(36 000 for N = 30), started from a simplex sized by the swarm's spread. Gradient "
        "stage (not in the paper, `refine=\"bfgs\"`): BFGS on J through the scan (exact BPTT "
        "gradient), at most 2000 steps, box kept by the sine reparametrisation. LuGre: "
        "MAPSO 5×5, G = 200, Nelder–Mead 1200 iterations, then Levenberg–Marquardt "
        "(`refine=\"lm\"`, 200 steps); data-centred search box (`identify`'s default, `models.data_ranges`). "
        "\"MAPSO only\" and \"MAPSO + BFGS\" are separate runs with `solver=MAPSO(...)` "
        "(the same lattice and G).\n")

    timing = R.select(TIMING_CONFIG, "paper default (first call)")
    if timing:
        add(f"## Timing of one full ENN identification (N = {n_main}): the default pipeline and the paper's\n")
        add("`identify(\"elman\", data, key=...)` with every default (float32 unless "
            "`--x64`). Compile time comes from JAX's compile events, apart from the run.\n")
        add("| call | compile [s] | run [s] | total wall [s] | MSE % train | MSE % valid |")
        add("|---|---|---|---|---|---|")
        for label in ("paper default (first call)", "paper default (cached)",
                      "default + refine='bfgs'", JAXFRIC_LABEL, JAXFRIC_LABEL + " (cached)"):
            for r in R.select(TIMING_CONFIG, label):
                add(f"| {label} | {r['time_compile_s']:.1f} | {r['time_run_s']:.1f} | "
                    f"{r['time_total_s']:.1f} | {r['mse_percent_train']:.3f} | "
                    f"{r['mse_percent_valid']:.3f} |")
        add("")

    mse_cols = [("mse_percent_train", 3), ("mse_percent_valid", 3), ("num_params", 0),
                ("time_run_s", 1)]
    hdr = ["method", "MSE % train", "MSE % valid", "#params", "run time [s]"]

    add(f"## Optimiser stages (ENN N = {n_main}, \\|r\\| ≤ {rb_default:g})\n")
    add(table(R, [
        ("MAPSO only", main_cfg, "MAPSO only", []),
        ("MAPSO–NMDS (paper)", main_cfg, "MAPSO–NMDS", []),
        ("MAPSO–NMDS + BFGS", main_cfg, "MAPSO–NMDS + BFGS", []),
        ("MAPSO + BFGS (no Nelder–Mead)", main_cfg, "MAPSO + BFGS", []),
    ], mse_cols, hdr))
    add("")

    add(f"## Elman context-weight box (N = {n_main})\n")
    add("\\|r\\| ≤ 5 is the spec's box (§2.4); with it about 98 % of random networks are "
        f"chaotic over 1600 samples (models/elman.py). `identify(\"elman\", ...)` uses "
        f"\\|r\\| ≤ {rb_default:g}.\n")
    add(table(R, [(f"\\|r\\| ≤ {rb:g}, {m}", f"N={n_main} r<={rb:g}", meth, [])
                  for rb in BOXES for m, meth in (("MAPSO–NMDS", "MAPSO–NMDS"),
                                                  ("+ BFGS", "MAPSO–NMDS + BFGS"),
                                                  ("MAPSO + BFGS", "MAPSO + BFGS"))],
                mse_cols, ["box, method"] + hdr[1:]))
    add("")

    add(f"## Neuron study (\\|r\\| ≤ {rb_default:g})\n")
    add("The paper does not say which window its MSE covers (§6); ours are per window.\n")
    cfg_n = {n: (main_cfg if n == n_main else f"N={n} r<={rb_default:g}") for n in neurons}
    entries = []
    for n in neurons:
        paper = f"{PAPER_NEURONS[n]:.4f}" if n in PAPER_NEURONS else "–"
        entries.append((f"N = {n}, MAPSO–NMDS", cfg_n[n], "MAPSO–NMDS", [paper]))
        entries.append((f"N = {n}, + BFGS", cfg_n[n], "MAPSO–NMDS + BFGS", [paper]))
    add(table(R, entries, mse_cols, ["N, method"] + hdr[1:] + ["paper MSE %"]))
    add("")

    add("## ENN against LuGre (Table 4 of the paper)\n")
    full_cols = [("mse_percent_valid", 3), ("mse_percent_all", 3), ("max_abs_valid", 1),
                 ("max_abs_all", 1), ("fit_percent_valid", 2), ("fit_percent_all", 2),
                 ("num_params", 0)]
    add(table(R, [
        (f"ENN N = {n_main}, MAPSO–NMDS", main_cfg, "MAPSO–NMDS", []),
        (f"ENN N = {n_main}, MAPSO–NMDS + BFGS", main_cfg, "MAPSO–NMDS + BFGS", []),
        ("LuGre, MAPSO–NMDS", "LuGre", "MAPSO–NMDS", []),
        ("LuGre, MAPSO–NMDS + LM", "LuGre", "MAPSO–NMDS + LM", []),
    ], full_cols, ["model, method", "MSE % valid", "MSE % all", "MAX valid [N]", "MAX all [N]",
                   "FIT % valid", "FIT % all", "#params"]))
    add("")
    red = {}
    add("MSE reduction of the ENN against LuGre (means over keys; paper: 95.6 %, LuGre > 5 %):\n")
    add("| ENN method (LuGre method) | window | ENN MSE % | LuGre MSE % | reduction |")
    add("|---|---|---|---|---|")
    for enn_m, lug_m in (("MAPSO–NMDS", "MAPSO–NMDS"), ("MAPSO–NMDS + BFGS", "MAPSO–NMDS + LM")):
        for w in ("valid", "all"):
            e = stats([r[f"mse_percent_{w}"] for r in R.select(main_cfg, enn_m)])[0]
            g = stats([r[f"mse_percent_{w}"] for r in R.select("LuGre", lug_m)])[0]
            red[(enn_m, w)] = (e, g, 100 * (1 - e / g))
            add(f"| {enn_m} ({lug_m}) | {w} | {e:.3f} | {g:.3f} | {100 * (1 - e / g):.1f} % |")
    add("")

    budget_cfgs = sorted({r["config"] for r in rows if r["config"].startswith(f"N=30 r<={rb_default:g} G=")})
    if budget_cfgs:
        add(f"## MAPSO generation budget (N = 30, \\|r\\| ≤ {rb_default:g})\n")
        cfgs = [(DEFAULT_GENERATIONS_BLACK_BOX, main_cfg)] + [
            (int(c.rsplit("G=", 1)[1]), c) for c in budget_cfgs]
        entries = []
        for g, cfg in sorted(cfgs):
            tag = " (default)" if g == DEFAULT_GENERATIONS_BLACK_BOX else ""
            entries.append((f"G = {g}{tag}, MAPSO–NMDS", cfg, "MAPSO–NMDS", []))
            entries.append((f"G = {g}{tag}, + BFGS", cfg, "MAPSO–NMDS + BFGS", []))
        add(table(R, entries, mse_cols, ["budget, method"] + hdr[1:]))
        add("")

    # ------------------------------------------------------------- findings
    add("## Findings\n")
    refined = [r["mse_percent_valid"] for r in R.select(main_cfg, "MAPSO–NMDS + BFGS")]
    paper_only = [r["mse_percent_valid"] for r in R.select(main_cfg, "MAPSO–NMDS")]
    lug = [r["mse_percent_valid"] for r in R.select("LuGre", "MAPSO–NMDS")]
    if refined:
        ok = max(refined) <= 0.3
        verdict = ("met by every key" if ok else "met on average"
                   if np.mean(refined) <= 0.3 else "not met")
        po = stats(paper_only)[0]
        add(f"- ENN N = {n_main}, MAPSO–NMDS + BFGS: validation MSE {fmt(refined)} % over "
            f"{len(refined)} keys — the ≤ 0.3 % target is {verdict}. The paper's MAPSO–NMDS "
            f"alone reaches {fmt(paper_only)} %, {'above' if po > 0.2632 else 'at or below'} "
            "the paper's 0.2632 % (whose window is unknown).")
    if lug:
        from jaxfric.rig import SealFriction

        sf = SealFriction()
        lug_J = [r["J"] for r in R.select("LuGre", "MAPSO–NMDS + LM")]
        same = len(lug_J) > 1 and (max(lug_J) - min(lug_J)) <= 1e-3 * min(lug_J)
        add(f"- LuGre: validation MSE {fmt(lug)} % (paper: above 5 %), whole record "
            f"{fmt([r['mse_percent_all'] for r in R.select('LuGre', 'MAPSO–NMDS')])} %. "
            + ("Every key and the LM polish reach the same cost, so the error is structural: "
               if same else "")
            + "LuGre is symmetric and pressure-blind, while the rig's seal friction has "
            f"Coulomb levels of {sf.coulomb_pos:.0f} N extending and {sf.coulomb_neg:.0f} N "
            "retracting and grows with the rod-chamber pressure, which leaves a near-constant "
            "offset in the LuGre error (see the error figure).")
    if red:
        e, g, r = red[("MAPSO–NMDS", "valid")]
        e2, g2, r2 = red[("MAPSO–NMDS + BFGS", "valid")]
        add(f"- ENN against LuGre on validation: {r:.1f} % lower MSE with the paper's "
            f"optimiser, {r2:.1f} % lower after the gradient stage (paper: 95.6 %).")
    stage_rows = {m: stats([x["mse_percent_train"] for x in R.select(main_cfg, m)])[0]
                  for m in ("MAPSO only", "MAPSO–NMDS", "MAPSO–NMDS + BFGS", "MAPSO + BFGS")}
    if all(np.isfinite(v) for v in stage_rows.values()):
        a, b, c = (stage_rows[m] for m in ("MAPSO only", "MAPSO–NMDS", "MAPSO–NMDS + BFGS"))
        add(f"- Stages (training MSE %, means): MAPSO alone {a:.2f}, + Nelder–Mead {b:.2f} "
            f"({a / b:.1f}× lower), + BFGS {c:.3f} (another {b / c:.1f}×); BFGS straight after "
            f"MAPSO {stage_rows['MAPSO + BFGS']:.3f}.")
    tr = {n: stats([r["mse_percent_train"] for r in R.select(cfg_n[n], "MAPSO–NMDS + BFGS")])[0]
          for n in neurons}
    if len(tr) == 3:
        mono = tr[neurons[2]] <= tr[neurons[1]] <= tr[neurons[0]]
        add("- Neuron study, training MSE after BFGS: "
            + ", ".join(f"N = {n}: {tr[n]:.3f} %" for n in neurons)
            + (" — decreasing with N, as the paper's (§12 (b))." if mono else
               " — not monotone in N at this number of keys (§12 (b) expects it)."))
    if timing:
        cached = R.select(TIMING_CONFIG, "paper default (cached)")[0]
        first = timing[0]
        add(f"- A full paper-method identification (N = 30) ran in {cached['time_run_s']:.1f} s "
            f"from the jit cache; the first call added {first['time_compile_s']:.1f} s of "
            "compilation. A new record of the same length does not recompile (tests).")
        fast = R.select(TIMING_CONFIG, JAXFRIC_LABEL) + R.select(TIMING_CONFIG, JAXFRIC_LABEL + " (cached)")
        if fast:
            add(f"- The default pipeline ({JAXFRIC_LABEL}) reached validation MSE "
                + ", ".join(f"{r['mse_percent_valid']:.3f} %" for r in fast)
                + f" (keys {', '.join(str(int(r['seed'])) for r in fast)}) in "
                + ", ".join(f"{r['time_run_s']:.1f} s" for r in fast)
                + " of run time, against the paper method's "
                + ", ".join(f"{r['mse_percent_valid']:.3f} %" for r in timing + [cached])
                + ".")
    box_notes, box_stats = [], {}
    for rb in BOXES:
        cfg = f"N={n_main} r<={rb:g}"
        parts, runs = [], []
        for method in ("MAPSO–NMDS + BFGS", "MAPSO + BFGS"):
            rs = R.select(cfg, method)
            runs += rs
            if rs:
                parts.append(f"{fmt([r['mse_percent_valid'] for r in rs])} % after {method}")
        if runs:
            bad = [r for r in runs if r["mse_percent_valid"] > max(10 * r["mse_percent_train"], 5.0)]
            worst = max(r["mse_percent_valid"] for r in runs)
            box_stats[rb] = (len(bad), worst)
            box_notes.append(f"\\|r\\| ≤ {rb:g}: " + ", ".join(parts)
                             + f"; {len(bad)} of {len(runs)} gradient-refined keys diverged on the "
                             "validation window")
    if box_notes:
        # The default is judged on robustness: fewest diverged keys, then the best worst case.
        safest = min(box_stats, key=lambda rb: box_stats[rb])
        verdict = (f"\\|r\\| ≤ {safest:g} has the fewest diverged keys and the best worst case "
                   f"({box_stats[safest][1]:.3f} %)"
                   + (", hence the default." if safest == min(BOXES) else
                      "; the default (the narrowest box) is not the most robust in this run."))
        add("- Context-weight box, validation MSE: " + "; ".join(box_notes) + ". " + verdict)
    add("- The validation error of a free-running recurrent network scatters from key to key "
        "far more than the training error does (different local minima extrapolate "
        "differently); judge a fit on its validation window. `identify` warns when "
        "validation MSE exceeds 10× the training MSE and 5 %.")
    add("")
    add("## Figures\n")
    for name in files:
        add(f"![{name}]({name})\n")
    add(f"Raw numbers per key: `friction.csv`. Benchmark wall time: {meta['wall']:.0f} s.")
    (out / "friction.md").write_text("\n".join(L) + "\n")


def main(argv=None):
    args = parse(argv)
    if args.x64:
        jax.config.update("jax_enable_x64", True)
    import jaxfric
    from jaxfric import rig

    out = results_dir(args.out, quick=args.quick)
    load = os.getloadavg()[0]
    t_start = time.perf_counter()
    print("simulating the rig ...", flush=True)
    data = rig.synthetic_friction_data(jax.random.key(args.data_seed))
    meta_path = out / "friction_meta.json"
    if args.report_only:
        rows = read_csv(out / "friction.csv")
        files = sorted(p.name for p in out.glob("friction_*.png"))
        meta = json.loads(meta_path.read_text())  # the run's own machine load and wall time
    else:
        rows, files = run_benchmark(args, data, out)
        write_csv(rows, out / "friction.csv")
        meta = {"data_seed": args.data_seed, "n_samples": data.n_samples,
                "n_train": data.n_train, "fs": 1.0 / float(data.dt),
                "dtype": "float64" if args.x64 else "float32",
                "machine": platform.processor() or platform.machine(), "cores": os.cpu_count(),
                "load": load, "jax": jax.__version__, "jaxfric": jaxfric.__version__,
                "wall": time.perf_counter() - t_start}
        meta_path.write_text(json.dumps(meta, indent=1) + "\n")
    write_markdown(out, rows, files, meta)
    print(f"wrote {out / 'friction.md'}, friction.csv and {len(files)} figures")


if __name__ == "__main__":
    main()
