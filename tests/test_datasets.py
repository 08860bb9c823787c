"""jaxfric.datasets: local copies are found and checked, the cache folder follows
$JAXFRIC_DATA, and without the network a missing file is one line that says what to
download and where to put it. These tests never use the network: the downloader is
replaced by one that fails (or writes given bytes)."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import numpy as np
import pytest

from jaxfric import datasets

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
EMPS = SHARED / "emps" / "DATA_EMPS.mat"
ORING = SHARED / "pneumatic_seal_friction" / "raw" / "O-ring_3bar.csv"
needs_data = pytest.mark.skipif(not (EMPS.is_file() and ORING.is_file()),
                                reason="no local copy of the data in ../shared/data")


def _offline(url, dest):
    raise OSError(f"no network in the tests ({url})")


@pytest.fixture
def empty_cache(tmp_path, monkeypatch):
    monkeypatch.delenv(datasets.DATA_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.setattr(datasets, "_download", _offline)
    return tmp_path / "xdg" / "jaxfric" / "data"


def test_cache_folder_default_and_override(empty_cache, tmp_path, monkeypatch):
    assert datasets.cache_dir() == empty_cache
    monkeypatch.setenv(datasets.DATA_ENV, str(tmp_path / "mine"))
    assert datasets.cache_dir() == tmp_path / "mine"


def test_offline_is_one_line_saying_what_to_download_and_where(empty_cache):
    with pytest.raises(datasets.DatasetUnavailable) as info:
        datasets.emps_path()
    msg = str(info.value)
    assert "\n" not in msg
    assert "could not download DATA_EMPS.mat" in msg and "no network in the tests" in msg
    assert "https://" in msg and str(empty_cache / "emps" / "DATA_EMPS.mat") in msg
    assert datasets.DATA_ENV in msg
    with pytest.raises(datasets.DatasetUnavailable, match="O-ring_3bar.csv is not on disk"):
        datasets.pneumatic_path("O-ring", 3, download=False)
    assert not (empty_cache / "emps").exists() or not any((empty_cache / "emps").iterdir())


def test_unknown_seal_pressure_or_file_named():
    with pytest.raises(ValueError, match="unknown seal 'Q-ring'"):
        datasets.pneumatic_path("Q-ring")
    with pytest.raises(ValueError, match="no recording at 2 bar"):
        datasets.pneumatic_path("PK", 2)
    with pytest.raises(KeyError, match="unknown data file"):
        datasets.fetch("emps/other.mat")


def test_every_published_checksum_is_a_sha256():
    for rel, (url, sha, size) in datasets._FILES.items():
        assert url.startswith("https://") and url.endswith(Path(rel).name)
        assert len(sha) == 64 and int(sha, 16) >= 0 and size > 0
    assert len(datasets._FILES) == 1 + len(datasets.PNEUMATIC_SEALS) * len(datasets.PNEUMATIC_BARS)


def test_download_is_checked_then_cached(empty_cache, monkeypatch):
    """A download goes into the cache and is used from there; bytes that fail the
    checksum are removed and named as such."""
    payload = b"not the EMPS file"
    rel = "emps/DATA_EMPS.mat"
    url, sha, size = datasets._FILES[rel]

    def bad(url, dest):
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_bytes(payload)

    monkeypatch.setattr(datasets, "_download", bad)
    with pytest.raises(datasets.DatasetUnavailable, match="does not match its published SHA-256"):
        datasets.emps_path()
    assert not (empty_cache / rel).exists()
    # the same rule with a checksum that the payload meets: kept and found again offline
    monkeypatch.setitem(datasets._FILES, rel, (url, hashlib.sha256(payload).hexdigest(), len(payload)))
    assert datasets.emps_path() == empty_cache / rel
    monkeypatch.setattr(datasets, "_download", _offline)
    assert datasets.emps_path().read_bytes() == payload


@needs_data
def test_local_copies_pass_their_checksums_and_load(empty_cache, tmp_path, monkeypatch):
    """The checked-in checksums are those of the shared copies (computed independently
    here with hashlib), found through local= and through $JAXFRIC_DATA."""
    for rel, (_, sha, size) in datasets._FILES.items():
        path = SHARED / rel
        assert path.stat().st_size == size, rel
        assert hashlib.sha256(path.read_bytes()).hexdigest() == sha, rel
    assert datasets.emps_path(SHARED) == EMPS
    monkeypatch.setenv(datasets.DATA_ENV, str(SHARED))
    assert datasets.pneumatic_path("O-ring", 3) == ORING
    rec = datasets.emps()
    assert rec.n_samples == 24841 and abs(rec.dt - 1e-3) < 1e-6
    meas, data = datasets.pneumatic("O-ring", 3)
    raw = np.loadtxt(ORING)[datasets.PNEUMATIC_DROP_ROWS:]
    # resampled onto the median step of the raw stamps, over the same span
    assert abs(float(data.dt) - np.median(np.diff(raw[:, 0])) * 1e-3) < 1e-9
    assert abs(meas.t[-1] - meas.t[0] - (raw[-1, 0] - raw[0, 0]) * 1e-3) <= float(data.dt)
    assert data.n_train == int(0.8 * data.n_samples) or abs(data.n_train - 0.8 * data.n_samples) <= 1


@needs_data
def test_a_corrupted_copy_is_refused(empty_cache, tmp_path):
    folder = tmp_path / "copy"
    (folder / "emps").mkdir(parents=True)
    shutil.copy(EMPS, folder / "emps" / "DATA_EMPS.mat")
    with open(folder / "emps" / "DATA_EMPS.mat", "r+b") as fh:
        fh.seek(1000)
        fh.write(b"\0\0\0\0")
    with pytest.raises(datasets.DatasetUnavailable, match="does not match its published SHA-256"):
        datasets.emps_path(folder)


def test_a_failed_download_leaves_no_folder(tmp_path, monkeypatch):
    """The real downloader with the network refused (urlopen raising, as offline): one line,
    and nothing made in the data folder."""
    import urllib.error

    def refuse(url, timeout=None):
        raise urllib.error.URLError("network unreachable")

    monkeypatch.setattr(datasets.urllib.request, "urlopen", refuse)
    monkeypatch.setenv(datasets.DATA_ENV, str(tmp_path / "data"))
    with pytest.raises(datasets.DatasetUnavailable, match=r"could not download O-ring_3bar.csv \(network unreachable\)"):
        datasets.pneumatic_path("O-ring", 3)
    assert not (tmp_path / "data").exists()
