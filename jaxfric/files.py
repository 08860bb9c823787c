"""Files, once for the whole package: atomic writes, JSON values, delimited text rows.

* [`atomic_write`][jaxfric.files.atomic_write] and friends write to a temporary file in the target folder and
  move it into place with ``os.replace``: a crash or Ctrl-C leaves either the old file or
  the new one, never half of one, and the temporary is removed on failure. The file gets
  the user's usual permissions (``0o666`` less the umask), as ``open`` would give it;
  ``tempfile.mkstemp`` alone would leave it ``0600``.
* [`jsonable`][jaxfric.files.jsonable] turns NumPy/JAX values, tuples and mappings into JSON types (one rule
  for fits, checkpoints and reports); [`write_json`][jaxfric.files.write_json] writes it atomically.
* [`read_rows`][jaxfric.files.read_rows] reads a delimited text file through the `csv` module (quoted
  cells, delimiters inside quotes) with comment lines and blank lines dropped, and every
  problem a `ValueError` that names the file and line; [`column_index`][jaxfric.files.column_index] maps a
  header name or index to a column and refuses a name the header holds twice;
  [`csv_text`][jaxfric.files.csv_text] / [`write_csv`][jaxfric.files.write_csv] write named columns back (full precision).
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import tempfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["TEMP_SUFFIX", "atomic_write", "atomic_write_bytes", "atomic_write_text", "column_index",
           "csv_text", "jsonable", "read_rows", "usual_mode", "write_csv", "write_json"]

TEMP_SUFFIX = ".jaxfric-tmp"
"""Suffix of the temporaries of an unfinished write (``.<name>.<random>.jaxfric-tmp``)."""


def usual_mode() -> int:
    """``0o666`` less the process umask: the mode ``open(path, "w")`` gives a new file."""
    # os.umask can only be read by setting it; set it straight back.
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def atomic_write(path, write: Callable[[Path], None]) -> Path:
    """Call ``write(tmp)`` on a temporary path next to ``path``, then move it onto ``path``.

    The temporary is removed when ``write`` or the move fails (the exception propagates),
    so the previous file, if any, stays complete. Missing parent folders are created.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=TEMP_SUFFIX)
    os.close(fd)
    tmp = Path(name)
    try:
        write(tmp)
        with open(tmp, "rb+") as fh:  # on disk before the rename makes it visible
            os.fsync(fh.fileno())
        os.chmod(tmp, usual_mode())
        os.replace(tmp, path)
    except BaseException:
        try:
            tmp.unlink()
        except OSError:
            pass
        raise
    return path


