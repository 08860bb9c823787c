"""What every benchmark script shares: start-up, data, where results go, timing, tables.

Importing it puts the checkout's ``jaxfric`` first on ``sys.path``. :func:`results_dir`: ``--out``
when given, else ``results/``, or ``results/quick/`` (git-ignored) for ``--quick``, so a smoke run
never overwrites the committed numbers. Real data (:func:`emps_file`, :func:`pneumatic`) comes from
``jaxfric.datasets``' folders, never a download, or is ``None`` (:func:`skipped`). A script starts
with ``sys.path.insert(0, str(Path(__file__).resolve().parent))`` (under ``jaxfric bench`` the
folder is not on ``sys.path``) and then imports from here.
"""

from __future__ import annotations

import argparse
import csv
import io
import os
import platform
import re
import shlex
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
QUICK_RESULTS = RESULTS / "quick"
ROOT = HERE.parent
if (ROOT / "jaxfric").is_dir() and str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))  # this checkout's jaxfric, installed or not
#: the data folder next to a checkout (``../shared/data``), the last place looked in
SHARED_DATA = ROOT.parent / "shared" / "data"


# --------------------------------------------------------------------------- start-up
def x64() -> None:
    """Switch this process to float64 (call before any array is made)."""
    import jax

    jax.config.update("jax_enable_x64", True)


def machine() -> str:
    """Machine, cores, load and versions, for a report's first lines."""
    import jax
    import numpy

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return (f"{platform.machine()}, {os.cpu_count()} CPU cores (load average {load:.1f}); devices: "
            f"{', '.join(sorted({d.platform for d in jax.devices()}))}; jax {jax.__version__}, "
            f"numpy {numpy.__version__}, Python {platform.python_version()}")


def emps_file(path=None) -> Path | None:
    """``DATA_EMPS.mat``: ``path``, else ``$JAXFRIC_EMPS``, else ``jaxfric.datasets``' folders
    (``$JAXFRIC_DATA``, the cache; never a download), else ``../shared/data``; ``None`` if absent."""
    from jaxfric import datasets

    given = path or os.environ.get("JAXFRIC_EMPS")
    if given:
        return Path(given) if Path(given).is_file() else None
    try:
        found = datasets.emps_path(download=False)
    except datasets.DatasetUnavailable:
        found = None
    if found is None and (SHARED_DATA / "emps" / "DATA_EMPS.mat").is_file():
        found = SHARED_DATA / "emps" / "DATA_EMPS.mat"
    return found


def pneumatic(seal: str = "O-ring", bar: int = 3, folder=None):
    """``(measurements, friction_data)`` of one pneumatic seal recording
    (:func:`jaxfric.datasets.pneumatic`; ``folder`` holds ``raw/``), or ``None`` if absent."""
    from jaxfric import datasets

    local = folder or os.environ.get("JAXFRIC_PNEUMATIC_DATA")
    candidates = [Path(local).parent] if local else [None, SHARED_DATA]
    for where in candidates:
        try:
            return datasets.pneumatic(seal, bar, where, download=False)
        except datasets.DatasetUnavailable:
            continue
    return None


def friction_record(record: str, data_dir=None):
    """``(FrictionData or None, description)`` of ``--record``: ``rig`` (the simulated rig,
    key 0, 1600/400), ``emps`` (the EMPS estimation file at 1 kHz, the benchmark's recipe,
    80 % training) or ``oring`` (the pneumatic O-ring at 3 bar, 80 % training); ``data_dir``
    holds ``DATA_EMPS.mat`` or ``pneumatic_seal_friction/``. ``None`` with the reason when absent."""
    import jax

    from jaxfric import rig

    if record == "rig":
        return rig.synthetic_friction_data(jax.random.key(0)), "simulated rig, key 0 (2000 samples, 128 Hz)"
    if record == "emps":
        path = emps_file(data_dir and Path(data_dir) / "DATA_EMPS.mat")
        if path is None:
            return None, "no EMPS file (pass --data-dir or set JAXFRIC_DATA)"
        return (rig.emps_friction_data(rig.load_emps(path)),
                "EMPS estimation file at 1 kHz (DATA_EMPS.mat, the benchmark's recipe, IDIM-LS mass, 80 % training)")
    rec = pneumatic("O-ring", 3, data_dir)
    if rec is None:
        return None, "no O-ring_3bar.csv (pass --data-dir or set JAXFRIC_DATA)"
    return rec[1].with_split(0.8), "pneumatic O-ring_3bar.csv (jaxfric.datasets.pneumatic pipeline)"


