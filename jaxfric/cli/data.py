"""Data for the command line: the demo's simulated rig and users' CSV files.

CSV files are read here into named NumPy columns (with one-line errors naming the
file, the column and what the header holds), then handed to the library loaders
([`jaxfric.rig.load_friction_pairs`][jaxfric.rig.load_friction_pairs], [`jaxfric.rig.load_measurements`][jaxfric.rig.load_measurements],
[`jaxfric.rig.estimate_friction`][jaxfric.rig.estimate_friction]), which apply the unit factors, check the
signals and resample irregular time stamps.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from jaxfric.files import column_index, read_rows

from .errors import UserError
from .units import unit_factor


@dataclass
class Table:
    """Columns of a delimited text file: ``header`` (may be empty) and float64 ``data``."""

    path: str
    header: list[str]
    data: np.ndarray

    def column(self, spec: str, option: str) -> np.ndarray:
        """The column named ``spec`` (header name, or a 0-based index), after checking
        it has no empty or NaN cell (other columns may: they are not used)."""
        spec = str(spec).strip()
        if spec in self.header:  # column_index also refuses a name the header holds twice
            try:
                i = column_index(self.header, spec, path=self.path, what=option)
            except ValueError as err:
                raise UserError(f"{option}: {err}") from None
            return self._checked(self.data[:, i], spec, option)
        try:
            i = int(spec)
        except ValueError:
            have = f"the header has {', '.join(self.header)}" if self.header else "the file has no header row"
            raise UserError(f"{option}: no column {spec!r} in {self.path}; {have}") from None
        width = self.data.shape[1]
        if not -width <= i < width:
            raise UserError(f"{option}: column index {i} is out of range; {self.path} has {width} columns")
        return self._checked(self.data[:, i], spec, option)

    def _checked(self, col: np.ndarray, spec: str, option: str) -> np.ndarray:
        missing = np.nonzero(np.isnan(col))[0]
        if missing.size:
            raise UserError(f"{option}: column {spec!r} of {self.path} has {missing.size} empty or NaN "
                            f"cell(s), first in data row {int(missing[0]) + 1}")
        return col


def _delimiter(text: str | None):
    if text is None or text.strip().lower() in ("whitespace", "space", "spaces", "ws", "none", ""):
        return None
    return {"\\t": "\t", "tab": "\t"}.get(text, text)


def read_table(path: str, *, delimiter: str | None = ",", skip_rows: int = 0) -> Table:
    """Read a delimited text file with an optional header row (detected: a first line that is
    not all numbers). ``#`` starts a comment line. Raises [`UserError`][jaxfric.cli.UserError] for a missing or
    unreadable file, no data rows, ragged rows or non-numeric values."""
    if skip_rows < 0:
        raise UserError(f"--skip-rows must be >= 0, got {skip_rows}")
    sep = _delimiter(delimiter)
    try:
        rows = [cells for _, cells in read_rows(path, delimiter=sep, comments="#")]
    except ValueError as err:
        raise UserError(str(err)) from None
    if not rows:
        raise UserError(f"{path} is empty")
    first = rows[0]
    if len(first) == 1:
        for other, name in ((",", "','"), (";", "';'"), ("\t", "tab"), (None, "whitespace")):
            if other != sep and len(first[0].split(other)) > 1:
                raise UserError(f"{path}: only one column found with --delimiter {delimiter!r}; the lines look "
                                f"{name}-separated (is --delimiter right?)")
    header: list[str] = []
    try:
        [float(c) for c in first]
    except ValueError:
        header, rows = first, rows[1:]
    rows = rows[skip_rows:]
    if not rows:
        raise UserError(f"{path} has no data rows")
    values = []
    width = len(header) if header else None
    for n, cells in enumerate(rows, start=1):
        if width is None:
            width = len(cells)
        if len(cells) != width:
            raise UserError(f"{path}: data row {n} has {len(cells)} columns, expected {width}"
                            + (" (is --delimiter right?)" if len(cells) == 1 else ""))
        try:
            values.append([float(c) if c != "" else np.nan for c in cells])
        except ValueError:
            bad = next(c for c in cells if not _is_number(c))
            raise UserError(f"{path}: data row {n} holds a non-number {bad!r}") from None
    return Table(path=path, header=header, data=np.asarray(values, dtype=np.float64))


def _is_number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return text == ""


def _given(**options) -> dict:
    """The options the user gave; the rest keep the library's defaults (never copied here)."""
    return {k: v for k, v in options.items() if v is not None}


def _with_defaults(fn, options: dict) -> dict:
    """``options`` completed with ``fn``'s own keyword defaults (for describing the run)."""
    import inspect

    params = inspect.signature(fn).parameters
    return {**{k: p.default for k, p in params.items() if p.default is not inspect.Parameter.empty}, **options}


