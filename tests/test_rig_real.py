"""The pipeline on real pneumatic seal-friction recordings (TU Delft, CC0; see the data's SOURCE.md).

Skipped when the data folder is absent. Looked up in the env var
JAXFRIC_PNEUMATIC_DATA, then next to the repository in shared/data/.
"""

from __future__ import annotations

import csv
import os
import warnings
from pathlib import Path

import numpy as np
import pytest

from jaxfric import rig


def _data_dir() -> Path | None:
    candidates = []
    if os.environ.get("JAXFRIC_PNEUMATIC_DATA"):
        candidates.append(Path(os.environ["JAXFRIC_PNEUMATIC_DATA"]))
    candidates.append(Path(__file__).resolve().parents[2] / "shared" / "data" / "pneumatic_seal_friction")
    for c in candidates:
        if (c / "friction_summary.csv").is_file() and any((c / "raw").glob("*.csv")):
            return c
    return None


DATA = _data_dir()
pytestmark = pytest.mark.skipif(DATA is None, reason="pneumatic_seal_friction data not found "
                                "(set JAXFRIC_PNEUMATIC_DATA)")


def test_coulomb_levels_agree_with_the_published_summary():
    summary = {r["file"]: r for r in csv.DictReader(open(DATA / "friction_summary.csv"))}
    report = []
    for path in sorted((DATA / "raw").glob("*.csv")):
        seal = path.stem.rsplit("_", 1)[0]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", rig.IrregularSamplingWarning)
            # SOURCE.md: ms, mm, bar, N; friction = F_loadcell - p A, i.e. the chamber acts like p2
            # on a rod-less area and the load cell force enters with the opposite sign of F_L
            meas = rig.load_measurements(path, {"t": 0, "x": 4, "p2": 5, "load": 6}, delimiter=None,
                                         scale={"t": 1e-3, "x": 1e-3, "p2": 1e5, "load": -1.0},
                                         fill={"p1": 0.0}, skip_rows=15)
        bore = 0.0257 if "257" in seal else 0.025
        data = rig.estimate_friction(meas, bore=bore, rod=0.0, mass=0.0)
        lev = rig.coulomb_levels(data.velocity, data.friction, 3e-3)
        ref = summary[path.name]
        rel = lev.halfrange / float(ref["coulomb_halfrange_N"]) - 1.0
        report.append((path.name, lev.halfrange, float(ref["coulomb_halfrange_N"]), rel))
        assert abs(lev.offset - float(ref["offset_N"])) < 0.5, path.name
    assert len(report) == len(summary) == 20
    worst = max(report, key=lambda r: abs(r[3]))
    assert abs(worst[3]) < 0.10, "\n".join(f"{n}: {c:.3f} N vs {s:.3f} N ({100 * r:+.1f} %)" for n, c, s, r in report)
    # the seal pressure effect the rig simulator models: friction grows with pressure for every seal
    by_seal = {}
    for name, c, _, _ in report:
        seal, p = name[:-4].rsplit("_", 1)
        by_seal.setdefault(seal, []).append((int(p[:-3]), c))
    for seal, levels in by_seal.items():
        levels.sort()
        assert np.all(np.diff([c for _, c in levels]) > 0), seal
