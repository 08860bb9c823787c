"""Sweeps: every (model, record, key) identification as one resumable call.

``jaxfric.sweep(models, records, keys, out_dir)`` runs [`jaxfric.identify`][jaxfric.identification.identify] (or
[`jaxfric.identify_motion`][jaxfric.motion.identify_motion] for [`jaxfric.MotionData`][jaxfric.motion.MotionData] records) once per
combination and writes, under ``out_dir``:

* ``fits/<model>/<record>/seed<k>.npz`` -- one [`jaxfric.Fit.save`][jaxfric.fit.Fit.save] file per run;
* ``results.csv`` -- one row per finished run (model, record, seed, cost, the metrics of
  every window, the run's wall time and its fit file), in the sweep's order;
* ``sweep.json`` -- what each model and record label stands for (the model
  configuration with the identify options, a SHA-256 of each record's arrays).

Every file is written atomically ([`jaxfric.files.atomic_write`][jaxfric.files.atomic_write]); a run whose
fit file exists is read back, not recomputed, so calling the same sweep again finishes
an interrupted one. Run ``i`` of the sweep's order belongs to process ``i % process_count``;
under JAX's distributed runtime process 0 writes the table of every run at the end.
Resuming, batching and several processes or hosts: docs/scale.md, "Sweeps".
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import numbers
import re
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .files import atomic_write_text, write_json
from .records import check_int

__all__ = ["Run", "SweepResult", "TABLE_COLUMNS", "read_table", "sweep"]

#: The table's leading columns; the metric columns follow (``<window>_<metric>``).
TABLE_COLUMNS = ("model", "record", "seed", "cost", "num_params", "run_s", "fit_file")
_LABEL = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+=-]*$")
_WINDOWS = ("train", "valid", "all", "train_kstep", "valid_kstep")
#: The metrics of each window the table keeps (friction fits: MSE %, FIT %, MAX [N],
#: R²; motion fits: position RMSE and MAX in mm, FIT %); the fit files hold them all.
_METRICS = ("mse_percent", "fit_percent", "max_abs", "r2", "rmse_mm", "max_abs_mm")


@dataclasses.dataclass(frozen=True)
class Run:
    """One (model, record, seed) combination; ``index`` is its place in the sweep."""

    model: str
    record: str
    seed: int
    index: int

    @property
    def fit_file(self) -> str:
        """The fit's path relative to the sweep folder."""
        return f"fits/{self.model}/{self.record}/seed{self.seed}.npz"


@dataclasses.dataclass
class SweepResult:
    """What [`sweep`][jaxfric.sweeps.sweep] did: ``rows`` (one dict per finished run, the table's rows in
    the sweep's order), the runs this call ``computed`` and those it found ``done``
    already, and the ``out_dir``. [`fit`][jaxfric.sweeps.SweepResult.fit] loads one run's fit."""

    out_dir: Path
    runs: list[Run]
    rows: list[dict]
    computed: list[Run]
    done: list[Run]
    motion: bool = False

    @property
    def table(self) -> Path:
        return self.out_dir / "results.csv"

    def fit(self, model: str, record: str, seed: int):
        """The saved fit of run ``(model, record, seed)``."""
        for run in self.runs:
            if (run.model, run.record, run.seed) == (model, record, int(seed)):
                return _load(self.out_dir / run.fit_file, self.motion)
        raise KeyError(f"no run ({model!r}, {record!r}, {seed!r}) in this sweep")


# ----------------------------------------------------------------- arguments
def _check_label(label, what: str) -> str:
    if not isinstance(label, str) or not _LABEL.match(label):
        raise ValueError(f"{what} label {label!r} must be a non-empty name of letters, digits and "
                         "'_.+=-' (it names folders under out_dir)")
    return label


def _models(models) -> dict[str, tuple[Any, dict]]:
    """Label -> (model, its own identify options); a model is a name or an instance."""
    from .fit import model_name
    from .models import AbstractFrictionModel

    def entry(m):
        if isinstance(m, tuple) and len(m) == 2 and isinstance(m[1], Mapping):
            return m[0], dict(m[1])
        return m, {}

    if isinstance(models, Mapping):
        items = [(label, *entry(m)) for label, m in models.items()]
    else:
        if isinstance(models, (str, AbstractFrictionModel)):
            models = [models]
        items = []
        for m in models:
            if isinstance(m, str):
                label = m.strip().lower().replace("-", "_")
            elif isinstance(m, AbstractFrictionModel):
                label = model_name(m) or type(m).__name__.lower()
            else:
                raise ValueError(f"models must be names, model instances or a mapping label -> model "
                                 f"(or -> (model, options)), got {type(m).__name__}")
            items.append((label, m, {}))
    if not items:
        raise ValueError("models is empty: give at least one model")
    labels = [label for label, _, _ in items]
    twice = sorted({x for x in labels if labels.count(x) > 1})
    if twice:
        raise ValueError(f"model label(s) {twice} appear twice; give a mapping label -> model "
                         "(e.g. {'elman10': Elman(neurons=10), 'elman30': Elman()})")
    for label, m, _ in items:
        if not isinstance(m, (str, AbstractFrictionModel)):
            raise ValueError(f"model {label!r} must be a name or a model instance, got {type(m).__name__}")
    return {_check_label(label, "model"): (m, opts) for label, m, opts in items}