def _time_column(table: Table, args) -> np.ndarray:
    """Time stamps [s] from ``--time-col`` (with ``--time-unit``) or ``--dt``."""
    if args.time_col is not None and args.dt is not None:
        raise UserError("give either --time-col or --dt, not both")
    n = table.data.shape[0]
    if args.time_col is not None:
        return table.column(args.time_col, "--time-col") * unit_factor("time", args.time_unit, "--time-unit")
    if args.dt is not None:
        return np.arange(n) * float(args.dt)
    raise UserError("the sample times are missing: give --time-col COL or --dt SECONDS")


def _load_quietly(fn, *a, **kw):
    """Call a library loader; its irregular-sampling warning becomes one stderr note."""
    from jaxfric.rig import IrregularSamplingWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", IrregularSamplingWarning)
        out = fn(*a, **kw)
    notes = [str(w.message) for w in caught if issubclass(w.category, IrregularSamplingWarning)]
    return out, notes


@dataclass
class Columns:
    """The columns of one input file a command uses, read and checked (no JAX): ``mode``
    (``"pairs"``, ``"raw"`` or ``"predict"``), NumPy ``cols`` in the file's units, their
    ``scale`` factors to SI and the constant ``fill`` channels."""

    path: str
    mode: str
    cols: dict
    scale: dict
    fill: dict


def identification_columns(args, path: str) -> Columns:
    """Read ``jaxfric identify``'s columns of ``path`` (FILE or a ``--valid`` file) and
    check the options that choose them; one-line [`UserError`][jaxfric.cli.UserError] otherwise. NumPy only:
    this runs before JAX is imported ([`jaxfric.cli.checks`][jaxfric.cli.checks])."""
    pairs = args.velocity_col is not None or args.friction_col is not None
    raw_cols = {"x": args.x_col, "p1": args.p1_col, "p2": args.p2_col, "load": args.load_col}
    raw = any(v is not None for v in raw_cols.values())
    if pairs and (args.x_col is not None or args.load_col is not None):
        raise UserError("give either --velocity-col/--friction-col (velocity and friction, with "
                        "--p1-col/--p2-col for a pressure-dependent model) or "
                        "--x-col/--p1-col/--p2-col/--load-col (raw rig channels), not both")
    if not pairs and not raw:
        raise UserError("say which columns to use: --velocity-col and --friction-col, or the raw rig "
                        "channels --x-col --p1-col --p2-col --load-col (see 'jaxfric identify --help')")
    if pairs and (args.velocity_col is None or args.friction_col is None):
        raise UserError("the velocity/friction mode needs both --velocity-col and --friction-col")
    fills = {"p1": args.p1_fill, "p2": args.p2_fill, "load": args.load_fill}
    if not pairs:
        if args.x_col is None:
            raise UserError("the raw-channel mode needs --x-col (piston position)")
        for ch in ("p1", "p2", "load"):
            if raw_cols[ch] is None and fills[ch] is None:
                raise UserError(f"--{ch}-col is missing (or give a constant with --{ch}-fill)")
            if raw_cols[ch] is not None and fills[ch] is not None:
                raise UserError(f"give either --{ch}-col or --{ch}-fill, not both")
        missing = [f"--{k}" for k in ("bore", "rod", "mass") if getattr(args, k) is None]
        if missing:
            raise UserError(f"the raw-channel mode needs the cylinder geometry: {' '.join(missing)} "
                            "(bore and rod diameters in m, moving mass in kg)")
        if args.rod >= args.bore:
            raise UserError(f"--rod ({args.rod} m) must be smaller than --bore ({args.bore} m)")
    table = read_table(path, delimiter=args.delimiter, skip_rows=args.skip_rows)
    t = _time_column(table, args)
    if pairs:
        cols = {"t": t,
                "velocity": table.column(args.velocity_col, "--velocity-col"),
                "friction": table.column(args.friction_col, "--friction-col")}
        scale = {"velocity": unit_factor("velocity", args.velocity_unit, "--velocity-unit"),
                 "friction": unit_factor("force", args.friction_unit, "--friction-unit")}
        if args.p1_col is not None or args.p2_col is not None:
            # chamber pressures beside the pairs, for a model that takes them (Cylinder)
            if args.p1_col is None or args.p2_col is None:
                raise UserError("chamber pressures beside velocity and friction need both "
                                "--p1-col and --p2-col")
            p_unit = unit_factor("pressure", args.pressure_unit, "--pressure-unit")
            for ch in ("p1", "p2"):
                cols[ch] = table.column(raw_cols[ch], f"--{ch}-col")
                scale[ch] = p_unit
        return Columns(path, "pairs", cols, scale, {})
    cols = {"t": t, "x": table.column(args.x_col, "--x-col")}
    fill = {}
    for ch in ("p1", "p2", "load"):
        if raw_cols[ch] is not None:
            cols[ch] = table.column(raw_cols[ch], f"--{ch}-col")
        else:
            fill[ch] = float(fills[ch])
    p_unit = unit_factor("pressure", args.pressure_unit, "--pressure-unit")
    scale = {"x": unit_factor("length", args.x_unit, "--x-unit"), "p1": p_unit, "p2": p_unit,
             "load": unit_factor("force", args.load_unit, "--load-unit")}
    return Columns(path, "raw", cols, scale, fill)


