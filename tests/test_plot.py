"""Figures of jaxfric.plot: each returns a Figure with labelled axes that shows the data."""

import io

import matplotlib.image as mpimg
import numpy as np
import pytest
from matplotlib.figure import Figure

import jaxfric as jf
from jaxfric import plot
from jaxfric.rig import FrictionData


@pytest.fixture(scope="module")
def data():
    t = np.arange(400) / 128.0
    v = 0.01 * np.sin(2 * np.pi * 0.4 * t)
    f = 300 * np.tanh(v / 1e-3) + 2e3 * v
    return FrictionData.from_arrays(v, f, 1 / 128.0, n_train=320)


def _pixels(fig: Figure) -> np.ndarray:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=60)
    assert buf.tell() > 5000
    buf.seek(0)
    return mpimg.imread(buf)


def _check(fig):
    assert isinstance(fig, Figure)
    img = _pixels(fig)
    assert img[..., :3].std() > 0.05  # not a blank canvas
    used = [ax for ax in fig.axes if ax.has_data()]
    assert used and all(ax.get_ylabel() for ax in used)
    assert any(ax.get_xlabel() for ax in used)  # shared-x panels label the bottom one only


def test_plot_data_marks_split_and_units(data):
    fig = plot.plot_data(data)
    _check(fig)
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert "piston velocity [mm/s]" in labels and "friction force [N]" in labels
    assert "320" in fig._suptitle.get_text()


def test_plot_friction_velocity_with_and_without_fits(data):
    _check(plot.plot_friction_velocity(data))
    fig = plot.plot_friction_velocity(data, {"model": np.asarray(data.friction) * 0.9})
    _check(fig)
    assert "model" in [t.get_text() for t in fig.axes[0].get_legend().get_texts()]


def test_plot_fit_titles_with_mse(data, make_fit):
    fig = plot.plot_fit(make_fit(jf.Coulomb(), [300.0, 1.0], dt=1 / 128.0, n_train=320, n_samples=400), data)
    _check(fig)
    assert "Coulomb" in fig._suptitle.get_text()
    assert "valid" in fig.axes[0].get_title()


def test_plot_fit_rejects_wrong_length(data):
    with pytest.raises(ValueError, match="samples"):
        plot.plot_fit(np.zeros(3), data)


def test_plot_error_one_curve_per_fit(data, make_fit):
    fits = [make_fit(jf.Coulomb(), [fc, 1.0], dt=1 / 128.0, n_train=320, n_samples=400) for fc in (270.0, 330.0)]
    fig = plot.plot_error(fits, data)
    _check(fig)
    texts = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert sum("MAX |e|" in t for t in texts) == 2 and texts[-1].startswith("start-up transient"), texts


def test_plot_convergence_accepts_histories_solutions_and_pairs(data, make_fit):
    fit = make_fit(jf.Coulomb(), [300.0, 1.0], dt=1 / 128.0, n_train=320, n_samples=400)
    hist = jf.History.from_arrays(np.arange(1, 11) * 10, np.geomspace(5.0, 0.1, 10))
    sol = jf.Solution(value=np.zeros(2), f=np.float64(0.1), result=jf.RESULTS.successful,
                      stats={"num_evals": 100, "num_evals_global": 60}, history=hist)
    pair = (np.array([0, 10, 20]), np.array([1.0, 0.5, 0.0]))  # an exact zero on a log axis
    fig = plot.plot_convergence([fit, sol, pair], ["fit", "sol", "pair"])
    _check(fig)
    assert fig.axes[0].get_yscale() == "log"
    with pytest.raises(ValueError, match="labels"):
        plot.plot_convergence([fit], ["a", "b"])
    with pytest.raises(TypeError, match="history"):
        plot.plot_convergence([object()], ["x"])


def test_plot_table1(data):
    rows = [dict(function="sphere", solver="A", mean=1e-9, best=0.0, worst=1e-8),
            dict(function="sphere", solver="B", mean=1e-2, best=1e-3, worst=1e-1),
            dict(function="ackley", solver="A", mean=0.0),
            dict(function="ackley", solver="B", mean=0.5)]
    fig = plot.plot_table1(rows)
    _check(fig)
    assert "floor" in fig.axes[0].get_title()


def test_velocity_unit():
    assert plot.velocity_unit(np.array([0.01, -0.02])) == (1e3, "mm/s")
    assert plot.velocity_unit(np.array([1.0])) == (1.0, "m/s")


def test_figures_take_jaxfric_types_only(data):
    class Duck:
        def predict(self, velocity, dt=None):
            return np.asarray(data.friction)

    with pytest.raises(TypeError, match="a fit must be a jaxfric.Fit.*got Duck"):
        plot.plot_fit(Duck(), data)
    with pytest.raises(TypeError, match="data must be a jaxfric.FrictionData, got tuple"):
        plot.plot_data((data.velocity, data.friction, 1 / 128.0))


def test_one_style_per_model_family_and_a_dashed_baseline():
    assert plot.style("ENN (30 neurons)") == plot.style("elman") == plot.STYLES["ENN"]
    assert plot.style("LuGre (asymmetric + offset)")["color"] == plot.STYLES["LuGre"]["color"]
    assert plot.style("LS baseline") == {"color": "black", "ls": "--"}
    assert plot.style("MAPSO-NMDS") != plot.style("PSO")
    colours = {plot.style(m)["color"] for m in ("ENN", "LuGre", "Coulomb", "Stribeck", "Dahl", "GMS", "baseline")}
    assert len(colours) == 7
    assert plot.style("something else", 1)["color"] != plot.style("something else", 2)["color"]


def test_plot_models_shows_the_measurement_every_model_and_their_errors(data, make_fit):
    fit = make_fit(jf.Coulomb(), [300.0, 1.0], dt=1 / 128.0, n_train=320, n_samples=400)
    fig = plot.plot_models({"LS baseline": np.asarray(data.friction) * 0.95, "Coulomb": fit}, data)
    _check(fig)
    top, errors = fig.axes[0], fig.axes[1]
    labels = [t.get_text() for t in top.get_legend().get_texts()]
    assert labels[0].startswith("measured") and "LS baseline" in labels and "Coulomb" in labels
    assert [ln.get_linestyle() for ln in top.get_lines()][1] == "--"  # the baseline, dashed
    assert sum("MSE" in t.get_text() for t in errors.get_legend().get_texts()) == 2
    assert all(np.size(ln.get_xdata()) == 80 for ln in errors.get_lines() if np.size(ln.get_xdata()) > 2)  # validation
    with pytest.raises(ValueError, match="window"):
        plot.plot_models(fit, data, window="test")
