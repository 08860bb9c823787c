"""The search box is data (issue 19.2): a validated SearchBox given to identify, completed
from the model's defaults and the data, stored in the fit, and no part of the jit key."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

import jaxfric as jf
from jaxfric import pipeline
from jaxfric.identification import BoundWarning
from jaxfric._timing import Stopwatch
from jaxfric.models import DEFAULT_RANGES, GMS, Coulomb, Cylinder, LuGre, SearchBox

DT = 0.01
SOLVER = jf.mapso_nmds(lattice_size=3, num_generations=4, nm_max_steps=40)


def coulomb_record(n=300, Fc=40.0, sigma2=800.0):
    t = np.arange(n) * DT
    v = 0.02 * np.sin(2 * np.pi * 0.5 * t) + 0.005 * np.sin(2 * np.pi * 1.3 * t)
    model = Coulomb()
    f = np.asarray(model.simulate(model.from_physical(Fc=Fc, sigma2=sigma2), jnp.asarray(v)), np.float64)
    return v, f, DT


def test_models_carry_no_range_fields():
    for model in (Coulomb(), LuGre(asymmetric=True, offset=True), GMS(), Cylinder()):
        assert not [f for f in type(model).__dataclass_fields__ if f.endswith("_range")]


def test_box_keys_and_defaults_follow_the_search_coordinates():
    assert LuGre().box_keys == ("sigma0", "sigma1", "sigma2", "Fc", "Fs_ratio", "vs")
    assert Coulomb(asymmetric=True, offset=True).box_keys == ("Fc", "sigma2", "F_off")  # _pos/_neg share
    assert GMS(num_elements=2).box_keys == ("k", "C", "Fc", "Fs_ratio", "vs", "sigma2")  # splits are fixed
    box = LuGre().search_box()
    assert dict(box) == {k: DEFAULT_RANGES[k] for k in LuGre().box_keys}
    lo, hi = LuGre().bounds(box)
    np.testing.assert_allclose(lo, [4.0, 1.0, 1.0, 10.0, 1.0, -4.0])
    np.testing.assert_allclose(hi, [9.0, 6.0, 5.0, 2000.0, 3.0, np.log10(5e-2)])


def test_a_partial_box_overrides_only_its_entries():
    v, f, _ = coulomb_record()
    model = LuGre()
    centred = model.search_box(None, v, f)
    given = model.search_box({"vs": (1e-3, 1e-2), "Fs_ratio": (1.0, 1.5)}, v, f)
    assert given["vs"] == (1e-3, 1e-2) and given["Fs_ratio"] == (1.0, 1.5)
    assert {k: r for k, r in given.items() if k not in ("vs", "Fs_ratio")} == \
        {k: r for k, r in centred.items() if k not in ("vs", "Fs_ratio")}
    # against the defaults (no data) likewise
    plain = model.search_box({"Fc": (1.0, 2.0)})
    assert dict(plain) == {**{k: DEFAULT_RANGES[k] for k in model.box_keys}, "Fc": (1.0, 2.0)}
    # ... and through identify, into the fit
    fit = jf.identify("coulomb", (v, f, DT), key=0, solver=SOLVER, box={"sigma2": (100.0, 5000.0)})
    expected = Coulomb().search_box(None, v[:240], f[:240]) | {"sigma2": (100.0, 5000.0)}
    assert fit.box == expected and fit.box["Fc"] == pytest.approx((0.05 * np.percentile(np.abs(f[:240]), 95),
                                                                  1.2 * np.percentile(np.abs(f[:240]), 95)))
    assert fit.to_dict()["box"]["sigma2"] == [100.0, 5000.0]
    assert "box: Fc [" in fit.summary() and "sigma2 [100, 5000]" in fit.summary()
    without = jf.identify("coulomb", (v, f, DT), key=0, solver=SOLVER, box={"sigma2": (100.0, 5000.0)},
                          data_bounds=False)
    assert without.box == Coulomb().search_box({"sigma2": (100.0, 5000.0)})


@pytest.mark.parametrize("box, words", [
    ({"Fc": (20.0, 10.0)}, ["search box: Fc range must satisfy low < high"]),
    ({"sigma2": (0.0, 10.0)}, ["sigma2 range must be positive"]),
    ({"sigma2": (1.0, np.inf)}, ["sigma2 range", "finite"]),
    ({"sigma0": (1e4, 1e6)}, ["Coulomb has no parameter 'sigma0'", "Fc, sigma2"]),
    ({"Fc": "wide"}, ["Fc must be a (low, high) pair"]),
    (["Fc", (1, 2)], ["a search box is a mapping"]),
])
def test_a_bad_box_is_refused_before_any_computation(monkeypatch, box, words):
    def forbidden(*args, **kwargs):
        raise AssertionError("the optimiser ran")

    monkeypatch.setattr(pipeline, "minimise", forbidden)  # identify's global search
    v, f, _ = coulomb_record()
    f_before = f.copy()
    with pytest.raises(ValueError) as info:
        jf.identify("coulomb", (v, f, DT), key=0, solver=SOLVER, box=box)
    for w in words:
        assert w in str(info.value), (w, str(info.value))
    np.testing.assert_array_equal(f, f_before)


def test_same_model_different_boxes_share_one_compiled_cost(run_cache_size):
    """The box travels as the (lower, upper) arrays: a second box recompiles nothing, and
    the second fit really searched its own box."""
    v, f, _ = coulomb_record()
    jf.identify("coulomb", (v, f, DT), key=0, solver=SOLVER, box={"Fc": (1.0, 100.0)})
    size = run_cache_size()
    with Stopwatch() as sw, pytest.warns(BoundWarning, match=r"Fc = 20 .*box=\{'Fc': \(1, 39\)\}"):
        fit = jf.identify("coulomb", (v, f, DT), key=0, solver=SOLVER, box={"Fc": (1.0, 20.0)})
    assert sw.num_compiles == 0 and run_cache_size() == size
    assert fit.box["Fc"] == (1.0, 20.0) and float(fit.params["Fc"]) <= 20.0 + 1e-4
    assert [d["box_key"] for d in fit.diagnostics["on_bound"]] == ["Fc"]  # truth 40 N lies outside


def test_identify_motion_takes_the_box():
    from jaxfric.motion import MotionData, identify_motion

    t = np.arange(400) * 1e-3
    data = MotionData.from_arrays(20.0 * np.sin(2 * np.pi * 2 * t), 0.01 * np.sin(2 * np.pi * 2 * t - 0.5), 1e-3)
    box = {"Fc": (2.0, 40.0), "sigma2": (5.0, 500.0)}
    fit = identify_motion("coulomb", data, key=0, mass=1.0, solver=jf.NelderMead(max_steps=5),
                          box=box, data_bounds=False)
    assert fit.box == Coulomb().search_box(box)
    with pytest.raises(ValueError, match="Coulomb has no parameter 'vs'"):
        identify_motion("coulomb", data, key=0, mass=1.0, box={"vs": (1e-3, 1e-2)})


#: every physical model's search coordinates, directional and offset forms included
PHYSICAL = [Coulomb(asymmetric=True, offset=True), jf.models.Stribeck(asymmetric=True, offset=True),
            LuGre(asymmetric=True, offset=True), jf.models.Dahl(), GMS(num_elements=2), Cylinder()]


@pytest.mark.parametrize("model", PHYSICAL, ids=lambda m: type(m).__name__)
@pytest.mark.parametrize("ranges", ["defaults", "near the floors"])
def test_bound_advice_is_a_box_the_model_accepts(model, ranges):
    """A parameter on either bound of its range gets advice the box then accepts: a
    strictly wider range (one width more, ten times for a log10 entry, never below what
    the entry allows: Fc (1, 20) -> (0.1, 20), not (-18, 20)), or, where the range starts
    at the least value the model allows (Fs/Fc at 1), no range to pass at all.
    (0.8.1 told a LuGre fit on EMPS to pass box={'Fs_ratio': (-1, 3)}, which identify
    then refused.)"""
    import ast
    import re

    from jaxfric.identification import on_bound

    box = model.search_box()
    if ranges == "near the floors":  # ranges starting just above, or at, each entry's least value
        near = {"Fc": (1.0, 20.0), "Fs_ratio": (1.2, 3.0), "K_brk": (1.0, 2.0), "F_pr": (5.0, 100.0),
                "f_cfr": (0.0, 1e-5), "delta": (0.6, 3.0), "F_off": (-1.0, 1.0)}
        box = model.search_box({k: r for k, r in near.items() if k in model.box_keys})
    lower, upper = model.bounds(box)
    for i, search in enumerate(model.param_names):
        for side, edge in (("lower", lower), ("upper", upper)):
            theta = np.where(np.arange(lower.size) == i, edge, (lower + upper) / 2)
            flags = on_bound(model, theta, box)
            if search.startswith("split"):  # GMS's element splits: a range the model fixes
                assert flags == []
                continue
            assert [f["search_name"] for f in flags] == [search], (search, side, flags)
            (flag,) = flags
            key, (lo, hi) = flag["box_key"], flag["range"]
            passed = re.search(r"pass box=(\{.*?\})", flag["message"])
            assert flag["at_limit"] == (passed is None), flag["message"]
            if passed is None:
                assert side == "lower" and key in ("Fs_ratio", "K_brk", "F_pr", "f_cfr"), flag["message"]
                assert "the least the model allows" in flag["message"]
                continue
            wider = ast.literal_eval(passed.group(1))
            assert list(wider) == [key]
            model.search_box(wider)  # accepted: raises ValueError otherwise
            new_lo, new_hi = wider[key]
            if side == "lower":
                assert new_lo < lo * (1 - 1e-9) - 1e-300 and new_hi == pytest.approx(hi, rel=1e-3)
            else:
                assert new_hi > hi * (1 + 1e-9) and new_lo == pytest.approx(lo, rel=1e-3)


def test_report_marks_a_parameter_at_the_models_limit_apart_from_one_to_widen():
    """The report's parameter table (one verdict per parameter, jaxfric.uncertainty.report_markdown)."""
    from jaxfric.uncertainty import report_markdown

    verdicts = {"Fs": {"value": 16.8, "identifiable": True, "reasons": [], "on_bound": True, "at_limit": True},
                "Fc": {"value": 20.0, "identifiable": True, "reasons": [], "on_bound": True, "at_limit": False},
                "vs": {"value": 1e-3, "identifiable": True, "reasons": [], "on_bound": False, "at_limit": False}}
    rows = [line for line in report_markdown({"level": 0.95, "verdicts": verdicts}) if line.startswith("| F")
            or line.startswith("| vs")]
    assert rows == ["| Fs | 16.8 | **at the least value the model allows** |",
                    "| Fc | 20 | **on a bound: widen its range** |", "| vs | 0.001 | identifiable |"]