def emps_motion(path):
    """``DATA_EMPS.mat`` as :class:`jaxfric.motion.MotionData`: force ``gtau·vir``, position
    ``qm``, the benchmark's 100 Hz filter for the initial states' velocity."""
    from jaxfric.motion import MotionData
    from jaxfric.rig.emps import EMPS_CUTOFF_HZ, load_emps

    rec = load_emps(path)
    return MotionData.from_arrays(rec.force, rec.qm, rec.dt, cutoff=EMPS_CUTOFF_HZ)


def fit_cells(fit) -> dict:
    """An ``identify`` fit's cells: validation and training MSE % (NaN where absent), and the
    run and compile seconds of its global and gradient stages together."""
    t, m = fit.timings, fit.metrics
    return {"valid": (m.get("valid") or {}).get("mse_percent", float("nan")),
            "train": (m.get("train") or {}).get("mse_percent", float("nan")),
            "run_s": t.get("run_s", 0.0) + t.get("refine_run_s", 0.0),
            "compile_s": t.get("compile_s", 0.0) + t.get("refine_compile_s", 0.0)}


def pyplot():
    """matplotlib's ``pyplot`` on the file-only Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def skipped(name: str, why: str) -> int:
    """Say on stderr that ``name`` wrote nothing and why (its data is absent); exit status 0."""
    print(f"{name}: {why}; skipped, nothing written.", file=sys.stderr)
    return 0


def about(doc: str) -> str:
    """A script's docstring but its first line and its command lines, as Markdown for a
    report's header (what the script measures, written once)."""
    paras = [" ".join(p.split()) for p in doc.split("\n\n")[1:] if not p.lstrip().startswith("python ")]
    return re.sub(r":\w+:`([^`]+)`", r"`\1`", "\n\n".join(paras)).replace("``", "`")


def command(script: str, argv=None) -> str:
    """``python benchmarks/<script> ARGS``, the command line a report quotes (``argv``, else
    this process's arguments; under ``jaxfric bench NAME ARGS``, ``ARGS``)."""
    if argv is None:
        argv = sys.argv[3:] if sys.argv[0].startswith("jaxfric bench") else sys.argv[1:]
    return " ".join([f"python benchmarks/{script}", *map(shlex.quote, argv)])


def results_dir(out=None, *, quick: bool = False) -> Path:
    """The output folder: ``out`` if given, else ``results/quick/`` or ``results/`` (created)."""
    path = Path(out) if out is not None else (QUICK_RESULTS if quick else RESULTS)
    path.mkdir(parents=True, exist_ok=True)
    return path


def add_output_arguments(parser: argparse.ArgumentParser, quick_help: str = "tiny sizes (smoke test)",
                         *, tag: bool = False) -> None:
    """``--quick`` and ``--out`` (default: :func:`results_dir`'s rule, resolved after parsing);
    ``tag``: also ``--tag`` (a suffix of the result files' names, :func:`tagged`)."""
    parser.add_argument("--quick", action="store_true", help=quick_help)
    parser.add_argument("--out", type=Path, default=None,
                        help=f"output folder (default {RESULTS}, or {QUICK_RESULTS} with --quick)")
    if tag:
        parser.add_argument("--tag", default="", help="suffix of the output files (e.g. gpu: NAME_gpu.md)")


def tagged(stem: str, tag: str = "") -> str:
    """``stem`` or ``stem_tag``: the name of a result file measured elsewhere (``--tag gpu``)."""
    return f"{stem}_{tag}" if tag else stem


