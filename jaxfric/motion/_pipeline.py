"""The default search of [`jaxfric.identify_motion`][jaxfric.motion.identify_motion]: global, then shooting, then free run (§13.2).

A free-run position error over a long closed-loop record is a hard cost to search: the
plant integrates twice, so a small force error early moves every later sample, and
the cost is flat in some directions and steep and many-valleyed in others. The
default pipeline therefore grows the simulation horizon:

1. **global** — a small [`jaxfric.optim.PSO`][jaxfric.optim.PSO] swarm on short windows spread over
   the training records (`GLOBAL_SAMPLES` samples in all, windows of
   ``lead + global_window`` samples, each started from the measurement and with its
   friction state carried along the measured velocity over the ``lead`` samples,
   `._shooting`). It only has to find the basin;
2. **shooting** — Levenberg–Marquardt (`._lm`) on the whole training data cut
   into segments, each started from the measurement (multiple shooting). ``horizons``
   lists the segment lengths of successive stages (default one stage of 5 000 samples,
   5 s at 1 kHz); a list of growing lengths gives a coarse-to-fine schedule, ``None`` is
   the free run of each whole training record. Within a segment the errors accumulate as
   in a free run of that length; across segments they do not, which keeps the cost
   smooth enough for a gradient method;
3. **free run** — the physical models' default ends with Levenberg–Marquardt on the
   free run of each whole training record (``horizons=(5000, None)``), the cost the fit
   is judged by: shooting alone stopped at points whose training free run differed by up
   to 2x with the key;
4. **several starts** — stages 2–3 run from ``starts`` points: the swarm's best
   distinct personal bests, and the deterministic starts the caller adds (the
   least-squares Coulomb + viscous + offset solution, `._baseline`); the start whose
   final cost is lowest wins, and ``polish`` more free-run steps continue from it
   (``benchmarks/results/motion_keys.md``).

Measured on the EMPS estimation split (80 % trains, ``benchmarks/motion.py``): the
earlier default (MAPSO for 200 generations, then up to 200·n Nelder–Mead evaluations of
the free run) took 87 s (LuGre) and 136 s (GMS) per model; this pipeline took 8–25 s
per model, compilation included, on a busier machine
(``benchmarks/results/motion_timing.md``), with a lower held-back error for every
physical model (``benchmarks/results/motion.md``).

The budget ([`MotionBudget`][jaxfric.motion.MotionBudget]) is checked between the stages and after every
Levenberg–Marquardt step, so a run stops with the best point so far.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..models import GreyBox
from ..optim import PSO, minimise
from ..optim.progress import step_progress
from ._lm import levenberg_marquardt

__all__ = ["MotionBudget", "MotionSearch", "default_search"]

#: Samples the global stage simulates per candidate (short windows spread over the data).
GLOBAL_SAMPLES = 4000


class MotionSearch(eqx.Module):
    """Settings of [`jaxfric.identify_motion`][jaxfric.motion.identify_motion]'s default search (module docstring).

    Args:
        particles, generations: the global PSO stage (``particles·(generations + 1)``
            evaluations of the window cost).
        global_window: samples simulated per window in the global stage.
        lead: forced samples before every window or segment start (the friction state is
            carried along the measured velocity over them; they carry no error).
        horizons: multiple-shooting segment lengths [samples] of the Levenberg–Marquardt
            stages, in order (``None``: free run of each whole record).
        steps: Levenberg–Marquardt step cap of each of ``horizons``.
        rtol: a stage ends when ``3`` accepted steps in a row lower its cost by less than
            ``rtol`` relative.
        starts: how many of the swarm's distinct personal bests (best first) the
            Levenberg–Marquardt stages polish, each in turn; the lowest final cost wins.
            The deterministic starts of the caller come on top of these.
        least_squares_start: add the least-squares Coulomb + viscous + offset solution
            mapped into the model (`._baseline`) as a start (physical models).
        polish: Levenberg–Marquardt steps of a last stage on the free run of the whole
            training records, from the winning start only (0: none).
    """

    particles: int = eqx.field(default=25, static=True)
    generations: int = eqx.field(default=20, static=True)
    global_window: int = eqx.field(default=200, static=True)
    lead: int = eqx.field(default=20, static=True)
    horizons: tuple = eqx.field(default=(5000,), static=True)
    steps: tuple = eqx.field(default=(60,), static=True)
    rtol: float = eqx.field(default=1e-4, static=True)
    starts: int = eqx.field(default=1, static=True)
    least_squares_start: bool = eqx.field(default=False, static=True)
    polish: int = eqx.field(default=0, static=True)

    def check(self) -> None:
        for name, least in (("particles", 2), ("generations", 1), ("global_window", 2), ("starts", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < least:
                raise ValueError(f"MotionSearch.{name} must be an integer >= {least}, got {value!r}")
        if isinstance(self.lead, bool) or not isinstance(self.lead, int) or self.lead < 0:
            raise ValueError(f"MotionSearch.lead must be a non-negative integer, got {self.lead!r}")
        if not isinstance(self.horizons, tuple) or not isinstance(self.steps, tuple) \
                or len(self.horizons) != len(self.steps):
            raise ValueError(f"MotionSearch.horizons and .steps must be tuples of one length, got "
                             f"{self.horizons!r} and {self.steps!r}")
        for h in self.horizons:
            if h is not None and (isinstance(h, bool) or not isinstance(h, int) or h < 2):
                raise ValueError(f"MotionSearch.horizons entries must be None or integers >= 2, got {h!r}")
        for k in (*self.steps, self.polish):
            if isinstance(k, bool) or not isinstance(k, int) or k < 0:
                raise ValueError(f"MotionSearch.steps entries must be non-negative integers, got {k!r}")
        if not (isinstance(self.rtol, (int, float)) and self.rtol >= 0):
            raise ValueError(f"MotionSearch.rtol must be >= 0, got {self.rtol!r}")
        if self.starts > self.particles:
            raise ValueError(f"MotionSearch.starts ({self.starts}) cannot exceed particles ({self.particles})")


#: Above this many search parameters (the networks) `default_search` grows the
#: horizon: 60 steps on 1 000-sample segments, then 150 on 5 000.
NETWORK_PARAMS = 20


def default_search(model) -> MotionSearch:
    """The default [`MotionSearch`][jaxfric.motion.MotionSearch] for ``model``.

    Physical models (a dozen parameters at most): Levenberg–Marquardt on 5 000-sample
    segments (at most 60 steps), then on the free run of each whole training record (at
    most 100 steps), from 3 of the swarm's personal bests and the least-squares start; the
    lowest training free-run cost wins and up to 200 more free-run steps polish it
    (``benchmarks/results/motion_keys.md``). Networks (more than `NETWORK_PARAMS`
    parameters, e.g. ``Elman(neurons=10)``, 60): the swarm cannot place 60 weights, so the
    gradient stages do the work, coarse to fine: 60 steps on 1 000-sample segments, then 150
    on 5 000. On the EMPS estimation split this took the Elman(10) network's held-back error
    from 15.3 mm (the physical models' schedule, converged at a poor point) to 3.1 mm
    (``benchmarks/results/motion.md``). A [`jaxfric.models.GreyBox`][jaxfric.models.GreyBox] is
    not searched from a swarm: [`jaxfric.identify_motion`][jaxfric.motion.identify_motion] fits its
    physical model first and starts from that fit with the correction off; then 60 steps on
    5 000-sample segments, 100 on the free run and a 100-step polish.
    """
    if isinstance(model, GreyBox):  # starts from its physical model's fit: no swarm, free run last
        return MotionSearch(horizons=(5000, None), steps=(60, 100), polish=100)
    if model.num_params > NETWORK_PARAMS:
        return MotionSearch(horizons=(1000, 5000), steps=(60, 150))
    return MotionSearch(horizons=(5000, None), steps=(60, 100), starts=3, least_squares_start=True, polish=200)


@dataclasses.dataclass
class MotionBudget:
    """``max_evals``: most cost evaluations in all (a PSO candidate or a residual pass
    counts 1, a Jacobian ``1 + n``); ``max_time``: most wall seconds from the start of the
    search. ``None`` = no limit. The global stage is one compiled call: its generations
    are cut to fit ``max_evals``, and ``max_time`` is checked before and after it."""

    max_evals: int | None = None
    max_time: float | None = None

    def check(self) -> None:
        if self.max_evals is not None and (isinstance(self.max_evals, bool)
                                           or not isinstance(self.max_evals, numbers.Integral)
                                           or self.max_evals < 1):
            raise ValueError(f"max_evals must be None or a positive integer, got {self.max_evals!r}")
        if self.max_time is not None and not (isinstance(self.max_time, numbers.Real)
                                              and not isinstance(self.max_time, bool)
                                              and math.isfinite(self.max_time) and self.max_time > 0):
            raise ValueError(f"max_time must be None or a positive number of seconds, got {self.max_time!r}")


def _lm_progress(progress, desc, total):
    """``(on_step, close)`` for one Levenberg–Marquardt stage."""
    return step_progress(progress, desc, total)


class _Clock:
    def __init__(self, budget: MotionBudget):
        self.t0 = time.perf_counter()
        self.budget = budget
        self.evals = 0
        self.stopped = None

    @property
    def deadline(self):
        return None if self.budget.max_time is None else self.t0 + float(self.budget.max_time)

    def left(self):
        return None if self.budget.max_evals is None else self.budget.max_evals - self.evals

    def out_of_time(self) -> bool:
        return self.deadline is not None and time.perf_counter() >= self.deadline


def distinct_starts(points, values, count: int, lower, upper, *, tol: float = 1e-3) -> list:
    """Up to ``count`` rows of ``points`` in order of ``values`` (lowest first, non-finite
    values never), each farther than ``tol`` of the box width (max-norm) from those kept."""
    points = np.asarray(points, np.float64)
    values = np.asarray(values, np.float64)
    width = np.maximum(np.asarray(upper, np.float64) - np.asarray(lower, np.float64), 1e-300)
    kept = []
    for i in np.argsort(np.where(np.isfinite(values), values, np.inf), kind="stable"):
        if len(kept) == count or not np.isfinite(values[i]):
            break
        if all(np.max(np.abs(points[i] - k) / width) > tol for k in kept):
            kept.append(points[i])
    return kept


def run_search(search: MotionSearch, budget: MotionBudget, residuals, total_cost, lower, upper, *,
               global_data, stage_data, key, dtype, progress=None, y0=None, extra_starts=()):
    """Run the stages (module docstring; ``stage_data(horizon)``: the cost's data for one
    horizon) and return ``(y, stages, stopped)``: the best search vector, one dict per stage
    (``stage``, ``start``, ``J``, ``num_evals``, ``num_steps``, ``seconds``, ``reason``) and
    why the budget ended the run (``None`` when it did not).

    Starts: ``y0`` alone when given; otherwise ``search.starts`` distinct personal bests of
    the swarm, then ``extra_starts`` (clipped into the box). Each start runs every
    Levenberg–Marquardt stage; the one whose last stage ends lowest is returned."""
    clock = _Clock(budget)
    stages = []
    lower = np.asarray(lower, np.float64)
    upper = np.asarray(upper, np.float64)
    gens = search.generations
    left = clock.left()
    if left is not None:
        gens = min(gens, left // search.particles - 1)
    if y0 is None and gens < 1:
        raise ValueError(f"max_evals={budget.max_evals} leaves no room for the global stage: it needs "
                         f"at least 2 x {search.particles} evaluations (a population and one generation)")
    if y0 is not None:
        starts = [np.asarray(y0, np.float64)]
    else:
        t = time.perf_counter()
        solver = PSO(num_particles=search.particles, num_generations=gens)
        sol = minimise(total_cost, solver, (lower, upper), args=global_data, key=key, dtype=dtype,
                       progress=progress)
        best = np.asarray(jax.block_until_ready(sol.value), np.float64)
        n_ev = int(sol.stats["num_evals"])
        clock.evals += n_ev
        stages.append({"stage": "pso", "start": None, "J": float(sol.f), "num_evals": n_ev,
                       "num_steps": gens, "seconds": time.perf_counter() - t, "reason": "done"})
        starts = [best]
        if search.starts > 1:
            X, f = solver.personal_bests(sol.state)
            starts = distinct_starts(np.vstack([best, np.asarray(X)]),
                                     np.concatenate([[float(sol.f)], np.asarray(f, np.float64)]),
                                     search.starts, lower, upper) or [best]
        starts += [np.clip(np.asarray(y, np.float64), lower, upper) for y in extra_starts]
    plan = [(("free_run" if h is None else f"shooting_{h}"), stage_data(h), k)
            for h, k in zip(search.horizons, search.steps) if k > 0]
    y_best, f_best = starts[0], np.inf
    for index, y in enumerate(starts):
        f_end = np.inf
        for name, data, steps in plan:
            if clock.out_of_time():
                clock.stopped = "max_time"
                break
            left = clock.left()
            if left is not None and left < 2 + y.size:
                clock.stopped = "max_evals"
                break
            label = name if len(starts) == 1 else f"{name} (start {index + 1}/{len(starts)})"
            on_step, close = _lm_progress(progress, f"{label} (Levenberg-Marquardt)", steps)
            t = time.perf_counter()
            try:
                out = levenberg_marquardt(residuals, jnp.asarray(y, dtype), jnp.asarray(lower, dtype),
                                          jnp.asarray(upper, dtype), data, max_steps=steps, rtol=search.rtol,
                                          deadline=clock.deadline, max_evals=left, on_step=on_step)
            finally:
                close()
            clock.evals += out.evals
            f_end = out.f
            if np.isfinite(out.f):
                y = out.theta
            stages.append({"stage": name, "start": index, "J": out.f, "num_evals": out.evals,
                           "num_steps": out.steps, "seconds": time.perf_counter() - t, "reason": out.reason})
            if out.reason in ("max_time", "max_evals"):
                clock.stopped = out.reason
                break
        # a start the budget cut short ended on another stage's cost: it wins only when
        # no start finished
        finished = clock.stopped is None
        if index == 0 or (finished and f_end < f_best):
            y_best, f_best = y, (f_end if finished else np.inf)
        if clock.stopped is not None:
            break
    if search.polish and clock.stopped is None and not clock.out_of_time():
        left = clock.left()
        if left is None or left >= 2 + y_best.size:
            on_step, close = _lm_progress(progress, "polish, free run (Levenberg-Marquardt)", search.polish)
            t = time.perf_counter()
            try:
                out = levenberg_marquardt(residuals, jnp.asarray(y_best, dtype), jnp.asarray(lower, dtype),
                                          jnp.asarray(upper, dtype), stage_data(None), max_steps=search.polish,
                                          rtol=search.rtol, deadline=clock.deadline, max_evals=left,
                                          on_step=on_step)
            finally:
                close()
            clock.evals += out.evals
            if np.isfinite(out.f) and out.f <= f_best:
                y_best = out.theta
            stages.append({"stage": "polish", "start": None, "J": out.f, "num_evals": out.evals,
                           "num_steps": out.steps, "seconds": time.perf_counter() - t, "reason": out.reason})
            if out.reason in ("max_time", "max_evals"):
                clock.stopped = out.reason
    return y_best, stages, clock.stopped
