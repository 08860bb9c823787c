"""The ``jaxfric`` argument parser: sub-commands, options, help texts with examples.

Parsing only; nothing here touches JAX, so ``jaxfric --help`` answers at once.
Argument errors are one line (``jaxfric: error: ...``), like every other user error.
"""

from __future__ import annotations

import argparse
import math
import sys

from .checks import MODEL_NAMES
from .errors import EXIT_USER_ERROR, error_line
from .fitting import REFINE_CHOICES
from .spec import SOLVERS
from .units import UNITS

DEFAULT_OUT = "jaxfric-report"


class Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are a single ``jaxfric: error:`` line (no usage dump)."""

    def error(self, message):  # noqa: D102 - argparse API
        hint = f" (see '{self.prog} --help')"
        print(error_line(message) + hint, file=sys.stderr, flush=True)
        raise SystemExit(EXIT_USER_ERROR)


class _Formatter(argparse.RawDescriptionHelpFormatter):
    """Keep the epilog's example layout; show a default only where there is one."""

    def _get_help_string(self, action):
        text = action.help or ""
        default = action.default
        if (default is None or default is False or default is argparse.SUPPRESS
                or "%(default)" in text or not action.option_strings):
            return text
        return f"{text} (default: {default})" if text else f"default: {default}"


# --------------------------------------------------------------- value checkers
def _number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
    return value


def positive_float(text: str) -> float:
    value = _number(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text!r}")
    return value


def nonnegative_float(text: str) -> float:
    value = _number(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text!r}")
    return value


def fraction(text: str) -> float:
    value = _number(text)
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f"must lie strictly between 0 and 1, got {text!r}")
    return value


