"""Which judge predicts new excitation, and do ensembles beat their best member (issue 45 items 2, 4)?

    python benchmarks/motion_judge.py [--proxy rig|emps-blocked|pneumatic] [--keys 5] [--members 3]
                                      [--quick] [--out DIR] [--save-fits DIR | --rescore DIR]

``--proxy rig`` (default): the simulated hydraulic rig (true friction known, richer than every
candidate) driven by four excitation families of one length and amplitude scale, each with its
own sensor noise: ``sweep`` (a chirp), ``steps`` (trapezoidal strokes, dwells at standstill),
``multisine`` (four tones), ``reversals`` (slow motion, many reversals). Key ``k`` trains on
family ``k mod 4`` (80 %; the tail held back, as ``compare_motion``'s data form) and scores
every candidate on the other three, each simulated from its own first 20 samples: the *truth*,
pooled free-run position RMSE on unseen excitation. Candidates: Stribeck, LuGre, GMS, Elman(10)
in the mechanics (known mass, fitted offset) and the least-squares baseline.
``--proxy emps-blocked``: DATA_EMPS.mat in 3 contiguous blocks (`emps_blocks`); key ``k`` trains
Coulomb, Stribeck, LuGre and GMS (mass in [50, 200] kg, fitted offset) on block ``k mod 3`` and
scores them on the two others. ``--proxy pneumatic``: force balance; key ``k`` is seal ``k`` of
``pressure_records.py``: Stribeck, LuGre, GMS, ``Cylinder`` (each with an offset) and the
least-squares asymmetric Coulomb + viscous + offset baseline train on the first 80 % of the 1, 5
and 7 bar records, the truth is MSE % on 3 bar (criteria in MSE % of the training friction's
variance, float32 as `jaxfric.identify`'s default).

Criteria, from the training data alone (lower is better): ``tail``, free-run RMSE of the held-back
20 % from the state at its start; ``blocked``, 3-fold blocked cross-validation of the 80 % (each
held-out block from its own first 20 samples, ``jaxfric.motion.blocked_score``); ``short``, the
whole training record cut into 2 s windows, each simulated from its own first 20 samples (no
refit; pneumatic: rolled out from the model's initial state, scored from sample 20); ``spread``,
``tail`` plus the ensemble members' RMS disagreement on the tail (``--members 1``: none); ``bic``,
``log(rmse) + p log(n)/(2n)`` on the training free run; ``gated`` (`compare_motion`'s default), ``short``
among the models whose ``blocked`` beats the baseline's, the baseline only where none does. From saved fits (``--save-fits DIR``, then
``--rescore DIR``): ``short_<samples>`` at other windows (`WIDTHS` seconds), ``short_median``
(the median over the 2 s windows), ``short_reversals`` (2 s windows started 20 samples before a
velocity reversal, `reversal_starts`), ``short_margin`` (the baseline kept unless a model is more
than 10 % lower), and the averaged predictions `AVERAGES` (issue 45 item 4: a weighted mean of
the candidates' predictions, the baseline's included, weights `average_weights` from the
training ``short`` scores, judged as one candidate).

A criterion's choice (the lowest, the baseline included) *succeeds* on a key when its unseen
RMSE is within 10 % of the best candidate's and not above the baseline's. Rows go to
``<stem>.csv`` as they come (a rerun skips keys done), the summary to ``<stem>.md`` (`STEMS`).
``main`` switches x64 on (benchmarks choose it).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # not on sys.path under `jaxfric bench`
from _harness import (add_output_arguments, cell, emps_file, markdown_table, pneumatic, read_csv,  # noqa: E402
                      results_dir, skipped, write_csv, write_report, x64)

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxfric as jf  # noqa: E402
from jaxfric import rig  # noqa: E402
from jaxfric.metrics import friction_metrics  # noqa: E402
from jaxfric.motion import (MotionData, baseline_fit, identify_motion, load_motion_fit, motion_metrics,  # noqa: E402
                            short_runs_score)
from jaxfric.motion._compare import blocked_score, short_window, window_scores  # noqa: E402
from jaxfric.rig.emps import EMPS_CUTOFF_HZ, load_emps  # noqa: E402

FS, N, INIT, MARGIN = 128.0, 2000, 20, 0.10
SHORT = None  # compare_motion's default window: 2 s (256 samples at 128 Hz, 2 000 at 1 kHz)
CANDIDATES = {**{m: (m, None) for m in ("stribeck", "lugre", "gms")}, "elman": ("elman", {"neurons": 10})}
EMPS_CANDIDATES = {m: (m, None) for m in ("coulomb", "stribeck", "lugre", "gms")}
PNEUMATIC_CANDIDATES = ("stribeck", "lugre", "gms", "cylinder")
BASE = "baseline"
CRITERIA = ("tail", "blocked", "short", "spread", "bic", "gated")
#: The short-runs criterion at other window lengths [s], from saved fits (``--rescore``).
WIDTHS = (0.5, 1.0, 4.0, 8.0)
#: Pseudo-candidates: the candidates' predictions averaged (`average_weights`; module docstring).
AVERAGES = ("avg_all", "avg_beats_ls", "avg_top3", "avg_inv_var")
STEMS = {"rig": "motion_judge", "emps-blocked": "judge_emps", "pneumatic": "judge_pneumatic"}


def _strokes(t, period=6.0, peak=0.009, ramp=0.6, dwell=0.4):
    half = period / 2
    tau, sign = np.mod(t, half), np.where(np.mod(t, period) < half, 1.0, -1.0)
    return sign * peak * np.minimum(np.clip(tau / ramp, 0, 1), np.clip((half - dwell - tau) / ramp, 0, 1))


def families(n=N, fs=FS) -> dict:
    """Reference velocities [m/s] of the four excitation families (positions stay in the stroke)."""
    t = np.arange(n) / fs
    tones = sum(a * np.sin(2 * np.pi * f * t + p) for a, f, p in
                ((0.005, 0.13, 0.3), (0.004, 0.31, 1.9), (0.003, 0.67, 4.0), (0.002, 1.3, 2.2)))
    return {"sweep": 0.010 * np.sin(2 * np.pi * (0.1 * t + 0.5 * 0.9 / t[-1] * t ** 2)),
            "steps": _strokes(t),
            "multisine": tones,
            "reversals": 0.003 * np.sin(2 * np.pi * 0.08 * t) + 0.0015 * np.sin(2 * np.pi * 0.45 * t)}


def records(key: int, n=N) -> dict:
    """One MotionData per family, each with its own sensor noise (key ``key``)."""
    r = rig.Rig()
    a1, a2 = (float(a) for a in r.cylinder.areas)
    out = {}
    for i, (name, vref) in enumerate(families(n).items()):
        m = rig.simulate(r, jax.random.fold_in(jax.random.key(key), i), n_samples=n, fs=FS,
                         velocity_reference=jnp.asarray(vref)).measurements()
        out[name] = MotionData.from_pressures(m.p1, m.p2, a1, a2, m.x, 1.0 / FS, load=m.load, cutoff=5.0)
    return out


def emps_blocks(path, blocks: int = 3) -> dict:
    """DATA_EMPS.mat as ``blocks`` contiguous records ``block0``, ... (`MotionData.window` of the
    whole file, whose velocity, for initial states only, is filtered over the whole file)."""
    rec = load_emps(path)
    data = MotionData.from_arrays(rec.force, rec.qm, rec.dt, cutoff=EMPS_CUTOFF_HZ)
    edges = [round(i * data.n_samples / blocks) for i in range(blocks + 1)]
    return {f"block{i}": data.window(a, b) for i, (a, b) in enumerate(zip(edges[:-1], edges[1:]))}


def setup(proxy, key, quick, emps=None) -> tuple:
    """(records by name, the training record's name, candidates, identify_motion options)."""
    if proxy == "rig":
        recs, cands, opts = records(key), CANDIDATES, dict(mass=float(rig.Rig().cylinder.mass))
    else:
        recs, cands, opts = emps_blocks(emps), EMPS_CANDIDATES, dict(mass=(50.0, 200.0))
    opts.update(fit_offset=True, dtype=jnp.float64)
    if quick:
        from jaxfric.motion import MotionSearch
        opts["search"] = MotionSearch(particles=10, generations=5, horizons=(500, None), steps=(10, 20),
                                      starts=1, least_squares_start=True)
    return recs, list(recs)[key % len(recs)], cands, opts


def pooled(rmses) -> float:
    """Pooled RMSE of equally long records: sqrt(mean rmse_i^2)."""
    r = np.asarray(rmses, np.float64)
    return float(np.sqrt(np.mean(r ** 2))) if np.all(np.isfinite(r)) else float("inf")


def short_runs(fit, rec, width=SHORT) -> float:  # the ``short`` criterion of the whole record
    return short_runs_score(fit, [rec], width, INIT)


def tail_spread(fit, rec, n_train) -> float:
    """RMS spread [mm] of the kept members' free runs of the held-back tail."""
    runs = np.stack([fit.member(i).simulate_from(rec, n_train)["x"] for i in fit.ensemble_kept()])
    return float(1e3 * np.sqrt(np.mean(runs.var(axis=0))))


def measure_key(key, members, quick, on_row, save=None, proxy="rig", emps=None):
    recs, train_name, candidates, opts = setup(proxy, key, quick, emps)
    rec, unseen = recs[train_name], {k: r for k, r in recs.items() if k != train_name}
    n_train = int(round(0.8 * rec.n_samples))
    base = None
    for label, (name, mopts) in candidates.items():
        t0 = time.perf_counter()
        fit = identify_motion(name, rec, key=key, keys=members, train=0.8, model_options=mopts, **opts)
        row = {"key": key, "train": train_name, "model": label, "params": fit.metrics["num_params"],
               "tail": fit.metrics["valid"]["rmse_mm"], "train_rmse": fit.metrics["train"]["rmse_mm"]}
        row["short"] = short_runs(fit, rec)
        row["spread"] = row["tail"] + tail_spread(fit, rec, n_train)
        row["bic"] = math.log(row["train_rmse"]) + row["params"] * math.log(n_train) / (2 * n_train)
        ens = [fit.member(i) for i in fit.ensemble_kept()]
        per = {k: fit.score(r, INIT)["rmse_mm"] for k, r in unseen.items()}
        row["unseen"] = pooled(list(per.values()))
        row["unseen_ensemble"] = pooled([_ens_score(ens, r) for r in unseen.values()])
        row["kept"] = len(ens)
        row["unseen_members"] = ";".join(f"{pooled([m.score(r, INIT)['rmse_mm'] for r in unseen.values()]):.10g}"
                                         for m in (fit.member(i) for i in range(len(fit.ensemble['mass']))))
        row.update({f"unseen_{k}": v for k, v in per.items()})
        row["blocked"], b_blocked = blocked_score(name, [rec.window(0, n_train)], 3, key=key,
                                                  model_options=mopts, **opts)
        row["seconds"] = time.perf_counter() - t0
        if save is not None:  # the fits, for criteria computed later without refitting
            save.mkdir(parents=True, exist_ok=True)
            fit.save(save / f"key{key}_{label}.npz")
        on_row(row)
        if base is None:  # the baseline depends on the training data only: once per key
            bf = baseline_fit(fit)
            bper = {k: bf.score(r, INIT)["rmse_mm"] for k, r in unseen.items()}
            base = {"key": key, "train": train_name, "model": BASE, "params": 4,
                    "tail": fit.metrics["baseline"]["valid"]["rmse_mm"],
                    "train_rmse": fit.metrics["baseline"]["train"]["rmse_mm"], "short": short_runs(bf, rec),
                    "blocked": b_blocked, "unseen": pooled(list(bper.values())), "seconds": 0.0,
                    **{f"unseen_{k}": v for k, v in bper.items()}}
            base.update(spread=base["tail"], bic=math.log(base["train_rmse"]) + 4 * math.log(n_train) / (2 * n_train),
                        unseen_ensemble=base["unseen"], unseen_members="")
    on_row(base)


def _ens_score(fits, rec) -> float:
    x = np.mean([f.simulate(rec, init_window=INIT)["x"] for f in fits], axis=0)
    return motion_metrics(rec.position[INIT:], x[INIT:])["rmse_mm"]


def summarise(rows, criteria=CRITERIA) -> tuple[list, list, list]:
    """(judge rows, ensemble rows, per-key choice rows) from the measured rows."""
    by_key = {}
    for r in rows:
        by_key.setdefault(int(r["key"]), []).append(r)
    done = {k: v for k, v in by_key.items() if any(r["model"] == BASE for r in v)}
    for rs in done.values():  # short among the models whose blocked cross-validation beats the baseline's, else it
        b = next(float(r["blocked"]) for r in rs if r["model"] == BASE)
        gate = {r["model"]: float(r["blocked"]) < b for r in rs if r["model"] != BASE}
        rs[:] = [{**r, "gated": r["short"] if gate.get(r["model"], not any(gate.values())) else math.inf} for r in rs]
    choices, judges = [], []
    extra = sorted({c for rs in done.values() for r in rs for c in r if c.startswith("short_")},
                   key=lambda c: (not c[6:].isdigit(), int(c[6:]) if c[6:].isdigit() else 0, c))
    for crit in criteria + tuple(c for c in extra if all(r.get(c) not in (None, "") for v in done.values() for r in v)):
        wins = never_worse = 0
        for k, rs in sorted(done.items()):
            pick = min(rs, key=lambda r: (float(r[crit]), r["model"]))
            best = min(float(r["unseen"]) for r in rs)
            base = next(float(r["unseen"]) for r in rs if r["model"] == BASE)
            u = float(pick["unseen"])
            ok_base, within = u <= base, u <= (1 + MARGIN) * best
            wins += within and ok_base
            never_worse += ok_base
            choices.append({"criterion": crit, "key": k, "train": rs[0]["train"], "pick": pick["model"],
                            "pick_unseen_mm": u, "best": min(rs, key=lambda r: float(r["unseen"]))["model"],
                            "best_unseen_mm": best, "baseline_unseen_mm": base,
                            "within_10pct": within, "not_worse_than_baseline": ok_base})
        judges.append({"criterion": crit, "keys": len(done), "within 10 % and not worse than baseline": wins,
                       "not worse than baseline": never_worse})
    ens = []
    for r in rows:
        if r["model"] == BASE or not r.get("unseen_members") or ";" not in str(r["unseen_members"]):
            continue
        mem = [float(x) for x in str(r["unseen_members"]).split(";")]
        ens.append({"key": int(r["key"]), "train": r["train"], "model": r["model"],
                    "ensemble_mm": float(r["unseen_ensemble"]), "best_member_mm": min(mem),
                    "chosen_member_mm": float(r["unseen"]), "median_member_mm": float(np.median(mem)),
                    "kept": r.get("kept", ""), "ensemble / best member": float(r["unseen_ensemble"]) / min(mem),
                    "ensemble / chosen member": float(r["unseen_ensemble"]) / float(r["unseen"])})
    return judges, ens, choices


def average_summary(rows) -> tuple[list, list]:
    """(judge rows, the report's section) of the averaging rules (`AVERAGES`) by the criteria's
    success rule, per key beside the single candidates' unseen error (best, median, worst)."""
    out = []
    for b in (r for r in rows if r["model"] == BASE):
        one = sorted(float(q["unseen"]) for q in rows if int(q["key"]) == int(b["key"]))
        out += [{"rule": a, "key": b["key"], "train": b["train"], "members": b[f"members_{a}"], "average_unseen": u,
                 "best_single": one[0], "median_single": np.median(one), "worst_single": one[-1],
                 "baseline_unseen": float(b["unseen"]), "within_10pct": u <= (1 + MARGIN) * one[0],
                 "not_worse_than_baseline": u <= float(b["unseen"])}
                for a in AVERAGES if b.get(f"unseen_{a}") not in (None, "") for u in [float(b[f"unseen_{a}"])]]
    return [{"criterion": a, "keys": len(c), "within 10 % and not worse than baseline":
             sum(x["within_10pct"] and x["not_worse_than_baseline"] for x in c),
             "not worse than baseline": sum(x["not_worse_than_baseline"] for x in c)}
            for a in AVERAGES if (c := [x for x in out if x["rule"] == a])], [] if not out else [
        ("## Averaged predictions: each candidate's prediction of the unseen records (motion: a free run from each "
         "record's first 20 samples) averaged with the weights `members` (`average_weights`, from the training short scores)"), "",
        markdown_table(sorted(out, key=lambda x: AVERAGES.index(x["rule"])), fmt=_fmt), ""]


def ensemble_summary(ens) -> list:
    """How often the kept members' average beats the best member (known only afterwards) and
    the member ``keys=K`` returns (lowest training RMSE), by more than 1 %."""
    out = []
    for col in ("ensemble / best member", "ensemble / chosen member"):
        ratios = np.array([e[col] for e in ens])
        out.append({"against": col.split(" / ")[1], "fits": len(ens), "average better (< 0.99)": int(np.sum(ratios < 0.99)),
                    "tied (0.99-1.01)": int(np.sum(np.abs(ratios - 1) <= 0.01)),
                    "average worse (> 1.01)": int(np.sum(ratios > 1.01)), "median ratio": float(np.median(ratios))})
    return out


def reversal_starts(v, width, init=INIT) -> list:
    """Starts of non-overlapping windows of ``width`` samples, ``init`` before a velocity ``v`` sign change."""
    out = []
    for i in np.flatnonzero(np.sign(v[1:]) * np.sign(v[:-1]) < 0) + 1 - init:
        if i >= (out[-1] + width if out else 0) and i + width <= v.size:
            out.append(int(i))
    return out


def variants(fit, rec, baseline) -> dict:
    """The criteria ``--rescore`` adds (module docstring) for one fit."""
    width = short_window(rec.dt)
    out = {f"short_{round(w / rec.dt)}": short_runs(fit, rec, round(w / rec.dt)) for w in WIDTHS}
    per = [m["rmse_mm"] if math.isfinite(m["rmse_mm"]) else math.inf for m in window_scores(fit, [rec], width, INIT)]
    out["short_median"] = float(np.median(per))
    out["short_reversals"] = short_runs_score(fit, [rec.window(a, a + width) for a in
                                                   reversal_starts(np.asarray(rec.velocity), width)], width, INIT)
    out["short_margin"] = short_runs(fit, rec) * ((1 - MARGIN) if baseline else 1.0)
    return out


def average_weights(short: dict, rule: str) -> dict:
    """Weights (label -> w, sum 1) of ``rule`` from the ``short`` scores (the baseline's ``short[BASE]``): ``avg_all``
    equal; ``avg_beats_ls`` the baseline and those below it; ``avg_top3`` the three lowest; ``avg_inv_var`` 1/short^2."""
    w = {"avg_all": {k: 1.0 for k in short}, "avg_top3": {k: 1.0 for k in sorted(short, key=lambda k: (short[k], k))[:3]},
         "avg_beats_ls": {k: 1.0 for k in short if k == BASE or short[k] < short[BASE]},
         "avg_inv_var": {k: float(s) ** -2 for k, s in short.items()}}[rule]
    return {k: w[k] / sum(w.values()) for k in sorted(w, key=lambda k: (-w[k], k))}


def averaged_rmse(position, runs: dict, weights: dict, init=INIT) -> float:
    """Position RMSE [mm] from sample ``init`` of ``sum_k weights[k] runs[k]`` (free runs [m])."""
    return motion_metrics(position[init:], sum(w * np.asarray(runs[k]) for k, w in weights.items())[init:])["rmse_mm"]


def rescore(rows, folder, proxy="rig", emps=None) -> list:
    """Add the ``short`` variants (`variants`) to every row from the fits saved in ``folder``
    (no refit), check that they reproduce the ``short`` and ``unseen`` columns, and add to each
    key's baseline row ``unseen_<rule>`` (`AVERAGES`: the pooled unseen RMSE of the candidates'
    free runs averaged) and ``members_<rule>`` (their weights)."""
    cache, worst, runs = {}, 0.0, {}
    for r in rows:
        key = int(r["key"])
        recs = cache.setdefault(key if proxy == "rig" else 0, setup(proxy, key, False, emps)[0])
        rec = recs[r["train"]]
        first = next(iter(CANDIDATES if proxy == "rig" else EMPS_CANDIDATES))
        fit = load_motion_fit(folder / f"key{key}_{first if r['model'] == BASE else r['model']}.npz")
        fit = baseline_fit(fit) if r["model"] == BASE else fit
        worst = max(worst, abs(short_runs(fit, rec) / float(r["short"]) - 1.0))
        r.update(variants(fit, rec, r["model"] == BASE))
        x = runs.setdefault(key, {})[r["model"]] = {k: fit.simulate(u, init_window=INIT)["x"]
                                                    for k, u in recs.items() if k != r["train"]}
        worst = max(worst, abs(pooled([averaged_rmse(recs[k].position, x, {k: 1.0}) for k in x]) / float(r["unseen"]) - 1))
    for r in (r for r in rows if r["model"] == BASE):
        key, recs = int(r["key"]), cache[int(r["key"]) if proxy == "rig" else 0]
        for rule in AVERAGES:
            w = average_weights({q["model"]: float(q["short"]) for q in rows if int(q["key"]) == key}, rule)
            r[f"unseen_{rule}"] = pooled([averaged_rmse(recs[k].position, {m: runs[key][m][k] for m in w}, w)
                                          for k in runs[key][BASE]])
            r[f"members_{rule}"] = " ".join(f"{m}:{v:.2f}" for m, v in w.items())
    print(f"saved fits reproduce the short and unseen columns within {worst:.2e} relative", flush=True)
    return rows


def _cut(d, a, b):  # samples [a, b) of a FrictionData as a record of its own (all for training)
    return d._view(slice(a, b), b - a)


def _fitter(label, key, quick):
    """``fit(records, members) -> (predictor, member predictors, parameters)``: `jaxfric.identify`
    of ``label`` (with an offset) on whole records, or the least-squares baseline."""
    if label == BASE:
        from baselines import ls_coulomb_viscous

        def ls(recs, members=1):
            v, f = (np.concatenate([getattr(d, k) for d in recs]) for k in ("velocity", "friction"))
            return (lambda d: ls_coulomb_viscous(np.r_[v, d.velocity], np.r_[f, d.friction], v.size)[0][v.size:]), [], 5
        return ls
    extra = {}
    if quick:
        from jaxfric.optim import MAPSO, MAPSONMDS, NelderMead
        extra["solver"] = MAPSONMDS(mapso=MAPSO(lattice_size=3, num_generations=5),
                                    nelder_mead=NelderMead(max_steps=60, max_evals=60))

    def run(fit):  # a predictor of FrictionData records
        return lambda d: np.asarray(fit.predict(d.velocity, inputs=np.stack([d.p1, d.p2])), np.float64)

    def fit(recs, members=1):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # bounds and extrapolation: the scores say what matters here
            f = jf.identify(label, train=list(recs), key=key, keys=members if members > 1 else None,
                            model_options={"offset": True}, **extra)
        mem = [run(f.replace(theta=th)) for th in np.asarray(f.ensemble["theta"])] if members > 1 else []
        return run(f), mem, f.num_params
    return fit


def pneumatic_key(key, members, quick, on_row, folder=None, folds=3):
    """The pneumatic proxy's rows of seal ``SEALS[key]`` (module docstring)."""
    from pressure_records import SEALS, TRAIN_BAR, VALID_BAR
    seal = SEALS[key % len(SEALS)]
    full, held = [pneumatic(seal, b, folder)[1] for b in TRAIN_BAR], pneumatic(seal, VALID_BAR, folder)[1]
    cuts = [round(0.8 * d.n_samples) for d in full]
    heads = [_cut(d, 0, n) for d, n in zip(full, cuts)]
    blocks = [[_cut(h, round(i * h.n_samples / folds), round((i + 1) * h.n_samples / folds)) for i in range(folds)]
              for h in heads]
    width = short_window(full[0].dt)
    windows = [_cut(d, a, a + width) for d in full for a in range(0, d.n_samples - width + 1, width)]
    scale = 100.0 / float(np.var(np.concatenate([d.friction for d in heads])))

    def mse(pairs):  # pooled MSE % of the training friction's variance
        return scale * float(np.mean(np.concatenate([y - yh for y, yh in pairs]) ** 2))

    on_held, short = {}, {}
    for label in PNEUMATIC_CANDIDATES + (BASE,):
        t0, fit = time.perf_counter(), _fitter(label, key, quick)
        pred, mem, p = fit(heads, members)
        runs = [pred(d) for d in full]
        row = {"key": key, "train": seal, "model": label, "params": p,
               "tail": mse([(d.friction[n:], y[n:]) for d, n, y in zip(full, cuts, runs)]),
               "train_mse": mse([(d.friction[:n], y[:n]) for d, n, y in zip(full, cuts, runs)]),
               "short": mse([(w.friction[INIT:], pred(w)[INIT:]) for w in windows])}
        var = [np.var([m(d)[n:] for m in mem], axis=0) for d, n in zip(full, cuts)] if mem else [np.zeros(1)]
        row["spread"] = row["tail"] + scale * float(np.mean(np.concatenate(var)))
        row["bic"] = 0.5 * math.log(row["train_mse"]) + p * math.log(sum(cuts)) / (2 * sum(cuts))
        pairs = []
        for f in range(folds):
            pf = fit([b for rec in blocks for i, b in enumerate(rec) if i != f])[0]
            pairs += [(rec[f].friction[INIT:], pf(rec[f])[INIT:]) for rec in blocks]
        row["blocked"] = mse(pairs)
        row["unseen"] = float(friction_metrics(held.friction, pred(held))["mse_percent"])
        on_held[label], short[label] = pred(held), row["short"]
        for rule in AVERAGES if label == BASE else ():  # the candidates' predictions averaged (`AVERAGES`)
            w = average_weights(short, rule)
            row[f"unseen_{rule}"] = float(friction_metrics(held.friction, sum(w[m] * on_held[m] for m in w))["mse_percent"])
            row[f"members_{rule}"] = " ".join(f"{m}:{v:.2f}" for m, v in w.items())
        row["seconds"] = time.perf_counter() - t0
        on_row(row)


_fmt = cell(".4g")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--proxy", choices=tuple(STEMS), default="rig")
    p.add_argument("--data", default=None, help="DATA_EMPS.mat or the pneumatic_seal_friction folder")
    p.add_argument("--keys", type=int, default=5)
    p.add_argument("--start", type=int, default=0, help="first key (split a long run over processes)")
    p.add_argument("--members", type=int, default=3, help="ensemble members per fit (keys=K)")
    p.add_argument("--save-fits", type=Path, default=None, help="folder to save every fit in (.npz)")
    p.add_argument("--rescore", type=Path, default=None,
                   help="folder of saved fits: add the short criterion's variants (no refit)")
    p.add_argument("--fits-from", default=None, help="the commit whose search made the rescored fits (reports it)")
    p.add_argument("--summary-only", action="store_true", help="rebuild the tables from the CSV")
    add_output_arguments(p)
    a = p.parse_args(argv)
    if a.proxy != "pneumatic":
        x64()  # here, not at import (tests import the functions); force balance: float32 as pressure_records.py
    out = results_dir(a.out, quick=a.quick)
    csv_path = out / f"{STEMS[a.proxy]}.csv"
    emps = emps_file(a.data) if a.proxy == "emps-blocked" else None
    if (a.proxy == "emps-blocked" and emps is None) or (a.proxy == "pneumatic" and pneumatic("NAPN", 3, a.data) is None):
        return skipped(STEMS[a.proxy], f"no {a.proxy} data ({a.data or 'JAXFRIC_DATA, ../shared/data'})")
    rows = read_csv(csv_path, parse=False)
    done = {int(r["key"]) for r in rows if r["model"] == BASE}
    if a.rescore is not None:
        rows = rescore(rows, a.rescore, a.proxy, emps)
        write_csv(rows, csv_path)
    elif not a.summary_only:
        for key in range(a.start, a.keys):
            if key in done:
                continue
            rows = [r for r in rows if int(r["key"]) != key]

            def on_row(row):
                rows.append(row)
                write_csv(rows, csv_path)
                print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()}, flush=True)

            if a.proxy == "pneumatic":
                pneumatic_key(key, a.members, a.quick, on_row, a.data)
            else:
                measure_key(key, a.members, a.quick, on_row, a.save_fits, a.proxy, emps)
    judges, ens, choices = summarise(rows, CRITERIA if a.members > 1 else tuple(c for c in CRITERIA if c != "spread"))
    avg_judges, averages = average_summary(rows)
    judges += avg_judges
    cmd = " ".join(["python benchmarks/motion_judge.py --proxy", a.proxy, *(["--quick"] if a.quick else []), *(
        ["--start", str(a.start)] if a.start else []), "--keys", str(a.keys), "--members", str(a.members)])
    made = f"; the fits were made with the search of commit {a.fits_from}" if a.fits_from else ""
    rescored = None if a.rescore is None and not a.fits_from else made
    if a.proxy != "rig":
        return real_report(out, a.proxy, cmd, judges, choices, rows, rescored, averages)
    text = ["# Which judge predicts new excitation (rig proxy)", "", (f"Command: `{cmd}`" if rescored is None else (
            f"Commands: `{cmd} --save-fits FITS`, then `{cmd} --rescore FITS` (the short criterion's variants from "
            f"the saved fits, no refit{made})")) + ". Free-run position RMSE [mm]; "
            "`unseen`: pooled over the three families the fit never saw, each simulated from its first 20 samples. "
            "Module docstring: the proxy and the criteria.", "",
            "## Criteria: choice within 10 % of the best on unseen excitation, never worse than the baseline", "",
            markdown_table(judges), "", *averages, "## Choices per key", "", markdown_table(choices, fmt=_fmt), "",
            "## Ensemble average against its members on unseen excitation (pooled free-run RMSE [mm])", "",
            markdown_table(ensemble_summary(ens), fmt=_fmt), "", markdown_table(ens, fmt=_fmt), ""]
    write_report(out, "motion_judge", text)