def _records(records) -> dict[str, Any]:
    if isinstance(records, Mapping):
        items = list(records.items())
    elif isinstance(records, (list, tuple)) and records and not isinstance(records[0], numbers.Number):
        items = [(f"record{i}", r) for i, r in enumerate(records)]
    else:
        raise ValueError("records must be a mapping label -> record or a list of records "
                         "(FrictionData, MotionData or (velocity, friction, dt) tuples)")
    if not items:
        raise ValueError("records is empty: give at least one record")
    return {_check_label(label, "record"): r for label, r in items}


def _seeds(keys) -> list[int]:
    if isinstance(keys, numbers.Integral) and not isinstance(keys, bool):
        if keys < 1:
            raise ValueError(f"keys must be a number of seeds >= 1 or a list of seeds, got {keys}")
        return list(range(int(keys)))
    try:
        seeds = list(keys)
    except TypeError:
        raise ValueError(f"keys must be a number of seeds or a list of int seeds, got {keys!r}") from None
    bad = [s for s in seeds if not isinstance(s, numbers.Integral) or isinstance(s, bool) or s < 0]
    if bad or not seeds:
        raise ValueError("keys must be a number of seeds or a non-empty list of int seeds >= 0 "
                         f"(each run's key is jax.random.key(seed)), got {keys!r}")
    seeds = [int(s) for s in seeds]
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"keys holds a seed twice: {seeds}")
    return seeds


def _processes(process_index, process_count) -> tuple[int, int, bool]:
    """``(index, count, distributed)``: given, or JAX's (then ``distributed`` is whether
    JAX's runtime joins several processes)."""
    if (process_index is None) != (process_count is None):
        raise ValueError("give both process_index and process_count, or neither")
    if process_index is None:
        import jax

        count = jax.process_count()
        return jax.process_index(), count, count > 1
    count = check_int("process_count", process_count)
    return check_int("process_index", process_index, 0, count - 1, " (below process_count)"), count, False


def _record_digest(record) -> str:
    """SHA-256 of a record's arrays and sample time (what the fit depends on)."""
    h = hashlib.sha256()
    if isinstance(record, tuple):
        parts = list(record)
    else:
        parts = [getattr(record, f.name) for f in dataclasses.fields(record)
                 if f.name not in ("name",)] if dataclasses.is_dataclass(record) else [
            getattr(record, k, None) for k in ("velocity", "friction", "force", "position", "load",
                                               "p1", "p2", "dt", "n_train")]
    for p in parts:
        a = np.asarray(p) if p is not None else np.zeros(0)
        h.update(str(a.dtype).encode() + str(a.shape).encode())
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def _model_entry(model, options: dict) -> dict:
    from .fit import model_config

    described = ({"name": model} if isinstance(model, str)
                 else {"class": type(model).__name__, "config": model_config(model)})
    return {**described, "options": {k: repr(v) for k, v in sorted(options.items())}}


def _check_manifest(out: Path, manifest: dict) -> None:
    """Refuse labels that ``out`` already holds for other settings or data."""
    path = out / "sweep.json"
    if not path.exists():
        return
    try:
        old = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise ValueError(f"{path} is not readable ({err}); remove it or choose another out_dir") from None
    for part, what in (("models", "model"), ("records", "record")):
        for label, entry in manifest[part].items():
            before = (old.get(part) or {}).get(label)
            if before is not None and before != entry:
                raise ValueError(
                    f"{out} holds a sweep in which {what} {label!r} stood for other "
                    f"{'settings' if what == 'model' else 'data'} ({before} now {entry}); its finished runs "
                    "would be mixed with new ones: choose another out_dir or another label")


def _merged_manifest(out: Path, manifest: dict) -> dict:
    path = out / "sweep.json"
    old = json.loads(path.read_text()) if path.exists() else {}
    return {part: {**(old.get(part) or {}), **manifest[part]} for part in ("models", "records")}


# ---------------------------------------------------------------------- rows
def _load(path: Path, motion: bool):
    if motion:
        from .motion import load_motion_fit

        return load_motion_fit(path)
    from .fit import load_fit

    return load_fit(path)