def _whole(text: str, minimum: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if value < minimum:
        raise argparse.ArgumentTypeError(f"must be >= {minimum}, got {text!r}")
    return value


def positive_int(text: str) -> int:
    return _whole(text, 1)


def box_entry(text: str) -> tuple[str, tuple[float, float]]:
    """``NAME=LO,HI`` -> ``(NAME, (LO, HI))``: two finite numbers, low < high (no JAX here;
    the parameter's name and the range rules of [`jaxfric.models.SearchBox`][jaxfric.models.SearchBox] are
    checked once the models are imported, before any stage)."""
    name, sep, pair = text.partition("=")
    parts = pair.split(",")
    if not sep or not name.strip() or len(parts) != 2:
        raise argparse.ArgumentTypeError(f"give NAME=LO,HI (e.g. Fc=1,100), got {text!r}")
    lo, hi = _number(parts[0]), _number(parts[1])
    if not lo < hi:
        raise argparse.ArgumentTypeError(f"{name.strip()} range must satisfy low < high, got {lo:g},{hi:g}")
    return name.strip(), (lo, hi)


def seed(text: str) -> int:
    return _whole(text, 0)


def model_list(text: str) -> list[str]:
    names = [t.strip().lower().replace("-", "_") for t in text.split(",") if t.strip()]
    if not names:
        raise argparse.ArgumentTypeError("give at least one model, e.g. elman,lugre")
    return list(dict.fromkeys(names))


# ------------------------------------------------------------------- epilogs
MAIN_EPILOG = """\
examples:
  jaxfric demo                          simulate the rig, fit ENN and LuGre, write ./jaxfric-report/
  jaxfric demo --quick --out /tmp/r     the same with a tiny budget (seconds)
  jaxfric identify data.csv --velocity-col v --friction-col F --time-col t
  jaxfric predict jaxfric-report/models/elman.npz new.csv --velocity-col v --dt 0.0078125
  jaxfric bench table1 --quick
  jaxfric COMMAND --help                options of one command

Set JAXFRIC_DEBUG=1 (or pass --debug) to see tracebacks instead of one-line errors.
"""

DEMO_EPILOG = """\
The demo simulates the paper's experiment (docs/algorithms.md §1, §7) and identifies it with
jaxfric's own pipeline (--paper: the paper's MAPSO-NMDS): 2000 samples at 128 Hz, 5 Hz
Butterworth, friction by force balance, the first 1600 samples for estimation and the last
400 for validation. Pipelines (the same words as the stage lines and the report):
  ENN (30 neurons, 180 parameters):
    MAPSO (8x8 agents, G = 50) on the 1600 training samples -> BFGS (<= 500 steps)
  LuGre (asymmetric + offset, 10 parameters, as the rig's asymmetric friction needs; --form):
    MAPSO (5x5 agents, G = 200) -> Nelder-Mead (<= 2000 evaluations)
  with --paper, both: MAPSO -> Nelder-Mead (the paper's MAPSO-NMDS), no gradient stage.
Then a position loop on the same rig compares each fit's friction feed-forward.

The report folder holds report.md, results.json, figures (*.png), the saved fits
(models/*.npz, for 'jaxfric predict') and the simulated raw channels
(rig_measurements.csv, to try 'jaxfric identify' on).

examples:
  jaxfric demo
  jaxfric demo --out results/demo --seed 3
  jaxfric demo --models elman --neurons 20 --generations 400
  jaxfric demo --quick --quiet
"""

IDENTIFY_EPILOG = """\
Two kinds of CSV file (header row with column names; columns may also be 0-based indices):

  velocity and friction     --velocity-col, --friction-col and --time-col (or --dt);
                            add --p1-col and --p2-col (chamber pressures) for --model cylinder
  raw rig channels          --x-col, --p1-col, --p2-col, --load-col, --time-col (or --dt)
                            and the cylinder: --bore, --rod [m], --mass [kg]; the channels
                            are low-pass filtered (--cutoff), x is differentiated and the
                            friction follows from the force balance (docs/algorithms.md §7)

Units: give each channel's unit by name or as a factor to SI (a negative factor flips a
sign), e.g. --x-unit mm --pressure-unit bar --time-unit ms, or --load-unit -1.
Known names: """ + "; ".join(f"{k}: {', '.join(v)}" for k, v in UNITS.items()) + """.

examples:
  jaxfric identify pairs.csv --velocity-col v --friction-col F --time-col t
  jaxfric identify pairs.csv --velocity-col 0 --friction-col 1 --dt 0.0078125 --model lugre
  jaxfric identify run1.csv --valid run2.csv --valid run3.csv --velocity-col v --friction-col F --time-col t
  jaxfric identify rig.csv --time-col t --x-col x --p1-col p1 --p2-col p2 --load-col load \\
      --bore 0.10 --rod 0.07 --mass 120
  jaxfric identify rec.txt --delimiter whitespace --time-col 0 --time-unit ms --x-col 4 \\
      --x-unit mm --p2-col 5 --pressure-unit bar --load-col 6 --load-unit -1 --p1-fill 0 \\
      --bore 0.025 --rod 0 --mass 0 --model lugre,elman --neurons 10
"""

PREDICT_EPILOG = """\
Loads a fit saved by 'jaxfric demo' or 'jaxfric identify' (models/*.npz in the report
folder, or Fit.save in Python) and writes its free-run friction prediction for the
velocity record of DATA_CSV: columns t [s], velocity [m/s], friction_predicted [N]
(plus friction_measured and error when --friction-col is given).

A fit learns from the velocity it was given. Fits made from raw rig channels (and the
demo's) saw a low-pass filtered velocity (zero-phase Butterworth, 5 Hz by default): the
command says so, and --filter-velocity applies the same filter to an unfiltered record.

examples:
  jaxfric predict jaxfric-report/models/elman.npz new.csv --velocity-col v --time-col t
  jaxfric predict fit.npz new.csv --velocity-col 0 --dt 0.0078125 --out pred.csv
  jaxfric predict jaxfric-report/models/elman.npz raw.csv --velocity-col v --time-col t --filter-velocity
"""

BENCH_EPILOG = """\
Runs a benchmark script from the source tree's benchmarks/ folder; every argument after
the benchmark's name goes to it unchanged ('jaxfric bench table1 --help' shows them).

  table1     the paper's Table 1: MAPSO-NMDS against PSO on the test functions
  friction   the friction identification benchmark (ENN sizes, ENN against LuGre)

examples:
  jaxfric bench table1 --quick
  jaxfric bench table1 --dim 30 --runs 30 --out results
  jaxfric bench friction --help
"""


# ------------------------------------------------------------------ builders
def _common(p: argparse.ArgumentParser, *,
            x64_help: str = "compute in float64 (slower; float32 is accurate enough for these fits)") -> None:
    g = p.add_argument_group("general")
    g.add_argument("--quiet", "-q", action="store_true", help="no progress bars or stage messages")
    g.add_argument("--x64", action="store_true", help=x64_help)
    g.add_argument("--debug", action="store_true", help="show tracebacks instead of one-line errors")
    g.add_argument("--no-cache", action="store_true",
                   help="do not keep compiled programs on disk (default: in $JAX_COMPILATION_CACHE_DIR, "
                   "else ~/.cache/jaxfric/jax; a second run then skips most compilation)")


def _fitting(p: argparse.ArgumentParser, *, default_models: str) -> None:
    g = p.add_argument_group("identification")
    g.add_argument("--model", "--models", dest="models", type=model_list, default=default_models,
                   metavar="NAMES", help=f"comma-separated friction models: {', '.join(MODEL_NAMES)}")
    g.add_argument("--neurons", type=positive_int, default=None,
                   help="hidden neurons of the Elman network (default: the model's, 30)")
    g.add_argument("--solver", choices=SOLVERS, default="mapso-nmds", help="optimiser")
    g.add_argument("--generations", type=positive_int, default=None, metavar="G",
                   help="budget: swarm generations (for nelder-mead: its step cap); default depends on "
                   "the model, see --quick")
    g.add_argument("--nm-evals", type=positive_int, default=None, metavar="N",
                   help="Nelder-Mead evaluation budget of mapso-nmds (default: chosen with the generations)")
    g.add_argument("--refine", choices=("default", *REFINE_CHOICES), default="default",
                   help="gradient stage after the search: 'default' is the method's own (BFGS, <= 500 steps, for "
                   "the networks; none for the physical models and with --paper), 'none' turns it off, 'auto' is "
                   "LM for small models and BFGS for the networks")
    g.add_argument("--form", choices=("auto", "symmetric", "asymmetric"), default="auto",
                   help="physical models (LuGre, Dahl, Coulomb, Stribeck, GMS): 'asymmetric' adds direction-dependent "
                   "levels and a force offset; 'auto' chooses it when the data's sliding friction differs by more "
                   "than 5 %% between the two directions")
    g.add_argument("--paper", action="store_true",
                   help="the paper's method exactly: MAPSO-NMDS, no gradient stage (default: jaxfric's "
                   "faster, more accurate pipeline; for the networks a short MAPSO then BFGS)")
    g.add_argument("--box", action="append", type=box_entry, default=None, metavar="NAME=LO,HI",
                   help="search range of a physical model's parameter in SI units (repeatable), e.g. "
                   "--box Fc=1,100 --box vs=1e-4,0.1; each model takes the entries it has, the rest of its "
                   "box is centred on the data")
    g.add_argument("--seed", type=seed, default=0, help="random seed (same seed, same result)")
    g.add_argument("--quick", action="store_true", help="tiny budget: a smoke test in seconds, not a real fit")
    g.add_argument("--out", default=DEFAULT_OUT, metavar="DIR", help="report folder (created if needed)")


def _columns(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("columns (header name or 0-based index)")
    g.add_argument("--time-col", metavar="COL", help="time stamps (or give --dt)")
    g.add_argument("--dt", type=positive_float, metavar="S", help="sample interval [s] when there is no time column")
    g.add_argument("--velocity-col", metavar="COL", help="piston velocity")
    g.add_argument("--friction-col", metavar="COL", help="friction force")
    g.add_argument("--x-col", metavar="COL", help="piston position (raw rig channels)")
    g.add_argument("--p1-col", metavar="COL", help="cap-side chamber pressure")
    g.add_argument("--p2-col", metavar="COL", help="rod-side chamber pressure")
    g.add_argument("--load-col", metavar="COL", help="external load (force sensor), opposing +x")
    for ch in ("p1", "p2", "load"):
        g.add_argument(f"--{ch}-fill", type=float, metavar="VALUE",
                       help=f"constant {ch} (in its unit) when the file has no such column")
    f = p.add_argument_group("file format")
    f.add_argument("--delimiter", default=",", help="column separator; 'whitespace' for spaces/tabs")
    f.add_argument("--skip-rows", type=int, default=0, metavar="N", help="data rows to drop after the header")
    u = p.add_argument_group("units (a name or a factor to SI)")
    u.add_argument("--time-unit", default="s", metavar="UNIT", help="of the time column")
    u.add_argument("--velocity-unit", default="m/s", metavar="UNIT", help="of the velocity column")
    u.add_argument("--friction-unit", default="N", metavar="UNIT", help="of the friction column")
    u.add_argument("--x-unit", default="m", metavar="UNIT", help="of the position column")
    u.add_argument("--pressure-unit", default="Pa", metavar="UNIT", help="of both pressure columns")
    u.add_argument("--load-unit", default="N", metavar="UNIT", help="of the load column")


def _predict_parser(sub) -> None:
    """The ``predict`` sub-command."""
    r = sub.add_parser("predict", help="predict friction with a saved fit",
                       description="Predict friction for a velocity record with a saved fit and write a CSV.",
                       epilog=PREDICT_EPILOG, formatter_class=_Formatter)
    r.add_argument("model_file", metavar="MODEL_FILE", help="saved fit (models/*.npz of a report)")
    r.add_argument("data", metavar="DATA_CSV", help="CSV with a velocity column")
    g = r.add_argument_group("columns (header name or 0-based index)")
    g.add_argument("--velocity-col", default="velocity", metavar="COL", help="piston velocity")
    g.add_argument("--time-col", metavar="COL", help="time stamps (or give --dt)")
    g.add_argument("--dt", type=positive_float, metavar="S", help="sample interval [s] when there is no time column")
    g.add_argument("--friction-col", metavar="COL", help="measured friction, to report the error")
    g.add_argument("--delimiter", default=",", help="column separator; 'whitespace' for spaces/tabs")
    g.add_argument("--skip-rows", type=int, default=0, metavar="N", help="data rows to drop after the header")
    g.add_argument("--time-unit", default="s", metavar="UNIT", help="of the time column")
    g.add_argument("--velocity-unit", default="m/s", metavar="UNIT", help="of the velocity column")
    g.add_argument("--friction-unit", default="N", metavar="UNIT", help="of the friction column")
    f = r.add_argument_group("preprocessing")
    f.add_argument("--filter-velocity", action="store_true",
                   help="low-pass the velocity as the fit's training velocity was (zero-phase Butterworth; the "
                   "cutoff and order saved with the fit, or --cutoff)")
    f.add_argument("--cutoff", type=positive_float, default=None, metavar="HZ",
                   help="cutoff [Hz] for --filter-velocity (default: the fit's)")
    r.add_argument("--out", "-o", default="predictions.csv", metavar="FILE",
                   help="output CSV ('-' for standard output)")
    _common(r)


def build_parser() -> Parser:
    """The full ``jaxfric`` parser (sub-commands demo, identify, predict, bench)."""
    from jaxfric import __version__

    p = Parser(prog="jaxfric", description="Identify friction in hydraulic cylinders: an Elman network (ENN), "
               "LuGre and other models, fitted by jaxfric's pipeline (MAPSO -> BFGS for the networks, MAPSO -> "
               "Nelder-Mead for the physical models) or the paper's MAPSO-NMDS (--paper).", epilog=MAIN_EPILOG,
               formatter_class=_Formatter)
    p.add_argument("--version", action="version", version=f"jaxfric {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    sub.required = True

    d = sub.add_parser("demo", help="simulate a test rig, fit the ENN and LuGre with jaxfric's pipeline, "
                       "compare friction compensation, write a report",
                       description="Simulate the test rig, compute the friction, identify the ENN and "
                       "LuGre (jaxfric's pipeline; --paper: the paper's method), compare each fit's friction "
                       "compensation, print the comparison table and write a report folder.",
                       epilog=DEMO_EPILOG, formatter_class=_Formatter)
    _fitting(d, default_models="elman,lugre")
    _common(d)

    i = sub.add_parser("identify", help="fit friction models to your own CSV recording",
                       description="Fit friction models to a recorded CSV file and write the same report "
                       "as the demo.", epilog=IDENTIFY_EPILOG, formatter_class=_Formatter)
    i.add_argument("file", metavar="FILE", help="CSV (or whitespace-separated) file")
    _columns(i)
    g = i.add_argument_group("cylinder and pipeline (raw rig channels only)")
    g.add_argument("--bore", type=positive_float, metavar="M", help="piston (bore) diameter [m]")
    g.add_argument("--rod", type=nonnegative_float, metavar="M", help="rod diameter [m] (0: no rod)")
    g.add_argument("--mass", type=nonnegative_float, metavar="KG", help="moving mass [kg]")
    g.add_argument("--gravity", type=float, default=None, metavar="M/S2",
                   help="gravity component along -x [m/s^2] (default: the pipeline's, 0: a horizontal axis)")
    g.add_argument("--cutoff", type=positive_float, default=None, metavar="HZ",
                   help="Butterworth low-pass cutoff [Hz] (default: the pipeline's, 5 Hz as in the paper)")
    i.add_argument("--train-fraction", type=fraction, default=None, metavar="F",
                   help="leading fraction of the record used for estimation; the rest validates "
                   "(default: the library's, 0.8 as in the paper)")
    i.add_argument("--valid", action="append", default=[], metavar="FILE",
                   help="validation recording (same columns and options as FILE; repeatable): FILE is "
                   "then used whole for estimation and each --valid file whole for validation")
    _fitting(i, default_models="elman,lugre")
    _common(i)

    _predict_parser(sub)

    from .motion import add_parser as _add_motion

    _add_motion(sub, common=_common, formatter=_Formatter, positive_float=positive_float,
                positive_int=positive_int, fraction=fraction, seed=seed, model_list=model_list)

    from .sweep import add_parser as _add_sweep

    _add_sweep(sub, common=_common, columns=_columns, formatter=_Formatter, positive_int=positive_int,
               fraction=fraction, box_entry=box_entry, model_list=model_list, solvers=SOLVERS)

    b = sub.add_parser("bench", help="run a benchmark script (table1, friction)",
                       description="Run one of the benchmark scripts of benchmarks/.",
                       epilog=BENCH_EPILOG, formatter_class=_Formatter)
    b.add_argument("name", choices=("table1", "friction"), help="which benchmark")
    b.add_argument("args", nargs=argparse.REMAINDER, help="arguments passed to the benchmark")
    return p