def identification_data(args, path: str | None = None):
    """[`jaxfric.rig.FrictionData`][jaxfric.rig.FrictionData] from ``jaxfric identify``'s file and options.

    Returns ``(data, description, notes)``: the description says which mode and columns were
    used (for the report), the notes carry the loaders' warnings (e.g. resampled time stamps). Velocity/friction columns select the pairs mode; position and
    pressure/load columns the raw-channel mode through the §7 pipeline. The columns come
    from [`identification_columns`][jaxfric.cli.data.identification_columns] (read before JAX was imported, kept in ``args.columns``).
    """
    from jaxfric import rig

    path = args.file if path is None else path
    c = (getattr(args, "columns", None) or {}).get(path) or identification_columns(args, path)
    if c.mode == "pairs":
        data, notes = _load_quietly(rig.load_friction_pairs, c.cols, scale=c.scale,
                                    **_given(train_fraction=args.train_fraction))
        desc = (f"velocity/friction pairs from {path} (velocity column {args.velocity_col!r}, "
                f"friction column {args.friction_col!r}"
                + (f", pressures {args.p1_col!r} and {args.p2_col!r})" if "p1" in c.cols else ")"))
        return data, desc, notes
    meas, notes = _load_quietly(rig.load_measurements, c.cols, scale=c.scale, fill=c.fill)
    options = _given(gravity=args.gravity, cutoff=args.cutoff, train_fraction=args.train_fraction)
    data = rig.estimate_friction(meas, bore=args.bore, rod=args.rod, mass=args.mass, **options)
    used = _with_defaults(rig.estimate_friction, options)
    desc = (f"raw rig channels from {path} through the pipeline (Butterworth {used['cutoff']:g} Hz, "
            f"bore {args.bore:g} m, rod {args.rod:g} m, mass {args.mass:g} kg, "
            + (f"gravity {used['gravity']:g} m/s^2)" if used["gravity"] is not None else "no gravity term)"))
    return data, desc, notes


def velocity_filter(args) -> dict | None:
    """The low-pass the identification applied to the velocity, as saved with each fit
    (``fit.settings["velocity_filter"]``) so that ``jaxfric predict`` can say it and
    apply it: ``None`` when the file gave the velocity itself."""
    if getattr(args, "velocity_col", None) is not None:
        return None
    from jaxfric import rig

    used = _with_defaults(rig.estimate_friction, _given(cutoff=getattr(args, "cutoff", None)))
    return {"kind": "butterworth zero-phase", "order": int(used["order"]), "cutoff_hz": float(used["cutoff"])}


def prediction_columns(args) -> Columns:
    """``jaxfric predict``'s columns (no JAX; see [`identification_columns`][jaxfric.cli.data.identification_columns])."""
    table = read_table(args.data, delimiter=args.delimiter, skip_rows=args.skip_rows)
    t = _time_column(table, args)
    cols = {"t": t, "velocity": table.column(args.velocity_col, "--velocity-col")}
    scale = {"velocity": unit_factor("velocity", args.velocity_unit, "--velocity-unit")}
    if args.friction_col is not None:
        cols["friction"] = table.column(args.friction_col, "--friction-col")
        scale["friction"] = unit_factor("force", args.friction_unit, "--friction-unit")
    return Columns(args.data, "predict", cols, scale, {})


def prediction_input(args):
    """``(t, velocity, dt, friction_or_None)`` for ``jaxfric predict`` (SI units), one
    entry per data row of the file: irregular stamps are checked by the loader but not
    resampled here (``Fit.predict_at`` resamples onto the fit's grid and back)."""
    from jaxfric import rig

    c = (getattr(args, "columns", None) or {}).get(args.data) or prediction_columns(args)
    cols, scale = dict(c.cols), dict(c.scale)
    measured = "friction" in cols
    if not measured:
        cols["friction"] = np.zeros_like(cols["t"])  # placeholder: the loader wants the channel
        scale["friction"] = 1.0
    data, _ = _load_quietly(rig.load_friction_pairs, cols, scale=scale, train_fraction=1.0)
    friction = cols["friction"] * scale["friction"] if measured else None
    return cols["t"], cols["velocity"] * scale["velocity"], float(data.dt), friction


def simulated_rig(key):
    """The demo's data: simulate the default rig with ``key`` and run the §7 pipeline.

    Returns ``(rig, record, data)``: the [`jaxfric.rig.Rig`][jaxfric.rig.Rig], its
    [`RigRecord`][jaxfric.rig.RigRecord] (measured channels + ground truth) and the
    [`FrictionData`][jaxfric.rig.FrictionData] (1600/400 split).
    """
    from jaxfric import rig

    r = rig.Rig()
    record = rig.simulate(r, key)
    data = rig.estimate_friction(record.measurements(), r.cylinder)
    return r, record, data
