"""Figures stay readable on real, noisy records (issue 20.15)."""

import numpy as np
import pytest

from jaxfric import plot
from jaxfric.rig import FrictionData


@pytest.fixture(scope="module")
def noisy():
    """A 1 kHz-like record: 20 000 samples of noisy velocity and friction."""
    rng = np.random.default_rng(0)
    t = np.arange(20_000) / 1000.0
    v = 0.05 * np.sin(2 * np.pi * 0.5 * t) + 0.004 * rng.normal(size=t.size)
    f = 30 * np.tanh(v / 2e-3) + 200 * v + 3.0 * rng.normal(size=t.size)
    return FrictionData.from_arrays(v, f, 1e-3, n_train=16_000)


def _points(ax, marker="."):
    return sum(len(line.get_xdata()) for line in ax.get_lines() if line.get_marker() == marker)


def test_friction_velocity_thins_dense_points_and_draws_models_on_top(noisy):
    model = 30 * np.tanh(np.asarray(noisy.velocity) / 2e-3) + 200 * np.asarray(noisy.velocity)
    fig = plot.plot_friction_velocity(noisy, {"model": model}, max_points=2000, bins=50)
    ax = fig.axes[0]
    assert _points(ax) <= 2000  # not 20 000 dots
    lines = {line.get_label(): line for line in ax.get_lines()}
    curve = lines["model (binned median)"]
    dots = [line for line in ax.get_lines() if line.get_marker() == "."]
    assert all(curve.get_zorder() > d.get_zorder() for d in dots)
    assert len(curve.get_xdata()) <= 50
    # the binned model curve is the model's median per bin: compare with a direct computation
    v = np.asarray(noisy.velocity)
    edges = np.linspace(v.min(), v.max(), 51)
    k = len(curve.get_xdata()) // 2
    centre = curve.get_xdata()[k] / 1e3  # plotted in mm/s
    b = int(np.searchsorted(edges, centre)) - 1
    sel = (v >= edges[b]) & (v < edges[b + 1])
    assert curve.get_ydata()[k] == pytest.approx(np.median(model[sel]))


def test_friction_velocity_short_record_keeps_every_sample():
    t = np.arange(400) / 128.0
    v = 0.01 * np.sin(2 * np.pi * 0.4 * t)
    d = FrictionData.from_arrays(v, 300 * np.tanh(v / 1e-3), 1 / 128.0, n_train=320)
    fig = plot.plot_friction_velocity(d, {"m": np.asarray(d.friction)})
    assert _points(fig.axes[0]) == 400


def test_error_figure_quotes_the_validation_max_not_the_start_up_transient(noisy):
    y = np.asarray(noisy.friction)
    pred = y - 0.5
    pred[:50] -= 400.0  # start-up transient of a free run
    pred[17_000] -= 7.0  # the largest validation error
    fig = plot.plot_error({"model": pred}, noisy)
    text = fig.axes[0].get_legend().get_texts()[0].get_text()
    assert "MAX |e| validation = 7.5 N" in text, text


def test_error_figure_without_validation_skips_the_transient():
    t = np.arange(1000) / 100.0
    v = np.sin(t)
    d = FrictionData.from_arrays(v, 10 * np.tanh(v), 0.01, n_train=1000)
    pred = np.asarray(d.friction) - 1.0
    pred[:20] -= 50.0
    text = plot.plot_error({"m": pred}, d).axes[0].get_legend().get_texts()[0].get_text()
    assert "after the first 50 samples = 1 N" in text, text


def test_error_figure_is_scaled_to_the_steady_part_and_marks_the_transient(noisy):
    """A -400 N start-up spike does not set the error axis: it spans the steady errors, and
    the shaded transient says how far off the scale the spike reaches."""
    y = np.asarray(noisy.friction)
    pred = y - 0.5
    pred[:50] += 400.0  # start-up transient of a free run: e = -400.5 N
    pred[17_000] -= 7.0
    ax = plot.plot_error({"model": pred}, noisy).axes[0]
    lo, hi = ax.get_ylim()
    assert -5.0 < lo < -0.5 and 7.5 < hi < 12.0, (lo, hi)
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any(t.startswith("start-up transient (first ") and t.endswith("off scale, down to -400 N")
               for t in texts), texts
    # a transient inside the scale is still marked, without "off scale"
    pred[:50] = y[:50] - 3.0
    texts = [t.get_text() for t in plot.plot_error({"model": pred}, noisy).axes[0].get_legend().get_texts()]
    assert any(t.startswith("start-up transient") and "off scale" not in t for t in texts), texts


