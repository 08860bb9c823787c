"""Public real-data sets, one call away: the EMPS benchmark and the pneumatic seal recordings.

Each file is looked up, in this order,

1. in the folder given as ``local=`` (laid out as below),
2. in ``$JAXFRIC_DATA`` when that variable is set,
3. in the cache folder, ``$XDG_CACHE_HOME/jaxfric/data`` (by default ``~/.cache/jaxfric/data``),

and, when it is in none of them, downloaded once from its public source into the cache
folder (or into ``$JAXFRIC_DATA`` when set). Every file is checked against its SHA-256
checksum before it is used, downloaded or not. Offline, a missing file is one
[`DatasetUnavailable`][jaxfric.datasets.DatasetUnavailable] line that says what to download and where to put it.

The folder layout (the same as a checkout's ``../shared/data``)::

    emps/DATA_EMPS.mat
    pneumatic_seal_friction/raw/<seal>_<bar>bar.csv      e.g. raw/O-ring_3bar.csv

Sources and licences:

* EMPS: A. Janot, M. Gautier, M. Brunot, *Data Set and Reference Models of EMPS*,
  Workshop on Nonlinear System Identification Benchmarks, 2019; the estimation file
  ``DATA_EMPS.mat`` as held in ``forgi86/sysid-neural-continuous`` (GitHub).
* Pneumatic seals: E. Zillen, TU Delft 2021, ``EvaZillen/3D-printed-pneumatic-actuator``
  (GitHub), CC0 1.0; seals ``O-ring``, ``NAPN``, ``PK`` (25 mm bore) and ``O-ring257``,
  ``X-ring257`` (25.7 mm bore) at 1, 3, 5 and 7 bar.

The loaders return the library's records: [`emps`][jaxfric.datasets.emps] an
[`jaxfric.rig.EMPSRecording`][jaxfric.rig.EMPSRecording], [`pneumatic`][jaxfric.datasets.pneumatic] the record's measurements and its
friction ([`jaxfric.rig.FrictionData`][jaxfric.rig.FrictionData]) by the pipeline of docs/algorithms.md §7.
"""

from __future__ import annotations

import hashlib
import os
import urllib.request
from pathlib import Path

from .files import atomic_write

__all__ = ["DatasetUnavailable", "DATA_ENV", "cache_dir", "emps", "emps_path", "pneumatic",
           "pneumatic_path", "PNEUMATIC_SEALS", "PNEUMATIC_BARS"]

#: environment variable naming a data folder (read first, and downloaded into when set)
DATA_ENV = "JAXFRIC_DATA"

_EMPS_URL = ("https://raw.githubusercontent.com/forgi86/sysid-neural-continuous/"
             "93afc131780fb1d5477472935a18ac8405683890/examples/EMPS/data/DATA_EMPS.mat")
_PNEUMATIC_URL = ("https://raw.githubusercontent.com/EvaZillen/3D-printed-pneumatic-actuator/"
                  "6e0bcb4633bd53b2a8544cdbd497c4c06539afc7/results_pneumatic-actuator/data/friction/{name}")

PNEUMATIC_SEALS = ("O-ring", "NAPN", "PK", "O-ring257", "X-ring257")
PNEUMATIC_BARS = (1, 3, 5, 7)

