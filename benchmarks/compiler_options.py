"""jaxfric's per-computation XLA options against XLA's defaults, side by side.

Every workload is compiled several times in this one process: with
``compiler_options="auto"`` (what jaxfric uses on CPU: see ``jaxfric/_xla.py``)
and with ``compiler_options=None`` (XLA's defaults); then timed
round-robin so that load from other processes hits all alike. Medians over the
rounds; the first call (compile + run) is reported apart. Results must agree: the
script checks that the variants reach the same best value within 1e-4 and the same
evaluation count (swarms: XLA may sum in another order, so values can differ in
the last bits) or bit-identical outputs (rollouts).

Writes ``compiler_options.md``, ``.csv`` and ``.png`` to ``--out``.

    python benchmarks/compiler_options.py            # about 2 minutes
    python benchmarks/compiler_options.py --identify # adds a default ENN identify (slow)
    python benchmarks/compiler_options.py --emps ../shared/data/emps/DATA_EMPS.mat
                                                     # adds LuGre and ENN identified on EMPS
"""

from __future__ import annotations

import argparse
import csv
import platform
import statistics
import time
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import jaxfric as jf
from jaxfric import _xla
from jaxfric import functions as F

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/ is not on sys.path under `jaxfric bench`
from _harness import results_dir  # noqa: E402

CANDIDATE = "candidate solver options"
#: A measured alternative to "auto" for optimiser runs (session 17): copy-insertion region
#: analysis with XLA's newer fusion emitters. Faster for PSO, Nelder-Mead and identify on
#: EMPS, but ~25 % more memory per process and float32 cosines rounded differently on one and
#: several devices (README "Speed against the peers"); timed beside "auto" to keep the
#: question open with numbers.
CANDIDATE_SOLVER = {"xla_cpu_prefer_vector_width": 512, "xla_cpu_copy_insertion_use_region_analysis": True}


def _variants(kind):
    """(label, compiler_options) pairs timed for a workload of ``kind``."""
    variants = [("auto", "auto"), ("XLA defaults", None)]
    candidate = dict(_xla.supported(tuple(sorted(CANDIDATE_SOLVER.items())), "cpu"))
    if kind == "solver" and candidate != _xla.compiler_options("solver", "cpu"):
        variants.insert(1, (CANDIDATE, candidate))
    return variants


def _swarm_cases(dim, agents, generations, seeds):
    side = int(round(agents**0.5))
    mapso_gens = round((agents * (generations + 1) - agents) / (agents + 9 * 11 - 1))
    cases = []
    for fname in ("rosenbrock", "ackley"):
        lo, hi = F.get(fname).bounds(dim, np.float32)
        fn = F.objective(fname)
        solvers = [("PSO", jf.PSO(num_particles=agents, num_generations=generations)),
                   ("MAPSO", jf.MAPSO(lattice_size=side, num_generations=mapso_gens))]
        if fname == "rosenbrock":
            solvers.append(("Nelder-Mead", jf.NelderMead(max_evals=20000, max_steps=200000,
                                                         atol=0.0, rtol=0.0)))
        for name, solver in solvers:
            cases.append(dict(workload=f"{name}, {dim}-D {fname}", kind="solver",
                              make=_minimise_call(fn, solver, lo, hi)))
        if fname == "rosenbrock":
            cases.append(dict(workload=f"MAPSO, {seeds} seeds vmapped, {dim}-D {fname}",
                              kind="solver", make=_many_call(fn, solvers[1][1], lo, hi, seeds)))
    return cases


def _minimise_call(fn, solver, lo, hi):
    def make(options):
        counter = [0]

        def call():
            counter[0] += 1
            return jf.minimise(fn, solver, (lo, hi), key=jax.random.key(counter[0]),
                               compiler_options=options)
        return call, lambda sol: (float(sol.f), int(sol.stats["num_evals"]))
    return make


def _many_call(fn, solver, lo, hi, seeds):
    def make(options):
        counter = [0]

        def call():
            counter[0] += 1
            keys = jax.random.split(jax.random.key(counter[0]), seeds)
            return jf.minimise_many(fn, solver, (lo, hi), keys=keys, compiler_options=options)
        return call, lambda sol: (float(np.min(sol.f)), int(np.sum(sol.stats["num_evals"])))
    return make


