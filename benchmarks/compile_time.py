"""Where a new objective's compilation goes, per solver, and what an ask costs.

Each test function goes to :func:`jaxfric.minimise` as a *new* Python function (what a user,
or SciPy's global-optimisation suite, does with every new problem): the first call split by
JAX's compile events (tracing, lowering, XLA, programs compiled), the second (another key) the
run alone; on 2-D to 30-D beside SciPy's differential evolution and pycma (``compile_time.md``,
issue 47), or at one ``--dim`` (``--dims ''``). Then an objective outside JAX: milliseconds per
host call by ask/tell and by a ``jax.pure_callback`` objective. ``--cache DIR`` (empty): JAX's
persistent cache, one process fills it, the next reads it, then ``jaxfric demo --quick`` twice
on a new cache. ``--baseline DIR``: the jaxfric package in ``DIR`` measured in turn with this
one, solver by solver, each in a fresh process.

    python benchmarks/compile_time.py [--quick] [--dims 2,5] [--cache DIR] [--baseline DIR]
"""

from __future__ import annotations

import argparse
import collections
import importlib.util
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

import jaxfric as jf  # before _harness, which puts this checkout first: --baseline's PYTHONPATH wins
from jaxfric import functions as F

sys.path.insert(0, str(Path(__file__).resolve().parent))  # not on sys.path under `jaxfric bench`
from _harness import (HERE, add_output_arguments, cell, command, markdown_table, results_dir, tagged, timed,  # noqa: E402
                      write_csv, write_report)
from baselines import NUMPY_BATCH, numpy_batch  # noqa: E402

FUNCTIONS = ["sphere", "rosenbrock", "rastrigin", "ackley", "griewank", "schwefel_2_22"]

_EVENTS = {
    "/jax/core/compile/jaxpr_trace_duration": "trace_s",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower_s",
    "/jax/core/compile/backend_compile_duration": "compile_s",
}
_seen: collections.Counter = collections.Counter()
_programs: list = []


def _listen(event, duration, **kwargs):
    name = _EVENTS.get(event)
    if name is not None:
        _seen[name] += duration
        if name == "compile_s":
            _seen["programs"] += 1
            _programs.append(kwargs.get("fun_name", "?"))


jax.monitoring.register_event_duration_secs_listener(_listen)