def real_report(out, proxy, cmd, judges, choices, rows, rescored, averages=()):
    """The report of a real-data proxy: criteria, choices, every candidate's unseen score."""
    emps = proxy == "emps-blocked"
    unit = "free-run position RMSE [mm]" if emps else "MSE % of the friction's variance"
    head = (f"DATA_EMPS.mat in 3 contiguous blocks; key k trains on block k mod 3; `unseen`: {unit} pooled "
            "over the two other blocks, each simulated from its own first 20 samples" if emps else
            "pneumatic seals: key k trains seal k on the first 80 % of its 1, 5 and 7 bar records; `unseen`: "
            f"{unit} of the held-out 3 bar record (criteria: {unit} of the training records)")
    if not emps:  # MSE %, not mm
        choices = [{k.replace("_mm", "_mse_pct"): v for k, v in c.items()} for c in choices]
    cmds = f"`{cmd}`" if rescored is None else (f"`{cmd} --save-fits FITS`, then `{cmd} --rescore FITS` (the short "
                                                f"criterion's variants, no refit{rescored})")
    text = [f"# Which judge predicts new excitation ({proxy} proxy, real data)", "",
            f"Command: {cmds}. {head}. Module docstring of benchmarks/motion_judge.py: the criteria.", "",
            "## Criteria: choice within 10 % of the best on unseen excitation, never worse than the baseline", "",
            markdown_table(judges), "", *averages, "## Choices per key", "", markdown_table(choices, fmt=_fmt), "",
            f"## Every candidate ({unit}; `unseen` is the truth)", "",
            markdown_table(rows, ["key", "train", "model", "params", "unseen"] + [j["criterion"] for j in judges if j["criterion"] in rows[0]] + ["seconds"],
                           fmt=_fmt), ""]
    write_report(out, STEMS[proxy], text)
    return 0


if __name__ == "__main__":
    main()