def _rollout_cases(candidates, samples, neurons):
    el = jf.Elman(neurons=neurons)
    lo, hi = el.bounds()
    th = np.random.default_rng(0).uniform(lo, hi, (candidates, el.num_params))
    u = np.sin(2 * np.pi * 0.2 * np.arange(samples) / 128.0)
    cases = []
    for x64 in (False, True):
        dname = "float64" if x64 else "float32"

        def make(options, x64=x64):
            with jax.enable_x64(x64):
                dt = jnp.float64 if x64 else jnp.float32
                a, b = jnp.asarray(th, dt), jnp.asarray(u, dt)
            if options == "auto":  # the library's eager path, as a user calls it
                return (lambda: el.simulate_batch(a, b)), np.asarray
            plain = jax.jit(lambda t, v: el._simulate_batch(t, v, None))
            return (lambda: plain(a, b)), np.asarray
        cases.append(dict(workload=f"ENN rollout {candidates}x{samples}, N={neurons}, {dname}",
                          kind="rollout", make=make, x64=x64, bitwise=True))
    return cases


def _identify(model, data, key, options):
    """``jf.identify`` with ``options``; the candidate solver options (a dict equal to
    :data:`CANDIDATE_SOLVER`) replace only what "auto" passes to the optimiser run, so the
    gradient stage keeps its own options as in a user's call."""
    if options is not None and options != "auto":
        saved = _xla.CPU_OPTIONS["solver"]
        _xla.CPU_OPTIONS["solver"] = dict(options)
        try:
            return jf.identify(model, data, key=key)
        finally:
            _xla.CPU_OPTIONS["solver"] = saved
    return jf.identify(model, data, key=key, compiler_options=options)


def _identify_case(model="elman", data=None, label="simulated rig", fixed_key=False):
    """``identify(model)`` with its default pipeline. With ``fixed_key`` every call uses
    key 1, so the variants must agree to the bit (parameters compared)."""
    data = jf.rig.synthetic_friction_data(jax.random.key(0)) if data is None else data

    def make(options):
        counter = [0]

        def call():
            counter[0] += 1
            return _identify(model, data, 1 if fixed_key else counter[0], options)
        if fixed_key:
            return call, lambda fit: np.concatenate(
                [np.ravel(np.asarray(x, np.float64)) for x in jax.tree_util.tree_leaves(fit.params)])
        return call, lambda fit: (float(fit.stages[-1]["J"]), fit.stages[-1]["mse_percent_valid"])
    return dict(workload=f"identify('{model}') on {label}, default pipeline", kind="solver",
                make=make, compare=fixed_key, bitwise=fixed_key)


def _agree(case, a, b):
    if case.get("bitwise"):
        return bool(np.array_equal(a["result"], b["result"]))
    if not case.get("compare", True):
        return None
    return bool(np.isclose(a["result"][0], b["result"][0], rtol=1e-4, atol=1e-6)
                and a["result"][1] == b["result"][1])


def measure(cases, rounds):
    rows = []
    for case in cases:
        x64 = case.get("x64", False)
        timed = []
        with jax.enable_x64(x64):
            for label, options in _variants(case["kind"]):
                call, summary = case["make"](options)
                t0 = time.perf_counter()
                out = jax.block_until_ready(call())
                first = time.perf_counter() - t0
                timed.append(dict(label=label, call=call, first=first, times=[],
                                  result=summary(out)))
            for _ in range(rounds):
                for v in timed:
                    t0 = time.perf_counter()
                    jax.block_until_ready(v["call"]())
                    v["times"].append(time.perf_counter() - t0)
        by = {v["label"]: v for v in timed}
        a, d = by["auto"], by["XLA defaults"]
        # one word per variant against auto, in the table's order (candidate options, defaults)
        same = " / ".join({True: "yes", False: "NO", None: "n/a"}[_agree(case, a, v)]
                          for v in timed[1:])
        med = {v["label"]: statistics.median(v["times"]) for v in timed}
        prev = med["auto"] / med[CANDIDATE] if CANDIDATE in med else None
        rows.append(dict(
            workload=case["workload"],
            options=str(_xla.compiler_options(case["kind"])),
            auto_ms=1e3 * med["auto"],
            candidate_ms=1e3 * med[CANDIDATE] if prev else None,
            default_ms=1e3 * med["XLA defaults"],
            speedup=med["XLA defaults"] / med["auto"],
            candidate_speedup=prev,
            auto_first_s=a["first"], default_first_s=d["first"],
            same_result=same, rounds=rounds,
        ))
        extra = f"  candidate x{prev:.2f}" if prev else ""
        print(f"{case['workload']:50s} auto {rows[-1]['auto_ms']:9.2f} ms  "
              f"default {rows[-1]['default_ms']:9.2f} ms  x{rows[-1]['speedup']:.2f}{extra}  "
              f"same: {rows[-1]['same_result']}", flush=True)
    return rows


