"""The report folder written by ``jaxfric demo`` and ``jaxfric identify``.

One call, [`write_report`][jaxfric.report.write_report], writes into a folder::

    report.md            the comparison table, per-model details, figures, how to reproduce
    results.json         the same numbers, machine-readable
    data.png             velocity and computed friction against time (split marked)
    friction_velocity.png  friction against velocity, measured and per model
    fit_<model>.png      measured against estimated friction, one per model
    fit_<model>_<record>.png  the same on each extra validation record (``records=``)
    band_<model>.png     an ensemble's prediction band (fits from ``identify(..., keys=K)``)
    error.png            error curves of all models, scaled to the part after the start-up transient
    convergence.png      best objective against evaluations, all models
    (figures the caller drew, e.g. the demo's compensation.png, are listed with these)
    models/<model>.npz   each fit, saved with ``Fit.save`` (``jaxfric predict`` reads it)

Every file is written to a temporary name in the same folder and moved into place
with ``os.replace``, so an interrupted run never leaves a half-written file under a
final name (temporaries match [`TEMP_PATTERNS`][jaxfric.report.TEMP_PATTERNS]; [`remove_temporaries`][jaxfric.report.remove_temporaries]
clears them).

The writer takes jaxfric's own types: [`jaxfric.Fit`][jaxfric.fit.Fit] objects and a
[`jaxfric.FrictionData`][jaxfric.rig.FrictionData]; anything else is a ``TypeError`` before a file is written.
"""

from __future__ import annotations

import datetime as _dt
import os
import platform
import re
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from . import plot as _plot
from .fit import Fit
from .files import TEMP_SUFFIX, atomic_write, atomic_write_bytes, atomic_write_text, jsonable, write_json
from .metrics import METRIC_FORMULAS, friction_metrics
from .records import FrictionData
from .uncertainty import report_markdown, report_summary

__all__ = ["FIGURES", "TEMP_PATTERNS", "atomic_write_bytes", "atomic_write_text", "comparison_rows",
           "format_table", "markdown_table", "remove_temporaries", "save_figure", "write_report"]

FIGURES = ("data.png", "friction_velocity.png", "error.png", "convergence.png")
"""Figures every report holds, besides one ``fit_<model>.png`` per model."""

TEMP_PATTERNS = (f".*{TEMP_SUFFIX}", ".jaxfric-fit-*.tmp")
"""Globs of the temporary files of an unfinished write (ours, and ``Fit.save``'s)."""

WINDOWS = ("train", "valid", "all")


# ------------------------------------------------------------------ atomic files
# One implementation for the package (jaxfric.files); the names stay importable from here.
_atomic = atomic_write


def save_figure(fig, path, *, dpi: int = 110) -> Path:
    """Save a matplotlib figure as PNG atomically and release it."""
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return atomic_write_bytes(path, buf.getvalue())


def remove_temporaries(folder) -> list[Path]:
    """Delete temporaries left by an interrupted write in ``folder`` (and ``models/``)."""
    removed = []
    for sub in (Path(folder), Path(folder) / "models"):
        if sub.is_dir():
            for pattern in TEMP_PATTERNS:
                for p in sub.glob(pattern):
                    try:
                        p.unlink()
                        removed.append(p)
                    except OSError:
                        pass
    return removed


def _check_fit(fit) -> Fit:
    if not isinstance(fit, Fit):
        raise TypeError(f"a fit must be a jaxfric.Fit (from jaxfric.identify or jaxfric.load_fit), "
                        f"got {type(fit).__name__}")
    return fit


def save_fit(fit, path) -> Path:
    """``fit.save`` into a temporary file, then moved to ``path`` (atomic)."""
    return _atomic(path, lambda tmp: _check_fit(fit).save(tmp))


# ----------------------------------------------------------- reading a fit
def slug(name: str) -> str:
    """File-name form of a model name: ``"ENN (30)"`` -> ``"enn_30"``."""
    s = re.sub(r"[^a-z0-9]+", "_", str(name).lower()).strip("_")
    return s or "model"


def _windows(data):
    n, total = int(data.n_train), int(np.shape(data.velocity)[-1])
    out = {"train": slice(0, n), "all": slice(0, total)}
    if n < total:
        out["valid"] = slice(n, total)
    return out