def _number(x):
    return float(x) if isinstance(x, numbers.Real) and not isinstance(x, bool) else None


def _row(run: Run, fit) -> dict:
    metrics = fit.metrics or {}
    row = {"model": run.model, "record": run.record, "seed": run.seed,
           "cost": _number(metrics.get("cost")), "num_params": fit.num_params,
           "run_s": _number((fit.timings or {}).get("total_s")), "fit_file": run.fit_file}
    for window in _WINDOWS:
        values = metrics.get(window)
        if isinstance(values, Mapping):
            for name, v in values.items():
                if name in _METRICS and _number(v) is not None:
                    row[f"{window}_{name}"] = _number(v)
    return row


def _table_text(rows: list[dict]) -> str:
    import csv
    import io

    extra = sorted({k for r in rows for k in r} - set(TABLE_COLUMNS))
    columns = list(TABLE_COLUMNS) + extra
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r.get(k) is None else repr(r[k]) if isinstance(r[k], float) else r[k])
                    for k in columns})
    return buf.getvalue()


def _barrier(name: str) -> None:
    from jax.experimental import multihost_utils

    multihost_utils.sync_global_devices(name)


def _check_local_layout() -> None:
    """Refuse to run under JAX's distributed runtime when the optimiser would lay one
    process's run over other processes' devices: their different keys would mix."""
    import jax

    from .optim.sharding import resolve_devices

    layout = resolve_devices(None)
    if layout is None:
        return
    foreign = [d for d in layout.devices if d.process_index != jax.process_index()]
    if foreign:
        raise RuntimeError(
            "jaxfric.optim lays a run's population over every process's devices "
            f"({len(layout.devices)} devices, {len(foreign)} of other processes), so the "
            "independent runs of a multi-process sweep would be computed as one program and mix; "
            "the optimiser's default layout must use this process's devices (jax.local_devices())")


# --------------------------------------------------------------------- sweep
def sweep(models, records, keys, out_dir, *, progress: bool = True, on_run: Callable | None = None,
          process_index: int | None = None, process_count: int | None = None, **options) -> SweepResult:
    """Run every (model, record, key) identification, resumably (module docstring).

    Args:
        models: a model name or instance, a list of them (labelled by their
            [`jaxfric.models.get`][jaxfric.models.get] name) or a mapping label -> model, or label ->
            ``(model, options)`` for identify options of that model alone (they win over
            ``**options``; e.g. a solver sized for the model).
        records: a mapping label -> record or a list of records (labelled ``record0``,
            ``record1``, ...): [`jaxfric.FrictionData`][jaxfric.rig.FrictionData] or ``(velocity, friction,
            dt)`` for [`jaxfric.identify`][jaxfric.identification.identify]; [`jaxfric.MotionData`][jaxfric.motion.MotionData] (all of them)
            for [`jaxfric.identify_motion`][jaxfric.motion.identify_motion].
        keys: a number of seeds ``K`` (seeds ``0 .. K-1``) or a list of int seeds; each
            run's key is ``jax.random.key(seed)``, so run ``(m, r, k)`` equals
            ``identify(m, records[r], key=k, **options)``.
        out_dir: the sweep folder (created if needed; reused to resume).
        progress: one progress bar over the whole sweep (tqdm, on stderr).
        on_run: called as ``on_run(run, fit)`` after each run's files are written.
        process_index, process_count: this process's share of the runs; default JAX's
            (one process, unless ``jax.distributed.initialize`` joined several).
        **options: passed to every ``identify`` / ``identify_motion`` call (``solver=``,
            ``method=``, ``refine=``, ``dtype=``, ``box=``, ``mass=``, model options...).

    Returns:
        a [`SweepResult`][jaxfric.sweeps.SweepResult]; ``out_dir/results.csv`` holds its rows.

    Raises:
        ValueError: before any run, for empty or badly labelled models or records,
            bad seeds, a model name that does not exist, a record identify would
            refuse, or labels that ``out_dir`` holds for other settings or data.
    """
    from tqdm.auto import tqdm

    from .identification import identify
    from .motion import MotionData, identify_motion

    _refuse_own(options, "")
    model_map = _models(models)
    record_map = _records(records)
    seeds = _seeds(keys)
    index, count, distributed = _processes(process_index, process_count)
    kinds = {isinstance(r, MotionData) for r in record_map.values()}
    if len(kinds) > 1:
        raise ValueError("records mix MotionData (identify_motion) with friction records (identify); "
                         "sweep them separately")
    motion = kinds == {True}
    fit_fn = identify_motion if motion else identify
    run_options = _run_options(model_map, record_map, options, fit_fn, motion)
    if distributed:
        _check_local_layout()

    out = Path(out_dir)
    manifest = {"models": {label: _model_entry(m, run_options[label]) for label, (m, _) in model_map.items()},
                "records": {label: _record_digest(r) for label, r in record_map.items()}}
    _check_manifest(out, manifest)
    out.mkdir(parents=True, exist_ok=True)
    if index == 0:
        write_json(out / "sweep.json", _merged_manifest(out, manifest))

    runs = [Run(m, r, s, i) for i, (m, r, s) in enumerate(itertools.product(model_map, record_map, seeds))]
    mine = [run for run in runs if run.index % count == index]
    rows = _rows_on_disk(out, mine, motion, skip_unreadable=True)
    done = [run for run in mine if run.index in rows]
    todo = [run for run in mine if run.index not in rows]

    def write_table(known: dict[int, dict]) -> None:
        atomic_write_text(out / "results.csv", _table_text([known[i] for i in sorted(known)]))

    computed = []
    bar = tqdm(total=len(mine), initial=len(done), desc=f"sweep {out.name}", unit="run",
               disable=not progress, dynamic_ncols=True)
    try:
        if count == 1 and done and not todo:
            write_table(rows)
        for run in todo:
            bar.set_postfix_str(f"{run.model} {run.record} seed {run.seed}")
            start = time.perf_counter()
            fit = fit_fn(model_map[run.model][0], record_map[run.record], key=run.seed, **run_options[run.model])
            fit = fit.replace(timings={**(fit.timings or {}), "total_s": time.perf_counter() - start})
            fit.save(out / run.fit_file)
            rows[run.index] = _row(run, fit)
            computed.append(run)
            if count == 1:  # one process: the table is whole after every run
                write_table(rows)
            bar.update(1)
            if on_run is not None:
                on_run(run, fit)
    finally:
        bar.close()
    if distributed:
        _barrier(f"jaxfric.sweep:{out.resolve()}")
        rows = _rows_on_disk(out, runs, motion)
        if index == 0:
            write_table(rows)
        _barrier(f"jaxfric.sweep.table:{out.resolve()}")
    elif count > 1:
        # a share of a job array: the table of every run finished so far, once at the end
        rows = _rows_on_disk(out, runs, motion)
        write_table(rows)
    ordered = [rows[i] for i in sorted(rows)]
    return SweepResult(out_dir=out, runs=runs, rows=ordered, computed=computed, done=done, motion=motion)