def figure(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 0.45 * len(rows) + 1.2))
    y = np.arange(len(rows))
    s = [r["speedup"] for r in rows]
    # Within ±5 % is within this shared machine's noise: grey.
    ax.barh(y, s, color=["tab:green" if v >= 1.05 else "tab:red" if v <= 0.95 else "tab:grey"
                         for v in s])
    ax.axvline(1.0, color="k", lw=0.8)
    ax.set_yticks(y, [r["workload"] for r in rows], fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("speed-up of jaxfric's CPU options over XLA's defaults (median time ratio)")
    for yi, v in zip(y, s):
        ax.text(v, yi, f" {v:.2f}x", va="center", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rounds", type=int, default=15)
    p.add_argument("--seeds", type=int, default=8)
    p.add_argument("--identify", action="store_true", help="also time a default ENN identify")
    p.add_argument("--emps", default=None, metavar="DATA_EMPS.mat",
                   help="also time identify('lugre') and identify('elman') on the EMPS record")
    p.add_argument("--out", default=None)
    p.add_argument("--tag", default="", help="suffix for the output files")
    a = p.parse_args(argv)
    if jax.default_backend() != "cpu":
        print(f"backend {jax.default_backend()}: jaxfric passes no options there; nothing to compare")
        return
    t_start = time.perf_counter()
    cases = _swarm_cases(30, 100, 500, a.seeds) + _rollout_cases(64, 1600, 30)
    rows = measure(cases, a.rounds)
    if a.identify:
        rows += measure([_identify_case()], max(2, a.rounds // 5))
    if a.emps:
        record = jf.rig.emps_friction_data(jf.rig.load_emps(Path(a.emps)))
        rows += measure([_identify_case(m, record, "EMPS", fixed_key=True) for m in ("lugre", "elman")],
                        max(2, a.rounds // 5))
    out = results_dir(a.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = "compiler_options" + (f"_{a.tag}" if a.tag else "")
    with open(out / f"{stem}.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    figure(rows, out / f"{stem}.png")
    flags = open("/proc/cpuinfo").read() if Path("/proc/cpuinfo").exists() else ""
    lines = [
        "# jaxfric's XLA CPU options against XLA's defaults",
        "",
        "Generated by `benchmarks/compiler_options.py`. Each workload compiled with "
        "`compiler_options=\"auto\"` (jaxfric's default), for optimiser runs also with the "
        f"candidate solver options (`{CANDIDATE_SOLVER}`, XLA's newer fusion emitters), and with "
        "`compiler_options=None` (XLA's defaults); timed round-robin in the same process; "
        f"medians over {a.rounds} rounds (identify: fewer), first call (compile + run) apart. "
        "Swarms: float32, 100 agents, PSO 500 generations, MAPSO the same evaluation budget. "
        "'Same result' against auto, for the candidate options / XLA's defaults (one word where only "
        "the defaults run): best value within 1e-4 and equal evaluation count (swarms), "
        "bit-identical outputs (rollouts) or parameters (identify on EMPS, one key).",
        "",
        f"Machine: {platform.machine()}, {len(jax.devices())} device(s), "
        f"AVX-512: {'yes' if 'avx512f' in flags else 'no'}; jax {jax.__version__}. "
        f"Wall time {time.perf_counter() - t_start:.0f} s.",
        "",
        "| workload | XLA options (auto) | auto ms | candidate options ms | XLA defaults ms | "
        "speed-up vs defaults | candidate's speed-up | first call s (auto / defaults) | same result |",
        "|---|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        ns = f"{r['candidate_ms']:.2f}" if r["candidate_ms"] else "-"
        sk = f"{r['candidate_speedup']:.2f}x" if r["candidate_speedup"] else "-"
        lines.append(f"| {r['workload']} | `{r['options']}` | {r['auto_ms']:.2f} | {ns} | "
                     f"{r['default_ms']:.2f} | {r['speedup']:.2f}x | {sk} | "
                     f"{r['auto_first_s']:.2f} / {r['default_first_s']:.2f} | {r['same_result']} |")
    lines += ["", f"![speed-ups]({stem}.png)", ""]
    (out / f"{stem}.md").write_text("\n".join(lines))
    print(f"wrote {out / stem}.md")


if __name__ == "__main__":
    main()
