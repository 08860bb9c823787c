"""The swarms' two ways of bounding a coordinate, timed side by side.

``jnp.clip(x, lo, hi)`` (``min(max(x, lo), hi)``, each NaN-propagating) and
``jaxfric.optim._base.clip`` (two selects) give the same numbers. XLA:CPU compiles
them differently inside a swarm's fused generation, and the faster one differs by
solver: MAPSO bounds with selects, PSO with ``jnp.clip`` (``pso_move`` in
jaxfric/optim/pso.py).
This script keeps that choice honest: float64, 30-D Rosenbrock and Ackley, 100 agents,
500 generations, one run and 8 seeds vmapped, each solver with each form.

A compiled program cannot switch forms, so each form runs in its own process (the
script calls itself with ``--child``); the two alternate for ``--rounds`` rounds, each
child timing every case ``--repeats`` times after a warm-up, and each ratio is taken
within a round. Writes ``clip_forms.md`` and ``clip_forms.csv``.

    python benchmarks/clip_forms.py            # results/ (about 4 minutes on 2 cores)
    python benchmarks/clip_forms.py --quick    # results/quick/
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import add_output_arguments, markdown_table, results_dir, write_csv  # noqa: E402

FORMS = ("jnp.clip", "selects")
CASES = [(fn, solver, seeds) for fn in ("rosenbrock", "ackley")
         for solver in ("PSO", "MAPSO") for seeds in (1, 8)]


def use_form(form: str) -> None:
    """Make both swarms bound with ``form`` (before anything is compiled)."""
    import jax.numpy as jnp

    from jaxfric.optim import _base, mapso, pso

    chosen = jnp.clip if form == "jnp.clip" else _base.clip
    mapso.clip = chosen  # competition, self-learning and MAPSO's pso_move call
    pso.pso_move.__defaults__ = (True, chosen)  # PSO's pso_move call (zero_at_bounds, clip)


def child(form: str, generations: int, repeats: int, path: Path) -> None:
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    import jaxfric as jf
    from jaxfric import functions as F

    use_form(form)
    out = {}
    for fn, solver, seeds in CASES:
        lo, hi = F.get(fn).bounds(30, jnp.float64)
        obj = F.objective(fn)
        s = (jf.PSO(num_particles=100, num_generations=generations) if solver == "PSO"
             else jf.MAPSO(lattice_size=10, num_generations=generations))
        key = jax.random.key(0)
        if seeds == 1:
            def run():
                return jf.minimise(obj, s, (lo, hi), key=key)
        else:
            keys = jax.random.split(key, seeds)

            def run():
                return jf.minimise_many(obj, s, (lo, hi), keys=keys)
        sol = jax.block_until_ready(run())
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            jax.block_until_ready(run())
            times.append(time.perf_counter() - t0)
        out[f"{fn}/{solver}/{seeds}"] = {
            "s": statistics.median(times),
            "f": np.asarray(sol.f, np.float64).ravel().tolist(),
            "x": np.asarray(sol.value, np.float64).ravel().tolist(),
        }
    path.write_text(json.dumps(out))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--generations", type=int, default=500)
    p.add_argument("--child", choices=FORMS, help=argparse.SUPPRESS)
    p.add_argument("--json", type=Path, help=argparse.SUPPRESS)
    add_output_arguments(p)
    a = p.parse_args(argv)
    if a.child:
        return child(a.child, a.generations, a.repeats, a.json)
    if a.quick:
        a.rounds, a.repeats, a.generations = 1, 2, 50
    rounds: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(a.rounds):
            got = {}
            for form in (FORMS if r % 2 == 0 else FORMS[::-1]):
                path = Path(tmp) / f"{r}-{form}.json"
                subprocess.run([sys.executable, __file__, "--child", form, "--json", str(path),
                                "--generations", str(a.generations), "--repeats", str(a.repeats)],
                               check=True)
                got[form] = json.loads(path.read_text())
            rounds.append(got)
    rows = []
    for fn, solver, seeds in CASES:
        k = f"{fn}/{solver}/{seeds}"
        clip_s = [g["jnp.clip"][k]["s"] for g in rounds]
        sel_s = [g["selects"][k]["s"] for g in rounds]
        ratios = sorted(c / s for c, s in zip(clip_s, sel_s))
        first = rounds[0]
        same_x = first["jnp.clip"][k]["x"] == first["selects"][k]["x"]
        df = max(abs(u - v) / max(abs(u), 1e-300)
                 for u, v in zip(first["jnp.clip"][k]["f"], first["selects"][k]["f"]))
        rows.append({
            "function": fn, "solver": solver, "runs": "one" if seeds == 1 else f"{seeds} seeds vmapped",
            "jnp.clip ms": round(1e3 * statistics.median(clip_s), 2),
            "selects ms": round(1e3 * statistics.median(sel_s), 2),
            "selects speed-up": f"{statistics.median(ratios):.2f}x ({ratios[0]:.2f}-{ratios[-1]:.2f})",
            "same best point": "yes" if same_x else "no",
            "best f, largest relative difference": f"{df:.1e}",
        })
    out = results_dir(a.out, quick=a.quick)
    write_csv(rows, out / "clip_forms.csv")
    import jax

    lines = [
        "# The swarms' clip: jnp.clip against two selects",
        "",
        f"float64, 30-D, 100 agents, {a.generations} generations; each form in its own process, "
        f"the two alternating for {a.rounds} round(s), {a.repeats} timed calls per case after a "
        "warm-up (median); speed-up = jnp.clip time over selects time, median over rounds "
        "(lowest-highest round). 'Same best point': the runs' best positions agree to the bit; "
        "the best values may differ in the last bits, because XLA contracts the objective's "
        "arithmetic differently inside the other fusion.",
        "",
        f"Machine: {platform.machine()}, jax {jax.__version__}, Python {platform.python_version()}. "
        "Re-run: `python benchmarks/clip_forms.py`.",
        "",
        markdown_table(rows),
        "",
    ]
    (out / "clip_forms.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
