"""Motion identification and friction compensation benchmarks (docs/algorithms.md §13.2-13.3).

Usage::

    python benchmarks/motion.py [--emps PATH/DATA_EMPS.mat] [--out DIR]
                                [--parts emps,rig,compensation] [--quick]

* ``emps``: friction identified inside the mechanics of the EMPS axis (input ``gtau*vir``,
  output ``qm``, last 20 % held back) for Coulomb+viscous+offset, asymmetric
  Coulomb+viscous+offset, LuGre+offset, GMS+offset and Elman+offset friction
  (``--rows`` fits a subset and writes ``motion_rows.md`` instead); free-run and k-step
  position RMSE [mm] and FIT % on the held-back part, beside the published IDIM-LS
  reference (SOURCE.md) simulated the same way.
* ``rig``: on the simulated hydraulic rig, friction recovered from actuator force and
  position alone against the force-balance identification, both compared with the
  rig's true friction.
* ``keys``: the spread over keys 0..K-1 (``--keys``) of each physical model's training
  free-run RMSE on the whole estimation file (``identify_motion(..., keys=batch)``, the
  members being exactly the fits of those keys), beside the least-squares baseline and the
  ensemble average; then the same on the 80 % split with the held-back tail (same
  excitation). Writes ``motion_keys.md`` / ``motion_keys.csv``.
* ``compensation``: the position loop of ``jaxfric.compensation`` on the rig with no,
  static, LuGre, Elman and ideal (true friction) feed-forward.
* ``official``: the EMPS benchmark's official forward task (docs/motion.md; ANCHORS.md §4.1),
  ``--parts official --test PATH/DATA_EMPS_PULSES.mat [--rows coulomb,stribeck,lugre,gms]``:
  train on the whole estimation file, free-run the test recording from its input, only its
  first 20 samples setting the state (``MotionFit.score(..., init_window=20)``); RMSE of
  ``qm[20:]`` [mm] and FIT %, beside the least-squares baseline (IDIM-LS on the estimation
  file), the published IDIM-LS parameters and the published figures. The test recording is
  not shipped (never tune on it): without it the part says so and writes nothing.
  Writes ``emps_official.md`` / ``.csv``.

Writes ``motion.md`` and ``motion_*.png`` into ``--out`` (default ``benchmarks/results``;
``--quick``: ``benchmarks/results/quick``). x64 is switched on here (the library never does).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # the harness, also under `jaxfric bench`
from _harness import (add_output_arguments, cell, emps_file, emps_motion, markdown_table, pyplot,  # noqa: E402
                      results_dir, write_report, x64)

x64()
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from jaxfric import models  # noqa: E402
from jaxfric.motion import MotionData, MotionFit, baseline_motion_fit, identify_motion  # noqa: E402
from jaxfric.optim import MAPSO, MAPSONMDS, NelderMead  # noqa: E402
from jaxfric.rig.emps import EMPS_CUTOFF_HZ, emps_states, idim_ls, load_emps  # noqa: E402

#: Published IDIM-LS values of SOURCE.md (Janot, Gautier, Brunot 2019).
IDIM = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "offset": -3.1648}
K_STEP = 100


def emps_motion_data(path) -> tuple[MotionData, int]:
    """The EMPS estimation file as motion data (:func:`_harness.emps_motion`) and n_train = 80 %."""
    return (data := emps_motion(path)), int(round(0.8 * data.n_samples))


def reference_fit(M, Fc, Fv, offset, data, n_train) -> MotionFit:
    """The Coulomb + viscous + offset law with given (published, least-squares) values as a
    MotionFit (:func:`jaxfric.motion.baseline_motion_fit`), evaluated like the identified ones."""
    fit = baseline_motion_fit(M, Fc, Fv, offset, dt=data.dt, n_train=n_train)
    return fit.replace(metrics=fit.evaluate(data, n_train, K_STEP))


def _solver(n_params, quick):
    big = n_params > 20
    gens = 40 if quick else (60 if big else 100)
    side = 6 if big else 5
    nm = min(100 * n_params if quick else 200 * n_params, 3000)
    return MAPSONMDS(mapso=MAPSO(lattice_size=side, num_generations=gens),
                     nelder_mead=NelderMead(max_steps=nm, max_evals=nm))


#: The EMPS rows: label -> (model name, or a model with its own offset; model options). Every
#: row uses identify_motion's defaults (data-centred box, MotionSearch()) with the mass searched
#: in [50, 200] kg and a constant offset. The asymmetric row is the library's asymmetric Coulomb
#: + viscous friction with its own output offset (docs/algorithms.md §13.1):
#: F = Fc+ [v>0] - Fc- [v<0] + Fv+- v + F_off.
EMPS_MODELS = {
    "coulomb": ("static Coulomb+viscous+offset", "coulomb", None),
    "stribeck": ("static Stribeck+offset", "stribeck", None),
    "asymmetric": ("asymmetric Coulomb+viscous, own offset", models.Coulomb(asymmetric=True, offset=True,
                                                                             v_eps=1e-4), None),
    "dahl": ("Dahl+viscous+offset", "dahl", {"viscous": True}),
    "lugre": ("LuGre+offset", "lugre", None),
    "gms": ("GMS(3)+offset", "gms", None),
    "elman": ("Elman(10)+offset", "elman", {"neurons": 10}),
}
DEFAULT_EMPS_MODELS = "coulomb,stribeck,asymmetric,dahl,lugre,gms,elman"


#: official task: samples that set the state; the drive gain of a file without ``gtau``
#: (SOURCE.md); the published figures (ANCHORS.md §4)
INIT_WINDOW, GTAU = 20, 35.15065188248547
PUBLISHED = [("IDIM-LS physics, open loop (published parameters; ANCHORS.md, 0.1 ms Euler)", 8.44, 89.8),
             ("dynoNet (Forgione & Piga 2021)", 2.64, 96.8)]


def motion_data(path) -> MotionData:
    """An EMPS ``.mat`` file as motion data: the estimation file through
    :func:`_harness.emps_motion`; a file without all of its channels (a test recording may lack
    ``qg`` or the loop gains) read for ``qm``, ``vir``, ``t`` and ``gtau`` only."""
    try:
        return emps_motion(path)
    except (KeyError, ValueError):
        from scipy.io import loadmat

        mat = loadmat(path)
        qm, vir = (np.asarray(mat[k], np.float64).ravel() for k in ("qm", "vir"))
        gtau = float(np.asarray(mat["gtau"]).ravel()[0]) if "gtau" in mat else GTAU
        dt = float(np.median(np.diff(np.asarray(mat["t"], np.float64).ravel()))) if "t" in mat else 1e-3
        return MotionData.from_arrays(gtau * vir, qm, dt, cutoff=EMPS_CUTOFF_HZ)


def run_official(path, test_path, names, quick) -> list[dict]:
    """Rows of the ``official`` part (module docstring)."""
    from jaxfric.motion import MotionSearch

    est, test = motion_data(path), motion_data(test_path)
    rows = []

    def row(name, fit, seconds=None, kind="simulated here"):
        tr, te = fit.score(est, init_window=INIT_WINDOW), fit.score(test, init_window=INIT_WINDOW)
        rows.append({"model": name, "kind": kind, "mass_kg": fit.mass, "offset_N": fit.offset,
                     "estimation_rmse_mm": tr["rmse_mm"], "estimation_fit_percent": tr["fit_percent"],
                     "test_rmse_mm": te["rmse_mm"], "test_fit_percent": te["fit_percent"], "seconds": seconds})
        print(name, f"test {te['rmse_mm']:.3f} mm, FIT {te['fit_percent']:.2f} %", flush=True)

    s = emps_states(load_emps(path))
    ls = idim_ls(s["v"], s["a"], s["force"])  # the benchmark's own recipe, whole estimation file
    row(f"least squares Coulomb+viscous+offset (IDIM-LS here: M {ls.M:.2f}, Fv {ls.Fv:.1f}, "
        f"Fc {ls.Fc:.2f}, offset {ls.offset:.2f})", baseline_motion_fit(ls.M, ls.Fc, ls.Fv, ls.offset, dt=est.dt),
        kind="baseline")
    row("IDIM-LS published parameters", baseline_motion_fit(IDIM["M"], IDIM["Fc"], IDIM["Fv"], IDIM["offset"],
                                                            dt=est.dt), kind="reference")
    search = MotionSearch(particles=6, generations=3, horizons=(None,), steps=(3,)) if quick else None
    for name in names:
        t0 = time.perf_counter()
        fit = identify_motion(name, est, train=1.0, key=0, mass=(50.0, 200.0), fit_offset=True, dtype=jnp.float64,
                              model_options={"neurons": 10} if name.startswith("elman") else None, search=search)
        row(f"{name} + mass + offset (identify_motion defaults, whole estimation file)", fit,
            time.perf_counter() - t0, kind="jaxfric")
    return rows + [{"model": name, "kind": "published", "mass_kg": None, "offset_N": None, "estimation_rmse_mm": None,
                    "estimation_fit_percent": None, "test_rmse_mm": rmse, "test_fit_percent": fitp, "seconds": None}
                   for name, rmse, fitp in PUBLISHED]


OFFICIAL_NOTE = f"""Train on DATA_EMPS.mat (all samples), free-run simulate DATA_EMPS_PULSES.mat from its input; \
the first {INIT_WINDOW} samples of each file set the initial state (quadratic fit of the \
positions, friction state tracked along its slope) and are not scored. RMSE of qm in mm, \
FIT = 100 (1 - ||e|| / ||y - mean y||). 'estimation' = the same protocol on the training \
file itself. Times: wall seconds of the identify_motion call, compilation included."""


def total_offset(fit) -> float:
    """The constant force of a fit: the mechanics' offset plus the model's ``F_off``."""
    return fit.offset + float(fit.params.get("F_off", 0.0))


def least_squares_fit(path, data, n_train) -> MotionFit:
    """The least-squares Coulomb + viscous + offset baseline: IDIM-LS (M, Fv, Fc, offset;
    the benchmark's filter and differences) on the estimation part only."""
    from jaxfric.rig.emps import emps_states, idim_ls

    s = emps_states(load_emps(path))
    keep = s["t"] < n_train * data.dt
    est = idim_ls(s["v"][keep], s["a"][keep], s["force"][keep])
    return reference_fit(est.M, est.Fc, est.Fv, est.offset, data, n_train)


def identify_default(key_name, data, n_train, seed=0, progress=None, metric_horizon=K_STEP):
    """One EMPS row with identify_motion's defaults (``metric_horizon=None``: the default k
    of the k-step metrics too); returns (label, fit, wall seconds)."""
    extra = {} if metric_horizon is None else {"metric_horizon": metric_horizon}
    label, model, opts = EMPS_MODELS[key_name]
    t0 = time.perf_counter()
    fit = identify_motion(model, data, key=seed, mass=(50.0, 200.0), train=n_train,
                          fit_offset=isinstance(model, str), dtype=jnp.float64, model_options=opts,
                          progress=progress, **extra)
    return label, fit, time.perf_counter() - t0


def run_emps(path, quick, key=0, only=None):
    data, n_train = emps_motion_data(path)
    rows = [("IDIM-LS reference (published)",
             reference_fit(IDIM["M"], IDIM["Fc"], IDIM["Fv"], IDIM["offset"], data, n_train), 0.0)]
    rows.append(("least squares Coulomb+viscous+offset (IDIM-LS on the estimation part)",
                 least_squares_fit(path, data, n_train), 0.0))
    names = only or DEFAULT_EMPS_MODELS.split(",")
    for name in names:
        if quick and name == "elman":
            continue
        label, fit, secs = identify_default(name, data, n_train, key)
        print(label, fit.summary(), f"{secs:.1f} s", sep="\n", flush=True)
        rows.append((label, fit, secs))
    return data, n_train, rows


def run_timing(path, names, seed=0, reference=True):
    """Wall time of exactly the default calls for ``names`` in this process (compilation
    included), and, as a same-run reference for the machine's load, the pre-0.9 default
    search (MAPSO-NMDS) for LuGre on the first 2 000 samples."""
    from jaxfric.identification import default_solver

    data, n_train = emps_motion_data(path)
    out = []
    t_all = time.perf_counter()
    for name in names:
        label, fit, secs = identify_default(name, data, n_train, seed, metric_horizon=None)
        out.append({"model": label, "seconds": secs, "valid_rmse_mm": fit.metrics["valid"]["rmse_mm"],
                    "train_rmse_mm": fit.metrics["train"]["rmse_mm"],
                    "stages": "; ".join(f"{s['stage']} {s['seconds']:.1f} s/{s['num_steps']} steps"
                                        for s in fit.stages)})
        print(out[-1], flush=True)
    total = time.perf_counter() - t_all
    ref = None
    if reference:
        short = data.window(0, 2000)
        t0 = time.perf_counter()
        fit = identify_motion("lugre", short, key=seed, mass=(50.0, 200.0), fit_offset=True, dtype=jnp.float64,
                              solver=default_solver(models.LuGre()))
        ref = (time.perf_counter() - t0, fit.metrics["valid"]["rmse_mm"])
    return out, total, ref


def emps_table(rows) -> str:
    head = ("| friction | mass [kg] | offset [N] | valid free-run RMSE [mm] | valid FIT % | "
            f"valid {K_STEP}-step RMSE [mm] | train free-run RMSE [mm] | time [s] |\n"
            "|---|---|---|---|---|---|---|---|")
    lines = [head]
    for name, fit, secs in rows:
        m = fit.metrics
        lines.append(f"| {name} | {fit.mass:.2f} | {total_offset(fit):.2f} | {m['valid']['rmse_mm']:.3f} | "
                     f"{m['valid']['fit_percent']:.2f} | {m['valid_kstep']['rmse_mm']:.5f} | "
                     f"{m['train']['rmse_mm']:.3f} | {secs:.0f} |")
    return "\n".join(lines)


def emps_figure(data, n_train, rows, out):
    plt = pyplot()
    t = np.arange(data.n_samples) * data.dt
    fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    ax[0].plot(t[n_train:], 1e3 * data.position[n_train:], "k", lw=2, label="measured qm")
    for name, fit, _ in rows:
        x = fit.simulate_from(data, n_train)["x"]
        ax[0].plot(t[n_train:], 1e3 * x, lw=1, label=name)
        ax[1].plot(t[n_train:], 1e3 * (x - data.position[n_train:]), lw=1, label=name)
    ax[0].set_ylabel("position [mm]")
    ax[1].set_ylabel("free-run error [mm]")
    ax[1].set_xlabel("time [s] (held-back last 20 %)")
    ax[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "motion_emps.png", dpi=110)
    plt.close(fig)


def run_rig(quick, key=0):
    """Force balance vs motion identification on the simulated rig, both judged against
    the rig's true friction along the true velocity (normalised MSE %, whole record)."""
    from jaxfric import identify, rig
    from jaxfric.metrics import friction_metrics

    r = rig.Rig()
    rec = rig.simulate(r, jax.random.key(key))
    meas = rec.measurements()
    fb_data = rig.estimate_friction(meas, r.cylinder)
    a1, a2 = r.cylinder.areas
    mdata = MotionData.from_pressures(meas.p1, meas.p2, float(a1), float(a2), meas.x, float(meas.t[1] - meas.t[0]),
                                      load=meas.load, cutoff=5.0)
    v_true, f_true = np.asarray(rec.velocity, np.float64), np.asarray(rec.friction, np.float64)
    rows = []
    for name, make, horizons in (("Stribeck", models.Stribeck, (None, 10)), ("LuGre", models.LuGre, (10,))):
        t0 = time.perf_counter()
        fb = identify(make(), fb_data, key=key, dtype=jnp.float64, solver=_solver(make().num_params, quick))
        done = [("force balance", fb, time.perf_counter() - t0)]
        for h in horizons:
            t0 = time.perf_counter()
            mo = identify_motion(make(), mdata, key=key, mass=float(r.cylinder.mass), train=fb_data.n_train,
                                 horizon=h, solver=_solver(make().num_params + 1, quick), fit_offset=True,
                                 dtype=jnp.float64, metric_horizon=10)
            how = "motion, free-run cost" if h is None else f"motion, {h}-step cost"
            done.append((how, mo, time.perf_counter() - t0))
        for how, fit, secs in done:
            pred = np.asarray(fit.predict(v_true), np.float64)
            m = friction_metrics(f_true, pred)
            rows.append({"model": name, "method": how, "mse_percent": m["mse_percent"],
                         "rmse_N": m["rmse"], "seconds": secs})
            print(name, how, m["mse_percent"], secs, flush=True)
    return rows


def rig_table(rows) -> str:
    lines = ["| friction model | identified from | nMSE vs true friction [%] | RMSE [N] | time [s] |",
             "|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['model']} | {r['method']} | {r['mse_percent']:.3f} | {r['rmse_N']:.2f} | {r['seconds']:.0f} |")
    return "\n".join(lines)


def run_compensation(quick, out, key=0):
    """Fits by force balance on the simulated rig (Stribeck, LuGre, ENN), then the
    compensation study of jaxfric.compensation with their feed-forward."""
    from jaxfric import compensation, identify, rig

    data = rig.synthetic_friction_data(jax.random.key(key))
    fits = {}
    for label, model in (("static (Stribeck)", "stribeck"), ("LuGre", "lugre"), ("ENN (Elman, 30)", "elman")):
        solver = _solver(7 if model != "elman" else 180, True) if quick else None
        fits[label] = identify(model, data, key=key, solver=solver, refine="auto" if model == "elman" else None)
        print(label, fits[label].metrics["valid"]["mse_percent"], flush=True)
    rows, runs = compensation.compensation_study(fits)
    fig = compensation.plot_tracking(runs, compensation.reference())
    fig.savefig(out / "motion_compensation.png", dpi=110)
    return rows, fits


SPLITS = {"whole": "whole file", "tail": "80 % / tail"}


def run_keys(path, names, count, quick, on_row=None, splits=("whole", "tail")):
    """Rows of the ``keys`` part (module docstring): one per (model, split)."""
    data, n_train = emps_motion_data(path)
    batch = jnp.stack([jax.random.key(i) for i in range(count)])
    search = None
    if quick:
        from jaxfric.motion import MotionSearch

        search = MotionSearch(particles=6, generations=2, horizons=(1000, None), steps=(3, 3), starts=2,
                              least_squares_start=True)
    rows = []
    for name in names:
        _, model, opts = EMPS_MODELS[name]
        for split, train in ((SPLITS[k], 1.0 if k == "whole" else n_train) for k in splits):
            t0 = time.perf_counter()
            fit = identify_motion(model, data, keys=batch, mass=(50.0, 200.0), train=train, fit_offset=True,
                                  dtype=jnp.float64, model_options=opts, search=search)
            secs = time.perf_counter() - t0
            e, ens, base = fit.ensemble, fit.metrics["ensemble"], fit.metrics["baseline"]
            tr = np.asarray(e["train_rmse_mm"])
            row = {"model": name, "split": split, "keys": f"0-{count - 1}",
                   "train_rmse_mm_per_key": " ".join(f"{x:.3f}" for x in tr),
                   "train_spread_percent": 100 * (tr.max() / tr.min() - 1),
                   "train_best_mm": tr.min(), "train_ensemble_mm": ens["train"]["rmse_mm"],
                   "train_baseline_mm": base["train"]["rmse_mm"],
                   "worse_than_baseline_keys": int(np.sum(tr > base["train"]["rmse_mm"])),
                   "dropped": len(e["dropped"]), "seconds_per_key": secs / count}
            if "valid" in ens:
                va = np.asarray(e["valid_rmse_mm"], np.float64)
                row.update(tail_rmse_mm_per_key=" ".join(f"{x:.3f}" for x in va),
                           tail_best_member_mm=va[e["best"]], tail_ensemble_mm=ens["valid"]["rmse_mm"],
                           tail_baseline_mm=base["valid"]["rmse_mm"])
            print(row, flush=True)
            rows.append(row)
            if on_row is not None:
                on_row(rows)
    return rows


KEYS_NOTE = """Every row: `identify_motion(model, data, keys=[key(0), ..., key(K-1)], mass=(50, 200),
fit_offset=True, dtype=float64)` with the default search (docs/motion.md: PSO on windows, then
Levenberg-Marquardt on 5 000-sample shooting segments and on the whole free run, from 3 of the
swarm's personal bests, 2 more of its points ranked by their whole free-run cost and the
least-squares start (no slow-attraction starts: `MotionSearch.slow_starts=0`), a 200-step
polish of the lowest, then 16 rounds of screening: 64 whole free-run costs around the best point
per round, Levenberg-Marquardt from the lowest, the spread back to the first after 4 fruitless
widenings). Member i is the fit of key i. "whole file": trained on all 24 841 samples of
DATA_EMPS.mat, training free-run RMSE [mm] from the first sample; "80 % / tail": trained on the first
19 873 samples, "tail" = the held-back last 20 %, free run from the state at its start (the same
excitation as the training part: it is not a score on new motion). Spread = max/min - 1 over the
keys. Ensemble = the average of the kept members' trajectories (members with a training RMSE above
1.5x the best are dropped). Baseline = least-squares Coulomb + viscous + offset (IDIM-LS on the
training part) simulated the same way. seconds_per_key: wall time of the call / K, compilation
included, on the shared 2-core machine (load in the file's header)."""


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--emps", default=None, help="DATA_EMPS.mat (default: $JAXFRIC_EMPS, jaxfric.datasets' "
                    "folders, ../shared/data)")
    ap.add_argument("--parts", default="emps,rig,compensation")
    add_output_arguments(ap, "smaller budgets, no Elman row (smoke test)")
    ap.add_argument("--rows", default=None,
                    help=f"comma-separated EMPS rows to fit (of {DEFAULT_EMPS_MODELS}); the result then "
                         "goes to motion_rows.md, never over motion.md (--parts official: the models "
                         "fitted, default coulomb,stribeck,lugre,gms)")
    ap.add_argument("--test", default=os.environ.get("JAXFRIC_EMPS_TEST"),
                    help="--parts official: the benchmark's test recording DATA_EMPS_PULSES.mat (not shipped)")
    ap.add_argument("--models", default=None,
                    help="time exactly identify_motion's default calls for these EMPS rows (e.g. "
                         "coulomb,stribeck,lugre,gms) in this process, compilation included, beside the "
                         "pre-0.9 default on 2 000 samples as a load reference; writes motion_timing.md")
    ap.add_argument("--no-reference", action="store_true", help="with --models: skip the reference run")
    ap.add_argument("--keys", type=int, default=5, help="with --parts keys: keys 0..K-1")
    ap.add_argument("--key-models", default="coulomb,stribeck,lugre,gms",
                    help="with --parts keys: the EMPS rows to fit")
    ap.add_argument("--splits", default="whole,tail", help=f"with --parts keys: of {','.join(SPLITS)}")
    args = ap.parse_args(argv)
    path, load0, quick = emps_file(args.emps), os.getloadavg()[0], " --quick" if args.quick else ""
    if args.parts == "official" and (not args.test or not Path(args.test).exists() or path is None):
        print("EMPS estimation file not found: skipping" if args.test and Path(args.test).exists() else
              f"EMPS test recording {args.test!r} not given or not found: skipping the official task (pass "
              "--test PATH/DATA_EMPS_PULSES.mat)")
        return
    out = results_dir(args.out, quick=args.quick)
    if args.parts == "official":
        names = (args.rows or "coulomb,stribeck,lugre,gms").replace(" ", "")
        rows = run_official(path, args.test, names.split(","), args.quick)
        write_report(out, "emps_official", [
            "# EMPS official forward task (benchmarks/motion.py --parts official)", "",
            f"Command: `python benchmarks/motion.py --parts official --test PATH{quick} --rows {names}`", "",
            OFFICIAL_NOTE, "", markdown_table(rows, fmt=cell())], rows)
        return
    if path is None and (args.parts == "keys" or args.models):
        raise SystemExit(f"EMPS file {args.emps or 'DATA_EMPS.mat'} not found (pass --emps or set JAXFRIC_DATA)")
    if args.parts == "keys":
        def write(rows, echo=False):  # after every row: a long run leaves what it measured
            write_report(out, "motion_keys", [
                "# Motion identification over keys: spread, baseline, ensemble (benchmarks/motion.py)", "",
                f"Command: `python benchmarks/motion.py --parts keys --keys {args.keys} --key-models "
                f"{args.key_models} --splits {args.splits}{quick}` (1-minute load average {load0:.1f} at "
                f"the start, {os.getloadavg()[0]:.1f} at the last row, {os.cpu_count()} CPUs)", "",
                KEYS_NOTE, "", markdown_table(rows, fmt=cell(".4g"))], rows, echo=echo)

        write(run_keys(path, [m.strip() for m in args.key_models.split(",")], args.keys, args.quick,
                       on_row=write, splits=[k.strip() for k in args.splits.split(",")]), echo=True)
        return
    if args.models:
        rows, total, ref = run_timing(path, [m.strip() for m in args.models.split(",") if m.strip()],
                                      reference=not args.no_reference)
        md = ["# identify_motion default calls on the whole EMPS estimation split (benchmarks/motion.py)", "",
              f"Command: `python benchmarks/motion.py --models {args.models}`", "",
              "Each row: `identify_motion(name, data, key=0, mass=(50, 200), train=19873, "
              "fit_offset=True, dtype=float64)` with the default search, in one fresh process (so "
              "compilation is included), float64; RMSE of the held-back last 20 %.", "",
              markdown_table(rows, fmt=cell(".4g")), "", f"Total wall for these calls: **{total:.1f} s** "
              f"(1-minute load average {load0:.1f} at the start, {os.getloadavg()[0]:.1f} at the end, on "
              f"{os.cpu_count()} CPUs).", ""]
        if ref is not None:
            md += [f"Same-run load reference: the pre-0.9 default search (MAPSO 5x5, 200 generations, then "
                   f"Nelder-Mead) for LuGre + mass + offset on the first 2 000 samples: {ref[0]:.1f} s "
                   f"(held-back RMSE {ref[1]:.3f} mm)."]
        write_report(out, "motion_timing", md)
        return
    parts = set(args.parts.split(","))
    md = ["# Motion identification and friction compensation (benchmarks/motion.py)", "",
          f"Command: `python benchmarks/motion.py --parts {args.parts}{quick}`", ""]
    if "emps" in parts and path is None:
        print(f"EMPS file {args.emps or 'DATA_EMPS.mat'} not found: skipping the EMPS part")
    elif "emps" in parts:
        only = [r.strip() for r in args.rows.split(",")] if args.rows else None
        data, n_train, rows = run_emps(path, args.quick, only=only)
        if not only:
            emps_figure(data, n_train, rows, out)
        md += ["## EMPS: friction inside the mechanics, last 20 % held back", "",
               EMPS_NOTE, "", emps_table(rows), "", "![EMPS free run](motion_emps.png)", ""]
    if "rig" in parts:
        md += ["## Simulated rig: motion identification against force balance", "", RIG_NOTE, "",
               rig_table(run_rig(args.quick)), ""]
    if "compensation" in parts:
        from jaxfric.compensation import compensation_table

        rows, fits = run_compensation(args.quick, out)
        md += ["## Friction compensation on the rig simulator", "", COMP_NOTE, "",
               "| fit | valid MSE % (force balance) |", "|---|---|",
               *[f"| {k} | {f.metrics['valid']['mse_percent']:.3f} |" for k, f in fits.items()], "",
               compensation_table(rows), "", "![tracking error](motion_compensation.png)", ""]
    write_report(out, "motion_rows" if args.rows else "motion", md)


COMP_NOTE = """`jaxfric.compensation.compensation_study` on the default rig: 1 kHz cascade (outer PID on
position -> force demand, inner force loop -> valve), reference = 1 s hold, one 10 mm
sinusoid of 8 s period (two reversals), then a 1 mm/s ramp out and back (4 s each).
Feed-forward from each fit (identified by force balance on the 128 Hz synthetic record,
evaluated along the reference velocity on the fit's own time grid); "ideal" feeds the
rig's true friction at the current state. Metrics after the hold; stick-slip = largest
peak-to-peak tracking error on a ramp after its first quarter."""


RIG_NOTE = """Default `jaxfric.rig.Rig`, key 0, 2000 samples at 128 Hz (1600 estimation).
Force balance: `jaxfric.identify` on the §7 pipeline's friction (5 Hz low-pass, a = x'').
Motion: `jaxfric.identify_motion` from the actuator force p1 A1 - p2 A2, the measured load
and the measured position only (mass known, 120 kg; constant offset identified; 5 Hz
velocity filter for the initial states), with the free-run or the 10-step-ahead position
error as the cost. The free run of a closed-loop record through noisy pressures and load
integrates the force noise twice and drifts; the k-step cost does not. Both
fits are scored against the rig's *true* friction along the true velocity (whole record).
The rig's friction (asymmetric, pressure-dependent Maxwell-slip) lies outside both
model classes."""


EMPS_NOTE = f"""Input `gtau*vir` [N], output `qm` [m], 1 kHz, first 80 % (19 873 samples) for
estimation, last 20 % (4 968 samples) held back. Every fitted row is
`identify_motion(model, data, key=0, mass=(50, 200), train=19873, fit_offset=True)` with the
defaults: data-centred search box and the default search (`jaxfric.motion.MotionSearch()`:
PSO 25 x 20 on windows, then Levenberg-Marquardt on 5 000-sample shooting segments;
docs/motion.md). Every model is simulated with `jaxfric.motion.simulate_motion`
(one step per sample, friction at the end of the step, linearly implicit). The held-back
free run starts from the state estimated at its start (measured position, velocity from the
100 Hz zero-phase low-pass of `qm`, friction state tracked along it); the {K_STEP}-step-ahead
error (MATLAB `compare(..., {K_STEP})`) is reported beside it. The asymmetric row's offset is
the library model's own `F_off`. Time: wall seconds of the call in this process (the first
call of each model compiles). The IDIM-LS row simulates the published parameters of
SOURCE.md the same way; the least-squares row fits M, Fv, Fc and offset by IDIM-LS on the
estimation part (the benchmark's filter) and simulates them the same way."""


if __name__ == "__main__":
    main()
