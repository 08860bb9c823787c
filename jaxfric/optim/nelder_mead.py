"""Nelder–Mead downhill simplex (NMDS, ``docs/algorithms.md §5``): a jaxfric solver that
is also an optimistix minimiser.

``optx.NelderMead`` in optimistix 0.1.0 searches a 2-D plane for any dimension ≥ 3
(degenerate first simplex), expands greedily, and reads best/worst vertices from
the pre-update simplex. This is a correct replacement that runs through
``optx.minimise`` like any optimistix minimiser (``has_aux``, pytree ``y0``,
``throw``, ``jit``, ``vmap``, implicit differentiation of the solution through
``adjoint=optx.ImplicitAdjoint()``, ``jax_numpy_rank_promotion="raise"``):

* Lagarias et al. (1998) acceptance rules on a simplex kept sorted by value (§5 steps 1–5);
* Gao & Han (2012) adaptive coefficients ρ=1, χ=1+2/n, γ=¾−1/(2n), σ=1−1/n (the
  default: the standard ones stall in high dimension, §5) or the standard ρ=1, χ=2,
  γ=½, σ=½ (MATLAB ``fminsearch``, ``adaptive=False``);
* a first simplex scaled from the bounds (or fminsearch's 5 % / 0.00025 rule);
* bounds by clipping every trial point (as SciPy does), NaN/inf → +inf;
* the trial points of a step evaluated one after the other (fewest evaluations) or
  as one batch (``batched_trials``: one call of the objective per step);
* restarts from its own result with a fresh simplex (``restarts``);
* exact evaluation counts.

Bounds and an optional per-coordinate first step reach the solver through
``optx.minimise(..., options={"lower": lo, "upper": hi, "initial_step": step})``.

One algorithm, two protocols under their own names: the start and the step are written
once, as evaluation rounds ([`jaxfric.optim.rounds`][jaxfric.optim.rounds]) that receive ``(f, aux)``;
optimistix's ``init / step / terminate / postprocess`` drive them with the aux the
objective returns, jaxfric's contract (``init_rounds / step_rounds / finished / best /
num_evals``, [`AbstractSolver`][jaxfric.optim.AbstractSolver]) with none. So
[`jaxfric.minimise`][jaxfric.optim.minimise], chains and ask/tell run it directly, without an adapter.
"""

from __future__ import annotations

from typing import Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jax.flatten_util import ravel_pytree
from jaxtyping import Array

from ._base import (
    RESULTS,
    Solution,
    History,
    check_positive_int,
    check_range,
    count_dtype,
    put,
    safe_value,
    split_drawn,
    uniform_flat,
    uniform_in_box,
)
from .contract import AbstractLocal, AbstractStartDraws, Capabilities, optx_finished
from .rounds import Batch, drive, relay, skipped

_ZERO_STEP = 0.00025  # fminsearch's step for a coordinate that is exactly zero
#: The move counters of a ``NelderMeadState``, reported in ``stats``.
_MOVES = ("num_reflections", "num_expansions", "num_contractions", "num_shrinks", "num_restarts")


class NelderMeadState(eqx.Module):
    """Simplex sorted by value (``f_simplex[0]`` best), the auxiliary output of the best
    vertex, restart bookkeeping and counters."""

    simplex: Array
    f_simplex: Array
    aux: Any
    restarts_left: Array
    f_start: Array  # best value when the current (re)start began (+inf before the first)
    num_evals: Array
    num_reflections: Array
    num_expansions: Array
    num_contractions: Array
    num_shrinks: Array
    num_restarts: Array
    num_steps: Array


def _flat_bounds(options, y_flat):
    """Bounds from ``options`` as flat arrays of ``y_flat``'s shape (infinite when absent)."""
    dtype = y_flat.dtype

    def flat(name, fill):
        val = options.get(name) if options else None
        if val is None:
            return jnp.full_like(y_flat, fill)
        leaves = jax.tree_util.tree_leaves(val)
        if len(leaves) == 1 and jnp.ndim(leaves[0]) <= 1:
            return jnp.broadcast_to(jnp.asarray(leaves[0], dtype), y_flat.shape)
        return ravel_pytree(val)[0].astype(dtype)

    return flat("lower", -jnp.inf), flat("upper", jnp.inf)


def _i32(b):
    return jnp.asarray(b).astype(jnp.int32)


def _take(tree, i):
    return jax.tree_util.tree_map(lambda a: a[i], tree)