# --------------------------------------------------------------------------- timing
@dataclass
class Case:
    """One implementation timed round-robin: ``once(r) -> result`` (blocks until done)."""

    label: str
    once: Callable
    x64: bool = False
    max_rounds: int | None = None
    per_round: int = 1  # calls timed together per round (their mean is one sample)
    meta: dict = field(default_factory=dict)
    first: float = 0.0
    times: list = field(default_factory=list)
    results: list = field(default_factory=list)

    @property
    def median(self) -> float:
        return statistics.median(self.times)


def run_round_robin(cases: list[Case], rounds: int) -> None:
    """Warm every case once (its first call: compile + run), then time each case in
    turn, once per round (``per_round`` calls averaged into one sample)."""
    import jax

    for c in cases:
        with jax.enable_x64(c.x64):
            t0 = time.perf_counter()
            c.once(-1)
            c.first = time.perf_counter() - t0
    for r in range(rounds):
        for c in cases:
            if c.max_rounds is not None and r >= c.max_rounds:
                continue
            with jax.enable_x64(c.x64):
                t0 = time.perf_counter()
                for _ in range(c.per_round):
                    res = c.once(r)
                c.times.append((time.perf_counter() - t0) / c.per_round)
            c.results.append(res)


def timed(fn):
    """``(fn(), wall seconds, process CPU seconds)``."""
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c


# --------------------------------------------------------------------------- tables
def cell(spec: str = ".4g", none: str = "") -> Callable[[object], str]:
    """A table-cell formatter: floats with ``format(v, spec)``, ``None`` as ``none``, else ``str``."""
    return lambda v: none if v is None else (format(v, spec) if isinstance(v, float) else str(v))


def spread(values, digits: int = 3) -> str:
    """``mean (min–max)`` of the values that are not ``None``; the value alone for one, – for none."""
    import numpy as np

    a = np.asarray([v for v in values if v is not None], float)
    if a.size == 0:
        return "–"
    return f"{a.mean():.{digits}f}" if a.size == 1 else f"{a.mean():.{digits}f} ({a.min():.{digits}f}–{a.max():.{digits}f})"


def _value(text: str):
    if text in ("True", "False"):
        return text == "True"
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return text


def read_csv(path: Path, *, parse: bool = True) -> list[dict]:
    """The rows of a CSV :func:`write_csv` wrote (none if absent); ``parse``: numbers and
    booleans as such, else every cell as text (a rewrite then keeps it to the character)."""
    path = Path(path)
    if not path.is_file():
        return []
    with path.open(newline="") as f:
        return [{k: _value(v) if parse else v for k, v in row.items()} for row in csv.DictReader(f)]


def _columns(rows) -> list[str]:
    return list(dict.fromkeys(k for r in rows for k in r))


def write_csv(rows, path: Path, *, float_format: str = ".6g") -> Path:
    """Rows (dicts; the union of their keys in first-seen order) as a CSV file."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=_columns(rows), lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (format(v, float_format) if isinstance(v, float) else v) for k, v in r.items()})
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(buf.getvalue())
    return path


def markdown_table(rows, columns: list[str] | None = None, *, headers: list[str] | None = None,
                   fmt: Callable[[object], str] = str) -> str:
    """A GitHub Markdown table of ``rows`` (dicts) over ``columns`` (default: all keys)."""
    columns = columns or _columns(rows)
    headers = headers or columns
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    for r in rows:
        lines.append("| " + " | ".join(fmt(r.get(c, "")) for c in columns) + " |")
    return "\n".join(lines)


def write_report(out: Path, stem: str, text, rows=None, *, float_format: str = ".6g", echo: bool = True) -> Path:
    """``<out>/<stem>.md`` (``text``: a string or a list of lines) and, with ``rows``,
    ``<stem>.csv`` (:func:`write_csv`); ``echo``: print the page. Returns the ``.md`` path."""
    if rows is not None:
        write_csv(rows, Path(out) / f"{stem}.csv", float_format=float_format)
    text = "\n".join(text) if isinstance(text, (list, tuple)) else text
    path = Path(out) / f"{stem}.md"
    path.write_text(text.rstrip("\n") + "\n")
    print(text if echo else f"wrote {path}")
    return path
