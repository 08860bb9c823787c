"""What every benchmark script shares: start-up, data, where results go, timing, tables.

* :func:`results_dir` — the one rule for output folders: ``--out`` when given; otherwise
  ``benchmarks/results/`` for a full run and ``benchmarks/results/quick/`` (git-ignored)
  for a ``--quick`` smoke run, so a smoke test never overwrites the committed numbers.
  :func:`add_output_arguments` adds ``--quick`` and ``--out`` with that rule.
* :class:`Case` / :func:`run_round_robin` — time implementations side by side, in turn,
  medians over rounds, so load from other processes on a shared machine hits all alike.
* :func:`write_csv` / :func:`markdown_table` — result rows as CSV and as a Markdown table.
* Start-up: importing this module puts the checkout's ``jaxfric`` first on ``sys.path``;
  :func:`x64` switches a script to float64 (the script's choice: the library never does);
  :func:`emps_file` / :func:`pneumatic` find the real data (``jaxfric.datasets``' folders,
  no download) or return ``None`` so a script can say so and skip; :func:`machine` is
  the one-line machine description every report starts with.

A script starts with ``sys.path.insert(0, str(Path(__file__).resolve().parent))`` (under
``jaxfric bench`` the folder is not on ``sys.path``) and then imports from here.
"""

from __future__ import annotations

import argparse
import csv
import io
import os
import platform
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


def _found(get) -> Path | None:
    from jaxfric import datasets

    try:
        return get(datasets)
    except datasets.DatasetUnavailable:
        return None


def emps_file(path=None) -> Path | None:
    """``DATA_EMPS.mat``: ``path``, else ``$JAXFRIC_EMPS``, else ``jaxfric.datasets``' folders
    (``$JAXFRIC_DATA``, the cache; never a download), else ``../shared/data``; ``None`` if absent."""
    given = path or os.environ.get("JAXFRIC_EMPS")
    if given:
        return Path(given) if Path(given).is_file() else None
    found = _found(lambda d: d.emps_path(download=False))
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


def results_dir(out=None, *, quick: bool = False) -> Path:
    """The output folder: ``out`` if given, else ``results/quick/`` or ``results/`` (created)."""
    path = Path(out) if out is not None else (QUICK_RESULTS if quick else RESULTS)
    path.mkdir(parents=True, exist_ok=True)
    return path


def add_output_arguments(parser: argparse.ArgumentParser, quick_help: str = "tiny sizes (smoke test)") -> None:
    """``--quick`` and ``--out`` (default: :func:`results_dir`'s rule, resolved after parsing)."""
    parser.add_argument("--quick", action="store_true", help=quick_help)
    parser.add_argument("--out", type=Path, default=None,
                        help=f"output folder (default {RESULTS}, or {QUICK_RESULTS} with --quick)")


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


# --------------------------------------------------------------------------- tables
def _columns(rows) -> list[str]:
    keys: list[str] = []
    for r in rows:
        for k in r:
            if k not in keys:
                keys.append(k)
    return keys


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
