"""Throughput of ``jaxfric.sweep``: runs per second over a (model, record, seed) grid.

Records: the EMPS estimation record (``--data``, else :func:`_harness.emps_file`) cut into ``--segments`` equal pieces, each its own record; without the file,
simulated Coulomb + viscous friction records of the same length. Models: ``--models``
(default LuGre and Dahl, the library's default solver for each); seeds ``0 .. K-1``.

Reported: the sweep's wall time and runs/s; the first run of each model (it compiles; the
other runs of the model reuse its program, records of equal length included) and the
median of the others; the time to "resume" the finished sweep (every run read back from
its fit file, none recomputed). ``--tag gpu`` names the outputs ``sweep_gpu.*``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import add_output_arguments, emps_file, markdown_table, results_dir, write_csv  # noqa: E402


def _device() -> str:
    import jax

    d = jax.devices()[0]
    return f"{d.platform}:{getattr(d, 'device_kind', '')}".rstrip(":")


def records(path, segments: int, length: int | None):
    from jaxfric.records import FrictionData

    if path is not None:
        from jaxfric import rig

        data = rig.emps_friction_data(rig.load_emps(path))
        v, f, dt = data.velocity[: data.n_train], data.friction[: data.n_train], float(data.dt)
        source = f"EMPS estimation window ({path.name if hasattr(path, 'name') else path})"
    else:
        n = 20000
        dt = 1e-3
        t = np.arange(n) * dt
        v = 0.1 * np.sin(2 * np.pi * 0.3 * t) * np.sin(2 * np.pi * 0.05 * t + 0.4)
        f = 20.0 * np.tanh(v / 1e-3) + 200.0 * v + 0.5 * np.random.default_rng(0).normal(size=n)
        source = "simulated Coulomb + viscous friction (EMPS file not found)"
    size = len(v) // segments if length is None else length
    out = {f"seg{i}": FrictionData.from_arrays(v[i * size:(i + 1) * size], f[i * size:(i + 1) * size], dt)
           for i in range(segments)}
    return out, source, size


def ls_valid_mse(rec) -> float:
    """Validation MSE % of the least-squares Coulomb + viscous + offset baseline, fitted on
    the record's training window (the yardstick for accuracy on real data)."""
    from jaxfric.metrics import friction_metrics

    n, v, f = rec.n_train, np.asarray(rec.velocity), np.asarray(rec.friction)
    a = np.column_stack([np.sign(v), v, np.ones_like(v)])
    coef = np.linalg.lstsq(a[:n], f[:n], rcond=None)[0]
    return float(friction_metrics(f[n:], a[n:] @ coef)["mse_percent"])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_output_arguments(p)
    p.add_argument("--data", type=Path, default=None, help="DATA_EMPS.mat (default: _harness.emps_file)")
    p.add_argument("--models", default="lugre,dahl")
    p.add_argument("--segments", type=int, default=4)
    p.add_argument("--keys", type=int, default=4)
    p.add_argument("--tag", default="", help="suffix of the output names (e.g. gpu)")
    args = p.parse_args(argv)
    out = results_dir(args.out, quick=args.quick)

    import jaxfric

    models = args.models.split(",")
    segments, keys, length = (args.segments, args.keys, None) if not args.quick else (2, 2, 1000)
    if args.quick:
        models = models[:1]
    recs, source, size = records(emps_file(args.data), segments, length)
    options = {}
    if args.quick:
        options["solver"] = jaxfric.MAPSONMDS(mapso=jaxfric.MAPSO(lattice_size=3, num_generations=5),
                                              nelder_mead=jaxfric.NelderMead(max_steps=50))
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        res = jaxfric.sweep(models, recs, keys, Path(tmp) / "sweep", progress=False, **options)
        wall = time.perf_counter() - t0
        t0 = time.perf_counter()
        again = jaxfric.sweep(models, recs, keys, Path(tmp) / "sweep", progress=False, **options)
        resume = time.perf_counter() - t0
        assert again.computed == [] and len(again.done) == len(res.runs)
    rows = []
    for m in models:
        times = [r["run_s"] for r in res.rows if r["model"] == m]
        rows.append({"device": _device(), "model": m, "records": segments, "samples": size, "seeds": keys,
                     "runs": len(times), "first_run_s": times[0],
                     "median_other_run_s": statistics.median(times[1:]) if len(times) > 1 else float("nan"),
                     "valid_mse_percent_median": statistics.median(
                         r["valid_mse_percent"] for r in res.rows if r["model"] == m),
                     "ls_baseline_valid_mse_percent_median": statistics.median(
                         ls_valid_mse(r) for r in recs.values())})
    rows.append({"device": _device(), "model": "all", "records": segments, "samples": size, "seeds": keys,
                 "runs": len(res.runs), "sweep_wall_s": wall, "runs_per_s": len(res.runs) / wall,
                 "resume_s": resume})
    name = "sweep" + (f"_{args.tag}" if args.tag else "")
    write_csv(rows, out / f"{name}.csv")
    fmt = lambda v: f"{v:.3g}" if isinstance(v, float) else str(v)  # noqa: E731
    text = [f"# jaxfric.sweep throughput ({_device()})", "",
            f"`python benchmarks/sweep.py{' --quick' if args.quick else ''}"
            f"{' --tag ' + args.tag if args.tag else ''}`: models {', '.join(models)} (identify's default "
            f"solver{' replaced by a tiny one (--quick)' if args.quick else ''}), {segments} records of "
            f"{size} samples from the {source}, seeds 0..{keys - 1}; one process. `first_run_s` "
            "includes compilation; `resume_s`: the same sweep again, every run read back. Accuracy: "
            "validation MSE % (each record's last 20 %) against the least-squares Coulomb + viscous + "
            "offset baseline fitted on the same record's training window.", "",
            markdown_table(rows, fmt=fmt), ""]
    (out / f"{name}.md").write_text("\n".join(text))
    print("\n".join(text))
    return 0


if __name__ == "__main__":
    sys.exit(main())