def _tree_select(pred, a, b):
    return jax.tree_util.tree_map(lambda u, v: jnp.where(pred, u, v), a, b)


def _no_aux(rounds):
    """The simplex rounds (which receive ``(f, aux)``) fed values without aux."""
    return relay(rounds, answer=lambda f: (f, None))


class NelderMead(optx.AbstractMinimiser, AbstractLocal, AbstractStartDraws):
    """Nelder–Mead simplex minimiser (``docs/algorithms.md §5``), usable two ways:

    * ``jaxfric.minimise(fn, NelderMead(), bounds, key=key, y0=y0)`` (a jaxfric solver:
      also in chains, ``minimise_many`` and ask/tell);
    * ``optx.minimise(fn, NelderMead(), y0, args, options={"lower": lo, "upper": hi},
      has_aux=..., max_steps=..., throw=...)`` (``options`` may also hold
      ``"initial_step"``, a per-coordinate first step). ``sol.aux`` is the auxiliary
      output at the best vertex; ``sol.stats`` holds the evaluation and move counts.

    Args:
        rtol, atol: stop when every vertex is within ``atol + rtol·|x_best|`` of the best
            vertex (per coordinate) **and** every value within ``atol + rtol·|f_best|``
            of the best value (fminsearch's TolX/TolFun rule).
        norm: kept for optimistix compatibility (the test above is per coordinate).
        adaptive: Gao–Han coefficients (True), the standard ones (False, fminsearch's),
            or ``None`` (default): Gao–Han from n = 2 (at n = 2 both sets are equal; at
            n = 1 Gao–Han's σ = 0; measured: docs/algorithms.md §5,
            ``benchmarks/results/nm_vs_scipy.md``).
        initial_simplex: ``"bounds"`` — vertex ``i`` steps ``initial_step·(upper_i −
            lower_i)`` along coordinate ``i`` (away from the nearer bound); or
            ``"fminsearch"`` — steps of ``initial_step·|x_i|`` (0.00025 where
            ``x_i = 0``). ``"bounds"`` falls back to ``"fminsearch"`` without bounds.
        initial_step: see above (0.05).
        max_steps: iteration cap used by [`jaxfric.minimise`][jaxfric.optim.minimise] (``None``:
            ``200·n·(1 + restarts)``, SciPy's and fminsearch's default per (re)start).
        max_evals: optional evaluation budget; the run stops once it is spent.
        batched_trials: evaluate reflection, expansion and both contractions of a step
            as one batch of 4 (one call of the objective per step) instead of the
            sequential rule (reflection, then at most one more point). The simplex moves
            exactly as with the sequential rule; ``num_evals`` counts the 4 points actually
            evaluated, so at a fixed evaluation budget it takes fewer steps.
        restarts: after convergence, start again up to this many times from the best
            vertex with a fresh first simplex (the rule above, at the new point) — what
            ``fminsearch`` users do by calling it again on its own result. A restart that
            ends without improving the best value stops the run (another would repeat it).
    """

    rtol: float = 1e-8
    atol: float = 1e-8
    norm: Callable = optx.max_norm
    adaptive: bool | None = None
    initial_simplex: str = "bounds"
    initial_step: float = 0.05
    max_steps: int | None = None
    max_evals: int | None = None
    batched_trials: bool = False
    restarts: int = 0

    def check(self):
        check_range("rtol", self.rtol, 0.0)
        check_range("atol", self.atol, 0.0)
        check_range("initial_step", self.initial_step, 0.0, lo_open=True)
        if self.initial_simplex not in ("bounds", "fminsearch"):
            raise ValueError(
                "initial_simplex must be 'bounds' or 'fminsearch', "
                f"got {self.initial_simplex!r}"
            )
        if self.max_steps is not None:
            check_positive_int("max_steps", self.max_steps)
        if self.max_evals is not None:
            check_positive_int("max_evals", self.max_evals)
        check_positive_int("restarts", self.restarts, minimum=0)
        if not isinstance(self.batched_trials, bool):
            raise ValueError(f"batched_trials must be True or False, got {self.batched_trials!r}")

    def coefficients(self, n: int):
        """(ρ, χ, γ, σ): standard, or Gao–Han adaptive for dimension ``n`` (§5)."""
        # Gao–Han at n = 2 equals the standard set; at n = 1 its σ = 0 would collapse a shrink.
        adaptive = (n >= 2) if self.adaptive is None else self.adaptive
        if adaptive:
            return 1.0, 1.0 + 2.0 / n, 0.75 - 1.0 / (2.0 * n), 1.0 - 1.0 / n
        return 1.0, 2.0, 0.5, 0.5

    def start_options(self, spread, lower, upper):
        """The first simplex sized from a converged population's spread: after a
        global stage the basin is much smaller than the box, so a box-sized simplex
        would first spend many evaluations shrinking. At least ``initial_step``·1e-3
        of the box."""
        return {"initial_step": jnp.maximum(spread, 1e-3 * self.initial_step * (upper - lower))}

    def _step_cap(self, n: int) -> int:
        """Most steps of a run on ``n`` parameters (``max_steps``, or 200·n per (re)start)."""
        if self.max_steps is not None:
            return self.max_steps
        return 200 * n * (1 + self.restarts)

    # ------------------------------------------------------------------ pieces
    def _first_steps(self, x, lower, upper, options):
        """Signed per-coordinate steps of a first simplex around ``x`` (§5, §5.1)."""
        width = upper - lower
        # fminsearch (and SciPy): component i multiplied by 1 + initial_step, so the step
        # has the sign of x_i; reversed only where that would leave the box.
        fms = jnp.where(x != 0, self.initial_step * x, _ZERO_STEP)
        fms = jnp.where((x + fms > upper) | (x + fms < lower), -fms, fms)
        step_opt = options.get("initial_step") if options else None
        if step_opt is None and self.initial_simplex == "fminsearch":
            return fms
        if step_opt is not None:
            step = jnp.broadcast_to(jnp.asarray(step_opt, x.dtype), x.shape)
        else:
            step = self.initial_step * jnp.where(jnp.isfinite(width), width, 0.0)
        step = jnp.abs(step)
        step = jnp.where(step == 0, jnp.asarray(_ZERO_STEP, x.dtype), step)
        # Step away from the nearer bound so the vertex stays inside the box.
        step = jnp.where(upper - x >= x - lower, step, -step)
        if step_opt is None:  # "bounds" without a finite box: fminsearch's rule
            step = jnp.where(jnp.all(jnp.isfinite(width)), step, fms)
        return step

    @staticmethod
    def _evaluator(fn, unravel, args):
        """``X ↦ (f, aux)``: objective and aux at the rows of ``X``, as one batch;
        NaN/inf → +inf."""
        def evaluate(X):
            f, aux = jax.vmap(lambda x: fn(unravel(x), args))(X)
            return safe_value(f), aux

        return evaluate

    def _converged(self, state):
        S, F = state.simplex, state.f_simplex
        x_tol = self.atol + self.rtol * jnp.abs(S[0])
        x_ok = jnp.all(jnp.abs(S[1:] - S[0][None]) <= x_tol[None])
        f_ok = jnp.all(jnp.abs(F[1:] - F[0]) <= self.atol + self.rtol * jnp.abs(F[0]))
        return x_ok & f_ok

    def _restart_due(self, state):
        if self.restarts == 0:
            # never (static): the restart's convergence test and fresh simplex stay out
            # of the compiled step (issue 47); restarts_left is 0 throughout such a run
            return jnp.asarray(False)
        return (
            self._converged(state)
            & (state.restarts_left > 0)
            & (state.f_simplex[0] < state.f_start)
        )

    # ------------------------------------------------------------ optimistix protocol
    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        x0, unravel = ravel_pytree(y)
        return drive(self._first_simplex(x0, options), self._evaluator(fn, unravel, args))

    def _first_simplex(self, x0, options):
        """The start as evaluation rounds ([`jaxfric.optim.rounds`][jaxfric.optim.rounds]) on the flat start
        ``x0``: yields the first simplex (``n + 1`` points), receives ``(f, aux)``."""
        lower, upper = _flat_bounds(options, x0)
        x0 = jnp.clip(x0, lower, upper)
        step = self._first_steps(x0, lower, upper, options)
        simplex = jnp.concatenate([x0[None], x0[None] + jnp.diag(step)])
        simplex = jnp.clip(simplex, lower[None], upper[None])
        f, aux = yield Batch(simplex, split=False)
        order = jnp.argsort(f)
        num_evals = jnp.array(x0.shape[0] + 1, jnp.int32)
        return NelderMeadState(
            simplex=simplex[order],
            f_simplex=f[order],
            aux=_take(aux, order[0]),
            restarts_left=jnp.array(self.restarts, jnp.int32),
            f_start=jnp.asarray(jnp.inf, f.dtype),
            num_evals=num_evals,
            **dict.fromkeys((*_MOVES, "num_steps"), jnp.array(0, jnp.int32)),
        )

    def step(self, fn, y, args, options, state, tags):
        """One Lagarias step (§5 steps 1–5), or a restart when one is due."""
        _, unravel = ravel_pytree(y)

        def skip(X):
            aux = jax.tree_util.tree_map(
                lambda a: jnp.zeros((X.shape[0],) + jnp.shape(a), jnp.result_type(a)), state.aux
            )
            return skipped(X), aux

        x, new_state, aux = drive(self._simplex_step(state, options),
                                  self._evaluator(fn, unravel, args), skip)
        return unravel(x), new_state, aux

    def _simplex_step(self, state, options):
        """[`step`][jaxfric.optim.NelderMead.step] as evaluation rounds ([`jaxfric.optim.rounds`][jaxfric.optim.rounds]): yields the
        reflection (all four trial points with ``batched_trials``), then the second
        trial point (sequential rule) and a shrink's ``n`` points, each only where
        needed; receives ``(f, aux)``; returns ``(best vertex, state, its aux)``."""
        S, F = state.simplex, state.f_simplex
        n = S.shape[1]
        lower, upper = _flat_bounds(options, S[0])
        rho, chi, gamma, sigma = self.coefficients(n)
        restart = self._restart_due(state)

        best, worst = S[0], S[-1]
        f_best, f_second, f_worst = F[0], F[-2], F[-1]
        centroid = (jnp.sum(S, axis=0) - worst) / n
        d = centroid - worst
        # Reflection x̄ + ρd, expansion x̄ + ρχd, outside contraction x̄ + ργd,
        # inside contraction x̄ − γd.
        coef = jnp.asarray([rho, rho * chi, rho * gamma, -gamma], S.dtype)
        trials = jnp.clip(centroid[None] + coef[:, None] * d[None], lower[None], upper[None])

        # Nelder–Mead's few points are evaluated whole (not split over devices), as
        # optimistix's own step evaluates them
        f_t, aux_t = yield Batch(trials if self.batched_trials else trials[:1], ~restart,
                                 split=False)
        f_r, aux_r = f_t[0], _take(aux_t, 0)

        expand = f_r < f_best
        accept_r = (f_r >= f_best) & (f_r < f_second)
        outside = (f_r >= f_second) & (f_r < f_worst)
        second = jnp.where(expand, 1, jnp.where(outside, 2, 3))
        x_2 = trials[second]
        need_2 = ~restart & ~accept_r
        if self.batched_trials:
            f_2, aux_2 = f_t[second], _take(aux_t, second)
            trial_evals = jnp.where(restart, 0, 4)
        else:
            f_2v, aux_2v = yield Batch(x_2[None], need_2, split=False)
            f_2, aux_2 = f_2v[0], _take(aux_2v, 0)
            trial_evals = jnp.where(restart, 0, 1 + _i32(need_2))

        # Lagarias rules: greedy minimisation on expansion, then contractions.
        take_e = expand & (f_2 < f_r)
        oc_ok = outside & (f_2 <= f_r)
        ic_ok = ~expand & ~accept_r & ~outside & (f_2 < f_worst)
        take_2 = take_e | oc_ok | ic_ok
        shrink = ~restart & ~expand & ~accept_r & ~oc_ok & ~ic_ok
        x_new = jnp.where(take_2, x_2, trials[0])
        f_new = jnp.where(take_2, f_2, f_r)
        aux_new = _tree_select(take_2, aux_2, aux_r)

        # A shrink and a restart both replace every vertex but the best: one batch of n.
        shrunk = best[None] + sigma * (S[1:] - best[None])
        if self.restarts:
            fresh = best[None] + jnp.diag(self._first_steps(best, lower, upper, options))
            shrunk = jnp.where(restart, fresh, shrunk)
        pts = jnp.clip(shrunk, lower[None], upper[None])

        f_p, aux_p = yield Batch(pts, shrink | restart, split=False)

        def do_batch(_):
            i = jnp.argmin(f_p)
            return (
                jnp.concatenate([best[None], pts]),
                jnp.concatenate([f_best[None], f_p]),
                f_p[i],
                _take(aux_p, i),
            )

        def do_replace(_):
            return put(S, n, x_new), put(F, n, f_new), f_new, aux_new  # the worst, S[-1]

        S2, F2, f_cand, aux_cand = jax.lax.cond(shrink | restart, do_batch, do_replace, None)
        order = jnp.argsort(F2)  # stable: an old vertex wins ties against a new one
        S2, F2 = S2[order], F2[order]
        aux_best = _tree_select(f_cand < f_best, aux_cand, state.aux)
        num_evals = state.num_evals + trial_evals + _i32(shrink | restart) * n
        new_state = NelderMeadState(
            simplex=S2,
            f_simplex=F2,
            aux=aux_best,
            restarts_left=state.restarts_left - _i32(restart),
            f_start=jnp.where(restart, f_best, state.f_start),
            num_evals=num_evals,
            num_reflections=state.num_reflections
            + _i32(~restart & (accept_r | (expand & ~take_e))),
            num_expansions=state.num_expansions + _i32(take_e),
            num_contractions=state.num_contractions + _i32(oc_ok | ic_ok),
            num_shrinks=state.num_shrinks + _i32(shrink),
            num_restarts=state.num_restarts + _i32(restart),
            num_steps=state.num_steps + 1,
        )
        return S2[0], new_state, aux_best

    def terminate(self, fn, y, args, options, state, tags):
        converged = self._converged(state) & ~self._restart_due(state)
        nonfinite = ~jnp.isfinite(state.f_simplex[0])
        over_budget = state.num_evals >= self.max_evals if self.max_evals is not None else False
        done = converged | nonfinite | over_budget
        result = RESULTS.where(nonfinite, RESULTS.nonfinite,
                               RESULTS.where(over_budget & ~converged,
                                             RESULTS.nonlinear_max_steps_reached, RESULTS.successful))
        return done, result

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        _, unravel = ravel_pytree(y)
        stats = {name: getattr(state, name) for name in ("num_evals", *_MOVES)}
        # The best vertex and its aux (``aux`` from the loop is the same unless the
        # loop never stepped, when it is optimistix's zeros).
        return unravel(state.simplex[0]), state.aux, stats

    # ----------------------------------------------------------- jaxfric protocol
    def start_draws(self, lower, upper, key):
        """What the start draws from ``key`` without a ``y0``: ``U(0, 1)`` per coordinate
        (for a ``Drawn`` key; the numbers of `uniform_in_box`)."""
        return uniform_flat(key, lower.shape, lower.dtype)

    def init_rounds(self, lower, upper, key, x0=None, objective=None, options=None):
        """The first simplex around ``x0`` (a uniform draw in the box without one);
        ``options``: ``{"initial_step": ...}`` (see [`start_options`][jaxfric.optim.NelderMead.start_options])."""
        key, drawn = split_drawn(key)
        if x0 is None and drawn is not None:
            x0 = lower + drawn * (upper - lower)
        elif x0 is None:
            x0 = uniform_in_box(key, lower.shape, lower, upper)
        elif x0.ndim != 1:
            raise ValueError("Nelder–Mead takes one start y0, not a population")
        box = {"lower": lower, "upper": upper, **(options or {})}
        return (yield from _no_aux(self._first_simplex(x0, box)))

    def step_rounds(self, lower, upper, state, stage=0, objective=None):
        _, state, _ = yield from _no_aux(self._simplex_step(state, {"lower": lower,
                                                                    "upper": upper}))
        return state

    def finished(self, state):
        """optimistix's rule: [`terminate`][jaxfric.optim.NelderMead.terminate]'s test, or the step cap reached
        (``nonlinear_max_steps_reached``)."""
        done, result = self.terminate(None, None, None, None, state, None)
        return optx_finished(done, result, state.num_steps >= self._step_cap(state.simplex.shape[-1]))

    def best(self, state):
        return state.simplex[0], state.f_simplex[0]

    def num_evals(self, state):
        return state.num_evals.astype(count_dtype())

    def solution(self, fn, lower, upper, args, state, result) -> Solution:
        stats = {"num_evals": self.num_evals(state), **{name: getattr(state, name) for name in _MOVES},
                 "num_steps": state.num_steps}
        x, f = self.best(state)
        return Solution(value=x, f=f, result=result, stats=stats,
                        history=History.empty(1, f.dtype), state=state)

    def capabilities(self, n: int) -> Capabilities:
        cap = self._step_cap(n)
        worst = (n + 1) + cap * (n + 2)  # a shrink costs n + 2
        if self.max_evals is not None:
            worst = min(worst, self.max_evals + n + 2)
        # batches_runs: its trial points and shrinks are conditional batches
        return Capabilities(max_steps=cap, max_evaluations=worst,
                            batches_runs=False, progress_totals=(None, self.max_steps))