def test_a_model_has_one_colour_in_every_figure_of_the_report(noisy):
    """The ENN and LuGre are drawn in the same colour in the error, friction-velocity, fit,
    convergence and compensation figures (jaxfric.plot.style), distinct from each other and
    from the measured samples."""
    import matplotlib.colors as mcolors

    from jaxfric.compensation import plot_tracking

    y = np.asarray(noisy.friction)
    preds = {"ENN (30 neurons)": y - 1.0, "LuGre (asymmetric + offset)": y + 2.0}

    def colours(ax):
        return {ln.get_label().split(" (MAX")[0].split(" (binned")[0].removeprefix("estimated: "):
                mcolors.to_hex(ln.get_color()) for ln in ax.get_lines()}

    seen = [colours(plot.plot_error(preds, noisy).axes[0]),
            colours(plot.plot_friction_velocity(noisy, preds).axes[0])]
    seen += [colours(plot.plot_fit(p, noisy, label=k).axes[0]) for k, p in preds.items()]
    evals = np.arange(1.0, 11.0)
    seen.append({k.split(":")[0]: c for k, c in colours(plot.plot_convergence(
        {k: (evals, 1.0 / evals) for k in preds}).axes[0]).items()})
    t = np.arange(10) * 0.1
    seen.append(colours(plot_tracking({"none": {"t": t, "error": t}, **{k: {"t": t, "error": t} for k in preds},
                                       "ideal (true friction)": {"t": t, "error": t}}).axes[1]))
    for name in preds:
        got = {s[name] for s in seen if name in s}
        assert len(got) == 1, (name, seen)
    assert all(sum(name in s for s in seen) >= 1 for name in preds)
    assert sum("ENN (30 neurons)" in s for s in seen) == len(seen) - 1  # plot_fit draws one model each
    enn, lugre = (seen[0][k] for k in preds)
    dots = {mcolors.to_hex(ln.get_color()) for ln in plot.plot_friction_velocity(noisy, preds).axes[0].get_lines()
            if ln.get_label().startswith("measured")}
    assert enn != lugre and not {enn, lugre} & dots


def _overlaps_axes(fig) -> list[str]:
    """Axes whose legend overlaps the axes' own drawing area."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig).draw()
    bad = []
    for ax in fig.axes:
        legend = ax.get_legend()
        if legend is None:
            continue
        box, area = legend.get_window_extent(), ax.get_window_extent()
        if box.overlaps(area):
            bad.append(ax.get_title() or "axes")
    return bad


def test_legends_sit_beside_the_data_never_on_it(noisy, make_fit):
    """Every figure of a report keeps its legends outside the plotting area."""
    import jaxfric as jf

    fit = make_fit(jf.Coulomb(), [40.0, 3.0], dt=1e-3, n_train=16_000, n_samples=20_000)
    figures = {
        "data": plot.plot_data(noisy),
        "friction_velocity": plot.plot_friction_velocity(noisy, {"model": np.asarray(noisy.friction)}),
        "fit": plot.plot_fit(fit, noisy),
        "error": plot.plot_error({"model": np.asarray(noisy.friction) - 1.0}, noisy),
        "convergence": plot.plot_convergence({"Coulomb": fit}),
    }
    for name, fig in figures.items():
        assert not _overlaps_axes(fig), name


def test_convergence_names_every_stage_per_model(make_fit):
    """A network's gradient stage is drawn (to the cost it ended at) and named, and the
    switch between derivative-free stages is named by the fit's own stages."""
    import jaxfric as jf

    enn = make_fit(jf.Elman(neurons=2), np.zeros(jf.Elman(neurons=2).num_params),
                   stages=[{"stage": "mapso", "J": 0.1, "num_evals": 200},
                           {"stage": "bfgs", "J": 1e-4, "num_steps": 50}],
                   history={"evals": np.arange(1, 21) * 10, "f": np.geomspace(1.0, 0.1, 20)})
    lugre = make_fit(jf.Coulomb(), [40.0, 3.0])  # mapso then nelder_mead (make_fit's stages)
    fig = plot.plot_convergence({"ENN (2 neurons)": enn, "Coulomb": lugre})
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "ENN (2 neurons): MAPSO" in labels
    assert "ENN (2 neurons): BFGS, 50 steps (after MAPSO)" in labels
    assert "Coulomb: MAPSO -> Nelder-Mead switch" in labels
    assert not any("ENN (2 neurons): MAPSO -> Nelder-Mead" in t for t in labels)
    bfgs = next(line for line in ax.get_lines() if line.get_label().startswith("ENN (2 neurons): BFGS"))
    assert list(bfgs.get_xdata()) == [200.0, 250.0]
    assert bfgs.get_ydata()[-1] == pytest.approx(1e-4)
    assert "gradient step counted as one" in ax.get_xlabel()