# relative path -> (url, sha256, bytes); the checksums are those of the files as published
_FILES: dict[str, tuple[str, str, int]] = {
    "emps/DATA_EMPS.mat": (_EMPS_URL, "6cf6814ae14618795da0101aae2bb97ff0c6351b0501b5492751b02b07facf7e", 626039),
}
_PNEUMATIC_SHA256 = {
    "O-ring_1bar": ("b795d01ad801c0a4222ca0bd4fa561dbbb7a3c87546b0e2cbdc13efc2c9c874b", 347051),
    "O-ring_3bar": ("d78d5575b6d9dcf57453107bea96b6dd8d59944a9f2df57f448621025115dade", 389081),
    "O-ring_5bar": ("163b266a3ae723b4d3d8be90ad50f3caca390fa5e76ff13a7c5287a1c8502755", 513059),
    "O-ring_7bar": ("e3814abff4dae2bfa70a53d925a5990699dc65e5a6472b42d1dad01293de7a35", 432795),
    "O-ring257_1bar": ("4d3c6d4f9b90ddb3c01f691a4325d5ab9e72ca5597499a222e65ddcb1ee466fa", 283219),
    "O-ring257_3bar": ("3294ab343633987485d7df9aeda7310ea30c7ca10370f61cc881946b37a23d5f", 314448),
    "O-ring257_5bar": ("b09c0c8c90106a550c5b875d770c2e9cad0b8c04c820755e970fd0660e12444b", 351703),
    "O-ring257_7bar": ("b7fb325312617d426114878a88ce9fe320a13b765f27a5ac4f6ad51ef37e05b4", 424655),
    "X-ring257_1bar": ("22d35590e6423e1799cef0d2272ea9aad161610b9374354927de14b22bc9c5e5", 284855),
    "X-ring257_3bar": ("7bdd9fd9104779dfa13c13fdb1cba2122e2887ffdcdf1ce966aa6c44cec90392", 317244),
    "X-ring257_5bar": ("1ba41cbc9299b4f2655fbe67c19c706936b7047e2a43395457412045f7e99442", 351134),
    "X-ring257_7bar": ("4fdc68f71d112b4ff8bd69813fa15daa92220195ecbc5366800c0fd4d7a16edc", 435054),
    "NAPN_1bar": ("008a31e1007d67b1f0ebd9e6772cfe9e58a65667148e41ba29466deabb5551b9", 341854),
    "NAPN_3bar": ("87a0e11e56e8824203f1a2cb161f45a62ece2b95c1c5ad7712218a74035909f2", 398035),
    "NAPN_5bar": ("3bf6ec120f435a0e3feee07b4978db80f3d63208974e7c6749e0822270d9618b", 506379),
    "NAPN_7bar": ("fae7d01899d6111f32b726ab869c89128c572393fb40cc16df9553160c8f25a9", 421231),
    "PK_1bar": ("b00deabc985f29db36b45f1beac49400c74f8812b4f623188ed80e307ce45a3a", 335739),
    "PK_3bar": ("1b8279a4350d3f4ebadde61637fd80a0dabd0345056a07250625b26471edd004", 381139),
    "PK_5bar": ("d3c2be0a8c75f449ccd2f3fe7f89297bc5dcd9600ececabd2789d10dade01846", 480397),
    "PK_7bar": ("74c6509a51ad4aa0966791e849369713bac00253d061bdf5f5554ed1269f5a37", 404860),
}
for _name, (_sha, _size) in _PNEUMATIC_SHA256.items():
    _FILES[f"pneumatic_seal_friction/raw/{_name}.csv"] = (_PNEUMATIC_URL.format(name=f"{_name}.csv"), _sha, _size)


class DatasetUnavailable(OSError):
    """A data file is neither on disk nor downloadable (offline, or a failed checksum)."""


def cache_dir() -> Path:
    """Where downloaded files are kept: ``$JAXFRIC_DATA`` when set, else
    ``$XDG_CACHE_HOME/jaxfric/data`` (``~/.cache/jaxfric/data`` by default)."""
    env = os.environ.get(DATA_ENV)
    if env:
        return Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "jaxfric" / "data"


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _download(url: str, dest: Path) -> None:
    """Fetch ``url`` into ``dest`` (a temporary file beside it, moved into place whole)."""
    with urllib.request.urlopen(url, timeout=60) as response:  # offline: fails here, before any folder is made
        def write(tmp):
            with open(tmp, "wb") as out:
                for block in iter(lambda: response.read(1 << 20), b""):
                    out.write(block)

        atomic_write(dest, write)


def fetch(relpath: str, local=None, *, download: bool = True) -> Path:
    """The checked path of one data file, ``relpath`` in the layout of this module's
    docstring (e.g. ``"emps/DATA_EMPS.mat"``): from ``local``, ``$JAXFRIC_DATA`` or the
    cache, else downloaded into [`cache_dir`][jaxfric.datasets.cache_dir] (unless ``download=False``).

    Raises:
        KeyError: ``relpath`` is not one of the known files.
        DatasetUnavailable: the file is in none of the folders and cannot be downloaded,
            or a copy fails its SHA-256 checksum.
    """
    if relpath not in _FILES:
        raise KeyError(f"unknown data file {relpath!r}; known: {', '.join(sorted(_FILES))}")
    url, sha, _ = _FILES[relpath]
    # $JAXFRIC_DATA, when set, is the cache folder itself (read first, downloaded into)
    folders = ([Path(local).expanduser()] if local is not None else []) + [cache_dir()]
    for folder in folders:
        path = folder / relpath
        if path.is_file():
            if _sha256(path) != sha:
                raise DatasetUnavailable(
                    f"{path} does not match its published SHA-256 checksum ({sha[:12]}...): "
                    f"remove it to download it again, or fetch {url} yourself")
            return path
    dest = cache_dir() / relpath
    if not download:
        raise DatasetUnavailable(_missing(relpath, url, dest))
    try:
        _download(url, dest)
    except (OSError, ValueError) as err:
        reason = " ".join(str(getattr(err, "reason", err)).split())
        raise DatasetUnavailable(_missing(relpath, url, dest, reason)) from None
    if _sha256(dest) != sha:
        dest.unlink()
        raise DatasetUnavailable(f"the file downloaded from {url} does not match its published SHA-256 "
                                 f"checksum ({sha[:12]}...); it was removed. Fetch it yourself and put it at {dest}")
    return dest