def atomic_write_bytes(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (see [`atomic_write`][jaxfric.files.atomic_write])."""
    return atomic_write(path, lambda tmp: tmp.write_bytes(data))


def atomic_write_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def jsonable(x, *, finite: bool = False) -> Any:
    """``x`` as JSON types: mappings (keys as str), lists, str, bool, int, float, None.

    Tuples become lists, NumPy/JAX arrays nested lists, NumPy scalars Python ones.
    ``finite=True`` writes a non-finite float as its text (``"nan"``, ``"inf"``) so the
    result is standard JSON; otherwise it stays a float (``json`` writes ``NaN``).
    Anything else becomes its ``repr``.
    """
    if isinstance(x, Mapping):
        return {str(k): jsonable(v, finite=finite) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v, finite=finite) for v in x]
    if isinstance(x, (str, bool)) or x is None:
        return x
    if isinstance(x, (int, np.integer)) and not isinstance(x, np.bool_):
        return int(x)
    if isinstance(x, (float, np.floating)):
        v = float(x)
        return str(v) if finite and not math.isfinite(v) else v
    if isinstance(x, np.bool_):
        return bool(x)
    if hasattr(x, "__array__") or isinstance(x, np.ndarray):
        arr = np.asarray(x)
        if arr.dtype.kind in "fiub":
            return jsonable(arr.tolist() if arr.ndim else arr.item(), finite=finite)
    return repr(x)


def write_json(path, obj, *, indent: int = 2) -> Path:
    """``obj`` (through [`jsonable`][jaxfric.files.jsonable], standard JSON) to ``path`` atomically."""
    text = json.dumps(jsonable(obj, finite=True), indent=indent, allow_nan=False)
    return atomic_write_text(path, text + "\n")


def read_rows(path, *, delimiter: str | None = ",", comments: str | None = "#") -> list[tuple[int, list[str]]]:
    """The non-blank, non-comment rows of a delimited text file as ``(line number, cells)``.

    ``delimiter=None`` splits on runs of whitespace; otherwise the `csv` module reads
    the file (so ``"a,b"`` in quotes is one cell). Cells are stripped of spaces (and of
    quotes in whitespace mode). A line whose first non-blank character starts
    ``comments`` is dropped, and a ``comments`` character ends a row's data. A UTF-8 byte
    order mark is ignored. Raises `ValueError` naming the file for a missing file,
    a folder, a binary file or an unreadable one.
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        raise ValueError(f"file not found: {path}")
    if os.path.isdir(path):
        raise ValueError(f"{path} is a folder, not a data file")
    try:
        with open(path, encoding="utf-8-sig", newline="") as fh:
            lines = list(enumerate(fh, start=1))
    except UnicodeDecodeError:
        raise ValueError(f"{path} is not a text (CSV) file") from None
    except OSError as err:
        raise ValueError(f"cannot read {path}: {err.strerror or err}") from None
    kept = []
    for lineno, line in lines:
        if "\x00" in line:
            raise ValueError(f"{path} is not a text (CSV) file")
        if comments and comments in line:
            line = line.split(comments, 1)[0]
        if line.strip():
            kept.append((lineno, line))
    if delimiter is None:
        return [(n, [c.strip('"').strip("'") for c in line.split()]) for n, line in kept]
    if len(delimiter) != 1:  # the csv module takes one character; split longer ones plainly
        return [(n, [c.strip().strip('"').strip("'") for c in line.rstrip("\r\n").split(delimiter)])
                for n, line in kept]
    try:
        parsed = csv.reader((line for _, line in kept), delimiter=delimiter, skipinitialspace=True)
        return [(n, [c.strip() for c in cells]) for (n, _), cells in zip(kept, parsed)]
    except csv.Error as err:
        raise ValueError(f"{path}: {err}") from None


def column_index(header: Sequence[str], name: str, *, path, what: str) -> int:
    """Index of the column ``name`` in ``header``; a name held twice is refused.

    ``what`` says who asked (e.g. ``"channel 'x'"``, ``"--x-col"``) for the message.
    """
    hits = [i for i, h in enumerate(header) if h == name]
    if not hits:
        raise ValueError(f"{path}: column '{name}' ({what}) is missing; the header has {list(header)}")
    if len(hits) > 1:
        raise ValueError(f"{path}: column '{name}' ({what}) appears {len(hits)} times in the header "
                         f"(columns {', '.join(str(i) for i in hits)}); rename the duplicates or give "
                         "a 0-based column index")
    return hits[0]


def csv_text(columns: Mapping[str, Any]) -> str:
    """Named columns as CSV text with a header row, every value with 17 significant
    digits so that [`read_rows`][jaxfric.files.read_rows] reads back the same float64 numbers."""
    buf = io.StringIO()
    buf.write(",".join(columns) + "\n")
    np.savetxt(buf, np.column_stack([np.asarray(c, dtype=np.float64) for c in columns.values()]),
               delimiter=",", fmt="%.17g")
    return buf.getvalue()


def write_csv(path, columns: Mapping[str, Any]) -> Path:
    """[`csv_text`][jaxfric.files.csv_text] of ``columns``, written atomically to ``path``."""
    return atomic_write_text(path, csv_text(columns))
