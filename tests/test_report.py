"""The report folder: every file present, written atomically, numbers consistent."""

import json
import re

import matplotlib.image as mpimg
import numpy as np
import pytest

import jaxfric as jf
from jaxfric import report
from jaxfric.metrics import friction_metrics
from jaxfric.rig import FrictionData


@pytest.fixture(scope="module")
def data():
    t = np.arange(500) / 100.0
    v = 0.01 * np.sin(2 * np.pi * 0.3 * t)
    f = 200 * np.tanh(v / 2e-3)
    return FrictionData.from_arrays(v, f, 0.01, n_train=400)


@pytest.fixture(scope="module")
def written(data, tmp_path_factory, make_fit):
    out = tmp_path_factory.mktemp("report")
    # Fc = 300 N, sigma2 = 10 N s/m; a Stribeck curve with Fc = 100 N, Fs = 150 N, vs = 1 mm/s
    fits = {"good": make_fit(jf.Coulomb(), [300.0, 1.0]), "poor": make_fit(jf.Stribeck(), [100.0, 1.5, -3.0, 1.0])}
    seen = []
    res = report.write_report(out, data, fits, title="test report", command="jaxfric test",
                              source="synthetic", settings={"seed": 1}, notes=["a note"],
                              python="print('hi')", on_written=seen.append)
    return out, fits, res, seen


def test_every_file_is_there_and_figures_are_not_blank(written):
    out, fits, res, seen = written
    names = set(report.FIGURES) | {f"fit_{n}.png" for n in fits} | {"report.md", "results.json"}
    for name in names:
        assert (out / name).is_file(), name
    for name in names:
        if name.endswith(".png"):
            assert (out / name).stat().st_size > 10_000
            img = mpimg.imread(out / name)
            assert img[..., :3].std() > 0.05, f"{name} looks blank"
    for n, fit in fits.items():
        np.testing.assert_array_equal(jf.load_fit(out / "models" / f"{n}.npz").theta, fit.theta)
    assert sorted(map(str, seen)) == sorted(map(str, res["files"]))
    assert not list(out.glob(".*")), "temporary files left behind"


def test_results_json_matches_metrics(written, data):
    out, fits, res, _ = written
    d = json.loads((out / "results.json").read_text())
    assert d["title"] == "test report" and d["settings"] == {"seed": 1}
    assert d["data"]["n_samples"] == 500 and d["data"]["n_train"] == 400
    y = np.asarray(data.friction)
    for name, fit in fits.items():
        m = d["models"][name]
        assert m["num_params"] == fit.model.num_params
        assert m["seconds"] == pytest.approx(3.5)
        assert m["file"] == f"models/{name}.npz"
        y_hat = np.asarray(fit.predict(data.velocity, data.dt), dtype=np.float64)
        expect = friction_metrics(y[400:], y_hat[400:])
        assert m["metrics"]["valid"]["mse_percent"] == pytest.approx(expect["mse_percent"])
        assert m["fit"]["theta"] == pytest.approx(list(fit.theta))


def test_markdown_and_text_tables(written):
    out, _, res, _ = written
    md = (out / "report.md").read_text()
    for piece in ("# test report", "| Coulomb | 2 |", "| Stribeck | 4 |", "a note",
                  "![convergence](convergence.png)", "jaxfric test", "print('hi')", "| Fc | 300 |"):
        assert piece in md, piece
    lines = res["table"].splitlines()
    assert lines[0].split()[:2] == ["model", "#params"]
    assert "MSE % valid" in lines[0] and "FIT % valid" in lines[0] and "time [s]" in lines[0]
    assert len(lines) == 4


def test_fit_metrics_prefers_the_fits_own(data, make_fit):
    fit = make_fit(jf.Coulomb(), [300.0, 1.0])
    fit = fit.replace(metrics={"train": {"mse_percent": 1.5}, "valid": None, "all": {"mse_percent": 2.0}})
    m = report.fit_metrics(fit, data)
    assert m == {"train": {"mse_percent": 1.5}, "all": {"mse_percent": 2.0}}


def test_atomic_write_replaces_and_cleans_up(tmp_path):
    p = tmp_path / "a.txt"
    report.atomic_write_text(p, "one")
    report.atomic_write_text(p, "two")
    assert p.read_text() == "two"

    def boom(tmp):
        tmp.write_text("half")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        report._atomic(tmp_path / "b.txt", boom)
    assert not (tmp_path / "b.txt").exists()
    assert sorted(x.name for x in tmp_path.iterdir()) == ["a.txt"]
    (tmp_path / ".c.txt.123.jaxfric-tmp").write_text("left over")
    assert [x.name for x in report.remove_temporaries(tmp_path)] == [".c.txt.123.jaxfric-tmp"]


def test_no_fits_is_an_error(tmp_path, data):
    with pytest.raises(ValueError, match="no fits"):
        report.write_report(tmp_path, data, {}, title="x")


def test_slug():
    assert report.slug("ENN (30 neurons)") == "enn_30_neurons"
    assert report.slug("???") == "model"