def _missing(relpath: str, url: str, dest: Path, reason: str | None = None) -> str:
    why = f"could not download {Path(relpath).name} ({reason})" if reason else f"{Path(relpath).name} is not on disk"
    return (f"{why}: download {url} and put it at {dest}, or set {DATA_ENV} to a folder "
            f"that holds {relpath}")


# ------------------------------------------------------------------------------ EMPS
def emps_path(local=None, *, download: bool = True) -> Path:
    """Path of the EMPS estimation file ``DATA_EMPS.mat`` (checked; fetched on first use)."""
    return fetch("emps/DATA_EMPS.mat", local, download=download)


def emps(local=None, *, download: bool = True):
    """The EMPS estimation recording (24 841 samples at 1 kHz) as a
    [`jaxfric.rig.EMPSRecording`][jaxfric.rig.EMPSRecording]; [`jaxfric.rig.emps_friction_data`][jaxfric.rig.emps_friction_data] turns it
    into friction by the benchmark's recipe."""
    from . import rig

    return rig.load_emps(emps_path(local, download=download))


# ------------------------------------------------------------------------- pneumatic
def pneumatic_path(seal: str = "O-ring", bar: int = 3, local=None, *, download: bool = True) -> Path:
    """Path of one raw pneumatic seal recording (checked; fetched on first use)."""
    if seal not in PNEUMATIC_SEALS:
        raise ValueError(f"unknown seal {seal!r}; choose from {', '.join(PNEUMATIC_SEALS)}")
    if bar not in PNEUMATIC_BARS:
        raise ValueError(f"no recording at {bar!r} bar; choose from {', '.join(map(str, PNEUMATIC_BARS))}")
    return fetch(f"pneumatic_seal_friction/raw/{seal}_{bar}bar.csv", local, download=download)


#: rows the authors drop at the start of each file ("deviating starting values")
PNEUMATIC_DROP_ROWS = 15


def pneumatic(seal: str = "O-ring", bar: int = 3, local=None, *, download: bool = True,
              cutoff: float = 5.0, train_fraction: float = 0.8):
    """One pneumatic seal recording: ``(measurements, friction_data)``.

    The raw file's time [ms], position [mm], chamber pressure [bar] and load-cell force
    [N] (columns 0, 4, 5, 6, the first 15 rows dropped) are resampled to their median
    step, low-pass filtered (zero-phase Butterworth, ``cutoff`` Hz) and turned into
    friction by the force balance of docs/algorithms.md §7 with one pressurised chamber
    of the seal's bore (25 mm, 25.7 mm for the ``257`` seals), no rod and no inertia
    term, as the authors compute it. Returns [`jaxfric.rig.Measurements`][jaxfric.rig.Measurements] and
    [`jaxfric.rig.FrictionData`][jaxfric.rig.FrictionData] (the first ``train_fraction`` for estimation).
    """
    import warnings

    from . import rig

    path = pneumatic_path(seal, bar, local, download=download)
    with warnings.catch_warnings():
        # the stamps are irregular (~100 Hz with gaps); resampling them is the recipe
        warnings.simplefilter("ignore", rig.IrregularSamplingWarning)
        meas = rig.load_measurements(
            path, {"t": 0, "x": 4, "p2": 5, "load": 6},
            # ms -> s, mm -> m, bar -> Pa; the load cell pushes towards +x, the load channel opposes +x
            scale={"t": 1e-3, "x": 1e-3, "p2": 1e5, "load": -1.0},
            fill={"p1": 0.0}, delimiter=None, skip_rows=PNEUMATIC_DROP_ROWS, on_irregular="resample")
    bore = 0.0257 if "257" in seal else 0.025
    data = rig.estimate_friction(meas, bore=bore, rod=0.0, mass=0.0, cutoff=cutoff, train_fraction=train_fraction)
    return meas, data
