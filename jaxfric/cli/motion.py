"""``jaxfric identify-motion FILE``: friction from actuator force and position (docs/algorithms.md §13.2).

Reads a CSV with a force column (or a drive voltage and ``--force-gain``) and a position
column, identifies each ``--model`` inside the mechanics with
[`jaxfric.identify_motion`][jaxfric.motion.identify_motion] (trained on the leading
``--train-fraction``), ranks the fits and the least-squares baseline by a judge, prints the
ranking and writes a report folder: ``motion.md`` (position RMSE [mm] and FIT %, free run
and k-step, per model, the judge's score), ``results.json`` (the ranking's rows, the judge
and its scores), ``models/<model>.npz`` (load with
[`jaxfric.motion.load_motion_fit`][jaxfric.motion.load_motion_fit]) and ``motion_free_run.png``.

``--judge`` is [`jaxfric.motion.compare_motion`][jaxfric.motion.compare_motion]'s (``gated``, the default, ``short`` or
``tail``; [`jaxfric.motion.short_runs_score`][jaxfric.motion.short_runs_score], [`jaxfric.motion.gated_scores`][jaxfric.motion.gated_scores]); ``--max-time``/``--max-evals`` bound each model's search.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from .errors import KEPT, UserError, _prepare_out, _say, print_warning

#: members per model, as `jaxfric.motion.compare_motion`'s ``keys`` (tests/test_motion_dependable.py holds the two equal)
KEYS = 1
#: How each judge's choice is made, as the report says it.
CHOICE_RULE = {"gated": "the lowest score among the models that pass the gate; the baseline where none does",
               "short": "the lowest score, the baseline included", "tail": "the lowest score, the baseline included"}

EPILOG = """examples:
  jaxfric identify-motion emps.csv --force-col vir --force-gain 35.15 --x-col qm --dt 0.001 \\
      --mass-range 50,200 --offset --model coulomb,stribeck,lugre,gms
  jaxfric identify-motion rig.csv --force-col force --x-col x --time-col t --mass 120 --quick
  jaxfric identify-motion rig.csv --force-col force --x-col x --dt 0.01 --mass 120 --judge tail
