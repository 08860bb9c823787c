"""jaxfric.files: atomic writes with the user's permissions, JSON values, CSV rows."""

from __future__ import annotations

import json
import os
import stat

import numpy as np
import pytest

from jaxfric import files


@pytest.fixture
def umask022():
    old = os.umask(0o022)
    try:
        yield
    finally:
        os.umask(old)


def mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


# ---------------------------------------------------------------- permissions (issue 20.13)
def test_atomic_write_gives_the_usual_permissions(tmp_path, umask022):
    # what open(..., "w") gives under the same umask: the reference, not a constant
    ref = tmp_path / "plain.txt"
    ref.write_text("x")
    assert mode(ref) == 0o644
    p = files.atomic_write_text(tmp_path / "a.txt", "hello")
    assert mode(p) == mode(ref) == 0o644


def test_atomic_write_follows_a_strict_umask_too(tmp_path):
    old = os.umask(0o077)
    try:
        p = files.atomic_write_bytes(tmp_path / "b.bin", b"\x00\x01")
    finally:
        os.umask(old)
    assert mode(p) == 0o600


def test_saved_fit_in_a_report_gets_the_usual_permissions(tmp_path, umask022):
    import jaxfric as jf
    from jaxfric import report

    fit = jf.Fit(model=jf.Coulomb(), theta=np.array([40.0, 3.0]), velocity_scaler=None,
                 friction_scaler=None, dt=0.01, n_train=40, n_samples=50,
                 metrics={"train": None, "valid": None, "all": None})
    p = report.save_fit(fit, tmp_path / "models" / "coulomb.npz")
    assert mode(p) == 0o644  # Fit.save's mkstemp alone leaves 0600
    assert jf.load_fit(p).theta.tolist() == [40.0, 3.0]


def test_fit_save_gets_the_usual_permissions(tmp_path, umask022):
    import jaxfric as jf

    fit = jf.Fit(model=jf.Coulomb(), theta=np.array([40.0, 3.0]), velocity_scaler=None,
                 friction_scaler=None, dt=0.01, n_train=40, n_samples=50,
                 metrics={"train": None, "valid": None, "all": None})
    fit.save(tmp_path / "fit.npz")
    assert mode(tmp_path / "fit.npz") == 0o644


# ------------------------------------------------------------------------- atomicity
def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    p = tmp_path / "out.json"
    files.atomic_write_text(p, "old, complete")

    def half(tmp):
        tmp.write_text("half of the new")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        files.atomic_write(p, half)
    assert p.read_text() == "old, complete"
    assert sorted(x.name for x in tmp_path.iterdir()) == ["out.json"]
    with pytest.raises(KeyboardInterrupt):
        files.atomic_write(tmp_path / "new.txt", lambda tmp: (_ for _ in ()).throw(KeyboardInterrupt()))
    assert sorted(x.name for x in tmp_path.iterdir()) == ["out.json"]


def test_atomic_write_makes_the_folder(tmp_path):
    p = files.atomic_write_text(tmp_path / "a" / "b" / "c.txt", "x")
    assert p.read_text() == "x"


# ------------------------------------------------------------------------------- JSON
def test_jsonable_and_write_json(tmp_path):
    import jax.numpy as jnp

    value = {"a": np.float32(1.5), "b": (1, np.int64(2)), "c": jnp.arange(3), 4: np.array([[1.0, np.nan]]),
             "d": np.bool_(True), "e": float("inf")}
    assert files.jsonable(value)["b"] == [1, 2]
    assert files.jsonable(value)["c"] == [0, 1, 2]
    assert np.isnan(files.jsonable(value)["4"][0][1])
    strict = files.jsonable(value, finite=True)
    assert strict["4"] == [[1.0, "nan"]] and strict["e"] == "inf" and strict["d"] is True
    p = files.write_json(tmp_path / "r.json", value)
    assert json.loads(p.read_text()) == strict  # standard JSON: no NaN token
    assert "NaN" not in p.read_text()


# -------------------------------------------------------------------------------- CSV
def test_read_rows_goes_through_the_csv_module(tmp_path):
    p = tmp_path / "a.csv"
    p.write_text('\ufeff# a comment\nname,"note, with comma",v\n\n1, "x,y" ,2 # trailing\n')
    rows = files.read_rows(p)
    assert rows == [(2, ["name", "note, with comma", "v"]), (4, ["1", "x,y", "2"])]
    p.write_text("1 2  3\n'4' 5 6\n")
    assert files.read_rows(p, delimiter=None) == [(1, ["1", "2", "3"]), (2, ["4", "5", "6"])]


@pytest.mark.parametrize("kind, words", [
    ("missing", "file not found"), ("folder", "is a folder, not a data file"),
    ("binary", r"is not a text \(CSV\) file"), ("nul", r"is not a text \(CSV\) file"),
])
def test_read_rows_messages_name_the_file(tmp_path, kind, words):
    p = tmp_path / f"{kind}.csv"
    if kind == "folder":
        p.mkdir()
    elif kind == "binary":
        p.write_bytes(bytes(range(256)) * 4)
    elif kind == "nul":
        p.write_bytes(b"a,b\n1,\x002\n")
    with pytest.raises(ValueError, match=words) as err:
        files.read_rows(p)
    assert str(p) in str(err.value)


def test_column_index_refuses_a_duplicate_header_name():
    assert files.column_index(["t", "v", "F"], "v", path="f.csv", what="--velocity-col") == 1
    with pytest.raises(ValueError, match=r"column 'v' \(--velocity-col\) appears 2 times.*columns 1, 2"):
        files.column_index(["t", "v", "v"], "v", path="f.csv", what="--velocity-col")
    with pytest.raises(ValueError, match=r"column 'speed' .* is missing; the header has \['t', 'v'\]"):
        files.column_index(["t", "v"], "speed", path="f.csv", what="--velocity-col")


def test_cli_refuses_a_duplicate_header_name(tmp_path, capsys):
    # issue 20.5: the first of two 'v' columns was taken silently
    from jaxfric.cli import main

    p = tmp_path / "dup.csv"
    t = np.arange(50) * 0.01
    rows = "\n".join(f"{a},{np.sin(a)},{-np.sin(a)},{np.cos(a)}" for a in t)
    p.write_text("t,v,v,F\n" + rows + "\n")
    status = main(["identify", str(p), "--velocity-col", "v", "--friction-col", "F", "--time-col", "t",
                   "--model", "coulomb", "--quick", "--quiet", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert status == 2
    assert "column 'v'" in err and "appears 2 times" in err
    assert not (tmp_path / "r").exists()


def test_cli_reads_quoted_cells(tmp_path):
    from jaxfric.cli.data import read_table

    p = tmp_path / "q.csv"
    p.write_text('"time, s",v\n0,"1.5"\n1,2\n')
    table = read_table(str(p))
    assert table.header == ["time, s", "v"]
    assert table.column("time, s", "--time-col").tolist() == [0.0, 1.0]