def _refuse_own(options, where: str) -> None:
    for name in ("key", "keys", "progress"):
        if name in options:
            raise ValueError(f"{where}{name}= is the sweep's own: give the seeds as keys=, not as an identify option")


def _rows_on_disk(out: Path, runs: list[Run], motion: bool, skip_unreadable: bool = False) -> dict[int, dict]:
    """Run index -> row of the ``runs`` whose fit file ``out`` holds (``skip_unreadable``:
    leaving out a file that does not load, e.g. one written by hand, to compute it again)."""
    rows = {}
    for run in runs:
        path = out / run.fit_file
        if path.exists():
            try:
                rows[run.index] = _row(run, _load(path, motion))
            except ValueError:
                if not skip_unreadable:
                    raise
    return rows


def _run_options(model_map: dict, record_map: dict, options: dict, fit_fn, motion: bool) -> dict:
    """Each model's options for ``fit_fn`` (its own over the sweep's), after every check
    ``fit_fn`` would make on the models and records: before the first run."""
    import inspect

    from .identification import as_record, resolve_model

    keywords = {name for name, p in inspect.signature(fit_fn).parameters.items()
                if p.kind is not inspect.Parameter.VAR_KEYWORD}
    run_options = {}
    for label, (m, own) in model_map.items():
        _refuse_own(own, f"model {label!r}: ")
        run_options[label] = {**options, **own}
        model_options = {k: v for k, v in run_options[label].items() if k not in keywords}
        model_options.update(run_options[label].get("model_options") or {})
        try:
            resolve_model(m, model_options if isinstance(m, str) else None)
        except ValueError as err:
            raise ValueError(f"model {label!r}: {err}") from None
    for label, r in ({} if motion else record_map).items():
        try:
            as_record(r)
        except ValueError as err:
            raise ValueError(f"record {label!r}: {err}") from None
    return run_options


def read_table(path) -> list[dict]:
    """The rows of a sweep's ``results.csv`` (numbers as float, ``seed`` as int)."""
    import csv

    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    def value(k, v):
        if v == "":
            return None
        return int(v) if k in ("seed", "num_params") else v if k in ("model", "record", "fit_file") else float(v)
    return [{k: value(k, v) for k, v in r.items()} for r in rows]

