"""What a first contact with ask/tell costs: an objective outside JAX drives a solver.

Each case runs in a fresh Python process with no persistent compilation cache (as a new
user's first run), the cases in turn for ``--repeats`` rounds; medians over rounds. The
objective is a NumPy sum of squares in 4-D (the same bits as its JAX twin), evaluated on each batch ``ask`` returns. Per
case: seconds until the first batch, until 40 batches have been told, for the whole run,
the milliseconds an ask costs after the first 40, and the same run through
``jaxfric.minimise`` (a JAX objective, first call: compilation included) with its best
value and evaluation count, which ask/tell must reproduce.

Writes ``ask_tell.md`` and ``ask_tell.csv`` to ``--out`` (default ``benchmarks/results``;
``--quick`` writes to ``benchmarks/results/quick``). Another checkout can be measured
with the same script: ``PYTHONPATH=/path/to/checkout python benchmarks/ask_tell.py --out DIR``.

    python benchmarks/ask_tell.py              # about 3 minutes on a 2-core CPU
    python benchmarks/ask_tell.py --quick      # one round, short runs
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/ is not on sys.path under `jaxfric bench`
from _harness import add_output_arguments, markdown_table, results_dir, write_csv  # noqa: E402

TARGET = [0.5, -0.25, 0.1, 1.0]
CASES = ["pso", "mapso", "mapso_nmds", "pso_nm"]


def build(case: str, quick: bool):
    import jaxfric as jf

    g = 5 if quick else 30
    return {
        "pso": lambda: jf.PSO(num_particles=20, num_generations=2 * g),
        "mapso": lambda: jf.MAPSO(lattice_size=3, num_generations=g),
        "mapso_nmds": lambda: jf.mapso_nmds(lattice_size=3, num_generations=g),
        "pso_nm": lambda: jf.chain(jf.PSO(num_particles=20, num_generations=2 * g), jf.NelderMead()),
    }[case]()


def child(case: str, quick: bool) -> dict:
    """One case in this (fresh) process: ask/tell from NumPy, then ``minimise``."""
    t_start = time.perf_counter()
    import jax
    import jax.numpy as jnp
    import numpy as np

    import jaxfric as jf

    target = np.asarray(TARGET, np.float32)
    lo, hi = np.full(4, -2.0, np.float32), np.full(4, 3.0, np.float32)

    # written out term by term: nothing to reassociate, so NumPy and XLA give the same bits
    def f_np(X):
        d = np.asarray(X, np.float32) - target
        return (d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) + (d[:, 2] * d[:, 2] + d[:, 3] * d[:, 3])

    def f_jax(y, t):
        d = y - t
        return (d[0] * d[0] + d[1] * d[1]) + (d[2] * d[2] + d[3] * d[3])

    solver = build(case, quick)
    t_import = time.perf_counter()
    st = solver.ask_init(lo, hi, jax.random.key(0))
    asks, marks = 0, {}
    while not solver.ask_done(st):
        X, st = solver.ask(st)
        if asks == 0:
            marks["first"] = time.perf_counter() - t_import
        st = solver.tell(st, X, f_np(X))
        asks += 1
        if asks == 40:
            marks["forty"] = time.perf_counter() - t_import
    total = time.perf_counter() - t_import
    sol = solver.ask_result(st)
    t0 = time.perf_counter()
    ref = jf.minimise(f_jax, solver, (lo, hi), args=jnp.asarray(target), key=jax.random.key(0))
    jax.block_until_ready(ref.value)
    t_min = time.perf_counter() - t0
    forty = marks.get("forty", total)
    return {
        "case": case, "asks": asks, "import_s": t_import - t_start, "first_s": marks["first"],
        "forty_s": forty, "total_s": total,
        "ms_per_ask": 1e3 * (total - forty) / max(asks - 40, 1),
        "minimise_first_call_s": t_min,
        "f": float(sol.f), "f_minimise": float(ref.f),
        "evals": int(sol.stats["num_evals"]), "evals_minimise": int(ref.stats["num_evals"]),
        "max_abs_dx": float(np.max(np.abs(np.asarray(sol.value) - np.asarray(ref.value)))),
    }


def run_fresh(case: str, quick: bool) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"}
    cmd = [sys.executable, __file__, "--child", case] + (["--quick"] if quick else [])
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"case {case} failed:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _measured() -> str:
    """Which jaxfric was measured: its version and, in a git checkout, its commit."""
    import jaxfric

    pkg = Path(jaxfric.__file__).resolve().parent
    git = ["git", "-C", str(pkg.parent)]
    try:
        commit = subprocess.run([*git, "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True, check=True).stdout.strip()
        dirty = subprocess.run([*git, "status", "--porcelain", "--", str(pkg)], capture_output=True,
                               text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return f"jaxfric {jaxfric.__version__}"
    return f"jaxfric {jaxfric.__version__} at commit {commit}" + (" with changes" if dirty else "")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3, help="rounds of fresh processes (default 3)")
    ap.add_argument("--child", choices=CASES, help=argparse.SUPPRESS)
    add_output_arguments(ap, "one round of short runs (smoke test)")
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child, args.quick)))
        return
    repeats = 1 if args.quick else args.repeats
    runs: dict[str, list[dict]] = {c: [] for c in CASES}
    for r in range(repeats):
        for c in CASES:
            runs[c].append(run_fresh(c, args.quick))
            print(f"round {r + 1}/{repeats} {c}: {runs[c][-1]['forty_s']:.1f} s to 40 asks", flush=True)
    rows = []
    for c in CASES:
        rs = runs[c]
        med = {k: statistics.median(r[k] for r in rs)
               for k in ("first_s", "forty_s", "total_s", "ms_per_ask", "minimise_first_call_s")}
        last = rs[-1]
        rows.append({"case": c, "asks": last["asks"], **{k: round(v, 2) for k, v in med.items()},
                     "same_evals": all(r["evals"] == r["evals_minimise"] for r in rs),
                     "f": last["f"], "f_minimise": last["f_minimise"],
                     "max_abs_dx": max(r["max_abs_dx"] for r in rs)})
    out = results_dir(args.out, quick=args.quick)
    write_csv(rows, out / "ask_tell.csv")
    head = [f"# ask/tell first contact ({'quick' if args.quick else f'{repeats} rounds'})", "",
            f"{_measured()}, Python "
            f"{platform.python_version()}, {platform.machine()}, float32, 4-D sum of squares in "
            "NumPy; each case in a fresh process without a compilation cache; medians over rounds. "
            "`first_s`, `forty_s`, `total_s`: seconds after import until the first batch, after 40 "
            "told batches, for the whole run; `ms_per_ask` after the first 40; "
            "`minimise_first_call_s`: the same run through `minimise` (JAX objective, compilation "
            "included); `same_evals`: ask/tell and `minimise` count the same evaluations; "
            "`max_abs_dx`: largest distance between their best points.", "",
            "Command: `python benchmarks/ask_tell.py" + (" --quick" if args.quick else "") + "`", "", ""]
    (out / "ask_tell.md").write_text("\n".join(head) + markdown_table(rows) + "\n")
    print(markdown_table(rows))


if __name__ == "__main__":
    main()
