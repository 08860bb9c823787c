"""The four sub-commands: ``demo``, ``identify``, ``predict`` and ``bench``.

Each takes the parsed arguments and returns an exit status. They run in the CLI's
worker thread (see [`jaxfric.cli.errors`][jaxfric.cli.errors]); files go through the atomic writers of
[`jaxfric.report`][jaxfric.report], and every finished file is recorded in [`KEPT`][jaxfric.cli.errors.KEPT] so that
Ctrl-C can say what stayed on disk.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import shlex
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from .errors import KEPT, UserError, _prepare_out, _say, print_warning
from .fitting import check_fits, fit_all
from .spec import FitSpec


def _command_line(argv) -> str:
    return "jaxfric " + " ".join(shlex.quote(a) for a in argv)


def _write_csv(path: Path, columns: dict[str, np.ndarray]) -> Path:
    from jaxfric.files import write_csv

    p = write_csv(path, columns)
    KEPT.add(p)
    return p


def _save_fit_now(out: Path, velocity_filter=None):
    """Save each fit as soon as it exists, so an interrupted run keeps the finished models.

    The report folder is made here, when the first fit is done: a run refused or
    interrupted before that leaves no folder behind. ``velocity_filter`` (the low-pass
    the identification's velocity went through, or ``None``) is saved with each fit for
    ``jaxfric predict``."""
    from jaxfric.report import save_fit, slug

    def keep(name, fit):
        _prepare_out(str(out))
        if velocity_filter is not None:
            fit = fit.replace(settings={**fit.settings, "velocity_filter": dict(velocity_filter)})
        if hasattr(fit, "save"):
            KEPT.add(save_fit(fit, out / "models" / f"{slug(name)}.npz"))
        return fit

    return keep


def _settings(args, fits, data=None) -> dict:
    """Budgets, seeds and options of the run, for report.md and results.json (``data``: the
    training record, whose length the pipeline's description names)."""
    from .fitting import describe_solver

    s = {"seed": args.seed, "float64": bool(args.x64), "quick": bool(args.quick),
         "method": "the paper's MAPSO-NMDS (--paper)" if getattr(args, "paper", False) else "jaxfric's pipeline"}
    if getattr(args, "form_reason", None):
        s["physical models' form"] = args.form_reason
    for name in fits:
        spec = FitSpec.from_args(name, args)
        model = spec.build_model()
        s[f"{name}: pipeline"] = describe_solver(spec.build_solver(model), model, spec.paper, spec.refine,
                                                 n_train=_global_samples(args, data))
        if getattr(model, "neurons", None) is not None:
            s["neurons"] = model.neurons
    return s


def _global_samples(args, data) -> int | None:
    """The training samples of ``data`` the global stage sees (``None`` with ``--valid``,
    whose records are used whole)."""
    if data is None or getattr(args, "valid", None):
        return None
    return int(data.n_train)


def _choose_form(args, data, say) -> None:
    """``--form``: set ``args.asymmetric`` (read by [`FitSpec.from_args`][jaxfric.cli.spec.FitSpec.from_args]) and the
    sentence the report gives for it (``args.form_reason``)."""
    from .fitting import physical_form

    asymmetric, reason = physical_form(data)
    if args.form == "auto":
        args.asymmetric = asymmetric
        args.form_reason = reason
    else:
        args.asymmetric = args.form == "asymmetric"
        args.form_reason = f"{args.form}, as --form asked ({reason[0].lower() + reason[1:].split(', ')[0]})"
    say(f"note: {args.form_reason}")


def _python_snippet(args, names, data_lines: list[str], key_expr: str, valid: str | None = None) -> str:
    """Python that repeats the command's fits (shown under "Reproduce" in report.md), in the
    public API only: each fit is its [`FitSpec`][jaxfric.cli.spec.FitSpec]'s
    ``jf.identify(...)`` call ([`FitSpec.python`][jaxfric.cli.spec.FitSpec.python]), run on
    the same data and key."""
    lines = ["import jax", "import jaxfric as jf", "", *data_lines]
    train_name = getattr(args, "file", None) or "train"
    for name in names:
        lines.append(f"fit_{name} = " + FitSpec.from_args(name, args).python("data", key_expr, valid, train_name))
    return "\n".join(lines)


def _finish(args, out: Path, data, fits, *, title, source, argv, notes, python, extra_files,
            records=None, sections=None, figures=None) -> int:
    from jaxfric.report import write_report

    say = _say(args)
    say(f"writing the report to {out}/")
    result = write_report(out, data, fits, title=title, command=_command_line(argv), source=source,
                          settings=_settings(args, fits, data), notes=notes, python=python,
                          extra_files=extra_files, on_written=KEPT.add, records=records,
                          sections=sections, figures=figures)
    print(result["table"])
    print(f"\nreport: {out / 'report.md'} (with results.json, {len(result['figures'])} figures and the fits "
          f"in {out / 'models'})")
    return 0


# ---------------------------------------------------------------------- demo
def cmd_demo(args, argv) -> int:
    """Simulate the rig, compute friction, fit the models, write the report."""
    import jax

    from .data import simulated_rig, velocity_filter

    say = _say(args)
    check_fits(args, say)
    out = Path(args.out)  # made when the first fit is done (_save_fit_now)
    data_key, fit_key = jax.random.split(jax.random.key(args.seed))
    t0 = time.perf_counter()
    say(f"simulating the test rig (2000 samples at 128 Hz, seed {args.seed}) and computing the friction")
    r, record, data = simulated_rig(data_key)
    say(f"  done in {time.perf_counter() - t0:.1f} s")
    _choose_form(args, data, say)
    notes = ["Budget reduced with --quick: a smoke test, not a fit."] if args.quick else []
    fits = fit_all(data, args, fit_key, say=say, kept_fit=_save_fit_now(out, velocity_filter(args)), notes=notes)
    _write_csv(out / "rig_measurements.csv", {
        "t": record.t, "x": record.x, "p1": record.p1, "p2": record.p2, "load": record.load})
    _write_csv(out / "friction_data.csv", {"t": data.t, "velocity": data.velocity, "friction": data.friction})
    cyl = r.cylinder
    source = (f"Simulated low-speed press rig (jaxfric.rig.Rig(), seed {args.seed}): bore {cyl.bore:g} m, rod "
              f"{cyl.rod:g} m, moving mass {cyl.mass:g} kg; measured position, chamber pressures and load "
              "with sensor noise, then the paper's pipeline: zero-phase Butterworth 5 Hz, velocity and "
              "acceleration by differentiation, friction by force balance (docs/algorithms.md §7).")
    python = _python_snippet(args, list(fits), [
        f"data_key, fit_key = jax.random.split(jax.random.key({args.seed}))",
        "r = jf.rig.Rig()",
        "record = jf.rig.simulate(r, data_key)",
        "data = jf.rig.estimate_friction(record.measurements(), r.cylinder)"], "fit_key")
    extra = {
        "rig_measurements.csv": "the simulated raw channels t [s], x [m], p1, p2 [Pa], load [N]; try "
        f"`jaxfric identify rig_measurements.csv --time-col t --x-col x --p1-col p1 --p2-col p2 "
        f"--load-col load --bore {cyl.bore:g} --rod {cyl.rod:g} --mass {cyl.mass:g}`",
        "friction_data.csv": "the pipeline's output t [s], velocity [m/s], friction [N]; try `jaxfric "
        "identify friction_data.csv --velocity-col velocity --friction-col friction --time-col t`",
    }
    say("friction compensation on the rig simulator with each fit's feed-forward")
    t0 = time.perf_counter()
    comp_text = _compensation_section(out, r, fits, quick=args.quick, data=data)
    say(f"  done in {time.perf_counter() - t0:.1f} s")
    return _finish(args, out, data, fits, title="jaxfric demo: friction identification on the simulated rig",
                   source=source, argv=argv, notes=notes, python=python, extra_files=extra,
                   sections={"Friction compensation": comp_text},
                   figures={"compensation.png": "Tracking error against time for every compensation"})


def _compensation_section(out: Path, rig, fits, *, quick: bool, data=None) -> str:
    """docs/algorithms.md §13.3 on the demo's rig: the position loop of
    [`jaxfric.compensation`][jaxfric.compensation] with no, each fit's (ENN, LuGre, static: whichever the
    demo fitted) and the ideal friction feed-forward; the table and ``compensation.png``.
    ``quick`` shortens the reference (one 4 s, 5 mm sinusoid, whose speed stays inside the
    demo's training range, and 1 s ramps) to keep ``jaxfric demo --quick`` a smoke test.
    The loop runs in float64 (a scoped ``jax.enable_x64``: a float32 valve/pressure
    simulation at 1 kHz does not resolve micrometre stick-slip)."""
    import jax

    from jaxfric.compensation import compensation_study, compensation_table, plot_tracking, reference
    from jaxfric.plot import fit_label
    from jaxfric.report import save_figure

    ref = reference(period=4.0, amplitude=0.005, ramp_time=1.0, hold=0.2) if quick else reference()
    with jax.enable_x64(True):
        # the names of the report's comparison table, so each model reads the same everywhere
        rows, runs = compensation_study({fit_label(f, n): f for n, f in fits.items()}, rig, ref=ref)
    KEPT.add(save_figure(plot_tracking(runs, ref), out / "compensation.png"))
    length = "shortened with --quick: " if quick else ""
    return ("Position loop of `jaxfric.compensation` (docs/algorithms.md §13.3) on the same simulated rig, "
            "1 kHz cascade (PID on position, inner force loop to the valve), tracking a slow sinusoid and a "
            f"slow ramp out and back ({length}{ref.x.size / ref.fs:.3g} s). Feed-forward: none, each fit's "
            "friction along the reference velocity (the fit alone, never the rig's friction), and the rig's "
            "true friction as the unattainable ideal. Stick-slip is the peak-to-peak tracking error on the "
            "slow ramps.\n\n" + compensation_table(rows) + "\n\n" + _slow_speed_caveat(data, ref)
            + "![tracking error](compensation.png)")


def _slow_speed_caveat(data, ref) -> str:
    """Why stick-slip numbers differ between fits of equal validation MSE (and from the
    benchmark's table): they depend on each fit's friction at the ramp's speed, which
    the training record barely visits."""
    if data is None:
        return ""
    v = np.abs(np.asarray(data.velocity[: data.n_train], dtype=np.float64))
    ramp = float(np.max(np.abs(np.diff(ref.x[-ref.x.size // 4:])) * ref.fs))
    share = 100.0 * float(np.mean(v <= 2.0 * ramp))
    return (f"The slow ramps run at {ramp * 1e3:.3g} mm/s, and the stick-slip column measures each fit's friction "
            f"at about that speed ({share:.1f} % of the training samples have |v| <= {2e3 * ramp:.3g} mm/s): it can "
            "differ severalfold between fits of equal validation MSE, and so from the benchmark's table (another ENN "
            "fit of the same rig, validation MSE 0.162 %, gave 37 um in `benchmarks/results/motion.md`). The RMS "
            "column, dominated by the sinusoid, is the steadier comparison.\n\n")


# ------------------------------------------------------------------ identify
def cmd_identify(args, argv) -> int:
    """Fit friction models to a user's CSV file and write the report."""
    import jax

    from .data import identification_data, velocity_filter

    from jaxfric.identification import as_records

    say = _say(args)
    check_fits(args, say)
    data, desc, notes = identification_data(args)
    valid = {}
    for path in getattr(args, "valid", None) or []:
        # the same columns, units and pipeline as FILE
        v_data, _, v_notes = identification_data(args, path)
        valid[path] = v_data
        notes = list(notes) + [f"{path}: {n}" for n in v_notes]
    if valid:
        data = data.with_split(None, n_train=data.n_samples)  # FILE whole for estimation
    # identify's own record checks (lengths, NaN, split, constant friction, sample times), now:
    # before any stage message, progress bar or report folder.
    if valid:
        as_records(train={args.file: data}, valid=valid)
    else:
        as_records(data)
    for note in notes:
        say(f"note: {note}")
    _choose_form(args, data, say)
    if valid:
        say(f"{data.n_samples} samples at {1.0 / float(data.dt):.4g} Hz for estimation; validation on "
            + ", ".join(f"{p} ({d.n_samples} samples)" for p, d in valid.items()))
    else:
        say(f"{data.n_samples} samples at {1.0 / float(data.dt):.4g} Hz: {data.n_train} for estimation, "
            f"{data.n_valid} for validation")
    out = Path(args.out)  # made when the first fit is done (_save_fit_now)
    key = jax.random.key(args.seed)
    notes = list(notes) + (["Budget reduced with --quick: a smoke test, not a fit."] if args.quick else [])
    fits = fit_all(data, args, key, say=say, kept_fit=_save_fit_now(out, velocity_filter(args)), notes=notes,
                   valid=valid or None)
    split = (f"used whole; validation records {list(valid)} loaded the same way, and each fit is "
             "identify(name, train={FILE: data}, valid={...}, ...)" if valid
             else f"train_fraction={args.train_fraction}")
    python = _python_snippet(args, list(fits), [
        f"# data: {desc}, as a jaxfric.rig.FrictionData (see jaxfric.rig.load_friction_pairs /",
        f"# load_measurements + estimate_friction), {split}",
        "data = ...", *(["valid = {...}  # each --valid file's name -> its FrictionData, loaded the same way"]
                        if valid else [])], f"jax.random.key({args.seed})", "valid" if valid else None)
    return _finish(args, out, data, fits, title=f"jaxfric identify: {Path(args.file).name}",
                   source=desc[0].upper() + desc[1:] + ".", argv=argv, notes=notes, python=python,
                   extra_files=None, records=valid or None)


# ------------------------------------------------------------------- predict
def cmd_predict(args, argv) -> int:
    """Load a saved fit and write its friction prediction for a velocity record."""
    from jaxfric.files import atomic_write_text, csv_text
    from jaxfric.fit import FitKindError, load_fit
    from jaxfric.metrics import friction_metrics
    from jaxfric.motion import load_motion_fit

    from .data import prediction_input

    # precheck has refused a missing model file and an --out folder
    try:
        try:
            fit = load_fit(args.model_file)
        except FitKindError:  # a motion fit: its friction, offset included
            fit = load_motion_fit(args.model_file)
    except (ValueError, KeyError, TypeError, OSError) as e:
        raise UserError(f"cannot load the fit {args.model_file}: {e}") from None
    t, v, dt, measured = prediction_input(args)
    v = _velocity_as_trained(args, fit, v, dt)
    # Resampling and extrapolation change what the numbers mean: said even with --quiet.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        pred = np.asarray(fit.predict_at(t, v), dtype=np.float64)
    for w in caught:
        if issubclass(w.category, UserWarning):
            print_warning(" ".join(str(w.message).split()))
    cols = {"t": t, "velocity": v, "friction_predicted": pred}
    if measured is not None:
        cols["friction_measured"] = measured
        cols["error"] = measured - pred
    text = csv_text(cols)
    if args.out == "-":
        sys.stdout.write(text)
    else:
        KEPT.watch(Path(args.out).resolve().parent)
        p = atomic_write_text(args.out, text)
        KEPT.add(p)
        print(f"wrote {len(pred)} predictions to {p}")
    if measured is not None:
        m = friction_metrics(measured, pred)
        print(f"MSE % {m['mse_percent']:.4g}, MAX {m['max_abs']:.4g} N, FIT % {m['fit_percent']:.2f}",
              file=sys.stderr if args.out == "-" else sys.stdout)
    return 0


def _velocity_as_trained(args, fit, v, dt):
    """Say which velocity the fit was trained on; with ``--filter-velocity`` low-pass ``v``
    the same way (the zero-phase Butterworth of docs/algorithms.md §7)."""
    saved = fit.settings.get("velocity_filter")
    if saved:
        what = f"a zero-phase Butterworth low-pass (order {saved['order']}, {saved['cutoff_hz']:g} Hz)"
    if not args.filter_velocity:
        if not args.quiet:
            text = (f"this fit was trained on velocity filtered by {what}; pass --filter-velocity to filter this "
                    "record the same way, unless it is filtered already" if saved else
                    "this fit records no velocity filter (it was trained on the velocity it was given); give "
                    "this record's velocity processed as that one was")
            print(f"jaxfric: note: {text}", file=sys.stderr, flush=True)
        return v
    if args.cutoff is None and not saved:
        raise UserError("--filter-velocity: the fit records no velocity filter (it was trained on the velocity "
                        "as given); give the cutoff with --cutoff HZ")
    from jaxfric.rig.pipeline import lowpass

    cutoff = args.cutoff if args.cutoff is not None else float(saved["cutoff_hz"])
    order = {"order": int(saved["order"])} if saved else {}  # else lowpass's own
    if not args.quiet:
        print(f"jaxfric: note: velocity low-passed (zero-phase Butterworth, {cutoff:g} Hz) as the fit's "
              "training velocity was", file=sys.stderr, flush=True)
    return lowpass(v, 1.0 / dt, cutoff, **order)


# --------------------------------------------------------------------- bench
def benchmarks_dir() -> Path:
    """``benchmarks/`` of the source tree (or ``$JAXFRIC_BENCHMARKS``)."""
    env = os.environ.get("JAXFRIC_BENCHMARKS")
    if env:
        return Path(env)
    import jaxfric

    return Path(jaxfric.__file__).resolve().parents[1] / "benchmarks"


def bench_arguments(argv: list[str]) -> list[str]:
    """A ``--quick`` run without ``--out`` writes to ``benchmarks/results/quick/``.

    The committed ``benchmarks/results/`` hold full runs; a smoke test must not overwrite
    them (the rule of ``benchmarks/_harness.results_dir``, applied here too so it holds
    for every script ``jaxfric bench`` runs).
    """
    has_out = any(a == "--out" or a.startswith("--out=") for a in argv)
    if "--quick" in argv and not has_out:
        return [*argv, "--out", str(benchmarks_dir() / "results" / "quick")]
    return argv


def cmd_bench(args, argv) -> int:
    """Import ``benchmarks/<name>.py`` by path and call its ``main(argv)``."""
    path = benchmarks_dir() / f"{args.name}.py"
    if not path.is_file():
        raise UserError(f"benchmark script not found: {path} (the benchmarks live in the source tree's "
                        "benchmarks/ folder; set JAXFRIC_BENCHMARKS to it)")
    KEPT.otherwise = "the files the benchmark finished stay in its output folder"
    spec = importlib.util.spec_from_file_location(f"jaxfric_bench_{args.name}", path)
    module = importlib.util.module_from_spec(spec)
    old_argv0 = sys.argv[0]
    sys.argv[0] = f"jaxfric bench {args.name}"  # the script's argparse shows this as its name
    try:
        spec.loader.exec_module(module)
        main = getattr(module, "main", None)
        if not callable(main):
            raise UserError(f"{path} has no main(argv) function")
        status = main(bench_arguments(list(args.args)))
    finally:
        sys.argv[0] = old_argv0
    return 0 if status is None else int(status)


def _imported_on_use(module: str, name: str):
    """The command ``name`` of the submodule ``module``, imported when it runs."""
    def command(args, argv) -> int:
        return getattr(importlib.import_module(module, __package__), name)(args, argv)

    return command


COMMANDS = {"demo": cmd_demo, "identify": cmd_identify, "predict": cmd_predict, "bench": cmd_bench,
            "identify-motion": _imported_on_use(".motion", "cmd_identify_motion"),
            "sweep": _imported_on_use(".sweep", "cmd_sweep")}