def fit_metrics(fit, data) -> dict[str, dict[str, float]]:
    """Metrics per window (``train``, ``valid``, ``all``) of [`jaxfric.metrics.friction_metrics`][jaxfric.metrics.friction_metrics].

    Taken from ``fit.metrics`` when the fit carries them for these windows (the library is
    the authority), otherwise computed from the prediction on ``data``.
    """
    own = _check_fit(fit).metrics
    if isinstance(own, Mapping) and all(isinstance(own.get(w), Mapping) for w in ("train", "all")):
        return {w: {k: float(v) for k, v in own[w].items()} for w in WINDOWS if isinstance(own.get(w), Mapping)}
    y = np.asarray(data.friction, dtype=np.float64)
    y_hat = _plot.predict_on(fit, data)
    return {w: friction_metrics(y[s], y_hat[s]) for w, s in _windows(data).items()}


def fit_seconds(fit) -> float | None:
    """Wall time of the identification [s] (``fit.timings["total_s"]``), when recorded."""
    total = _check_fit(fit).timings.get("total_s")
    return None if total is None else float(total)


def fit_num_params(fit) -> int:
    return int(_check_fit(fit).model.num_params)


def fit_dict(fit) -> dict:
    """``fit.to_dict()``, made JSON-safe."""
    return jsonable(_check_fit(fit).to_dict(), finite=True)


# ------------------------------------------------------------------ tables
def comparison_rows(fits: Mapping[str, Any], data) -> list[dict]:
    """One row per fit: label, #params, metrics per window, time."""
    return [{"name": name, "label": _plot.fit_label(fit, name), "params": fit_num_params(fit),
             "metrics": fit_metrics(fit, data), "seconds": fit_seconds(fit)} for name, fit in fits.items()]


def _cell(rows, key, window, fmt):
    return ["-" if (v := r["metrics"].get(window, {}).get(key)) is None else format(v, fmt) for r in rows]


def _columns(rows):
    valid = any("valid" in r["metrics"] for r in rows)
    w = "valid" if valid else "all"
    cols = [
        ("model", [r["label"] for r in rows]),
        ("#params", ["-" if r["params"] is None else str(r["params"]) for r in rows]),
        ("MSE % train", _cell(rows, "mse_percent", "train", ".4g")),
    ]
    if valid:
        cols.append(("MSE % valid", _cell(rows, "mse_percent", "valid", ".4g")))
    cols += [
        (f"MAX [N] {w}", _cell(rows, "max_abs", w, ".4g")),
        (f"FIT % {w}", _cell(rows, "fit_percent", w, ".2f")),
        ("time [s]", ["-" if r["seconds"] is None else f"{r['seconds']:.1f}" for r in rows]),
    ]
    return cols


def format_table(rows: list[dict]) -> str:
    """The comparison as aligned plain text, for the terminal."""
    cols = _columns(rows)
    widths = [max(len(h), *(len(c) for c in cells)) for h, cells in cols]
    line = lambda cells: "  ".join(  # noqa: E731
        c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))
    out = [line([h for h, _ in cols]), line(["-" * w for w in widths])]
    out += [line([cells[i] for _, cells in cols]) for i in range(len(rows))]
    return "\n".join(out)


