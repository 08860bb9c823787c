"""Model choice by a judge of new motion: several friction models inside the mechanics, ranked (§13.2).

A richer friction model always fits its training data at least as well as a simpler
one it contains; what decides between them is the error on motion they were not
fitted on. [`compare_motion`][jaxfric.motion.compare_motion] fits every model with the same data, key and options,
ranks them by a judge, and warns ([`OverfitWarning`][jaxfric.motion.OverfitWarning]) when a model with more search
parameters is judged worse than one with fewer.

The default judge, ``"gated"``, scores many short free runs over the records, each started
from its own first 20 samples (`short_runs_score`), for the models whose blocked
cross-validation of the training part beats the least-squares baseline's (`gated_scores`);
the others are not chosen over the baseline. The gate alone decides between the models and
the baseline (both sides of it are out of sample); the short runs rank the models that pass.
On the proxies of ``benchmarks/motion_judge.py`` its choice was within 10 % of the best on the
unseen excitation more often than every other criterion's (measured: docs/motion.md,
"Choosing a model"; ``benchmarks/results/motion_judge*.md``): the tail of one record shares
its excitation, one long free run measures drift more than dynamics, and short windows alone
do not see where least squares predicts new motion best.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._warnings import BaselineWarning, ExtrapolationWarning, NarrowGateWarning
from ..records import SAMPLE_TIME_RTOL, same_sample_time
from ._api import (DEFAULT_INIT_WINDOW, _as_motion_data, _init_window, _split, baseline_motion_fit,
                   identify_motion, motion_metrics)
from ._baseline import BASELINE_LABEL
from ._forward import simulate_motion

__all__ = ["MotionComparison", "OverfitWarning", "compare_motion", "short_runs_score"]


class OverfitWarning(UserWarning):
    """A model with more parameters is worse on validation than a simpler one."""


#: Under the gated judge a chosen model whose blocked cross-validation beats least squares'
#: by less than this share (1 − blocked / least squares' blocked) passes *narrowly*, and
#: ``choice`` says so (`NarrowGateWarning`). ``NARROW_COUNTS``: the judge's proxy picks that
#: passed narrowly / widely, and how many of them predicted the unseen excitation worse than
#: least squares (the warning quotes them; measured: docs/motion.md, "A narrow pass is said").
NARROW_GATE = 0.05
NARROW_COUNTS = {"narrow": (16, 7), "wide": (62, 8)}  # (picks, worse than least squares)


@dataclasses.dataclass
class MotionComparison:
    """Fits of [`compare_motion`][jaxfric.motion.compare_motion]. ``fits``: name -> [`MotionFit`][jaxfric.motion.MotionFit] in the order
    given; ``ranking``: names from the lowest judge's score (``scores``; the validation RMSE
    for ``judge="tail"``); ``overfit``: ``(richer,
    simpler)`` pairs where the richer model validates worse; ``blocked`` and
    ``baseline_blocked``: the blocked cross-validation scores [mm] of the models and of the
    baseline under ``judge="gated"`` or ``"blocked"`` (empty and ``None`` otherwise)."""

    fits: dict
    ranking: list
    overfit: list
    judge: str = "tail"
    scores: dict = dataclasses.field(default_factory=dict)
    baseline_score: float | None = None
    blocked: dict = dataclasses.field(default_factory=dict)
    baseline_blocked: float | None = None

    @property
    def best(self):
        """The model the judge ranks first (a model, even where the baseline scores lower:
        see [`choice`][jaxfric.motion.MotionComparison.choice])."""
        return self.fits[self.ranking[0]]

    @property
    def choice_name(self) -> str:
        """The label of [`choice`][jaxfric.motion.MotionComparison.choice]: the first-ranked
        model's, or ``BASELINE_LABEL`` where the baseline scores lower under the same judge;
        under ``"gated"``, where no model passes the gate (every score inf), whatever the
        baseline's short score: a model whose blocked folds beat least squares' is chosen over it."""
        base, name = self._baseline_score(), self.ranking[0]
        if self.judge == "gated":
            return name if math.isfinite(self._score(name)) else BASELINE_LABEL
        return BASELINE_LABEL if base is not None and base < self._score(name) else name

    @property
    def choice(self):
        """The judge's pick among the models *and* the least-squares baseline, the pick
        benchmarks/motion_judge.py measures: [`best`][jaxfric.motion.MotionComparison.best],
        unless the baseline's score under the same judge is lower than every model's; then
        the baseline as a [`MotionFit`][jaxfric.motion.MotionFit] of its own (`baseline_fit`),
        with a ``BaselineWarning`` giving both scores."""
        if self.choice_name != BASELINE_LABEL:
            if self.passes_narrowly:
                margin = self.gate_margin
                (n, worse), (m, worse_wide) = NARROW_COUNTS["narrow"], NARROW_COUNTS["wide"]
                warnings.warn(
                    f"{self.choice_name} passes the gate narrowly: its blocked cross-validation "
                    f"({self.blocked[self.choice_name]:.4g} mm) beats least squares' "
                    f"({self.baseline_blocked:.4g} mm) by {100 * margin:.1f} %, under "
                    f"{100 * NARROW_GATE:.0f} %. On the judge's proxies {worse} of {n} such picks "
                    f"predicted new motion worse than least squares ({worse_wide} of {m} wider "
                    "passes): check it against `baseline_fit(comparison.best)` on motion it was "
                    "not fitted on", NarrowGateWarning, stacklevel=2)
            return self.best
        name = self.ranking[0]
        why = (f"{self._baseline_score():.4g} mm against {name}'s {self._score(name):.4g} mm" if
               math.isfinite(self._score(name)) else
               f"no model's blocked cross-validation beats least squares', {self.baseline_blocked:.4g} mm")
        warnings.warn(f"no model beats the least-squares baseline under the {self.judge!r} judge ({why}): "
                      "the choice is the baseline", BaselineWarning, stacklevel=2)
        return baseline_fit(self.best)

    @property
    def gate_margin(self) -> float | None:
        """How far the chosen model passes the gated judge's gate: ``1 − blocked /
        baseline_blocked`` (0.1: its blocked cross-validation is 10 % under least squares');
        ``None`` under another judge or where the choice is the baseline. Under
        `NARROW_GATE` the choice passes narrowly (see [`choice`][jaxfric.motion.MotionComparison.choice])."""
        if self.judge != "gated" or not self.baseline_blocked or self.choice_name == BASELINE_LABEL:
            return None
        return 1.0 - self.blocked[self.choice_name] / self.baseline_blocked

    @property
    def passes_narrowly(self) -> bool:
        """The chosen model passes the gated judge's gate by less than `NARROW_GATE`
        ([`gate_margin`][jaxfric.motion.MotionComparison.gate_margin]): ``choice`` warns, the
        table and the command line say so."""
        margin = self.gate_margin
        return margin is not None and margin < NARROW_GATE

    def _score(self, name) -> float:
        return self.scores.get(name, self.fits[name].metrics["valid"]["rmse_mm"])

    def _baseline_score(self) -> float | None:
        base = self.baseline
        if base is None:
            return None
        return base["valid"]["rmse_mm"] if self.baseline_score is None else self.baseline_score

    @property
    def baseline(self) -> dict | None:
        """The least-squares Coulomb + viscous + offset baseline's metrics on the same data
        and judge (``{"train": ..., "valid": ...}``, [`jaxfric.motion.motion_metrics`][jaxfric.motion.motion_metrics]);
        ``None`` for fits made without it (built by hand)."""
        return next(iter(self.fits.values())).metrics.get("baseline")

    def rows(self) -> list[dict]:
        """One dict per ranked fit, then the baseline: ``rank`` (``None`` for the
        baseline), ``model``, ``parameters``, ``mass_kg``, ``offset_N``, ``train_rmse_mm``,
        ``valid_rmse_mm``, ``valid_fit_percent``, ``judge_rmse_mm``, ``beats_baseline`` (under
        the judge; under ``"gated"``: passes the gate), ``worse_than_simpler``; with blocked
        scores also ``blocked_rmse_mm``."""
        base, base_score = self.baseline, self._baseline_score()
        out = []
        for i, name in enumerate(self.ranking, 1):
            fit = self.fits[name]
            m = fit.metrics
            score = self._score(name)
            out.append({"rank": i, "model": name, "parameters": m["num_params"], "mass_kg": fit.mass,
                        "offset_N": fit.offset, "train_rmse_mm": m["train"]["rmse_mm"],
                        "valid_rmse_mm": m["valid"]["rmse_mm"], "valid_fit_percent": m["valid"]["fit_percent"],
                        "judge_rmse_mm": score,
                        "beats_baseline": None if base is None else bool(
                            math.isfinite(score) if self.judge == "gated" else score < base_score),
                        "worse_than_simpler": any(r == name for r, _ in self.overfit),
                        **({"blocked_rmse_mm": self.blocked[name]} if self.blocked else {})})
        if base is None:
            return out
        settings = next(iter(self.fits.values())).mechanics.baseline
        out.append({"rank": None, "model": BASELINE_LABEL, "parameters": 4, "mass_kg": settings["M"],
                    "offset_N": settings["offset"], "train_rmse_mm": base["train"]["rmse_mm"],
                    "valid_rmse_mm": base["valid"]["rmse_mm"], "valid_fit_percent": base["valid"]["fit_percent"],
                    "judge_rmse_mm": base_score, "beats_baseline": None, "worse_than_simpler": False,
                    **({"blocked_rmse_mm": self.baseline_blocked} if self.blocked else {})})
        return out

    def table(self) -> str:
        """A Markdown table of [`rows`][jaxfric.motion.MotionComparison.rows]: rank, model, parameters, mass, offset, train and
        validation free-run RMSE [mm], validation FIT %; the baseline as the last row."""
        judged = self.judge != "tail"
        lines = ["| rank | model | parameters | mass [kg] | offset [N] | train RMSE [mm] | valid RMSE [mm] "
                 "| valid FIT % |" + (f" {self.judge} RMSE [mm] |" if judged else ""),
                 "|---|---|---|---|---|---|---|---|" + ("---|" if judged else "")]
        for r in self.rows():
            flags = []
            if r["worse_than_simpler"]:
                flags.append("worse than a simpler model")
            if self.judge == "gated" and r["rank"] is not None and not math.isfinite(r["judge_rmse_mm"]):
                flags.append(f"gated out: blocked {r['blocked_rmse_mm']:.4g} mm, least squares' "
                             f"{self.baseline_blocked:.4g}")
            elif r["beats_baseline"] is False:
                flags.append("not better than the baseline")
            elif r["model"] == self.choice_name and self.passes_narrowly:
                flags.append(f"passes narrowly: blocked {100 * self.gate_margin:.1f} % under least squares'")
            name = r["model"] + (f" ({'; '.join(flags)})" if flags else "")
            lines.append(f"| {'' if r['rank'] is None else r['rank']} | {name} | {r['parameters']} | "
                         f"{r['mass_kg']:.4g} | {r['offset_N']:.4g} | {r['train_rmse_mm']:.4g} | "
                         f"{r['valid_rmse_mm']:.4g} | {r['valid_fit_percent']:.2f} |"
                         + (f" {r['judge_rmse_mm']:.4g} |" if judged else ""))
        return "\n".join(lines)


def _valid_rmse(fit) -> float:
    m = fit.metrics.get("valid")
    if not m:
        raise ValueError("compare_motion ranks by validation error: hold a block back (train < 1) "
                         "or pass valid=[records...]")
    return float(m["rmse_mm"])


#: A richer model counts as worse on validation when its RMSE exceeds the simpler one's
#: by more than this fraction (equal models differ in the last bits only).
OVERFIT_MARGIN = 1e-3


def rank_fits(fits: dict, *, stacklevel: int = 2, scores: dict | None = None, judge: str = "tail",
              baseline_score: float | None = None, blocked: dict | None = None,
              baseline_blocked: float | None = None) -> MotionComparison:
    """Rank named motion fits by validation RMSE (or by the judge's ``scores``, name -> mm)
    and warn about overfitting (module docstring): a model with more search parameters
    (``metrics["num_params"]``) whose score exceeds a simpler one's by more than
    `OVERFIT_MARGIN`. ``blocked``/``baseline_blocked``: blocked cross-validation scores
    kept on the comparison (``judge="gated"`` or ``"blocked"``)."""
    judged = scores is not None
    scores = dict(scores) if judged else {name: _valid_rmse(fit) for name, fit in fits.items()}
    ranking = sorted(fits, key=lambda k: (scores[k], k))
    overfit = []
    for rich, fr in fits.items():
        for simple, fs in fits.items():
            if fr.metrics["num_params"] > fs.metrics["num_params"] and \
                    scores[rich] > (1.0 + OVERFIT_MARGIN) * scores[simple]:
                overfit.append((rich, simple))
    worse = "predicts the validation data worse" if judge == "tail" else f"is judged worse ({judge!r} judge)"
    for rich, simple in overfit:
        why = (f"{scores[rich]:.4g} mm against {scores[simple]:.4g} mm free-run RMSE" if math.isfinite(scores[rich])
               else "its blocked cross-validation does not beat the least-squares baseline's (the gate), "
                    f"{simple}'s scores {scores[simple]:.4g} mm")
        warnings.warn(
            f"{rich} ({fits[rich].metrics['num_params']} parameters) {worse} "
            f"than {simple} ({fits[simple].metrics['num_params']}): {why}; prefer the simpler model unless it "
            "fails elsewhere", OverfitWarning, stacklevel=stacklevel + 1)
    return MotionComparison(dict(fits), ranking, overfit, judge, scores if judged else {}, baseline_score,
                            dict(blocked or {}), baseline_blocked)


JUDGES = ("tail", "blocked", "short", "gated")
#: Seconds per window of the ``"short"`` judge (`short_runs_score`): 256 samples at the rig
#: proxy's 128 Hz (benchmarks/results/motion_judge.md; on EMPS: docs/motion.md).
SHORT_WINDOW_S = 2.0


def short_window(dt: float, window=None, init_window: int = DEFAULT_INIT_WINDOW) -> int:
    """Samples per window of the short judge: ``window`` when given (an integer
    ``>= init_window + 2``), else `SHORT_WINDOW_S` seconds at sample time ``dt``."""
    if window is None:
        return max(int(init_window) + 2, int(round(SHORT_WINDOW_S / float(dt))))
    if isinstance(window, bool) or not isinstance(window, numbers.Integral) or \
            not isinstance(init_window, numbers.Integral) or window < init_window + 2:
        raise ValueError(f"window must be an integer >= init_window + 2 = {init_window + 2}, got {window!r}")
    return int(window)


def _pooled_rmse(metrics) -> float:
    """RMSE [mm] of several windows pooled: sqrt(sum n_i rmse_i^2 / sum n_i)."""
    n = sum(m["n"] for m in metrics)
    return math.sqrt(sum(m["n"] * m["rmse_mm"] ** 2 for m in metrics) / n)


def blocked_score(model, records, folds: int, *, key, mass, init_window=DEFAULT_INIT_WINDOW, **kwargs):
    """Blocked cross-validation of ``model`` on ``records`` (the training part): they are
    joined end to end only in name; each is cut into ``folds`` contiguous blocks, and for each
    fold one fit trains on every other block (each block a record of its own, simulated from
    its first sample) and is scored on the held-out blocks, each simulated from its own first
    ``init_window`` samples (the benchmark protocol). Returns ``(score, baseline score)``:
    the pooled free-run RMSE [mm] of the model and of the least-squares baseline."""
    blocks = []
    for r in records:
        edges = [round(i * r.n_samples / folds) for i in range(folds + 1)]
        blocks.append([r.window(a, b) for a, b in zip(edges[:-1], edges[1:])])
    model_m, base_m = [], []
    for f in range(folds):
        train = [b for rec in blocks for i, b in enumerate(rec) if i != f]
        valid = [rec[f] for rec in blocks]
        with warnings.catch_warnings():  # a fold's range is not the compared fit's: its warnings would mislead
            warnings.simplefilter("ignore", ExtrapolationWarning)
            fit = identify_motion(model, train=train, valid=valid, key=key, mass=mass, init_window=init_window,
                                  **kwargs)
        model_m += [{**m, "n": v.n_samples - init_window} for m, v in zip(fit.metrics["records"]["valid"], valid)]
        base_m.append({"rmse_mm": fit.metrics["baseline"]["valid"]["rmse_mm"],
                       "n": sum(v.n_samples - init_window for v in valid)})
    return _pooled_rmse(model_m), _pooled_rmse(base_m)


@eqx.filter_jit
def _window_runs(step, theta, mass, force, dt, x0, v0, state0):
    """Free-run positions of K equal windows in one compiled call: `simulate_motion`
    vmapped over ``force`` ``(K, T)``, ``x0``, ``v0`` ``(K,)`` and the friction states
    (leading axis K). Returns ``(K, T)``."""
    def run(f, x, v, s):
        return simulate_motion(step, theta, mass, f, dt, x, v, s)["x"]

    return jax.vmap(run)(force, x0, v0, state0)


def window_scores(fit, records, window: int, init_window: int = DEFAULT_INIT_WINDOW) -> list[dict]:
    """[`MotionFit.score`][jaxfric.motion.MotionFit.score] of every window of ``window``
    samples of ``records`` (consecutive, a shorter rest at the end dropped), in order: the
    same initial-state rule ([`MotionFit.initial_state`][jaxfric.motion.MotionFit.initial_state]
    on each window's first ``init_window`` positions) and the same free run
    (`simulate_motion`, §13.2, from sample ``init_window - 1``), all windows in one
    vmapped, compiled call instead of one call per window. Each entry is
    [`motion_metrics`][jaxfric.motion.motion_metrics] of samples ``init_window`` onward plus
    ``"n"``, the samples scored."""
    n = _init_window(init_window)
    if window <= n:
        raise ValueError(f"init_window={n} leaves nothing to simulate in a window of {window} samples")
    heads, forces, targets = [], [], []
    for r in records:
        r = _as_motion_data(r)
        if not same_sample_time(r.dt, fit.dt):
            raise ValueError(f"the record's sample time {r.dt} s differs from the fit's {fit.dt} s "
                             f"by more than {SAMPLE_TIME_RTOL:g} relative: resample it to the fit's rate")
        force = r.net_force - fit.offset
        for a in range(0, r.n_samples - window + 1, window):
            heads.append(fit.initial_state(r.position[a:a + n], n))
            forces.append(force[a + n - 1:a + window])
            targets.append(r.position[a + n:a + window])
    if not heads:
        return []
    theta = jnp.asarray(fit.theta)
    x_hat = _window_runs(fit.friction_step(), theta, jnp.asarray(fit.mass, theta.dtype), jnp.asarray(np.stack(forces), theta.dtype),
                         jnp.asarray(fit.dt, theta.dtype), jnp.asarray([h["x0"] for h in heads], theta.dtype),
                         jnp.asarray([h["v0"] for h in heads], theta.dtype),
                         jax.tree_util.tree_map(lambda *s: jnp.stack(s), *[h["state0"] for h in heads]))
    x_hat = np.asarray(x_hat, np.float64)[:, 1:]  # the run starts at sample n - 1; scored from n
    return [{**motion_metrics(x, xh), "n": window - n} for x, xh in zip(targets, x_hat)]


def short_runs_score(fit, records, window: int | None = None, init_window: int = DEFAULT_INIT_WINDOW) -> float:
    """Many short free runs of ``fit`` over ``records``: each record cut into consecutive
    windows of ``window`` samples (a shorter rest at the end dropped), each window simulated
    from its own first ``init_window`` samples ([`MotionFit.score`][jaxfric.motion.MotionFit.score]) and scored on
    the rest. Returns the pooled free-run RMSE [mm], ``sqrt(sum_w n_w rmse_w^2 / sum_w n_w)``
    (inf when a window diverges). No refit: it measures how the fitted dynamics carry a
    state over a short horizon, across every kind of motion the records hold, without the
    drift of one long free run.

    All windows run in one vmapped, compiled free run (`window_scores`), equal to a loop of
    ``fit.score`` calls (1e-9 relative in float64, tests/test_motion_judge.py) for a fit
    whose free run is well conditioned (a chaotic one amplifies the two programs' rounding
    differences; its measurements and timings: docs/motion.md, "Choosing a model").
    """
    window, init_window = short_window(records[0].dt, window, init_window), int(init_window)
    metrics = window_scores(fit, records, window, init_window)
    if not metrics:
        raise ValueError(f"no record holds a whole window of {window} samples for the short-runs judge")
    if not all(math.isfinite(m["rmse_mm"]) for m in metrics):
        return math.inf
    return _pooled_rmse(metrics)


def short_judge(fits: dict, records, window: int | None = None,
                init_window: int = DEFAULT_INIT_WINDOW) -> tuple[dict, float]:
    """The short judge of named fits and of their least-squares baseline (`baseline_fit`
    of the first fit): ``(scores, baseline score)``, each `short_runs_score` over
    ``records`` [mm]."""
    scores = {label: short_runs_score(fit, records, window, init_window) for label, fit in fits.items()}
    return scores, short_runs_score(baseline_fit(next(iter(fits.values()))), records, window, init_window)


def blocked_scores(models: dict, records, folds: int, **options) -> tuple[dict, float]:
    """`blocked_score` of each of ``models`` (label -> model) on ``records``:
    ``({label: mm}, baseline mm)``; the baseline's score depends on the records alone."""
    scores, base = {}, math.inf
    for label, model in models.items():
        scores[label], base = blocked_score(model, records, folds, **options)
    return scores, base


def gated_scores(short: dict, blocked: dict, base_blocked: float) -> dict:
    """The ``"gated"`` judge's scores: each model's short score where its blocked
    cross-validation beats the baseline's (``blocked[name] < base_blocked``), else inf (the
    model is not chosen over the baseline; ``choice`` falls to the baseline when none passes,
    and only then)."""
    return {k: v if blocked[k] < base_blocked else math.inf for k, v in short.items()}


def baseline_fit(fit):
    """The least-squares Coulomb + viscous + offset baseline of ``fit`` (its
    ``mechanics.baseline``: ``M``, ``Fc``, ``Fv``, ``offset``) as a
    [`MotionFit`][jaxfric.motion.MotionFit] of its own ([`baseline_motion_fit`][jaxfric.motion.baseline_motion_fit]), to be
    simulated and scored like ``fit``."""
    b = fit.mechanics.baseline
    return baseline_motion_fit(b["M"], b["Fc"], b["Fv"], b["offset"], dt=fit.dt, n_train=fit.n_train)


def _as_records(value) -> list:
    return [_as_motion_data(r) for r in (value.values() if isinstance(value, dict) else
                                         value if isinstance(value, (list, tuple)) else [value])]


def compare_motion(models, data=None, *, key, mass, judge: str = "gated", folds: int = 3,
                   window: int | None = None, keys=None, **kwargs) -> MotionComparison:
    """Fit each of ``models`` (names or instances, or a mapping label -> model) with
    [`identify_motion`][jaxfric.motion.identify_motion] on the same data, key and options, rank them by the
    judge and warn ([`OverfitWarning`][jaxfric.motion.OverfitWarning]) when a model with more search
    parameters is judged worse than one with fewer.

    ``data``/``train``/``valid`` and every other keyword are [`identify_motion`][jaxfric.motion.identify_motion]'s;
    a validation part is required (a held-back block or ``valid=[...]``).

    ``judge``:

    * ``"gated"`` (default): the short score of each model whose blocked cross-validation
      beats the baseline's, inf for the others (`gated_scores`; ``folds`` more fits per model,
      so about ``1 + folds`` times ``"short"``'s time); ``choice`` is the baseline only where no
      model passes: the judge whose choice was within 10 % of the best on unseen excitation
      most often on the proxies of benchmarks/results/ (docs/motion.md, "Choosing a model");
    * ``"short"``: many short free runs (`short_runs_score`): every record
      (``data`` whole, or the ``train`` and ``valid`` records) cut into windows of ``window``
      samples, each simulated from its own first ``init_window`` samples; no refit;
    * ``"tail"`` ranks by the validation part's free-run RMSE (the held-back block, or the
      ``valid`` records);
    * ``"blocked"`` ranks by blocked cross-validation of the training part (`blocked_score`,
      ``folds`` blocks per record, each held-out block simulated from its own first 20
      samples): ``folds`` more fits per model, and every block is scored on motion its fit
      never saw.

    ``keys``: ``K`` members per model ([`identify_motion`][jaxfric.motion.identify_motion]'s ``keys``); each
    model is judged, and predicts, by its member of lowest training error (``fit.member(i)``
    gives the others, ``fit.simulate_ensemble`` their average and band). The blocked folds
    stay one fit each, as measured (docs/motion.md, "Ensembles in the comparison").

    ``window``: samples per window of the short judge (default ``None``: `SHORT_WINDOW_S`
    = 2 s of samples, 256 at 128 Hz, 2 000 at 1 kHz); a shorter rest at the end of a record is
    not scored. The table shows the judge's score beside the validation RMSE, and the
    baseline's under the same judge. benchmarks/results/motion_judge.md measures how often each judge's
    choice predicts new excitation.
    """
    if judge not in JUDGES:
        raise ValueError(f"judge must be one of {JUDGES}, got {judge!r}")
    if isinstance(folds, bool) or not isinstance(folds, numbers.Integral) or folds < 2:
        raise ValueError(f"folds must be an integer >= 2, got {folds!r}")
    init_window = kwargs.get("init_window", DEFAULT_INIT_WINDOW)
    short_window(1.0, window, init_window)  # a bad window fails here, before any fit
    if isinstance(models, str):
        models = [m for m in models.split(",") if m.strip()]
    items = dict(models) if isinstance(models, dict) else {
        (m.strip() if isinstance(m, str) else type(m).__name__): m for m in models}
    if len(items) < 1:
        raise ValueError("compare_motion needs at least one model")
    if data is not None and kwargs.get("train", 0.8) in (1, 1.0):
        raise ValueError("compare_motion ranks by validation error: keep a block back (train < 1)")
    if data is None and kwargs.get("valid") is None:
        raise ValueError("compare_motion ranks by validation error: pass valid=[records...] with train=[...]")
    if judge in ("short", "gated"):  # every record, whole: checked before any fit
        everything = [_as_motion_data(data)] if data is not None else \
            _as_records(kwargs["train"]) + _as_records(kwargs["valid"])
        window = short_window(everything[0].dt, window, init_window)
        if max(r.n_samples for r in everything) < window:
            raise ValueError(f"the short-runs judge needs a record of at least window={window} samples, "
                             f"the longest has {max(r.n_samples for r in everything)}")
    fits = {label: identify_motion(model, data, key=key, mass=mass, keys=keys, **kwargs)
            for label, model in items.items()}
    if judge == "tail":
        return rank_fits(fits, stacklevel=2)
    if judge == "short":
        scores, base = short_judge(fits, everything, window, init_window)
        return rank_fits(fits, stacklevel=2, scores=scores, judge=judge, baseline_score=base)
    if data is not None:
        data = _as_motion_data(data)
        records = [data.window(0, _split(data.n_samples, kwargs.get("train", 0.8)))]
    else:
        records = _as_records(kwargs["train"])
    options = {k: v for k, v in kwargs.items() if k not in ("train", "valid", "metric_horizon")}
    scores, base = blocked_scores(items, records, folds, key=key, mass=mass, **options)
    if judge == "gated":
        short, short_base = short_judge(fits, everything, window, init_window)
        return rank_fits(fits, stacklevel=2, scores=gated_scores(short, scores, base), judge=judge,
                         baseline_score=short_base, blocked=scores, baseline_blocked=base)
    return rank_fits(fits, stacklevel=2, scores=scores, judge=judge, baseline_score=base, blocked=scores,
                     baseline_blocked=base)