"""


def _pair(text: str) -> tuple[float, float]:
    try:
        lo, hi = (float(t) for t in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LOW,HIGH, got {text!r}") from None
    if not 0 < lo < hi:
        raise argparse.ArgumentTypeError(f"need 0 < LOW < HIGH, got {text!r}")
    return lo, hi


def add_parser(sub, *, common, formatter, positive_float, positive_int, fraction, seed, model_list) -> None:
    """Register the ``identify-motion`` sub-command on ``sub`` (the CLI's subparsers)."""
    p = sub.add_parser("identify-motion", help="identify friction inside the mechanics from force and position",
                       description="Simulation-error identification: m dv/dt = F_act - F_friction - F_load, "
                       "dx/dt = v; friction parameters (and optionally mass and offset) fitted to the "
                       "measured position. No friction signal or acceleration needed.",
                       epilog=EPILOG, formatter_class=formatter)
    p.add_argument("file", metavar="FILE", help="CSV (or whitespace-separated) file")
    g = p.add_argument_group("columns (header name or 0-based index)")
    g.add_argument("--force-col", required=True, metavar="COL", help="actuator force [N] (or voltage, see --force-gain)")
    g.add_argument("--force-gain", type=float, default=1.0, metavar="N/UNIT", help="force = gain * column")
    g.add_argument("--x-col", required=True, metavar="COL", help="position (in --x-unit)")
    g.add_argument("--load-col", metavar="COL", help="external load opposing +x [N]")
    g.add_argument("--time-col", metavar="COL", help="time stamps [s] (or give --dt)")
    g.add_argument("--dt", type=positive_float, metavar="S", help="sample interval [s]")
    g.add_argument("--time-unit", default="s", metavar="UNIT", help="of the time column")
    g.add_argument("--x-unit", default="m", metavar="UNIT", help="of the position column (e.g. mm)")
    g.add_argument("--delimiter", default=",", help="column separator; 'whitespace' for spaces/tabs")
    m = p.add_argument_group("mechanics (one of --mass and --mass-range is required)")
    which = m.add_mutually_exclusive_group(required=True)
    which.add_argument("--mass", type=positive_float, metavar="KG", help="known moving mass [kg]")
    which.add_argument("--mass-range", type=_pair, metavar="LO,HI", help="identify the mass in [LO, HI] kg")
    m.add_argument("--offset", action="store_true", help="identify a constant force offset")
    m.add_argument("--horizon", type=positive_int, metavar="K",
                   help="fit the K-step-ahead position error instead of the free run")
    m.add_argument("--cutoff", type=positive_float, metavar="HZ", help="velocity low-pass [Hz] (default fs/10)")
    f = p.add_argument_group("identification")
    f.add_argument("--model", "--models", dest="models", type=model_list, default="coulomb,lugre",
                   metavar="NAMES", help="comma-separated friction models")
    f.add_argument("--neurons", type=positive_int, default=10, help="hidden neurons of an Elman network")
    f.add_argument("--train-fraction", type=fraction, default=0.8, metavar="F",
                   help="leading fraction of the record used for estimation; the rest validates")
    f.add_argument("--judge", choices=("gated", "short", "tail"), default="gated",
                   help="how the fits are ranked: 'gated' (compare_motion's default) the short score of "
                        "the models whose 3-fold blocked cross-validation of the training block beats "
                        "least squares' (3 more fits per model), least squares where none does; 'short' pools the free-run RMSE of every "
                        "--window seconds of the whole record, each run from its own first 20 samples; "
                        "'tail' the held-back block's free-run RMSE")
    f.add_argument("--window", type=positive_float, default=None, metavar="S",
                   help="seconds per window of the short judge (default 2; the record must hold one)")
    f.add_argument("--keys", type=positive_int, default=KEYS, metavar="K",
                   help=f"members per model (identify_motion's keys=K; default {KEYS}, compare_motion's): each "
                        "model is ranked and saved as its member of lowest training error; 1: one fit of --seed")
    f.add_argument("--seed", type=seed, default=0, help="random seed (same seed, same result)")
    f.add_argument("--max-time", type=positive_float, default=None, metavar="S",
                   help="budget per model: wall seconds; the search then stops with the best so far")
    f.add_argument("--max-evals", type=positive_int, default=None, metavar="N",
                   help="budget per model: cost evaluations (a Jacobian counts 1 + parameters)")
    f.add_argument("--quick", action="store_true", help="tiny budget: a smoke test, not a real fit")
    f.add_argument("--out", default="jaxfric-motion", metavar="DIR", help="report folder")
    common(p, x64_help="compute in float64 (the default of this command; see --float32)")
    p.set_defaults(x64=True)
    f.add_argument("--float32", dest="x64", action="store_false", default=argparse.SUPPRESS,
                   help="compute in float32 (faster; float64 is the default here, since a free run "
                        "integrates twice and float32 rounding changed which model ranked first on EMPS)")


def _data(args):
    """[`jaxfric.motion.MotionData`][jaxfric.motion.MotionData] from the file and options; irregular time stamps
    are resampled onto a uniform grid and said on stderr (also under ``--quiet``)."""
    from jaxfric.motion import MotionData
    from jaxfric.rig.io import uniformise

    from .data import _load_quietly, _time_column, read_table
    from .units import unit_factor

    table = read_table(args.file, delimiter=args.delimiter)
    signals = {"t": _time_column(table, args),
               "force": table.column(args.force_col, "--force-col") * args.force_gain,
               "x": table.column(args.x_col, "--x-col") * unit_factor("length", args.x_unit, "--x-unit")}
    if args.load_col is not None:
        signals["load"] = table.column(args.load_col, "--load-col")
    try:
        signals, notes = _load_quietly(uniformise, signals, "resample", None, 1e-3)
        dt = float(np.median(np.diff(signals["t"])))
        data = MotionData.from_arrays(signals["force"], signals["x"], dt, load=signals.get("load"),
                                      cutoff=args.cutoff)
    except ValueError as e:
        raise UserError(f"{args.file}: {e}") from None
    for note in notes:
        print_warning(note)
    return data


def _judge_window(args, data):
    """Samples per window of the short judge (``None`` for ``--judge tail``); a UserError
    when the record holds no whole window."""
    if args.judge == "tail":
        return None
    from jaxfric.motion import SHORT_WINDOW_S, short_window

    seconds = SHORT_WINDOW_S if args.window is None else args.window
    try:
        window = short_window(data.dt, None if args.window is None else round(seconds / data.dt))
    except ValueError as e:
        raise UserError(f"--window {seconds:g} s: {e} (at the record's {data.dt:g} s per sample)") from None
    if data.n_samples < window:
        raise UserError(f"the short judge's window of {seconds:g} s ({window} samples) is longer than the "
                        f"record ({data.n_samples} samples, {data.n_samples * data.dt:.4g} s): pass a shorter "
                        "--window S or --judge tail")
    return window


def _judge(args, fits, data, window, say, blocked=None):
    """The short judge's scores of the fits and of the least-squares baseline over the
    whole record (``None`` for ``--judge tail``): ``{"name", "window_samples", "window_s",
    "init_window", "windows", "scores": name -> mm, "baseline": mm}``; with ``--judge gated``
    also ``"short"`` (the short scores), ``"blocked"`` (name -> mm) and ``"baseline_blocked"``
    (``blocked()``'s scores), ``"scores"`` then being `gated_scores`'."""
    if window is None:
        return None
    from jaxfric.motion import DEFAULT_INIT_WINDOW, gated_scores, short_judge

    say(f"judging by short free runs: {data.n_samples // window} windows of {window} samples")
    scores, base = short_judge(fits, [data], window)
    out = {"name": "short", "window_samples": window, "window_s": window * data.dt,
           "init_window": DEFAULT_INIT_WINDOW, "windows": data.n_samples // window, "scores": scores,
           "baseline": base}
    if args.judge == "gated":
        cv, cv_base = blocked()
        out.update(name="gated", short=scores, blocked=cv, baseline_blocked=cv_base,
                   scores=gated_scores(scores, cv, cv_base))
    return out


def cmd_identify_motion(args, argv) -> int:
    """Identify each model inside the mechanics and write the report folder."""
    import warnings

    import jax.numpy as jnp

    from jaxfric import models as _models
    from jaxfric._warnings import BaselineWarning
    from jaxfric.motion import MotionSearch, OverfitWarning, blocked_scores, identify_motion, rank_fits

    say = _say(args)
    data = _data(args)
    window = _judge_window(args, data)  # a record too short for the judge fails before any fit
    out = _prepare_out(args.out)
    (out / "models").mkdir(exist_ok=True)
    mass = args.mass if args.mass is not None else args.mass_range
    fits, models = {}, {}
    search = MotionSearch(particles=4, generations=2, horizons=(None,), steps=(2,)) if args.quick else None
    options = dict(key=args.seed, mass=mass, search=search, horizon=args.horizon, fit_offset=args.offset,
                   dtype=jnp.float64 if args.x64 else None, max_time=args.max_time, max_evals=args.max_evals)
    for name in args.models:
        opts = {"neurons": args.neurons} if name.startswith("elman") else {}
        model = models[name] = _models.get(name, **opts)
        say(f"identifying {name} inside the mechanics ({data.n_samples} samples)")
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", BaselineWarning)
                fit = identify_motion(model, data, train=args.train_fraction, progress=not args.quiet,
                                      keys=args.keys if args.keys > 1 else None, **options)
        except ValueError as e:
            raise UserError(str(e)) from None
        for w in caught:  # said even under --quiet, without a source line
            if issubclass(w.category, BaselineWarning):
                print_warning(w.message)
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        fits[name] = fit
        path = out / "models" / f"{name}.npz"
        fit.save(path)
        KEPT.add(path)
        if fit.mechanics.stopped:
            say(f"{name}: the search stopped at its budget ({fit.mechanics.stopped})")
        print(fit.summary())
    def blocked():  # --judge gated: 3-fold blocked cross-validation of the training block
        say(f"blocked cross-validation of {', '.join(models)} (3 more fits each)")
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", BaselineWarning)
                return blocked_scores(models, [data.window(0, next(iter(fits.values())).n_train)], 3, **options)
        except ValueError as e:  # e.g. a fold too short for a model's windows
            raise UserError(f"--judge gated, blocked cross-validation: {e}") from None

    judge = _judge(args, fits, data, window, say, blocked)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", OverfitWarning)
        if judge is None:
            ranked = rank_fits(fits)
        else:
            ranked = rank_fits(fits, scores=judge["scores"], judge=judge["name"], baseline_score=judge["baseline"],
                               blocked=judge.get("blocked"), baseline_blocked=judge.get("baseline_blocked"))
    for w in caught:  # said even under --quiet: it changes which model to use
        print_warning(w.message)
    _write_report(args, argv, out, data, fits, ranked, judge, window)
    say(f"report written to {out}")
    return 0

def _write_report(args, argv, out, data, fits, ranked, judge, window) -> None:
    """``motion.md``, ``results.json`` and ``motion_free_run.png`` of the ranked fits; the
    ranking table printed."""
    from jaxfric.files import atomic_write_text, jsonable
    from jaxfric.report import save_figure

    table = ranked.table()
    first = next(iter(fits.values()))
    k = first.metrics["horizon"]
    kstep = ["", f"{k}-step-ahead position RMSE on the held-back block [mm]: "
             + ", ".join(f"{name} {fits[name].metrics['valid_kstep']['rmse_mm']:.4g}" for name in ranked.ranking),
             "", "Wall time per model [s]: "
             + ", ".join(f"{name} {fits[name].timings['total_s']:.1f}" for name in ranked.ranking)]
    held = f"the last {100 * (1 - args.train_fraction):.0f} % of the record"
    if judge is None:
        ranked_by = (f"Ranked by the held-back block's free-run RMSE (`--judge tail`: {held}, simulated "
                     "from the state at its start). The held-back block shares the training record's "
                     "excitation: it ranks models, it does not measure how they predict new motion")
    elif judge["name"] == "gated":
        ranked_by = (f"Ranked by the gated judge (`--judge gated`, the default): the short score (the whole record in "
                     f"{judge['windows']} windows of {judge['window_s']:.4g} s, each from its own first "
                     f"{judge['init_window']} samples) of the models whose 3-fold blocked cross-validation of "
                     f"the training block beats least squares' ({judge['baseline_blocked']:.4g} mm; blocked: "
                     + ", ".join(f"{k} {v:.4g}" for k, v in judge["blocked"].items())
                     + " mm), inf for the others. The blocked folds are scored on motion their fits never saw")
    else:
        ranked_by = (f"Ranked by many short free runs (`--judge short`): the whole record cut "
                     f"into {judge['windows']} windows of {judge['window_s']:.4g} s ({window} samples), each "
                     f"simulated from its own first {judge['init_window']} samples, the RMSE pooled (the "
                     f"last column; the windows include the training part). The valid RMSE is the held-back "
                     f"block's ({held}) free run. Both share the record's excitation: neither is new motion")
    margin = ranked.gate_margin
    narrow = ([f"(passes the gate narrowly: blocked {100 * margin:.1f} % under least squares'; "
               "compare it with the baseline on motion it was not fitted on)"] if ranked.passes_narrowly else [])
    md = ["# jaxfric identify-motion", "", f"Command: `jaxfric {' '.join(argv)}`", "",
          f"{ranked_by} (score a separate recording with "
          "`jaxfric.load_motion_fit(path).score(record, init_window=20)`). The last row is the "
          "least-squares Coulomb + viscous + offset baseline on the same data and judge.", "",
          table, "", f"Choice ({CHOICE_RULE[ranked.judge]}): {ranked.choice_name}", *narrow, *kstep, "",
          "![free run](motion_free_run.png)", ""]
    print(table)
    print(f"choice: {ranked.choice_name}", *narrow)
    results = {"command": ["jaxfric", *argv], "split": "held-back block (last "
               f"{100 * (1 - args.train_fraction):.0f} % of {args.file})", "ranking": ranked.rows(),
               "choice": ranked.choice_name, "gate_margin": margin,
               "judge": judge if judge is not None else {"name": "tail", "scores": {
                   name: fits[name].metrics["valid"]["rmse_mm"] for name in ranked.ranking},
                   "baseline": first.metrics["baseline"]["valid"]["rmse_mm"]},
               "float64": bool(args.x64)}
    KEPT.add(atomic_write_text(out / "results.json", json.dumps(jsonable(results), indent=2)))
    KEPT.add(atomic_write_text(out / "motion.md", "\n".join(md)))
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 4))
    n_train = first.n_train
    t = np.arange(data.n_samples) * data.dt
    ax.plot(t[n_train:], 1e3 * data.position[n_train:], "k", lw=2, label="measured")
    for name, fit in fits.items():
        ax.plot(t[n_train:], 1e3 * fit.simulate_from(data, n_train)["x"], lw=1, label=name)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("position [mm]")
    ax.legend()
    KEPT.add(save_figure(fig, out / "motion_free_run.png"))