def solvers(quick: bool) -> dict:
    g = 20 if quick else 200
    out = {"PSO": jf.PSO(num_generations=g), "MAPSO": jf.MAPSO(num_generations=g // 2),
           "NelderMead": jf.NelderMead(max_steps=10 * g),
           "PSO->NM": jf.chain(jf.PSO(num_generations=g), jf.NelderMead(max_steps=10 * g)),
           "MAPSO-NMDS": jf.mapso_nmds(num_generations=g // 2, nm_max_steps=10 * g)}
    if importlib.util.find_spec("evosax"):
        out["Evosax CMA_ES"] = jf.Evosax("CMA_ES", num_generations=g)
        out["CMA-ES->NM"] = jf.cmaes_nm(num_generations=g, nm_max_steps=10 * g)
    return out


#: the peers of the per-dimension table: whole runs of a user's default call
PEERS = ("SciPy DE", "pycma")
#: the per-dimension table's functions (each has a NumPy twin for the peers)
DIM_FUNCTIONS = ["sphere", "rosenbrock", "rastrigin", "ackley"]
#: the solvers whose host-call costs (ask/tell, pure_callback) are measured
ASK_TELL = ("PSO", "NelderMead", "PSO->NM")


def peer_run(label: str, name: str, n: int, seed: int) -> dict:
    """One whole run of a peer on the box [-2, 2]^n, as a user calls it: SciPy's
    ``differential_evolution`` with its defaults but a vectorised NumPy objective
    (``vectorized=True``, ``updating="deferred"``), or pycma's ``fmin2`` with its defaults,
    the box as its bounds, a start drawn in the box, σ0 = 1 and ``maxfevals = 1000·n``
    (its own default, ~1e3·(n+5)²/√λ, runs minutes at 30-D)."""
    f_batch = numpy_batch(name)

    def run():
        if label == "SciPy DE":
            import scipy.optimize

            res = scipy.optimize.differential_evolution(lambda X: f_batch(np.asarray(X).T), [(-2.0, 2.0)] * n,
                                                        seed=seed, vectorized=True, updating="deferred")
            return float(res.fun), int(res.nfev)
        import cma

        es = cma.fmin2(lambda x: float(f_batch(np.asarray(x)[None])[0]), np.random.default_rng(seed).uniform(-2, 2, n),
                       1.0, {"bounds": [-2.0, 2.0], "verbose": -9, "seed": seed + 1, "maxfevals": 1000 * n})[1]
        return float(es.result.fbest), int(es.result.evaluations)

    (f, evals), whole, cpu = timed(run)
    return {"first_s": whole, "second_s": whole, "cpu_s": cpu, "compile_s": 0.0,
            "trace_s": 0.0, "lower_s": 0.0, "programs": 0, "f": f, "evals": evals}


def _warm() -> None:
    """JAX's own first-use costs, paid before anything is measured."""
    jf.minimise(fresh_objective("sphere"), jf.PSO(num_generations=2, num_particles=4),
                (-np.ones(2), np.ones(2)), key=0)


def fresh_objective(name: str):
    """A new Python function for the test function ``name`` (a jit cache miss)."""
    fn = F.get(name).fn
    return lambda y, args: fn(y)


#: a label ending in it measures the solver of the label before it with
#: ``compiler_options="fast-compile"`` (``--solvers "PSO->NM,PSO->NM fast-compile"``)
FAST = " fast-compile"


def measure_compile(solver, name: str, n: int, key: int, options="auto") -> dict:
    fn = fresh_objective(name)
    bounds = (-2.0 * np.ones(n), 2.0 * np.ones(n))
    _seen.clear()
    _programs.clear()
    run = lambda k: jax.block_until_ready(jf.minimise(fn, solver, bounds, key=k, compiler_options=options))  # noqa: E731
    sol, first, cpu = timed(lambda: run(key))
    row = {"first_s": first, "cpu_s": cpu, **{k: _seen.get(k, 0.0) for k in ("trace_s", "lower_s", "compile_s")},
           "programs": int(_seen.get("programs", 0)), "compiled": " ".join(_programs),
           "f": float(sol.f), "evals": int(sol.stats["num_evals"])}
    row["second_s"] = timed(lambda: run(key + 1))[1]
    return row


def _numpy_sphere(X):
    X = np.asarray(X, np.float64)
    return NUMPY_BATCH["sphere"](X.reshape(-1, X.shape[-1])).reshape(X.shape[:-1])


def ask_tell_ms(solver, n: int, seeds: int = 1) -> tuple[float, int]:
    """Milliseconds per ask of one ask/tell run told a NumPy sphere's values, after a
    first run has compiled the program; and the asks of a run. ``seeds`` > 1: one run of
    that many keys (``ask_init(..., keys=)``), each ask carrying every seed's batch."""
    lo, hi = np.full(n, -2.0, np.float32), np.full(n, 2.0, np.float32)

    def drive(seed):
        key = jax.random.key(seed)
        st = (jf.ask_init(solver, lo, hi, key) if seeds == 1 else
              jf.ask_init(solver, lo, hi, keys=jax.random.split(key, seeds)))
        asks = 0
        while not jf.ask_done(st):
            X, st = jf.ask(st)
            X = np.asarray(X)
            st = jf.tell(st, X, _numpy_sphere(X))
            asks += 1
        return asks

    drive(100)  # compiles
    t0 = time.perf_counter()
    asks = drive(0)
    return 1e3 * (time.perf_counter() - t0) / asks, asks


def callback_ms(solver, n: int, seeds: int) -> tuple[float, int]:
    """Milliseconds per host call of the documented recipe for an objective outside JAX:
    a ``jax.pure_callback`` objective under ``minimise`` (one seed) or ``minimise_many``
    (``seeds`` keys, each callback carrying every run's batch when the runs are
    vmapped); and the host calls of the whole call."""
    calls = [0]

    def host(X):
        calls[0] += 1
        return _numpy_sphere(X).astype(np.asarray(X).dtype)

    def fn(y, args):
        return jax.pure_callback(host, jax.ShapeDtypeStruct(y.shape[:-1], y.dtype), y, vmap_method="broadcast_all")

    box = (np.full(n, -2.0, np.float32), np.full(n, 2.0, np.float32))
    keys = jax.random.split(jax.random.key(0), seeds)
    run = (lambda: jf.minimise(fn, solver, box, key=0)) if seeds == 1 else (
        lambda: jf.minimise_many(fn, solver, box, keys=keys))
    run()  # compiles
    calls[0] = 0
    t0 = time.perf_counter()
    run()
    return 1e3 * (time.perf_counter() - t0) / calls[0], calls[0]


def measure(label: str, functions, dim: int, seeds: int, dims=None) -> dict:
    """Every measurement of one solver, in this process (``--one``): the compile rows of
    ``functions`` at ``dim``, or with ``dims`` of the per-dimension table's functions at
    each of ``dims``; then, for the ask/tell solvers, the host-call costs at ``dim``."""
    quick = len(functions) < len(FUNCTIONS)
    per_dim = DIM_FUNCTIONS[:2] if quick else DIM_FUNCTIONS
    with jax.enable_x64(True):
        if label in PEERS:
            return {"rows": [{"function": name, "dim": n, **peer_run(label, name, n, i)} for n in dims
                             for i, name in enumerate(per_dim)], "asks": []}
        _warm()
        solver = solvers(quick)[label.removesuffix(FAST)]
        options = "fast-compile" if label.endswith(FAST) else "auto"
        rows = [{"function": name, **({"dim": n} if dims else {}),
                 **measure_compile(solver, name, n, key=i, options=options)}
                for n in dims or [dim] for i, name in enumerate(per_dim if dims else functions)]
    asks = [{"route": route, "seeds": k, **dict(zip(("ms_per_host_call", "host_calls"), fn(solver, dim, k)))}
            for route, fn in (("ask/tell", ask_tell_ms), ("pure_callback", callback_ms)) for k in (1, seeds)
            if label in ASK_TELL and seeds and hasattr(jf, "ask_init")]  # float32; keys=: seeds in one run
    return {"rows": rows, "asks": asks}


def _in_subprocess(label, a, pythonpath=None) -> dict:
    """:func:`measure` in a fresh process (``pythonpath``: the library to measure)."""
    env = dict(os.environ, **({"PYTHONPATH": os.pathsep.join([pythonpath, str(HERE)])} if pythonpath else {}))
    cmd = [sys.executable, str(HERE / "compile_time.py"), "--one", label, "--dim", str(a.dim),
           "--seeds", str(a.seeds), "--dims", a.dims, *(["--quick"] if a.quick else []),
           *(["--functions", a.functions] if a.functions else []), *(["--cache", a.cache] if a.cache else []),
           *(["--no-asktell"] if a.no_asktell else [])]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if done.returncode:
        raise RuntimeError(f"{label} ({pythonpath or 'this'}) failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


DEMO = """
import collections, json, logging, re, sys, jax
events, seconds, hits = collections.Counter(), collections.Counter(), collections.Counter()
def name(s):  # 'jit(_chunk)' (a compile event), 'jit__chunk' (a cache log): '_chunk'
    return re.sub(r"^jit[(_]|[)]$", "", s)
def listen(event, duration, **kw):  # every compilation, including one loaded from the cache
    if event == "/jax/core/compile/backend_compile_duration":
        events[name(kw.get("fun_name", "?"))] += 1; seconds[name(kw.get("fun_name", "?"))] += duration
class Hits(logging.Handler):
    def emit(self, record):
        m = re.match(r"Persistent compilation cache hit for '([^']+)'", record.getMessage())
        if m:
            hits[name(m.group(1))] += 1
logging.getLogger("jax._src.compiler").setLevel(logging.DEBUG)
logging.getLogger("jax._src.compiler").addHandler(Hits())
jax.monitoring.register_event_duration_secs_listener(listen)
from jaxfric.cli import main
rc = main(sys.argv[2:])
json.dump({"rc": rc, "events": dict(events), "seconds": dict(seconds), "hits": dict(hits)}, open(sys.argv[1], "w"))
"""

#: The optimiser's programs (jaxfric.optim.loop: `_chunk`; `_run_many` for ensembles; before issue 47 `_run`).
SOLVER_PROGRAMS = ("_chunk", "_run_many", "_run")


def demo_twice(label: str, cache: Path, work: Path, pythonpath=None) -> list[dict]:
    """``jaxfric demo --quick`` (the library in ``pythonpath``, or this one) run twice
    in new processes on the one, new, cache folder ``cache``, as a user runs it (the
    command line's own cache settings): wall seconds of each process, XLA compilations
    (JAX's compile events, counted and timed by program name) and cache entries."""
    env = dict(os.environ, JAX_COMPILATION_CACHE_DIR=str(cache), JAX_PLATFORMS="cpu",
               **({"PYTHONPATH": pythonpath} if pythonpath else {}))
    rows = []
    for run in (1, 2):
        stats = work / f"{label}-{run}.json"
        cmd = [sys.executable, "-c", DEMO, str(stats), "demo", "--quick", "--out", str(work / f"{label}-{run}")]
        # outside the repository, so PYTHONPATH's library is the one imported
        done, wall, _ = timed(lambda: subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=work))
        if done.returncode:
            raise RuntimeError(f"demo ({label}, run {run}) failed:\n{done.stderr[-3000:]}")
        got = json.loads(stats.read_text())
        compiled = {k: n - got["hits"].get(k, 0) for k, n in got["events"].items()}
        solver = [k for k in SOLVER_PROGRAMS if k in got["events"]]
        rows.append({"version": label, "run": run, "wall_s": wall, "xla_s": sum(got["seconds"].values()),
                     "compiled": sum(compiled.values()), "loaded": sum(got["hits"].values()),
                     "solver_compiled": sum(compiled[k] for k in solver),
                     "solver_loaded": sum(got["hits"].get(k, 0) for k in solver),
                     "cache_entries": len(os.listdir(cache))})
        print(rows[-1], flush=True)
    return rows


def summarise(label, pooled, dims) -> list[dict]:
    """Medians per (version, dimension) of one solver's rows."""
    out = []
    for version, got_rows in pooled.items():
        for n in (dims or [None]):
            per = [r for r in got_rows if n is None or r.get("dim") == n]
            med = lambda k: statistics.median(r[k] for r in per)  # noqa: E731
            out.append({"version": version, "solver": label, **({"dim": n} if n is not None else {}), "runs": len(per),
                        **{k: med(k) for k in ("first_s", "cpu_s", "second_s", "trace_s", "lower_s", "compile_s")},
                        "programs": int(med("programs"))})
            print(out[-1], flush=True)
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_output_arguments(p, tag=True)
    p.add_argument("--dim", type=int, default=5, help="dimension of ask/tell and of --dims ''")
    p.add_argument("--dims", default=None, help="dimensions of the per-dimension table (default 2,5,10,30; "
                   "--quick: 2,5); '' for the single-dimension table")
    p.add_argument("--seeds", type=int, default=4, help="keys of minimise_many and of ask/tell with keys=")
    p.add_argument("--cache", default=None, help="JAX persistent compilation cache folder")
    p.add_argument("--baseline", default=None, help="a folder holding another version's jaxfric package")
    p.add_argument("--note", default="", help="recorded with the results")
    p.add_argument("--solvers", default=None, help="comma-separated labels (default: all)")
    p.add_argument("--repeat", type=int, default=1, help="rounds of the versions in turn; medians over all")
    p.add_argument("--no-asktell", action="store_true", help="compilation only")
    p.add_argument("--functions", default=None, help=f"functions of the per-dimension table (default "
                   f"{','.join(DIM_FUNCTIONS)}; --quick: the first two)")
    p.add_argument("--one", default=None, help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.cache:
        # the script's choice, never the library's: a user option (docs/solvers.md)
        jax.config.update("jax_compilation_cache_dir", a.cache)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    functions = FUNCTIONS[:2] if a.quick else FUNCTIONS
    if a.dims is None:  # the cache's measurements keep their single dimension
        a.dims = "" if a.cache else "2,5" if a.quick else "2,5,10,30"
    dims = [int(d) for d in a.dims.split(",") if d]
    if a.functions:
        DIM_FUNCTIONS[:] = a.functions.split(",")
    if a.one:
        print(json.dumps(measure(a.one, functions, a.dim, 0 if a.no_asktell else a.seeds, dims)))
        return
    out = results_dir(a.out, quick=a.quick)
    if a.cache and Path(a.cache).exists() and os.listdir(a.cache):
        raise SystemExit(f"--cache {a.cache} must be an empty folder")
    versions = ({"cache empty": None, "cache filled": None} if a.cache  # the first fills the cache, the second reads it
                else {"baseline": a.baseline, "this": None} if a.baseline else {"this": None})
    rows, summary, asks = [], [], []
    labels = a.solvers.split(",") if a.solvers else list(solvers(a.quick)) + (list(PEERS) if dims else [])
    for label in labels:
        pooled = collections.defaultdict(list)
        for r in range(a.repeat):
            for version, path in versions.items():
                if label in PEERS and version != next(iter(versions)):
                    continue  # a peer does not depend on jaxfric's version
                got = _in_subprocess(label, a, path)
                pooled[version] += got["rows"]
                rows += [{"version": version, "solver": label, "dim": a.dim, "round": r, **x} for x in got["rows"]]
                asks += [{"version": version, "solver": label, **x} for x in got["asks"]]
        summary += summarise(label, pooled, dims)
    demo = []
    if a.cache:
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            # the versions in turn, each on a new cache of its own: the same load for both
            todo = ([("baseline", a.baseline)] if a.baseline else []) + [("this", None)]
            for r in range(a.repeat):
                for label, path in todo:
                    cache = tmp / f"cache-{label}-{r}"
                    cache.mkdir()
                    demo += [{**row, "round": r} for row in demo_twice(label, cache, tmp, path)]
        write_csv(demo, out / "compile_time_cache_demo.csv")
    load = os.getloadavg()
    stem = tagged("compile_time_cache" if a.cache else "compile_time", a.tag)
    if asks:
        write_csv(asks, out / f"{stem}_asktell.csv")
    fmt = cell(".3g")
    baseline = (f"`baseline`: the library in {a.baseline}, measured in turn with `this` (each solver in a "
                "fresh process, one after the other). " if a.baseline else "")
    heading = _dims_text(summary, dims, a, load, fmt) if dims else [
        f"{a.note}\n\njax {jax.__version__}, float64, {a.dim} parameters, medians over {len(functions)} test "
        f"functions ({', '.join(functions)}) × {a.repeat} round(s) (`runs`), each a new Python function; load "
        f"average at the end {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f}; persistent cache: {a.cache or 'off'}. "
        f"{baseline}Seconds: the first call (a new objective), the second (same objective, another key: the run "
        f"alone), and the first call's tracing, lowering and XLA compilation as JAX reports them "
        f"(`jax.monitoring`); `programs`: XLA compilations in the first call.", markdown_table(summary, fmt=fmt)]
    text = "\n\n".join([
        "# Compilation per new objective", *heading,
        "An objective outside JAX, in float32 (a NumPy sphere, compiled run reused): "
        "milliseconds per host call (an ask, or a `pure_callback` call) and host calls per "
        f"run, by ask/tell (one seed, and {a.seeds} in one run with `keys=`) and by the "
        f"`pure_callback` recipe under `minimise` (one seed) or `minimise_many` ({a.seeds} keys).",
        markdown_table(asks, fmt=fmt) if asks else "(not measured: --no-asktell)",
        *(_demo_text(demo, a, fmt) if demo else []),
        f"Command: `{command('compile_time.py', argv)}`",
    ])
    write_report(out, stem, text, rows)


def _dims_text(summary, dims, a, load, fmt) -> list[str]:
    """The per-dimension table, its verdict on issue 47's target, and what was measured."""
    g = 20 if a.quick else 200
    lines = [
        f"{a.note}\n\njax {jax.__version__}, float64, on [-2, 2]^n; each (function, n) a new Python function, so "
        f"every first call compiles; medians over {len(DIM_FUNCTIONS[:2] if a.quick else DIM_FUNCTIONS)} functions "
        f"({', '.join(DIM_FUNCTIONS[:2] if a.quick else DIM_FUNCTIONS)}) × {a.repeat} round(s) (`runs`); load "
        f"average at the end {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} (2 cores shared with other work: wall "
        f"times carry the load, `cpu_s` much less). Budgets: PSO {g} generations, MAPSO {g // 2}, Nelder–Mead at "
        f"most {10 * g} steps, CMA-ES {g} generations, the chains the same stages. `first_s`: wall seconds of a "
        f"new objective's first `minimise` (compilation and run); `cpu_s`: the process's CPU seconds in it (XLA "
        f"compiles on several threads); `second_s`: the same objective again, another key (the run alone); "
        f"`trace_s`/`lower_s`/`compile_s`: JAX's compile events in the first call; `programs`: XLA compilations in "
        f"it (a solver's objective-free `_finish` compiles once per solver and shape, with the first function "
        f"only). Peers (whole runs, no compilation): SciPy's `differential_evolution` with its defaults and a "
        f"vectorised NumPy objective; pycma's `fmin2` with its defaults, σ0 = 1 and at most 1000·n evaluations.", markdown_table(summary, fmt=fmt),
    ]
    small = [d for d in dims if 2 <= d <= 10]
    for version in dict.fromkeys(r["version"] for r in summary):
        for label in ("PSO->NM", "MAPSO-NMDS", "PSO->NM" + FAST, "MAPSO-NMDS" + FAST):
            if per := [r for r in summary if r["version"] == version and r["solver"] == label and r.get("dim") in small]:
                first, cpu = (statistics.median(r[k] for r in per) for k in ("first_s", "cpu_s"))
                lines.append(f"- {version}, {label}, {min(small)}-D to {max(small)}-D: median "
                             f"first call {first:.2f} s wall, {cpu:.2f} s CPU (issue 47's target: ≤ 1 s)")
    return lines


def _demo_text(demo, a, fmt) -> list[str]:
    medians = []
    for version in dict.fromkeys(r["version"] for r in demo):
        first, second = ([r["wall_s"] for r in demo if r["version"] == version and r["run"] == k] for k in (1, 2))
        m1, m2 = statistics.median(first), statistics.median(second)
        medians.append({"version": version, "rounds": len(first), "first_s": m1, "second_s": m2, "second/first": m2 / m1})
    base = (f" `baseline` is the library in {a.baseline}, run in turn with `this` (each on a "
            "new cache of its own)." if a.baseline else "")
    return [
        "## The command line: `jaxfric demo --quick` twice on one new cache",
        f"Each run a new process with `JAX_COMPILATION_CACHE_DIR` set to a new, empty folder (the command line "
        f"turns the cache on, with JAX's default of writing programs that took at least 1 s to compile); the demo "
        f"shows its progress bars (no `--quiet`).{base} `wall_s`: the process, start to end; `xla_s`: the seconds "
        f"of JAX's compile events (a program loaded from the cache included); `compiled` / `loaded`: programs XLA "
        f"compiled / loaded from the cache; `solver_*`: those of the optimiser's runs (`_chunk`, `_run_many`; "
        f"before issue 47 `_run`); `cache_entries`: files in the cache afterwards; `round`: versions in turn, each "
        f"round on new caches.", markdown_table(demo, fmt=fmt), "Medians over the rounds:",
        markdown_table(medians, fmt=fmt)]


if __name__ == "__main__":
    main()
