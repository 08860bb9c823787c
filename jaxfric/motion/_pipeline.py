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
   distinct personal bests, ``free_run_starts`` more of the swarm's points ranked by their
   whole free-run cost (`free_run_ranked`: the window cost put a point first whose free
   run drifted), the deterministic starts the caller adds (the least-squares
   Coulomb + viscous + offset solution, `._baseline`) and, when asked for a model with an
   attraction rate (GMS), ``slow_starts`` points of a grid around that solution with soft
   elements and a slow attraction (`._baseline.slow_attraction_grid`, ranked by
   `grid_ranked`), which run the free-run stage only (off by default: they lower GMS's
   training cost and raise its error on new excitation, docs/motion.md); the start whose final cost is
   lowest wins, and ``polish`` more free-run steps continue from it
   (``benchmarks/results/motion_keys.md``);
5. **screening** — ``screen`` rounds around the best point (`screen_free_run`): the
   free-run cost is rough on a small scale, so Levenberg–Marquardt stops in a valley that
   depends on the key; each round draws points around the best one and continues from the
   lowest, keeping its end only if it is lower.

The measurements behind these defaults (spread over keys, timings against the pre-0.9
MAPSO–NMDS default): docs/motion.md, "The default search".

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
from ._residuals import SumOfSquares

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
        screen: rounds of the screening stage after the polish (`screen_free_run`; 0: none):
            each round draws ``screen_size`` points around the best point so far, with the
            Gauss–Newton step of parameter i that raises the free-run cost J by
            ``screen_spread·J`` as its standard deviation (4x wider after a round that
            found nothing lower), evaluates their whole free-run
            costs in one vectorised call, runs at most ``screen_steps``
            Levenberg–Marquardt steps from the lowest and keeps the end point if it is
            lower than the best so far.
        free_run_starts: more starts on top of ``starts``: the swarm's personal bests and
            final positions of lowest whole free-run cost (`free_run_ranked`, one vectorised
            call over ``2·particles`` points), distinct from the other starts. The swarm ranks
            its points by short windows, and a point that is best there can drift on the
            whole record (0: none).
        screen_cycle: after this many rounds in a row that found nothing lower, the
            screen's spread returns to ``screen_spread`` instead of growing 4x again (0, the
            class default: it keeps growing, up to a quarter of the box; `default_search` uses
            4 for physical models; why: docs/motion.md).
        slow_starts: more starts for models with an attraction rate (GMS): the ``slow_starts``
            lowest, by their whole free-run cost (one vectorised call), of the 27 variants of
            the least-squares start with soft elements and a slow attraction
            (`._baseline.slow_attraction_grid`), distinct from each other; each runs only the
            free-run stages of ``horizons`` (the shooting segments pull a point out of that
            basin). 0 (the default, also `default_search`'s): none; they lower GMS's training
            free run and raise its error on excitation it never saw (measured: docs/motion.md,
            "Deeper on training, worse on new motion"). The grid is empty for a model without
            an attraction rate.
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
    screen: int = eqx.field(default=0, static=True)
    screen_size: int = eqx.field(default=64, static=True)
    screen_steps: int = eqx.field(default=40, static=True)
    screen_spread: float = eqx.field(default=0.1, static=True)
    free_run_starts: int = eqx.field(default=0, static=True)
    screen_cycle: int = eqx.field(default=0, static=True)
    slow_starts: int = eqx.field(default=0, static=True)

    def check(self) -> None:
        for name, least in (("particles", 2), ("generations", 1), ("global_window", 2), ("starts", 1)):
            if not _is_count(getattr(self, name), least):
                raise ValueError(f"MotionSearch.{name} must be an integer >= {least}, got {getattr(self, name)!r}")
        if not _is_count(self.lead, 0):
            raise ValueError(f"MotionSearch.lead must be a non-negative integer, got {self.lead!r}")
        if not isinstance(self.horizons, tuple) or not isinstance(self.steps, tuple) \
                or len(self.horizons) != len(self.steps):
            raise ValueError(f"MotionSearch.horizons and .steps must be tuples of one length, got "
                             f"{self.horizons!r} and {self.steps!r}")
        for h in self.horizons:
            if h is not None and not _is_count(h, 2):
                raise ValueError(f"MotionSearch.horizons entries must be None or integers >= 2, got {h!r}")
        for name, least in (("screen_size", 2), ("screen_steps", 1)):
            if not _is_count(getattr(self, name), least):
                raise ValueError(f"MotionSearch.{name} must be an integer >= {least}, got {getattr(self, name)!r}")
        if not (isinstance(self.screen_spread, (int, float)) and not isinstance(self.screen_spread, bool)
                and math.isfinite(self.screen_spread) and self.screen_spread > 0):
            raise ValueError(f"MotionSearch.screen_spread must be a positive number, got {self.screen_spread!r}")
        for k in (*self.steps, self.polish, self.screen):
            if not _is_count(k, 0):
                raise ValueError(f"MotionSearch.steps, .polish and .screen must be non-negative integers, got {k!r}")
        if not (isinstance(self.rtol, (int, float)) and self.rtol >= 0):
            raise ValueError(f"MotionSearch.rtol must be >= 0, got {self.rtol!r}")
        for name in ("free_run_starts", "screen_cycle", "slow_starts"):
            if not _is_count(getattr(self, name), 0):
                raise ValueError(f"MotionSearch.{name} must be a non-negative integer, got {getattr(self, name)!r}")
        if self.starts > self.particles:
            raise ValueError(f"MotionSearch.starts ({self.starts}) cannot exceed particles ({self.particles})")


def _is_count(value, least: int) -> bool:
    """Whether ``value`` is an ``int`` (not a ``bool``) of at least ``least``."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= least


#: Above this many search parameters (the networks) `default_search` grows the
#: horizon: 60 steps on 1 000-sample segments, then 150 on 5 000.
NETWORK_PARAMS = 20


def default_search(model) -> MotionSearch:
    """The default [`MotionSearch`][jaxfric.motion.MotionSearch] for ``model``.

    Physical models (a dozen parameters at most): Levenberg–Marquardt on 5 000-sample
    segments (at most 60 steps), then on the free run of each whole training record (at
    most 100 steps), from 3 of the swarm's personal bests, 2 more of its points ranked by
    their whole free-run cost (`free_run_ranked`) and the least-squares start (no
    slow-attraction starts: `MotionSearch.slow_starts`); the lowest training free-run cost
    wins, up to 200 more free-run steps polish it, and 16 rounds of screening
    (`screen_free_run`, its spread back to the first after 4 fruitless widenings) follow
    (``benchmarks/results/motion_keys.md``). Networks (more than `NETWORK_PARAMS`
    parameters, e.g. ``Elman(neurons=10)``, 60): the swarm cannot place 60 weights, so the
    gradient stages do the work, coarse to fine: 60 steps on 1 000-sample segments, then 150
    on 5 000 (measured: docs/motion.md). A [`jaxfric.models.GreyBox`][jaxfric.models.GreyBox] is
    not searched from a swarm: [`jaxfric.identify_motion`][jaxfric.motion.identify_motion] fits its
    physical model first and starts from that fit with the correction off; then 60 steps on
    5 000-sample segments, 100 on the free run and a 100-step polish.
    """
    if isinstance(model, GreyBox):  # starts from its physical model's fit: no swarm, free run last
        return MotionSearch(horizons=(5000, None), steps=(60, 100), polish=100)
    if model.num_params > NETWORK_PARAMS:
        return MotionSearch(horizons=(1000, 5000), steps=(60, 150))
    return MotionSearch(horizons=(5000, None), steps=(60, 100), starts=3, least_squares_start=True, polish=200,
                        screen=16, free_run_starts=2, screen_cycle=4)


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


def distinct_starts(points, values, count: int, lower, upper, *, tol: float = 1e-3, taken=()) -> list:
    """Up to ``count`` rows of ``points`` in order of ``values`` (lowest first, non-finite
    values never), each farther than ``tol`` of the box width (max-norm) from those kept
    and from the points ``taken``."""
    points = np.asarray(points, np.float64)
    values = np.asarray(values, np.float64)
    width = np.maximum(np.asarray(upper, np.float64) - np.asarray(lower, np.float64), 1e-300)
    kept, seen = [], [np.asarray(y, np.float64) for y in taken]
    for i in np.argsort(np.where(np.isfinite(values), values, np.inf), kind="stable"):
        if len(kept) == count or not np.isfinite(values[i]):
            break
        if all(np.max(np.abs(points[i] - k) / width) > tol for k in seen):
            kept.append(points[i])
            seen.append(points[i])
    return kept


def _sumsq_batch(residuals, Y, data):
    return jax.vmap(lambda y: SumOfSquares(residuals)(y, data))(Y)


def _jacobian(residuals, y, data):
    return jax.jacfwd(lambda t: residuals(t, data))(y)


_sumsq_batch_jit = eqx.filter_jit(_sumsq_batch)
_jacobian_jit = eqx.filter_jit(_jacobian)


def _lm_stage(label, residuals, y, lo, hi, data, steps, rtol, clock, left, progress):
    """`levenberg_marquardt` from ``y`` for at most ``steps`` steps within the clock's
    deadline and ``left`` evaluations, with a progress bar ``label``."""
    on_step, close = step_progress(progress, label, steps)
    try:
        return levenberg_marquardt(residuals, y, lo, hi, data, max_steps=steps, rtol=rtol,
                                   deadline=clock.deadline, max_evals=left, on_step=on_step)
    finally:
        close()


def screen_free_run(search: MotionSearch, clock, residuals, y, f, lower, upper, data, key, dtype, stages,
                    progress=None):
    """The screening stage (`MotionSearch.screen`): ``search.screen`` rounds, each drawing
    ``search.screen_size`` points ``y + s ⊙ ξ`` (ξ standard normal from
    ``jax.random.fold_in(key, round)``; ``s_i = sqrt(ε J / (JᵀJ)_ii)``, the Gauss–Newton
    step of parameter i alone that raises ``J = Σ r²`` by ``ε J``, ε = ``screen_spread``,
    at most a quarter of the box; ε starts at ``screen_spread``, grows 4x after a round that
    found nothing lower and returns to ``screen_spread`` after one that did, or after
    ``search.screen_cycle`` that did not) clipped into the box, evaluating all their free-run
    costs in one vectorised call and running Levenberg–Marquardt from the lowest. The
    free-run cost of a long record is rough on a small scale (a Coulomb sign that
    switches, a stick that starts a sample earlier): Levenberg–Marquardt stops in the
    first small valley, and the valley depends on where the key started it. Returns the
    lowest ``(y, f)`` seen; appends one stage dict per round."""
    lo = jnp.asarray(lower, dtype)
    hi = jnp.asarray(upper, dtype)
    width = np.asarray(upper, np.float64) - np.asarray(lower, np.float64)
    n = y.size
    spread = float(search.screen_spread)
    widened = 0  # widenings since the last round that found a lower point
    for rnd in range(search.screen):
        left = clock.left()
        if clock.out_of_time():
            clock.stopped = "max_time"
            break
        if left is not None and left < search.screen_size + 2 * (1 + n):
            clock.stopped = "max_evals"
            break
        t, used = time.perf_counter(), spread
        jac = np.asarray(_jacobian_jit(residuals, jnp.asarray(y, dtype), data), np.float64)
        diag = np.einsum("ti,ti->i", jac, jac)
        scale = np.minimum(np.sqrt(spread * f / np.maximum(diag, 1e-300)), 0.25 * width)
        xi = np.asarray(jax.random.normal(jax.random.fold_in(key, rnd), (search.screen_size, n)), np.float64)
        Y = np.clip(y + scale * xi, lower, upper)
        J = np.asarray(_sumsq_batch_jit(residuals, jnp.asarray(Y, dtype), data), np.float64)
        evals = 1 + n + search.screen_size
        clock.evals += evals
        J = np.where(np.isfinite(J), J, np.inf)
        i = int(np.argmin(J))
        out = None
        if np.isfinite(J[i]):
            out = _lm_stage(f"screen {rnd + 1}/{search.screen}, free run (Levenberg-Marquardt)", residuals,
                            jnp.asarray(Y[i], dtype), lo, hi, data, search.screen_steps, search.rtol, clock,
                            clock.left(), progress)
            clock.evals += out.evals
            evals += out.evals
        end = J[i] if out is None else out.f
        if out is not None and np.isfinite(out.f) and out.f < f:
            y, f = out.theta, out.f
            spread = float(search.screen_spread)
            widened = 0
        else:  # nothing lower this close: look farther (back close after screen_cycle widenings)
            widened += 1
            spread *= 4.0
            if search.screen_cycle and widened % search.screen_cycle == 0:
                spread = float(search.screen_spread)
        stages.append({"stage": "screen", "start": None, "J": float(end), "num_evals": evals,
                       "num_steps": 0 if out is None else out.steps, "seconds": time.perf_counter() - t,
                       "reason": "done" if out is None else out.reason, "screen_min": float(J[i]),
                       "best": float(f), "spread": used})
        if out is not None and out.reason in ("max_time", "max_evals"):
            clock.stopped = out.reason
            break
    return y, f


def free_run_ranked(search: MotionSearch, clock, solver, sol, residuals, data, taken, lower, upper, dtype,
                    stages) -> list:
    """``search.free_run_starts`` more starts: the swarm's personal bests and final positions
    ranked by their whole free-run cost (one vectorised call), lowest first, each farther
    than `distinct_starts`' tolerance from ``taken`` and from each other. The swarm ranks by
    its short windows, which can put a basin whose free run drifts first."""
    t = time.perf_counter()
    X, _ = solver.personal_bests(sol.state)
    pool = np.vstack([np.asarray(X, np.float64), np.asarray(sol.state.x, np.float64)])
    J = np.asarray(_sumsq_batch_jit(residuals, jnp.asarray(pool, dtype), data), np.float64)
    clock.evals += pool.shape[0]
    J = np.where(np.isfinite(J), J, np.inf)
    kept = distinct_starts(pool, J, search.free_run_starts, lower, upper, taken=taken)
    stages.append({"stage": "rank", "start": None, "J": float(np.min(J)), "num_evals": pool.shape[0],
                   "num_steps": 0, "seconds": time.perf_counter() - t, "reason": "done"})
    return kept


def grid_ranked(search: MotionSearch, clock, residuals, data, grid, lower, upper, dtype, stages) -> list:
    """The ``search.slow_starts`` points of ``grid`` (clipped into the box) with the lowest
    whole free-run cost (one vectorised call), lowest first and distinct (`distinct_starts`);
    appends a ``"rank_slow"`` stage."""
    t = time.perf_counter()
    pool = np.clip(np.asarray(grid, np.float64), lower, upper)
    J = np.asarray(_sumsq_batch_jit(residuals, jnp.asarray(pool, dtype), data), np.float64)
    clock.evals += pool.shape[0]
    kept = distinct_starts(pool, J, search.slow_starts, lower, upper)
    stages.append({"stage": "rank_slow", "start": None, "J": float(np.min(np.where(np.isfinite(J), J, np.inf))),
                   "num_evals": pool.shape[0], "num_steps": 0, "seconds": time.perf_counter() - t,
                   "reason": "done"})
    return kept


def start_costs(stages) -> list:
    """Each start's final cost from run_search's ``stages``: ``[{"start": i, "J": J}]``
    (the cost of the last Levenberg–Marquardt stage the start ran), best first."""
    ends = {}
    for s in stages:
        if s.get("start") is not None:
            ends[s["start"]] = float(s["J"])
    return sorted(({"start": i, "J": J} for i, J in ends.items()), key=lambda e: (not np.isfinite(e["J"]), e["J"]))


def run_search(search: MotionSearch, budget: MotionBudget, residuals, total_cost, lower, upper, *,
               global_data, stage_data, key, dtype, progress=None, y0=None, extra_starts=(), grid_starts=()):
    """Run the stages (module docstring; ``stage_data(horizon)``: the cost's data for one
    horizon) and return ``(y, stages, stopped)``: the best search vector, one dict per stage
    (``stage``, ``start``, ``J``, ``num_evals``, ``num_steps``, ``seconds``, ``reason``) and
    why the budget ended the run (``None`` when it did not).

    Starts: ``y0`` alone when given; otherwise ``search.starts`` distinct personal bests of
    the swarm, then ``extra_starts`` (clipped into the box), then the ``search.slow_starts``
    lowest of ``grid_starts`` by their whole free-run cost (`grid_ranked`), which run the
    free-run stages only. Each start runs every Levenberg–Marquardt stage; the one whose
    last stage ends lowest is returned."""
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
        left = clock.left()
        if search.free_run_starts and not clock.out_of_time() and (left is None or left >= 2 * search.particles):
            starts += free_run_ranked(search, clock, solver, sol, residuals, stage_data(None), starts, lower,
                                      upper, dtype, stages)
        starts += [np.clip(np.asarray(y, np.float64), lower, upper) for y in extra_starts]
    free_only = len(starts)  # starts from this index on run the free-run stages only
    left = clock.left()
    if y0 is None and search.slow_starts and len(grid_starts) and not clock.out_of_time() \
            and (left is None or left >= len(grid_starts)):
        starts += grid_ranked(search, clock, residuals, stage_data(None), grid_starts, lower, upper, dtype, stages)
    lo, hi = jnp.asarray(lower, dtype), jnp.asarray(upper, dtype)
    plan = [(("free_run" if h is None else f"shooting_{h}"), stage_data(h), k)
            for h, k in zip(search.horizons, search.steps) if k > 0]
    y_best, f_best = starts[0], np.inf
    for index, y in enumerate(starts):
        f_end = np.inf
        for name, data, steps in (plan if index < free_only else [p for p in plan if p[0] == "free_run"]):
            if clock.out_of_time():
                clock.stopped = "max_time"
                break
            left = clock.left()
            if left is not None and left < 2 + y.size:
                clock.stopped = "max_evals"
                break
            label = name if len(starts) == 1 else f"{name} (start {index + 1}/{len(starts)})"
            t = time.perf_counter()
            out = _lm_stage(f"{label} (Levenberg-Marquardt)", residuals, jnp.asarray(y, dtype), lo, hi, data,
                            steps, search.rtol, clock, left, progress)
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
            t = time.perf_counter()
            out = _lm_stage("polish, free run (Levenberg-Marquardt)", residuals, jnp.asarray(y_best, dtype), lo, hi,
                            stage_data(None), search.polish, search.rtol, clock, left, progress)
            clock.evals += out.evals
            if np.isfinite(out.f) and out.f <= f_best:
                y_best, f_best = out.theta, out.f
            stages.append({"stage": "polish", "start": None, "J": out.f, "num_evals": out.evals,
                           "num_steps": out.steps, "seconds": time.perf_counter() - t, "reason": out.reason})
            if out.reason in ("max_time", "max_evals"):
                clock.stopped = out.reason
    if search.screen and clock.stopped is None and np.isfinite(f_best):
        y_best, f_best = screen_free_run(search, clock, residuals, np.asarray(y_best, np.float64), f_best,
                                         lower, upper, stage_data(None), key, dtype, stages, progress)
    return y_best, stages, clock.stopped
