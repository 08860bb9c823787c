"""Where a new objective's compilation goes, per solver, and what an ask costs.

For every solver, each of several test functions is handed to :func:`jaxfric.minimise`
as a *new* Python function (what a user, or SciPy's global-optimisation suite, does
with every new problem). The first call's wall time is split with JAX's own compile
events (``jax.monitoring``): tracing to a jaxpr, lowering to StableHLO, XLA's compile,
and the number of programs compiled; the second call (same function, another key) is
the run alone. Then an objective outside JAX: milliseconds per host call on top of a
trivial NumPy objective, by ask/tell (one seed, or several seeds in one run with
``keys=``) and by a ``jax.pure_callback`` objective under ``minimise`` (one seed) or
``minimise_many`` (several seeds in one call).

    python benchmarks/compile_time.py            # results/compile_time.{md,csv}
    python benchmarks/compile_time.py --quick    # results/quick/

The first table (issue 47) runs every solver and chain on 2-D to 30-D (``--dims``), each
(function, dimension) a new objective, beside SciPy's differential evolution and
pycma's whole-run times on the same functions: a benchmarking user's cost per problem.
    python benchmarks/compile_time.py --cache DIR  # JAX's persistent compilation cache
                                   # (a user option) in an empty DIR: one process fills
                                   # it, the next reads it; results/compile_time_cache.*
                                   # then `jaxfric demo --quick` twice on one new cache
                                   # (--no-demo: not), with --baseline DIR's version too

``--baseline DIR`` measures the jaxfric package in ``DIR`` in turn with this one, solver by
solver, each in a fresh process (``git archive <commit> jaxfric | tar -x -C DIR``);
``--note`` records what was measured.
"""

from __future__ import annotations

import argparse
import collections
import functools
import inspect
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import types
from pathlib import Path

import jax
import numpy as np

import jaxfric as jf  # before _harness, which puts this checkout first: --baseline's PYTHONPATH wins
from jaxfric import functions as F

