"""Matplotlib figures shared by the command line, the report writer and the notebooks.

Every function builds a new `Figure` and returns it; none
calls ``plt.show`` or picks a backend (the CLI selects Agg, notebooks keep theirs),
so the caller decides whether to show, save or close it.

Figures (each function's docstring says what it draws; paper numbering from docs/algorithms.md §1):
[`plot_data`][jaxfric.plot.plot_data] (Figs 9-10), [`plot_friction_velocity`][jaxfric.plot.plot_friction_velocity],
[`plot_fit`][jaxfric.plot.plot_fit] (Figs 11-12), [`plot_error`][jaxfric.plot.plot_error], [`plot_models`][jaxfric.plot.plot_models],
[`plot_band`][jaxfric.plot.plot_band], [`plot_convergence`][jaxfric.plot.plot_convergence], [`plot_table1`][jaxfric.plot.plot_table1].

Every figure draws a model in its own colour and line style ([`STYLES`][jaxfric.styles.STYLES],
[`style`][jaxfric.styles.style]): the same model looks the same in the CLI's report and in every
notebook, and the least-squares baseline is always a dashed black line.

They take jaxfric's own types: data a [`jaxfric.FrictionData`][jaxfric.rig.FrictionData], a fit a
[`jaxfric.Fit`][jaxfric.fit.Fit] (or a plain prediction array, ``F_hat`` in N on the data's time
grid), a history a [`jaxfric.History`][jaxfric.optim.History], a [`jaxfric.Solution`][jaxfric.optim.Solution] or a fit
(or an ``(evals, f)`` pair of arrays). Anything else is a `TypeError` naming
what was given.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import jax
import numpy as np
from matplotlib.figure import Figure

from .fit import ExtrapolationWarning, Fit
from .motion import DEFAULT_INIT_WINDOW, MotionData, MotionFit
from .optim import History, Solution
from .records import FrictionData
from .styles import STYLES, style

__all__ = ["fit_label", "plot_band", "plot_convergence", "plot_data", "plot_error", "plot_fit",
           "plot_friction_velocity", "plot_models", "plot_position_band", "plot_table1", "predict_on", "STYLES",
           "style", "velocity_unit"]

_MEASURED = dict(color="0.15", lw=1.1)
_VALID_SHADE = dict(color="tab:orange", alpha=0.08, lw=0)

# ----------------------------------------------------------------------- helpers
def _np(a) -> np.ndarray:
    return np.asarray(a, dtype=np.float64)


def velocity_unit(velocity) -> tuple[float, str]:
    """``(factor, label)`` to show a velocity in m/s: mm/s for slow records.

    Hydraulic press rigs move at millimetres per second, where axes in m/s would
    read ``0.01``; anything slower than 0.5 m/s is shown in mm/s.
    """
    vmax = float(np.max(np.abs(_np(velocity)))) if np.size(velocity) else 0.0
    return (1e3, "mm/s") if vmax < 0.5 else (1.0, "m/s")


def _checked(data) -> FrictionData:
    if not isinstance(data, FrictionData):
        raise TypeError(f"data must be a jaxfric.FrictionData, got {type(data).__name__}")
    return data


def _time(data) -> np.ndarray:
    return _np(_checked(data).t)


def _n_train(data) -> int:
    return _checked(data).n_train


def _mark_split(ax, data) -> None:
    """Shade the validation window and draw the split line (only when there is one)."""
    t = _time(data)
    n = _n_train(data)
    if 0 < n < t.size:
        split = 0.5 * (t[n - 1] + t[n])
        ax.axvspan(split, t[-1], **_VALID_SHADE)
        ax.axvline(split, color="tab:orange", ls="--", lw=1.0)


def _legend_outside(ax, **kwargs):
    """The axes' legend beside it, to the right, never over the data (the figures use
    constrained layout, which makes room for it)."""
    return ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, **{"fontsize": 8, **kwargs})


def _finish(ax, xlabel: str, ylabel: str, title: str, **legend) -> None:
    """Axis labels, title, grid, and the legend beside the axes."""
    ax.set(xlabel=xlabel, ylabel=ylabel, title=title)
    ax.grid(alpha=0.3)
    _legend_outside(ax, **legend)


def _split_legend_note(data) -> str:
    n = _n_train(data)
    t = _time(data)
    if 0 < n < t.size:
        return f"train: first {n} samples, validation (shaded): last {t.size - n}"
    return f"{t.size} samples (no validation window)"


def fit_label(fit, default: str = "model") -> str:
    """A short display name: a [`jaxfric.Fit`][jaxfric.fit.Fit]'s model class name (with the neuron
    count for an Elman network), ``default`` for anything else (a prediction array, a
    history)."""
    if not isinstance(fit, Fit):
        return default
    name = type(fit.model).__name__
    if name == "Elman":
        return f"ENN ({fit.model.neurons} neurons)"
    form = [w for w, on in (("asymmetric", getattr(fit.model, "asymmetric", False)),
                            ("offset", getattr(fit.model, "offset", False))) if on]
    return f"{name} ({' + '.join(form)})" if form else name


def predict_on(fit, data) -> np.ndarray:
    """Friction [N] predicted by ``fit`` on ``data``'s velocity (free run over the record),
    with ``data``'s measured channels for a model that needs them (``input_names``, e.g.
    the chamber pressures of [`Cylinder`][jaxfric.models.Cylinder]).

    ``fit`` is a [`jaxfric.Fit`][jaxfric.fit.Fit] or an array of predictions already on the data's grid.
    """
    _checked(data)
    if isinstance(fit, Fit):
        import warnings

        inputs = fit.model.inputs_from(data, _np(data.velocity).size)
        with warnings.catch_warnings():
            # a figure of the validation data shows the extrapolation; no console line for it
            warnings.simplefilter("ignore", ExtrapolationWarning)
            y_hat = _np(fit.predict(data.velocity, data.dt, inputs=inputs))
    elif isinstance(fit, (np.ndarray, jax.Array)):
        y_hat = _np(fit)
    else:
        raise TypeError(f"a fit must be a jaxfric.Fit or an array of predictions, got {type(fit).__name__}")
    n = _np(data.velocity).size
    if y_hat.shape != (n,):
        raise ValueError(f"prediction has shape {y_hat.shape}, the data have {n} samples")
    return y_hat


def _as_fit_items(fits, labels=None) -> list[tuple[str, Any]]:
    """Normalise ``fits`` (one fit, a sequence, or a mapping label -> fit) to pairs."""
    if isinstance(fits, Mapping):
        items = [(str(k), v) for k, v in fits.items()]
    elif isinstance(fits, (list, tuple)):
        items = [(fit_label(f, f"model {i + 1}"), f) for i, f in enumerate(fits)]
    else:
        items = [(fit_label(fits), fits)]
    if labels is not None:
        labels = list(labels)
        if len(labels) != len(items):
            raise ValueError(f"{len(labels)} labels for {len(items)} fits")
        items = [(lab, f) for lab, (_, f) in zip(labels, items)]
    return items


def _mse_percent(y, y_hat) -> float:
    var = float(np.var(y))
    return float("nan") if var == 0.0 else 100.0 * float(np.mean((y - y_hat) ** 2)) / var


# ------------------------------------------------------------------------- data
def plot_data(data, *, title: str | None = None) -> Figure:
    """Velocity and computed friction against time (the paper's Figs 9 and 10).

    ``data`` is a [`jaxfric.FrictionData`][jaxfric.rig.FrictionData]. The validation window is shaded.
    """
    t = _time(data)
    scale, unit = velocity_unit(data.velocity)
    fig = Figure(figsize=(9, 5.5), layout="constrained")
    ax_v, ax_f = fig.subplots(2, 1, sharex=True)
    ax_v.plot(t, _np(data.velocity) * scale, color="0.15", lw=1.1, label="velocity")
    ax_v.axhline(0.0, color="0.6", lw=0.6)
    ax_v.set_ylabel(f"piston velocity [{unit}]")
    # Records from the rig pipeline carry pressures; velocity/friction pairs loaded as such do not.
    from_pipeline = data.p1 is not None
    ax_v.set_title("Piston velocity (filtered position, differentiated)" if from_pipeline else "Piston velocity")
    ax_f.plot(t, _np(data.friction), label="friction (force balance)", **_MEASURED)
    ax_f.axhline(0.0, color="0.6", lw=0.6)
    ax_f.set_ylabel("friction force [N]")
    ax_f.set_xlabel("time [s]")
    ax_f.set_title("Friction force computed from pressures, load and acceleration" if from_pipeline
                   else "Friction force")
    for ax in (ax_v, ax_f):
        _mark_split(ax, data)
        ax.grid(alpha=0.3)
    ax_f.plot([], [], color="tab:orange", ls="--", label="train | validation split")
    _legend_outside(ax_f)
    fig.suptitle(title or f"Identification data: {_split_legend_note(data)}")
    return fig


def _binned(v, y, edges) -> tuple[np.ndarray, np.ndarray]:
    """Median of ``y`` in each velocity bin of ``edges`` (bins with fewer than 3 samples dropped)."""
    idx = np.digitize(v, edges) - 1
    centres, medians = [], []
    for b in range(edges.size - 1):
        sel = idx == b
        if np.count_nonzero(sel) >= 3:
            centres.append(0.5 * (edges[b] + edges[b + 1]))
            medians.append(float(np.median(y[sel])))
    return np.asarray(centres), np.asarray(medians)


def _thinned(n: int, max_points: int) -> np.ndarray:
    """Indices of at most ``max_points`` samples, evenly spread over ``n`` (all when fewer)."""
    if n <= max_points:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, max_points).round().astype(int))


def plot_friction_velocity(data, fits=None, *, title: str | None = None, max_points: int = 2000,
                           bins: int = 60) -> Figure:
    """Friction against velocity: the hysteresis loops of the record.

    Training samples are drawn in grey, validation samples in orange (the models'
    colours are [`style`][jaxfric.styles.style]'s). With
    ``fits`` (one fit, a sequence, or a mapping label -> fit) the models'
    predictions are drawn on top of the measurements.

    A long or noisy record (more than ``max_points`` samples, e.g. a real recording at
    1 kHz) would bury everything under a cloud of dots: its samples are then thinned
    to ``max_points`` evenly spread ones drawn faintly, the measured friction is also
    shown as its median in ``bins`` velocity bins, and each model as the median of its
    prediction in the same bins, so the curves stay readable.
    """
    v = _np(data.velocity)
    f = _np(data.friction)
    n = _n_train(data)
    scale, unit = velocity_unit(v)
    dense = v.size > max_points
    keep = _thinned(v.size, max_points)
    dots = dict(ms=2.0, alpha=0.35 if dense else 1.0, zorder=1, rasterized=dense)
    fig = Figure(figsize=(6.5, 5), layout="constrained")
    ax = fig.subplots()
    train, valid = keep[keep < n], keep[keep >= n]
    thin_note = f" ({keep.size} of {v.size} samples)" if dense else ""
    ax.plot(v[train] * scale, f[train], ".", color="0.6", label="measured, training" + thin_note, **dots)
    if valid.size:
        ax.plot(v[valid] * scale, f[valid], ".", color="tab:orange", label="measured, validation", **dots)
    edges = np.linspace(v.min(), v.max(), bins + 1) if dense and v.max() > v.min() else None
    if edges is not None:
        c, m = _binned(v, f, edges)
        ax.plot(c * scale, m, "o-", ms=3, lw=1.4, color="0.15", zorder=3, label="measured, binned median")
    if fits is not None:
        for i, (label, fit) in enumerate(_as_fit_items(fits)):
            y_hat = predict_on(fit, data)
            look = {"ls": "-", **style(label, i)}
            z = 5 if look == STYLES["baseline"] else 4  # the dashed baseline on top, never hidden
            if edges is not None:
                c, m = _binned(v, y_hat, edges)
                ax.plot(c * scale, m, lw=2.0, zorder=z, label=f"{label} (binned median)", **look)
            else:
                ax.plot(v * scale, y_hat, lw=1.2, zorder=z, label=label, **look)
    ax.axhline(0.0, color="0.6", lw=0.6)
    ax.axvline(0.0, color="0.6", lw=0.6)
    _finish(ax, f"piston velocity [{unit}]", "friction force [N]", title or "Friction against velocity", markerscale=4)
    return fig


# ------------------------------------------------------------------------- fits
def plot_fit(fit, data, *, label: str | None = None, title: str | None = None) -> Figure:
    """Measured against estimated friction for one model (the paper's Figs 11-12).

    Left: both against time, validation window shaded, normalised MSE % of each
    window in the legend. Right: the same against velocity.
    """
    label = label or fit_label(fit)
    t = _time(data)
    v = _np(data.velocity)
    y = _np(data.friction)
    y_hat = predict_on(fit, data)
    n = _n_train(data)
    scale, unit = velocity_unit(v)
    parts = [f"train {_mse_percent(y[:n], y_hat[:n]):.3g} %"] if n > 0 else []
    if n < y.size:
        parts.append(f"valid {_mse_percent(y[n:], y_hat[n:]):.3g} %")
    fig = Figure(figsize=(12, 4.6), layout="constrained")
    ax_t, ax_v = fig.subplots(1, 2, width_ratios=[2.4, 1])
    ax_t.plot(t, y, label="measured", **_MEASURED)
    look = {"ls": "-", **style(label)}
    ax_t.plot(t, y_hat, lw=1.0, label=f"estimated: {label}", **look)
    _mark_split(ax_t, data)
    _finish(ax_t, "time [s]", "friction force [N]", "MSE (normalised): " + ", ".join(parts))
    ax_v.plot(v * scale, y, ".", ms=1.5, color="0.35", label="measured")
    ax_v.plot(v * scale, y_hat, lw=0.8, label="estimated", **look)
    _finish(ax_v, f"piston velocity [{unit}]", "friction force [N]", "against velocity", markerscale=4)
    fig.suptitle(title or f"Measured and estimated friction: {label}")
    return fig


#: The start-up transient of a record: its first ``1 / TRANSIENT_DIVISOR`` (5 %), where a
#: free run's initial state and the zero-phase filter's edges dominate the error.
TRANSIENT_DIVISOR = 20


def _transient(n: int) -> int:
    """Samples of the start-up transient of an ``n``-sample record (see ``TRANSIENT_DIVISOR``)."""
    return n // TRANSIENT_DIVISOR


def _max_window(data, n: int) -> tuple[slice, str]:
    """Where the error figure quotes MAX |e|: the validation window; without one, the
    record after its start-up transient (``_transient``)."""
    n_train = _n_train(data)
    if 0 < n_train < n:
        return slice(n_train, n), "validation"
    skip = _transient(n)
    return slice(skip, n), f"after the first {skip} samples"


def _scale_to_steady(ax, t, errors, skip: int) -> None:
    """Scale the error axis to the errors after the start-up transient (the first ``skip``
    samples), and mark the transient: shaded, its extreme error named in the legend when it
    is off the scale. A spike of a free run's first samples would otherwise set the scale and
    flatten the errors that matter."""
    errors = np.asarray(errors, np.float64)
    if skip < 1 or errors.shape[-1] <= skip:
        return
    steady = errors[:, skip:]
    lo, hi = float(np.nanmin(steady)), float(np.nanmax(steady))
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return
    pad = 0.08 * (hi - lo) if hi > lo else max(abs(hi), 1.0)
    lo, hi = min(lo, 0.0) - pad, max(hi, 0.0) + pad
    ax.set_ylim(lo, hi)
    start = errors[:, :skip]
    worst = float(start.flat[np.nanargmax(np.abs(start))])
    off = worst < lo or worst > hi
    ax.axvspan(t[0], t[skip], color="0.5", alpha=0.15, lw=0,
               label=f"start-up transient (first {t[skip] - t[0]:.2g} s)"
               + (f": off scale, down to {worst:.3g} N" if off and worst < 0
                  else f": off scale, up to {worst:.3g} N" if off else ""))


def plot_error(fits, data, *, labels: Sequence[str] | None = None, title: str | None = None) -> Figure:
    """Error curves ``F - F_hat`` [N] of one or several fits against time.

    ``fits``: one fit, a sequence of fits, or a mapping label -> fit (or -> prediction
    array). The validation window is shaded; the legend gives each model's MAX
    error |e| over the validation window (the paper's MAX, docs/algorithms.md §6), or,
    without one, over the record after its start-up transient: a spike in the first
    samples would otherwise be the number quoted. The error axis is scaled to the errors
    after that transient, which is shaded and, when its error is off the scale, says how
    far it reaches.
    """
    t = _time(data)
    y = _np(data.friction)
    window, where = _max_window(data, y.size)
    fig = Figure(figsize=(9, 4.2), layout="constrained")
    ax = fig.subplots()
    errors = []
    for i, (label, fit) in enumerate(_as_fit_items(fits, labels)):
        e = y - predict_on(fit, data)
        errors.append(e)
        ax.plot(t, e, lw=0.9, **style(label, i),
                label=f"{label} (MAX |e| {where} = {np.max(np.abs(e[window])):.3g} N)")
    ax.axhline(0.0, color="0.4", lw=0.6)
    _mark_split(ax, data)
    _scale_to_steady(ax, t, errors, _transient(y.size))
    _finish(ax, "time [s]", "error  F - F_hat [N]", title or "Friction estimation error")
    return fig


def plot_models(fits, data, *, window: str = "valid", labels: Sequence[str] | None = None,
                title: str | None = None, max_points: int = 4000) -> Figure:
    """Several models against the measured friction on one window of ``data``.

    Top: the measured friction as grey dots (so that it stays visible under the models)
    and each model's prediction as a line in its [`style`][jaxfric.styles.style]; bottom: each model's
    error ``F - F_hat``, with its normalised MSE % over the window in the legend.
    ``fits``: one fit, a sequence, or a mapping label -> fit or prediction array (on the
    whole record). ``window``: ``"valid"`` (the validation window; the whole record
    when there is none), ``"train"`` or ``"all"``. At most ``max_points`` samples are
    drawn as dots (evenly thinned); the lines use every sample.
    """
    t = _time(data)
    y = _np(data.friction)
    n = _n_train(data)
    if window not in ("valid", "train", "all"):
        raise ValueError(f"window must be 'valid', 'train' or 'all', got {window!r}")
    sl = {"valid": slice(n, None) if 0 < n < y.size else slice(None), "train": slice(None, n),
          "all": slice(None)}[window]
    name = {"valid": "validation window" if 0 < n < y.size else "whole record",
            "train": "training window", "all": "whole record"}[window]
    ts, ys = t[sl], y[sl]
    keep = _thinned(ys.size, max_points)
    fig = Figure(figsize=(11, 6.2), layout="constrained")
    ax_f, ax_e = fig.subplots(2, 1, sharex=True, height_ratios=[1.6, 1])
    ax_f.plot(ts[keep], ys[keep], ".", ms=2.5, color=STYLES["measured"]["color"], alpha=0.6, zorder=1,
              label="measured" + (f" ({keep.size} of {ys.size} samples)" if keep.size < ys.size else ""))
    for i, (label, fit) in enumerate(_as_fit_items(fits, labels)):
        look = {"ls": "-", **style(label, i)}
        y_hat = predict_on(fit, data)[sl]
        # the dashed baseline on top: the models show through its gaps, and it is never hidden
        ax_f.plot(ts, y_hat, lw=1.1, zorder=4 if look == STYLES["baseline"] else 3, label=label, **look)
        ax_e.plot(ts, ys - y_hat, lw=0.9, label=f"{label}: MSE {_mse_percent(ys, y_hat):.3g} %", **look)
    ax_e.axhline(0.0, color="0.4", lw=0.6)
    _finish(ax_f, "", "friction force [N]", title or f"Measured friction and the models on the {name}", markerscale=3)
    _finish(ax_e, "time [s]", "error  F - F_hat [N]", f"Error on the {name} (normalised MSE % in the legend)",
            markerscale=3)
    return fig


def plot_band(fit, data, *, label: str | None = None, title: str | None = None) -> Figure:
    """An ensemble's prediction band (``fit.predict_band``: min-max over the members of
    ``identify(..., keys=K)``) around the best member's prediction, with the measured
    friction, against time; the validation window is shaded."""
    if not (isinstance(fit, Fit) and fit.ensemble):
        raise TypeError(f"plot_band needs a jaxfric.Fit of identify(..., keys=K), got {type(fit).__name__}"
                        + (" without an ensemble" if isinstance(fit, Fit) else ""))
    label = label or fit_label(fit)
    t = _time(data)
    y = _np(data.friction)
    lo, hi = (_np(a) for a in fit.predict_band(data.velocity, data.dt))
    y_hat = predict_on(fit, data)
    k = len(fit.ensemble.get("J", []))
    fig = Figure(figsize=(9, 4.2), layout="constrained")
    ax = fig.subplots()
    colour = style(label)["color"]
    ax.fill_between(t, lo, hi, color=colour, alpha=0.25, lw=0, label=f"band: min-max of {k} members")
    ax.plot(t, y, label="measured", **_MEASURED)
    ax.plot(t, y_hat, color=colour, lw=1.0, label=f"best member: {label}")
    _mark_split(ax, data)
    _finish(ax, "time [s]", "friction force [N]", title or f"Ensemble prediction band: {label}")
    return fig


def plot_position_band(fit, record, *, level: float = 0.95, init_window: int = DEFAULT_INIT_WINDOW,
                       label: str | None = None, title: str | None = None) -> Figure:
    """A motion fit's free run of ``record`` (a [`MotionData`][jaxfric.motion.MotionData]) from its
    first ``init_window`` samples inside its position band
    ([`MotionFit.prediction_interval`][jaxfric.motion.MotionFit.prediction_interval]): top, the
    measured and the simulated position [mm]; bottom, the error ``x − x̂`` [mm] with the band
    around zero, and in the legend the share of samples the band holds (docs/uncertainty.md
    says what the band leaves out)."""
    if not isinstance(fit, MotionFit):
        raise TypeError(f"plot_position_band needs a jaxfric.motion.MotionFit, got {type(fit).__name__}")
    if not isinstance(record, MotionData):
        raise TypeError(f"plot_position_band needs a jaxfric.motion.MotionData record, got {type(record).__name__}")
    x_hat, lo, hi = fit.prediction_interval(record, level, init_window=init_window)
    x = _np(record.position)
    t = np.arange(x.size) * record.dt
    held = float(np.mean(((x >= lo) & (x <= hi))[init_window:]))
    label = label or fit_label(fit)
    colour = style(label)["color"]
    fig = Figure(figsize=(10, 5.6), layout="constrained")
    ax_x, ax_e = fig.subplots(2, 1, sharex=True, height_ratios=[1.4, 1])
    ax_x.fill_between(t, 1e3 * lo, 1e3 * hi, color=colour, alpha=0.25, lw=0, label=f"{level:.0%} band")
    ax_x.plot(t, 1e3 * x, label="measured", **_MEASURED)
    ax_x.plot(t, 1e3 * x_hat, color=colour, lw=1.0, label=f"free run: {label}")
    ax_e.fill_between(t, 1e3 * (lo - x_hat), 1e3 * (hi - x_hat), color=colour, alpha=0.25, lw=0,
                      label=f"{level:.0%} band: holds {held:.1%} of the samples")
    ax_e.plot(t, 1e3 * (x - x_hat), color=colour, lw=0.9, label="measured − free run")
    ax_e.axhline(0.0, color="0.4", lw=0.6)
    _finish(ax_x, "", "position [mm]", title or f"Free run from the first {init_window} samples: {label}")
    _finish(ax_e, "time [s]", "error [mm]", "Error inside the position band")
    return fig


# ------------------------------------------------------------------ convergence
def _history_arrays(item) -> tuple[np.ndarray, np.ndarray]:
    """``(evals, f)`` from a [`History`][jaxfric.optim.History], a [`Solution`][jaxfric.optim.Solution],
    a [`Fit`][jaxfric.fit.Fit] or an
    ``(evals, f)`` pair.

    Batched histories (from ``minimise_many``) come back 2-D, one row per run.
    """
    if isinstance(item, tuple) and len(item) == 2:
        return _np(item[0]), _np(item[1])
    if isinstance(item, Fit):  # its history is the {"evals", "f"} record it saves
        return _np(item.history["evals"]), _np(item.history["f"])
    if isinstance(item, Solution):
        item = item.history
    if isinstance(item, History):
        evals, f, length = _np(item.evals), _np(item.f), np.asarray(item.length)
        if evals.ndim == 1:
            n = max(int(length), 1)
            return evals[:n], f[:n]
        return evals, f
    raise TypeError("a convergence curve needs a jaxfric History, Solution or Fit (or an (evals, f) "
                    f"pair) holding an optimiser history, got {type(item).__name__}")


#: How a stage of ``Fit.stages`` is named in figures.
STAGE_NAMES = {"mapso": "MAPSO", "pso": "PSO", "nelder_mead": "Nelder-Mead", "bfgs": "BFGS",
               "lbfgs": "L-BFGS", "lm": "Levenberg-Marquardt", "gauss_newton": "Gauss-Newton"}


def _stage_name(stage: Mapping) -> str:
    name = str(stage.get("stage", "?"))
    return STAGE_NAMES.get(name, name)


def _global_phase_evals(item):
    """``(evaluations, "first -> second")`` where a hybrid run's second derivative-free
    stage took over from its global stage, if recorded; else ``None``."""
    solution = item.solution if isinstance(item, Fit) else item
    stages = item.stages if isinstance(item, Fit) else []
    searched = [s for s in stages if "num_evals" in s]  # the stages the history covers
    if isinstance(solution, Solution) and "num_evals_global" in solution.stats:
        g = np.asarray(solution.stats["num_evals_global"])
        names = (" -> ".join(_stage_name(s) for s in searched[:2]) if len(searched) > 1 else "MAPSO -> Nelder-Mead")
        return (float(np.median(g)) if g.ndim else float(g)), names
    if len(searched) > 1:  # a Fit loaded from disk keeps its stages only
        return float(searched[0]["num_evals"]), f"{_stage_name(searched[0])} -> {_stage_name(searched[1])}"
    return None


def _gradient_stages(item) -> list[Mapping]:
    """The stages of a fit after its derivative-free search (the gradient stage, e.g.
    the networks' BFGS): each has a final cost ``J`` and a number of steps, and is not
    part of the search history."""
    if not isinstance(item, Fit):
        return []
    return [s for s in item.stages if "num_evals" not in s and "J" in s]


def _convergence_items(items, labels) -> tuple[list, list[str]]:
    """``plot_convergence``'s items (one, a sequence, or a mapping label -> item; an
    ``(evals, f)`` pair is one item) and their labels."""
    if isinstance(items, Mapping):
        labels = list(items) if labels is None else labels
        items = list(items.values())
    elif isinstance(items, (list, tuple)) and not (
        len(items) == 2 and isinstance(items, tuple) and np.ndim(items[0]) >= 1
    ):
        items = list(items)
    else:
        items = [items]
    if labels is None:
        labels = [fit_label(it, f"run {i + 1}") for i, it in enumerate(items)]
    labels = list(labels)
    if len(labels) != len(items):
        raise ValueError(f"{len(labels)} labels for {len(items)} histories")
    return items, labels


def plot_convergence(solutions_or_histories, labels: Sequence[str] | None = None, *,
                     title: str | None = None, ylabel: str = "best objective value J") -> Figure:
    """Best objective value against function evaluations, log scale.

    Items may be [`jaxfric.Solution`][jaxfric.optim.Solution], [`jaxfric.History`][jaxfric.optim.History], fits holding
    a solution, or ``(evals, f)`` pairs; a mapping label -> item works too. For a
    batch of runs (``minimise_many``) the median is drawn with the min-max band.
    Every stage of a fit is drawn and named in the legend per model: a dotted line
    where its second derivative-free stage took over (e.g. MAPSO -> Nelder-Mead), and
    its gradient stage (e.g. the networks' BFGS), whose steps are counted on the
    evaluation axis, as a dashed segment to the cost it ended at.
    """
    items, labels = _convergence_items(solutions_or_histories, labels)
    curves = [_history_arrays(it) for it in items]
    ends = [float(s["J"]) for it in items for s in _gradient_stages(it)]
    finite = np.concatenate([f[np.isfinite(f)].ravel() for _, f in curves] + [np.asarray(ends, float)]
                            or [np.zeros(0)])
    finite = finite[np.isfinite(finite)]
    positive = finite[finite > 0]
    log = finite.size > 0 and np.all(finite >= 0)
    # Exact zeros (a test function solved) cannot sit on a log axis: draw them at a floor
    # a decade below the smallest positive value, and say so in the title.
    floor = positive.min() / 10.0 if positive.size else 1e-300
    fig = Figure(figsize=(8.5, 4.6), layout="constrained")
    ax = fig.subplots()
    clipped = False
    gradient_steps = False
    for i, ((evals, f), label) in enumerate(zip(curves, labels)):
        color = style(label, i)["color"]
        searched = [s for s in getattr(items[i], "stages", []) if "num_evals" in s]
        first = _stage_name(searched[0]) if searched else None
        if evals.ndim == 2:  # a batch of runs: median and band on a common grid
            grid = np.linspace(0.0, float(np.max(evals)), 200)
            rows = np.stack([np.interp(grid, e, np.where(np.isfinite(v), v, np.nan)) for e, v in zip(evals, f)])
            mid, lo, hi = (np.nanmedian(rows, 0), np.nanmin(rows, 0), np.nanmax(rows, 0))
            if log:
                clipped |= bool(np.any(lo <= 0))
                mid, lo, hi = (np.maximum(a, floor) for a in (mid, lo, hi))
            ax.plot(grid, mid, color=color, lw=1.4, label=f"{label} (median of {evals.shape[0]})")
            ax.fill_between(grid, lo, hi, color=color, alpha=0.15, lw=0)
            continue
        y = np.where(np.isfinite(f), f, np.nan)
        if log:
            clipped |= bool(np.any(y <= 0))
            y = np.maximum(y, floor)
        stage_text = " -> ".join(_stage_name(s) for s in searched) if searched else ""
        ax.step(evals, y, where="post", color=color, lw=1.4, label=f"{label}: {stage_text}" if stage_text else label)
        switch = _global_phase_evals(items[i])
        if switch is not None:
            ax.axvline(switch[0], color=color, ls=":", lw=1.0, label=f"{label}: {switch[1]} switch")
        # the gradient stage(s): from the search's end to the cost each one ended at
        x0 = float(evals[-1]) if evals.size else 0.0
        y0 = float(y[-1]) if y.size else np.nan
        for stage in _gradient_stages(items[i]):
            steps = int(stage.get("num_steps", 0) or 0)
            j = float(stage["J"])
            j = max(j, floor) if log else j
            x1 = x0 + max(steps, 1)
            ax.plot([x0, x1], [y0, j], color=color, ls="--", lw=1.4, marker="o", markevery=[1],
                    label=f"{label}: {_stage_name(stage)}" + (f", {steps} steps" if steps else "")
                    + (f" (after {first})" if first else ""))
            x0, y0 = x1, j
            gradient_steps = True
    if log:
        ax.set_yscale("log")
    ax.set_xlabel("function evaluations" + (" (a gradient step counted as one)" if gradient_steps else ""))
    ax.set_ylabel(ylabel + (" (log scale)" if log else ""))
    ax.set_title((title or "Optimiser convergence") + (" (zeros drawn at the floor)" if clipped else ""))
    ax.grid(True, which="both", alpha=0.3)
    _legend_outside(ax)
    return fig


# ----------------------------------------------------------------------- table 1
def plot_table1(rows: Sequence[Mapping], *, title: str | None = None) -> Figure:
    """Mean final value per test function and solver (Table 1), with best-worst bars.

    ``rows``: dicts with ``function``, ``solver``, ``mean`` and optionally ``best``,
    ``worst`` (the rows ``benchmarks/table1.py`` writes). Log scale; values of
    exactly zero sit at a floor below the smallest positive value.
    """
    rows = list(rows)
    if not rows:
        raise ValueError("no rows to plot")
    functions = list(dict.fromkeys(r["function"] for r in rows))
    solvers = list(dict.fromkeys(r["solver"] for r in rows))
    vals = [float(r[k]) for r in rows for k in ("mean", "best", "worst") if k in r]
    pos = [x for x in vals if x > 0 and np.isfinite(x)]
    floor = min(pos) / 10.0 if pos else 1e-300
    width = 0.8 / len(solvers)
    fig = Figure(figsize=(max(6.0, 1.6 * len(functions) + 2), 4.6), layout="constrained")
    ax = fig.subplots()
    x = np.arange(len(functions))
    for j, solver in enumerate(solvers):
        means, lo, hi = [], [], []
        for fn in functions:
            r = next((r for r in rows if r["function"] == fn and r["solver"] == solver), None)
            m = float(r["mean"]) if r else np.nan
            means.append(max(m, floor))
            lo.append(max(float(r.get("best", m)), floor) if r else np.nan)
            hi.append(max(float(r.get("worst", m)), floor) if r else np.nan)
        means, lo, hi = map(np.asarray, (means, lo, hi))
        ax.bar(x + (j - (len(solvers) - 1) / 2) * width, means, width, color=style(solver, j)["color"], label=solver,
               yerr=np.stack([np.maximum(means - lo, 0), np.maximum(hi - means, 0)]), capsize=2,
               error_kw=dict(lw=0.8))
    ax.set_yscale("log")
    if any(float(r["mean"]) <= 0 for r in rows):
        title = (title or "Table 1: final objective value per test function") + " (zeros drawn at the floor)"
    ax.set_xticks(x, functions)
    ax.set_xlabel("test function")
    ax.set_ylabel("final best f: mean (bars), best-worst (whiskers)")
    ax.set_title(title or "Table 1: final objective value per test function")
    ax.grid(True, axis="y", which="both", alpha=0.3)
    _legend_outside(ax)
    return fig