def test_report_shows_records_bounds_and_the_ensemble_band(data, tmp_path):
    """A real Fit with several records, a parameter on a bound and an ensemble: per-record
    table and figure, the bound mark with the range to widen, and the band figure."""
    from jaxfric.fit import Fit
    from jaxfric.identification import on_bound
    from jaxfric.models import Coulomb

    model, box = Coulomb(), {"Fc": (10.0, 190.0)}
    v = np.asarray(data.velocity)
    thetas = np.asarray([model.from_physical(Fc=190.0, sigma2=s) for s in (1.0, 50.0, 300.0)], np.float64)
    valid = FrictionData.from_arrays(v[:300], np.asarray(data.friction)[:300], 0.01, n_train=1).valid()

    def rec(name, role, fr, fh):
        m = friction_metrics(fr, fh)
        return {"name": name, "role": role, "n_samples": fr.size, "n_train": fr.size if role == "train" else 0,
                "train": m if role == "train" else None, "valid": m if role == "valid" else None, "all": m}

    f_all = np.asarray(data.friction)
    fit = Fit(model=model, theta=thetas[0], velocity_scaler=None, friction_scaler=None, dt=0.01,
              n_train=500, n_samples=799,
              metrics={"train": friction_metrics(f_all, f_all + 1.0), "valid": friction_metrics(f_all, f_all + 2.0),
                       "all": friction_metrics(f_all, f_all + 1.5),
                       "records": [rec("run1", "train", f_all, f_all + 1.0),
                                   rec("run2", "valid", f_all[1:300], f_all[1:300] + 2.0)]},
              diagnostics={"on_bound": on_bound(model, thetas[0], box)}, box=box,
              ensemble={"theta": thetas, "J": [0.1, 0.2, 0.3], "best": 0, "valid_mse_percent": [1.0, 2.0, 3.0],
                        "keys": [[0, 1], [0, 2], [0, 3]], "spread": {"Fc": {k: 190.0 for k in
                                                                             ("min", "p5", "median", "p95", "max")}}})
    report.write_report(tmp_path, data.with_split(None, n_train=500), {"coulomb": fit}, title="records",
                        records={"run2": valid})
    text = (tmp_path / "report.md").read_text()
    assert "| run2 | valid | 299 |" in text and "Validation record `run2`" in text
    assert "| Fc | 190 | **on a bound: widen its range** |" in text and "box={'Fc': (10, 370)}" in text
    assert "Search box (SI; `Fs_ratio` = Fs/Fc): Fc [10, 190], sigma2 [10, 1e+05]." in text
    assert "Ensemble of 3 runs" in text and "![ensemble band](band_coulomb.png)" in text
    for name in ("band_coulomb.png", "fit_coulomb_run2.png"):
        img = mpimg.imread(tmp_path / name)
        assert img[..., :3].std() > 0.05, name
    res = json.loads((tmp_path / "results.json").read_text())["models"]["coulomb"]
    assert res["on_bound"][0]["name"] == "Fc" and res["on_bound"][0]["side"] == "upper"
    assert [r["name"] for r in res["records"]] == ["run1", "run2"]
    assert "theta" not in res["ensemble"] and res["ensemble"]["J"] == [0.1, 0.2, 0.3]


def test_unidentifiable_parameters_are_named_with_reasons_in_summary_json_and_report(tmp_path):
    """A real LuGre Fit on a record that never moves slowly (no pre-sliding): sigma0 and
    sigma1 are marked in Fit.summary(), results.json and report.md, each with its reason."""
    import jaxfric
    from jaxfric.identification import identify

    dt = 1e-3
    t = np.arange(1000) * dt
    v = 0.1 * np.sign(np.sin(2 * np.pi * 2.0 * t)) + 0.02 * np.sin(2 * np.pi * 7.0 * t)
    data = FrictionData.from_arrays(v, 20.0 * np.sign(v) + 50.0 * v, dt)
    fit = identify("lugre", data, key=0, solver=jaxfric.MAPSO(lattice_size=3, num_generations=2), refine=False)
    texts = fit.diagnostics["unidentifiable"]
    by_name = {s.split(": ", 1)[0]: s.split(": ", 1)[1] for s in texts}
    assert {"sigma0", "sigma1"} <= set(by_name) and "Fc" not in by_name
    assert "pre-sliding" in by_name["sigma0"]  # the model's reason, not only the name
    summary = fit.summary()
    assert re.search(r"sigma0=\S+ \[not identifiable\]", summary)
    assert not re.search(r"Fc=\S+ \[not identifiable\]", summary)
    assert re.search(rf"!   (\w+, )*sigma0(, \w+)*: {re.escape(by_name['sigma0'])}", summary)
    assert "do not read them as physical properties" in summary
    report.write_report(tmp_path, data, {"lugre": fit}, title="no pre-sliding", save_models=False)
    text = (tmp_path / "report.md").read_text()
    assert re.search(r"\| sigma0 \| \S+ \|.*\| \*\*not identifiable\*\* \|", text)
    assert re.search(rf"- (\w+, )*sigma1(, \w+)*: {re.escape(by_name['sigma1'])}", text)
    res = json.loads((tmp_path / "results.json").read_text())["models"]["lugre"]
    assert res["unidentifiable"] == list(texts)


def test_only_jaxfric_types_are_reported(tmp_path, data, make_fit):
    class Duck:
        def predict(self, velocity, dt=None):
            return np.asarray(data.friction)

    with pytest.raises(TypeError, match="a fit must be a jaxfric.Fit.*got Duck"):
        report.write_report(tmp_path, data, {"duck": Duck()}, title="x")
    with pytest.raises(TypeError, match="data must be a jaxfric.FrictionData, got tuple"):
        report.write_report(tmp_path, (data.velocity, data.friction, 0.01),
                            {"c": make_fit(jf.Coulomb(), [300.0, 1.0])}, title="x")
    assert not list(tmp_path.iterdir())