sys.path.insert(0, str(Path(__file__).resolve().parent))  # not on sys.path under `jaxfric bench`
from _harness import HERE, add_output_arguments, cell, command, markdown_table, results_dir, write_csv, write_report  # noqa: E402
from baselines import NUMPY_BATCH  # noqa: E402

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
    out = {
        "PSO": jf.PSO(num_generations=g),
        "MAPSO": jf.MAPSO(num_generations=g // 2),
        "NelderMead": jf.NelderMead(max_steps=10 * g),
        "PSO->NM": jf.chain(jf.PSO(num_generations=g), jf.NelderMead(max_steps=10 * g)),
        "MAPSO-NMDS": jf.mapso_nmds(num_generations=g // 2, nm_max_steps=10 * g),
    }
    try:
        import evosax  # noqa: F401
        out["Evosax CMA_ES"] = jf.Evosax("CMA_ES", num_generations=g)
        out["CMA-ES->NM"] = jf.cmaes_nm(num_generations=g, nm_max_steps=10 * g)
    except ImportError:
        pass
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
    f_batch = NUMPY_BATCH[name]  # checked against jaxfric's function first
    probe = np.random.default_rng(1).uniform(-2, 2, (3, n))
    ref = np.asarray(jax.vmap(F.get(name).fn)(jax.numpy.asarray(probe)))
    np.testing.assert_allclose(f_batch(probe), ref, rtol=1e-9, atol=1e-9)
    c0, t0 = time.process_time(), time.perf_counter()
    if label == "SciPy DE":
        import scipy.optimize

        res = scipy.optimize.differential_evolution(
            lambda X: f_batch(np.asarray(X).T), [(-2.0, 2.0)] * n, seed=seed, vectorized=True,
            updating="deferred")
        f, evals = float(res.fun), int(res.nfev)
    else:
        import cma

        x0 = np.random.default_rng(seed).uniform(-2, 2, n)
        x, es = cma.fmin2(lambda x: float(f_batch(np.asarray(x)[None])[0]), x0, 1.0,
                          {"bounds": [-2.0, 2.0], "verbose": -9, "seed": seed + 1,
                           "maxfevals": 1000 * n})
        f, evals = float(es.result.fbest), int(es.result.evaluations)
    whole, cpu = time.perf_counter() - t0, time.process_time() - c0
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


def measure_compile(solver, name: str, n: int, key: int) -> dict:
    fn = fresh_objective(name)
    bounds = (-2.0 * np.ones(n), 2.0 * np.ones(n))
    _seen.clear()
    _programs.clear()
    c0, t0 = time.process_time(), time.perf_counter()
    sol = jax.block_until_ready(jf.minimise(fn, solver, bounds, key=key))
    first, cpu = time.perf_counter() - t0, time.process_time() - c0
    row = {"first_s": first, "cpu_s": cpu,
           **{k: _seen.get(k, 0.0) for k in ("trace_s", "lower_s", "compile_s")},
           "programs": int(_seen.get("programs", 0)), "compiled": " ".join(_programs),
           "f": float(sol.f), "evals": int(sol.stats["num_evals"])}
    t0 = time.perf_counter()
    jax.block_until_ready(jf.minimise(fn, solver, bounds, key=key + 1))
    row["second_s"] = time.perf_counter() - t0
    return row


def _numpy_sphere(X):
    X = np.asarray(X, np.float64)
    return NUMPY_BATCH["sphere"](X.reshape(-1, X.shape[-1])).reshape(X.shape[:-1])


def _ask_tell_api(solver):
    """ask/tell of the library measured: the functions beside ``minimise``
    (``jf.ask_init(solver, ...)``), or a version's solver methods (before issue 46 item 3);
    ``None`` where it has neither (a version whose NelderMead has no ask/tell)."""
    if hasattr(jf, "ask_init"):
        return types.SimpleNamespace(
            ask_init=functools.partial(jf.ask_init, solver), ask=jf.ask, tell=jf.tell,
            ask_done=jf.ask_done)
    return solver if hasattr(solver, "ask_init") else None


def ask_tell_ms(api, n: int, seeds: int = 1) -> tuple[float, int]:
    """Milliseconds per ask of one ask/tell run told a NumPy sphere's values, after a
    first run has compiled the program; and the asks of a run. ``seeds`` > 1: one run of
    that many keys (``ask_init(..., keys=)``), each ask carrying every seed's batch."""
    lo, hi = np.full(n, -2.0, np.float32), np.full(n, 2.0, np.float32)

    def drive(seed):
        key = jax.random.key(seed)
        st = (api.ask_init(lo, hi, key) if seeds == 1 else
              api.ask_init(lo, hi, keys=jax.random.split(key, seeds)))
        asks = 0
        while not api.ask_done(st):
            X, st = api.ask(st)
            X = np.asarray(X)
            st = api.tell(st, X, _numpy_sphere(X))
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
        return jax.pure_callback(host, jax.ShapeDtypeStruct(y.shape[:-1], y.dtype), y,
                                 vmap_method="broadcast_all")

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
    rows = []
    with jax.enable_x64(True):
        if label in PEERS:
            return {"rows": [{"function": name, "dim": n, **peer_run(label, name, n, i)} for n in dims
                             for i, name in enumerate(DIM_FUNCTIONS[:2] if quick else DIM_FUNCTIONS)],
                    "asks": []}
        _warm()
        solver = solvers(quick)[label]
        for n in dims or [dim]:
            for i, name in enumerate((DIM_FUNCTIONS[:2] if quick else DIM_FUNCTIONS) if dims else functions):
                rows.append({"function": name, **({"dim": n} if dims else {}),
                             **measure_compile(solver, name, n, key=i)})
    asks = []
    if label in ASK_TELL and seeds:  # in float32, JAX's default
        api = _ask_tell_api(solver)
        if api is not None:  # None: a version whose NelderMead has no ask/tell
            many = "keys" in inspect.signature(api.ask_init).parameters
            for k in (1, seeds) if many else (1,):  # keys=: several seeds in one run
                ms, n_asks = ask_tell_ms(api, dim, k)
                asks.append({"route": "ask/tell", "seeds": k, "ms_per_host_call": ms,
                             "host_calls": n_asks})
        for k in (1, seeds):
            ms, calls = callback_ms(solver, dim, k)
            asks.append({"route": "pure_callback", "seeds": k, "ms_per_host_call": ms,
                         "host_calls": calls})
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
        events[name(kw.get("fun_name", "?"))] += 1
        seconds[name(kw.get("fun_name", "?"))] += duration
class Hits(logging.Handler):
    def emit(self, record):
        m = re.match(r"Persistent compilation cache hit for '([^']+)'", record.getMessage())
        if m:
            hits[name(m.group(1))] += 1
log = logging.getLogger("jax._src.compiler")
log.setLevel(logging.DEBUG)
log.addHandler(Hits())
jax.monitoring.register_event_duration_secs_listener(listen)
from jaxfric.cli import main
rc = main(sys.argv[2:])
json.dump({"rc": rc, "events": dict(events), "seconds": dict(seconds), "hits": dict(hits)},
          open(sys.argv[1], "w"))
"""

#: The optimiser's programs (jaxfric.optim.loop: `_chunk`; `_run_many` for ensembles;
#: before issue 47, `_run`).
SOLVER_PROGRAMS = ("_chunk", "_run_many", "_run")


def demo_twice(label: str, cache: Path, work: Path, pythonpath=None, quick=True) -> list[dict]:
    """``jaxfric demo --quick`` (the library in ``pythonpath``, or this one) run twice
    in new processes on the one, new, cache folder ``cache``, as a user runs it (the
    command line's own cache settings): wall seconds of each process, XLA compilations
    (JAX's compile events, counted and timed by program name) and cache entries."""
    env = dict(os.environ, JAX_COMPILATION_CACHE_DIR=str(cache), JAX_PLATFORMS="cpu")
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    rows = []
    for run in (1, 2):
        stats = work / f"{label}-{run}.json"
        cmd = [sys.executable, "-c", DEMO, str(stats), "demo", *(["--quick"] if quick else []),
               "--out", str(work / f"{label}-{run}")]
        t0 = time.perf_counter()
        # outside the repository, so PYTHONPATH's library is the one imported
        done = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=work)
        wall = time.perf_counter() - t0
        if done.returncode:
            raise RuntimeError(f"demo ({label}, run {run}) failed:\n{done.stderr[-3000:]}")
        got = json.loads(stats.read_text())
        compiled = {k: n - got["hits"].get(k, 0) for k, n in got["events"].items()}
        solver = [k for k in SOLVER_PROGRAMS if k in got["events"]]
        rows.append({
            "version": label, "run": run, "wall_s": wall,
            "xla_s": sum(got["seconds"].values()),
            "compiled": sum(compiled.values()),
            "loaded": sum(got["hits"].values()),
            "solver_compiled": sum(compiled[k] for k in solver),
            "solver_loaded": sum(got["hits"].get(k, 0) for k in solver),
            "cache_entries": len(os.listdir(cache)),
        })
        print(rows[-1], flush=True)
    return rows


def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_output_arguments(p)
    p.add_argument("--dim", type=int, default=5, help="dimension of the ask/tell part "
                   "(and of the single-dimension table, with --dims '')")
    p.add_argument("--dims", default=None,
                   help="comma-separated dimensions of the per-dimension table (default "
                        "2,5,10,30; --quick: 2,5); '' for the single-dimension table")
    p.add_argument("--seeds", type=int, default=4,
                   help="keys of the minimise_many recipe and of ask/tell with keys=")
    p.add_argument("--cache", default=None, help="JAX persistent compilation cache folder")
    p.add_argument("--baseline", default=None,
                   help="a folder holding another version's jaxfric package: measured in "
                        "turn with this one, solver by solver (same load for both)")
    p.add_argument("--note", default="", help="recorded with the results")
    p.add_argument("--solvers", default=None, help="comma-separated labels (default: all)")
    p.add_argument("--repeat", type=int, default=1,
                   help="rounds of the versions in turn; medians over all rounds")
    p.add_argument("--no-asktell", action="store_true", help="compilation only")
    p.add_argument("--stem", default=None, help="result file stem (default compile_time)")
    p.add_argument("--no-demo", action="store_true",
                   help="with --cache: leave out `jaxfric demo --quick` run twice")
    p.add_argument("--functions", default=None,
                   help=f"comma-separated functions of the per-dimension table (default "
                        f"{','.join(DIM_FUNCTIONS)}; --quick: the first two)")
    p.add_argument("--one", default=None, help=argparse.SUPPRESS)
    return p.parse_args(argv)


def summarise(label, pooled, dims) -> list[dict]:
    """Medians per (version, dimension) of one solver's rows."""
    out = []
    for version, got_rows in pooled.items():
        for n in (dims or [None]):
            per = [r for r in got_rows if n is None or r.get("dim") == n]
            med = lambda k: statistics.median(r[k] for r in per)  # noqa: E731
            out.append({"version": version, "solver": label, **({"dim": n} if n is not None else {}),
                        "runs": len(per), **{k: med(k) for k in ("first_s", "cpu_s", "second_s", "trace_s",
                                                                   "lower_s", "compile_s")},
                        "programs": int(med("programs"))})
            print(out[-1], flush=True)
    return out


def main(argv=None):
    a = parse(argv)
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
    if a.cache:  # the first process fills the cache, the second reads it
        versions = {"cache empty": None, "cache filled": None}
        if Path(a.cache).exists() and os.listdir(a.cache):
            raise SystemExit(f"--cache {a.cache} must be an empty folder")
    else:
        versions = {"baseline": a.baseline, "this": None} if a.baseline else {"this": None}
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
    if a.cache and not a.no_demo:
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            # the versions in turn, each on a new cache of its own: the same load for both
            todo = ([("baseline", a.baseline)] if a.baseline else []) + [("this", None)]
            for r in range(a.repeat):
                for label, path in todo:
                    cache = tmp / f"cache-{label}-{r}"
                    cache.mkdir()
                    demo += [{**row, "round": r} for row in demo_twice(label, cache, tmp, path, quick=True)]
        write_csv(demo, out / f"{a.stem or 'compile_time_cache'}_demo.csv")
    load = os.getloadavg()
    stem = a.stem or ("compile_time_cache" if a.cache else "compile_time")
    if asks:
        write_csv(asks, out / f"{stem}_asktell.csv")
    fmt = cell(".3g")
    baseline = (f"`baseline`: the library in {a.baseline}, measured in turn with `this` (each solver in a "
                "fresh process, one after the other). " if a.baseline else "")
    heading = _dims_text(summary, dims, a, load, fmt) if dims else [
        f"{a.note}\n\njax {jax.__version__}, float64, {a.dim} parameters, medians over "
        f"{len(functions)} test functions ({', '.join(functions)}) × {a.repeat} round(s) "
        f"(`runs`), each a new Python function; load average at the end {load[0]:.2f} / {load[1]:.2f} / "
        f"{load[2]:.2f}; persistent cache: {a.cache or 'off'}. {baseline}Seconds: the first call (a new "
        "objective), the second (same objective, another key: the run alone), and the "
        "first call's tracing, lowering and XLA compilation as JAX reports them "
        "(`jax.monitoring`); `programs`: XLA compilations in the first call.",
        markdown_table(summary, fmt=fmt)]
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
        f"{a.note}\n\njax {jax.__version__}, float64, on [-2, 2]^n; each (function, n) a new "
        f"Python function, so every first call compiles; medians over {len(DIM_FUNCTIONS[:2] if a.quick else DIM_FUNCTIONS)} "
        f"functions ({', '.join(DIM_FUNCTIONS[:2] if a.quick else DIM_FUNCTIONS)}) × {a.repeat} round(s) "
        f"(`runs`); load average at the end {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} "
        "(2 cores shared with other work: wall times carry the load, `cpu_s` much less). "
        f"Budgets: PSO {g} generations, MAPSO {g // 2}, Nelder–Mead at most {10 * g} steps, "
        f"CMA-ES {g} generations, the chains the same stages. `first_s`: wall seconds of a "
        "new objective's first `minimise` (compilation and run); `cpu_s`: the process's CPU "
        "seconds in it (XLA compiles on several threads); `second_s`: the same objective "
        "again, another key (the run alone); `trace_s`/`lower_s`/`compile_s`: JAX's compile "
        "events in the first call; `programs`: XLA compilations in it (a solver's objective-free "
        "`_finish` compiles once per solver and shape, with the first function only). Peers "
        "(whole runs, no compilation): SciPy's `differential_evolution` with its defaults and "
        "a vectorised NumPy objective; pycma's `fmin2` with its defaults, σ0 = 1 and at most "
        "1000·n evaluations.",
        markdown_table(summary, fmt=fmt),
    ]
    small = [d for d in dims if 2 <= d <= 10]
    for version in dict.fromkeys(r["version"] for r in summary):
        for label in ("PSO->NM", "MAPSO-NMDS"):
            per = [r for r in summary if r["version"] == version and r["solver"] == label
                   and r.get("dim") in small]
            if per:
                first = statistics.median(r["first_s"] for r in per)
                cpu = statistics.median(r["cpu_s"] for r in per)
                lines.append(f"- {version}, {label}, {min(small)}-D to {max(small)}-D: median "
                             f"first call {first:.2f} s wall, {cpu:.2f} s CPU (issue 47's "
                             "target: ≤ 1 s)")
    return lines


def _demo_text(demo, a, fmt) -> list[str]:
    base = (f" `baseline` is the library in {a.baseline}, run in turn with `this` (each on a "
            "new cache of its own)." if a.baseline else "")
    return [
        "## The command line: `jaxfric demo --quick` twice on one new cache",
        "Each run a new process with `JAX_COMPILATION_CACHE_DIR` set to a new, empty folder "
        "(the command line turns the cache on, with JAX's default of writing programs that "
        "took at least 1 s to compile); the demo shows its progress bars (no `--quiet`)."
        f"{base} `wall_s`: the process, start to end; `xla_s`: the seconds of JAX's compile "
        "events (a program loaded from the cache included); `compiled` / `loaded`: programs "
        "XLA compiled / loaded from the cache; `solver_*`: those of the optimiser's runs "
        "(`_chunk`, `_run_many`; before issue 47 `_run`); `cache_entries`: files in the "
        "cache afterwards; `round`: versions in turn, each round on new caches.",
        markdown_table(demo, fmt=fmt),
        *_demo_medians(demo, fmt),
    ]


def _demo_medians(demo, fmt) -> list[str]:
    rows = []
    for version in dict.fromkeys(r["version"] for r in demo):
        first = [r["wall_s"] for r in demo if r["version"] == version and r["run"] == 1]
        second = [r["wall_s"] for r in demo if r["version"] == version and r["run"] == 2]
        rows.append({"version": version, "rounds": len(first),
                     "first_s": statistics.median(first), "second_s": statistics.median(second),
                     "second/first": statistics.median(second) / statistics.median(first)})
    return ["Medians over the rounds:", markdown_table(rows, fmt=fmt)]


if __name__ == "__main__":
    main()