def _md(header, rows) -> list[str]:
    """Markdown table lines: the header, its rule, one line per row (cells as text)."""
    return (["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
            + ["| " + " | ".join(map(str, row)) + " |" for row in rows])


def markdown_table(rows: list[dict]) -> str:
    """The comparison as a Markdown table."""
    cols = _columns(rows)
    return "\n".join(_md([h for h, _ in cols], zip(*(cells for _, cells in cols))))


# ------------------------------------------------------------------ the report
def _data_summary(data) -> dict:
    v = np.asarray(data.velocity, dtype=np.float64)
    f = np.asarray(data.friction, dtype=np.float64)
    dt = float(np.asarray(data.dt))
    n = int(v.shape[-1])
    return {"n_samples": n, "n_train": int(data.n_train), "n_valid": n - int(data.n_train),
            "dt_s": dt, "fs_hz": 1.0 / dt, "duration_s": n * dt,
            "velocity_range_m_s": [float(v.min()), float(v.max())],
            "friction_range_N": [float(f.min()), float(f.max())]}


def _environment() -> dict:
    import jax

    from . import __version__

    return {"jaxfric": __version__, "jax": jax.__version__, "python": platform.python_version(),
            "platform": platform.platform(), "cpu_count": os.cpu_count(),
            "backend": jax.default_backend(),
            "float64": bool(jax.config.jax_enable_x64)}


def write_report(out, data, fits: Mapping[str, Any], *, title: str, command: str | None = None,
                 source: str = "", settings: Mapping | None = None, notes: list[str] | None = None,
                 python: str | None = None, extra_files: Mapping[str, str] | None = None,
                 save_models: bool = True, on_written: Callable[[Path], None] | None = None,
                 records: Mapping[str, Any] | None = None,
                 sections: Mapping[str, str] | None = None,
                 figures: Mapping[str, str] | None = None) -> dict:
    """Write the report folder ``out`` for ``fits`` (name -> fit) on ``data``.

    Args:
        out: folder (created if needed; existing report files are replaced).
        data: the [`jaxfric.FrictionData`][jaxfric.rig.FrictionData] the fits were made on.
        fits: mapping model name (used in file names) -> [`jaxfric.Fit`][jaxfric.fit.Fit] (anything
            else is a ``TypeError``).
        title: report title.
        command: the command line that produced it (shown under "Reproduce").
        source: one sentence on where the data came from.
        settings: budgets, seeds and options (into report.md and results.json).
        notes: extra remarks (e.g. resampling warnings), listed under the data.
        python: Python code that reproduces the fits (shown under "Reproduce").
        extra_files: name -> description of other files the caller put in ``out``.
        save_models: save each fit to ``models/<name>.json`` (needs ``fit.save``).
        on_written: called with each finished file's path (progress, bookkeeping).
        records: name -> validation record (``FrictionData``) the fits were validated on
            besides ``data`` (``identify(train=..., valid=...)``): one figure per model
            and record; the per-record metrics come from each fit's ``metrics["records"]``.
        sections: heading -> Markdown body of further sections the caller computed (e.g.
            ``jaxfric demo``'s friction-compensation table, [`jaxfric.compensation.compensation_table`][jaxfric.compensation.compensation_table]),
            placed after the model sections and kept in ``results.json`` under ``sections``.
        figures: name -> caption of figures the caller drew into ``out`` (e.g. ``jaxfric
            demo``'s ``compensation.png``): listed in ``results.json`` with the report's own.

    Returns:
        ``{"files": [paths], "rows": comparison rows, "table": plain-text table,
        "figures": {name: caption} of every figure of the report}``.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if not fits:
        raise ValueError("no fits to report")
    for fit in fits.values():  # before any figure is drawn
        _check_fit(fit)
    if not isinstance(data, FrictionData):
        raise TypeError(f"data must be a jaxfric.FrictionData, got {type(data).__name__}")
    written: list[Path] = []

    def done(p: Path) -> None:
        written.append(p)
        if on_written is not None:
            on_written(p)

    rows = comparison_rows(fits, data)
    records = dict(records or {})
    figs, record_figs, missing = _draw_figures(out, data, fits, rows, records, done)
    notes = list(notes or []) + missing if missing else notes
    for name, caption in (figures or {}).items():
        if not (out / name).is_file():
            raise ValueError(f"figure {name} is not in {out}: draw it before write_report")
        figs[name] = caption

    model_files = {}
    if save_models:
        for r in rows:
            p = save_fit(fits[r["name"]], out / "models" / f"{slug(r['name'])}.npz")
            model_files[r["name"]] = str(p.relative_to(out))
            done(p)

    results = {
        "title": title,
        "created": _dt.datetime.now().astimezone().isoformat(timespec="seconds"),
        "command": command,
        "source": source,
        "environment": _environment(),
        "settings": jsonable(dict(settings or {}), finite=True),
        "data": _data_summary(data),
        "validation_records": {k: _data_summary(v) for k, v in records.items()},
        "metric_definitions": METRIC_FORMULAS,
        "models": {r["name"]: _model_results(r, fits[r["name"]], data, model_files.get(r["name"]),
                                             record_figs.get(r["name"], {})) for r in rows},
        "figures": figs,
        "notes": list(notes or []),
        "sections": dict(sections or {}),
    }
    done(write_json(out / "results.json", results))
    text = _markdown(results, rows, fits, python=python, extra_files=extra_files or {})
    done(atomic_write_text(out / "report.md", text))
    return {"files": written, "rows": rows, "table": format_table(rows), "figures": dict(figs)}


def _draw_figures(out: Path, data, fits: Mapping, rows: list[dict], records: dict, done: Callable):
    """The report's figures, each saved into ``out`` and passed to ``done``: ``({name:
    caption}, {model: {record: figure}}, notes)`` (a note when a fit has no optimiser history)."""
    figs: dict[str, str] = {}
    record_figs: dict[str, dict[str, str]] = {}
    by_label = {r["label"]: fits[r["name"]] for r in rows}

    def figure(name: str, make: Callable, caption: str) -> None:
        done(save_figure(make(), out / name))
        figs[name] = caption

    figure("data.png", lambda: _plot.plot_data(data), "Velocity and friction from the force balance")
    figure("friction_velocity.png", lambda: _plot.plot_friction_velocity(data, by_label),
           "Friction against velocity, measured and estimated")
    for r in rows:
        figure(f"fit_{slug(r['name'])}.png", lambda r=r: _plot.plot_fit(fits[r["name"]], data, label=r["label"]),
               f"Measured and estimated friction: {r['label']}")
    for rec_name, rec in records.items():
        for r in rows:
            name, title = f"fit_{slug(r['name'])}_{slug(rec_name)}.png", f"Validation record {rec_name}: {r['label']}"
            figure(name, lambda r=r, rec=rec, title=title: _plot.plot_fit(fits[r["name"]], rec, label=r["label"],
                                                                         title=title), title)
            record_figs.setdefault(r["name"], {})[rec_name] = name
    for r in rows:
        if fits[r["name"]].ensemble:
            figure(f"band_{slug(r['name'])}.png", lambda r=r: _plot.plot_band(fits[r["name"]], data, label=r["label"]),
                   f"Ensemble prediction band: {r['label']}")
    figure("error.png", lambda: _plot.plot_error(by_label, data), "Estimation error of each model")
    try:
        figure("convergence.png", lambda: _plot.plot_convergence(
            by_label, ylabel="best objective J (each model's own cost)"), "Optimiser convergence")
    except ValueError as e:  # a fit without an optimiser history (e.g. loaded from disk)
        return figs, record_figs, [f"no convergence figure: {e}"]
    return figs, record_figs, []


def _model_results(r: dict, fit, data, file: str | None, record_figures: dict) -> dict:
    """results.json's entry of one model: its comparison row ``r``, saved ``file`` and
    figures on the validation records, and what the fit says of itself."""
    return {"label": r["label"], "num_params": r["params"], "seconds": r["seconds"], "metrics": r["metrics"],
            "file": file, "records": _fit_records(fit), "on_bound": list(fit.diagnostics.get("on_bound", [])),
            "unidentifiable": list(fit.diagnostics.get("unidentifiable", [])), "ensemble": _ensemble(fit),
            "uncertainty": jsonable(report_summary(fit, data), finite=True), "record_figures": record_figures,
            "fit": fit_dict(fit)}


def _fit_records(fit) -> list[dict]:
    """Per-record metrics of a fit (``fit.metrics["records"]``), when it has several records."""
    recs = (fit.metrics or {}).get("records") or []
    return list(recs) if len(recs) > 1 else []


def _ensemble(fit) -> dict | None:
    e = fit.ensemble
    return None if not e else {k: v for k, v in e.items() if k != "theta"}


def _g5(v) -> str:
    return "-" if v is None else f"{v:.5g}"


def _markdown(results: dict, rows: list[dict], fits: Mapping, *, python: str | None,
              extra_files: Mapping[str, str]) -> str:
    d, env = results["data"], results["environment"]
    L = [f"# {results['title']}", ""]
    L.append(f"Written {results['created']} by jaxfric {env['jaxfric']} (jax {env['jax']}, "
             f"{'float64' if env['float64'] else 'float32'}, {env['cpu_count']} CPU core(s), {env['backend']}).")
    L += ["", "## Data", ""]
    if results["source"]:
        L += [results["source"], ""]
    if d["n_valid"] > 0:
        split = f"the first {d['n_train']} estimate the models, the last {d['n_valid']} validate them"
    else:
        split = "all of them estimate the models"
    L.append(f"{d['n_samples']} samples at {d['fs_hz']:.4g} Hz ({d['duration_s']:.3g} s); {split}. Velocity "
             f"{d['velocity_range_m_s'][0] * 1e3:.3g} to {d['velocity_range_m_s'][1] * 1e3:.3g} mm/s, "
             f"friction {d['friction_range_N'][0]:.4g} to {d['friction_range_N'][1]:.4g} N.")
    for name, v in results["validation_records"].items():
        L.append(f"\nValidation record `{name}`: {v['n_samples']} samples ({v['duration_s']:.3g} s), "
                 "rolled out whole from the model's initial state.")
    for note in results["notes"]:
        L.append(f"\n*Note:* {note}")
    L += ["", "![data](data.png)", "", "![friction against velocity](friction_velocity.png)", ""]
    L += ["## Comparison", "", markdown_table(rows), "",
          "MSE % is the normalised MSE, 100·mean(e²)/var(F) over the window (100 % = no better than the "
          "mean; < 1 % excellent, > 5 % poor); MAX is max|e|; FIT % is 100·(1 − ‖e‖/‖F − mean F‖). "
          "Predictions are free-run: the measured friction is never fed back. Time is the wall time of "
          "the identification, compilation included.", ""]
    L += ["![error](error.png)", ""]
    if "convergence.png" in results["figures"]:
        L += ["![convergence](convergence.png)", ""]
    for r in rows:
        L += _model_markdown(r, results["models"][r["name"]], fits[r["name"]], results["figures"])
    for heading, body in results.get("sections", {}).items():
        L += [f"## {heading}", "", body.rstrip(), ""]
    if results["settings"]:
        L += ["## Settings", ""] + _md(("setting", "value"), results["settings"].items()) + [""]
    if extra_files:
        L += ["## Other files", ""] + [f"- `{k}`: {v}" for k, v in extra_files.items()] + [""]
    L += ["## Reproduce", ""]
    if results["command"]:
        L += ["```", results["command"], "```", ""]
    if python:
        L += ["In Python:", "", "```python", python.strip("\n"), "```", ""]
    return "\n".join(L)


def _model_markdown(r: dict, m: dict, fit, figures: dict) -> list[str]:
    """report.md's section of one model: its comparison row ``r``, its results.json entry
    ``m``, the fit, and the report's figures."""
    L = [f"## {r['label']}", "", f"![{r['label']}](fit_{slug(r['name'])}.png)", ""]
    L += _md(("metric", "train", "valid", "all"), [
        [key] + [_g5(r["metrics"].get(w, {}).get(key)) for w in WINDOWS]
        for key in ("mse_percent", "max_abs", "fit_percent", "rmse", "mse_scaled_percent", "r2")])
    if m["records"]:
        L += [""] + _md(("record", "role", "samples", "MSE %", "MAX [N]", "FIT %"), [
            [rec["name"], rec["role"], rec["n_samples"]]
            + [_g5((rec.get("all") or {}).get(k)) for k in ("mse_percent", "max_abs", "fit_percent")]
            for rec in m["records"]])
        L += ["", "Each record is rolled out from the model's initial state; the comparison table "
              "pools the samples of the training and of the validation records."]
        for rec_name, fig in m["record_figures"].items():
            L += ["", f"![{r['label']} on {rec_name}]({fig})"]
    # the parameters, one verdict each (identifiable or not, and why), their intervals
    L += report_markdown(m.get("uncertainty"))
    if not fit.model.needs_scaling and fit.box is not None:
        L += ["", f"Search box (SI; `Fs_ratio` = Fs/Fc): {fit.box}."]
    for d in m["on_bound"]:
        L += ["", f"**On a bound:** {d['message']}."]
    e = m["ensemble"]
    if e:
        vm = [x for x in e.get("valid_mse_percent", []) if x is not None]
        L += ["", f"Ensemble of {len(e['J'])} runs (one vmapped call); this fit is member "
              f"{e['best']}, the one with the lowest training cost"
              + (f"; validation MSE % over the members {min(vm):.4g} to {max(vm):.4g}" if vm else "") + "."]
        if e.get("spread"):
            L += [""] + _md(("parameter", "min", "5 %", "median", "95 %", "max"), [
                [k] + [_g5(sp[q]) for q in ("min", "p5", "median", "p95", "max")] for k, sp in e["spread"].items()])
        band = f"band_{slug(r['name'])}.png"
        if band in figures:
            L += ["", f"![ensemble band]({band})"]
    if fit.stages:
        parts = [f"{name}: J = {J:.5g} ({n} {'evaluations' if evals else 'steps'})"
                 for name, J, n, evals in fit.stage_counts()]
        L += ["", "Optimiser stages: " + " → ".join(parts) + "."]
    if m["file"]:
        L += ["", f"Saved fit: `{m['file']}` (use `jaxfric predict {m['file']} DATA.csv`)."]
    L.append("")
    return L
