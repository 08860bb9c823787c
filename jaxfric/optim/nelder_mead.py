"""Nelder–Mead downhill simplex (NMDS, ALGORITHMS.md §5) as an optimistix minimiser.

``optx.NelderMead`` in optimistix 0.1.0 searches a 2-D plane for any dimension ≥ 3
(degenerate first simplex), expands greedily, and reads best/worst vertices from
the pre-update simplex (PEERS.md §1.4–1.6). This is a correct replacement that still
runs through ``optx.minimise``:

* Lagarias et al. (1998) acceptance rules on a simplex kept sorted by value;
* standard coefficients ρ=1, χ=2, γ=½, σ=½ (MATLAB ``fminsearch``), or Gao & Han
  (2012) adaptive ones ρ=1, χ=1+2/n, γ=¾−1/(2n), σ=1−1/n — the default from 10
  parameters, where the standard ones stall;
* a first simplex scaled from the bounds (or fminsearch's 5 % / 0.00025 rule);
* bounds by clipping every trial point (as SciPy does), NaN/inf → +inf;
* exact evaluation counts and a fixed-size history of the best value.

Bounds and an optional per-coordinate first step reach the solver through
``optx.minimise(..., options={"lower": lo, "upper": hi, "initial_step": step})``.
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
    AbstractSolver,
    History,
    Solution,
    check_positive_int,
    check_range,
    safe_value,
    uniform_in_box,
)


class NelderMeadState(eqx.Module):
    """Simplex sorted by value (``f_simplex[0]`` best), counters and history."""

    simplex: Array
    f_simplex: Array
    num_evals: Array
    num_reflections: Array
    num_expansions: Array
    num_contractions: Array
    num_shrinks: Array
    history: History


def _flat_bounds(options, y_flat, unravel_like):
    """Bounds from ``options`` as flat arrays (infinite when absent)."""
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


class NelderMead(optx.AbstractMinimiser, AbstractSolver):
    """Nelder–Mead simplex minimiser (ALGORITHMS.md §5), usable two ways:

    * ``jaxfric.minimise(fn, NelderMead(), bounds, key=key, y0=y0)``;
    * ``optx.minimise(fn, NelderMead(), y0, args, options={"lower": lo, "upper": hi},
      max_steps=..., throw=False)`` (``options`` may also hold ``"initial_step"``, a
      per-coordinate first step, and ``"progress"``, a ``ProgressHook``).

    Args:
        rtol, atol: stop when every vertex is within ``atol + rtol·|x_best|`` of the best
            vertex (per coordinate) **and** every value within ``atol + rtol·|f_best|``
            of the best value (fminsearch's TolX/TolFun rule).
        adaptive: Gao–Han coefficients; ``None`` (default) uses them when ``n >= 10``
            (at n = 10 they solve 9/10 Rosenbrock starts against 7/10 for the standard ones).
        initial_simplex: ``"bounds"`` — vertex ``i`` steps ``initial_step·(upper_i −
            lower_i)`` along coordinate ``i`` (away from the nearer bound); or
            ``"fminsearch"`` — steps of ``initial_step·|x_i|`` (0.00025 where
            ``x_i = 0``). ``"bounds"`` falls back to ``"fminsearch"`` without bounds.
        initial_step: see above (0.05).
        max_steps: iteration cap used by :func:`jaxfric.minimise` (``None``: 200·n,
            SciPy's and fminsearch's default).
        max_evals: optional evaluation budget; the run stops once it is spent.
        history_size: entries of the fixed-size history.
    """

    rtol: float = 1e-8
    atol: float = 1e-8
    norm: Callable = optx.max_norm
    adaptive: bool | None = None
    initial_simplex: str = "bounds"
    initial_step: float = 0.05
    max_steps: int | None = None
    max_evals: int | None = None
    history_size: int = 256

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
        check_positive_int("history_size", self.history_size, minimum=2)

    def coefficients(self, n: int):
        """(ρ, χ, γ, σ): standard, or Gao–Han adaptive for dimension ``n``."""
        adaptive = (n >= 10) if self.adaptive is None else self.adaptive
        if adaptive:
            return 1.0, 1.0 + 2.0 / n, 0.75 - 1.0 / (2.0 * n), 1.0 - 1.0 / n
        return 1.0, 2.0, 0.5, 0.5

    def steps_for(self, n: int) -> int:
        return self.max_steps if self.max_steps is not None else 200 * n

    # ------------------------------------------------------------ optimistix protocol
    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        x0, unravel = ravel_pytree(y)
        n = x0.shape[0]
        lower, upper = _flat_bounds(options, x0, y)
        x0 = jnp.clip(x0, lower, upper)
        width = upper - lower
        finite_box = jnp.all(jnp.isfinite(width))
        step_opt = options.get("initial_step") if options else None
        if step_opt is not None:
            step = jnp.broadcast_to(jnp.asarray(step_opt, x0.dtype), x0.shape)
        elif self.initial_simplex == "bounds":
            rel = self.initial_step * jnp.where(jnp.isfinite(width), width, 0.0)
            fms = jnp.where(x0 != 0, self.initial_step * jnp.abs(x0), 0.00025)
            step = jnp.where(finite_box, rel, fms)
        else:
            step = jnp.where(x0 != 0, self.initial_step * jnp.abs(x0), 0.00025)
        # Step away from the nearer bound so the vertex stays inside the box.
        up_room = upper - x0
        down_room = x0 - lower
        step = jnp.where(up_room >= down_room, step, -step)
        step = jnp.where(step == 0, jnp.asarray(0.00025, x0.dtype), step)
        simplex = jnp.concatenate([x0[None], x0[None] + jnp.diag(step)])
        simplex = jnp.clip(simplex, lower, upper)
        f = jax.vmap(lambda x: safe_value(fn(unravel(x), args)[0]))(simplex)
        order = jnp.argsort(f)
        zero = jnp.array(0, jnp.int32)
        hist = History.empty(self.history_size, f.dtype)
        num_evals = jnp.array(n + 1, jnp.int32)
        return NelderMeadState(
            simplex=simplex[order],
            f_simplex=f[order],
            num_evals=num_evals,
            num_reflections=zero,
            num_expansions=zero,
            num_contractions=zero,
            num_shrinks=zero,
            history=hist.record(num_evals, f[order][0]),
        )

    def step(self, fn, y, args, options, state, tags):
        _, unravel = ravel_pytree(y)
        S, F = state.simplex, state.f_simplex
        n = S.shape[1]
        lower, upper = _flat_bounds(options, S[0], y)
        rho, chi, gamma, sigma = self.coefficients(n)

        def f(x):
            return safe_value(fn(unravel(x), args)[0])

        best, worst = S[0], S[-1]
        f_best, f_second, f_worst = F[0], F[-2], F[-1]
        centroid = (jnp.sum(S, axis=0) - worst) / n
        d = centroid - worst
        x_r = jnp.clip(centroid + rho * d, lower, upper)
        f_r = f(x_r)

        expand = f_r < f_best
        accept_r = (f_r >= f_best) & (f_r < f_second)
        outside = (f_r >= f_second) & (f_r < f_worst)
        # Expansion x̄ + ρχd, outside contraction x̄ + ργd or inside contraction x̄ − γd:
        # one trial point whose coefficient depends on the case.
        coef = jnp.where(expand, rho * chi, jnp.where(outside, rho * gamma, -gamma))
        x_2 = jnp.clip(centroid + coef.astype(d.dtype) * d, lower, upper)
        f_2 = jax.lax.cond(
            accept_r, lambda x: jnp.asarray(jnp.inf, F.dtype), f, x_2
        )
        # Lagarias rules: greedy minimisation on expansion, then contractions.
        take_e = expand & (f_2 < f_r)
        oc_ok = outside & (f_2 <= f_r)
        ic_ok = ~expand & ~accept_r & ~outside & (f_2 < f_worst)
        shrink = ~expand & ~accept_r & ~oc_ok & ~ic_ok
        x_new = jnp.where(take_e | oc_ok | ic_ok, x_2, x_r)
        f_new = jnp.where(take_e | oc_ok | ic_ok, f_2, f_r)

        def do_shrink(_):
            pts = best + sigma * (S[1:] - best)
            return jnp.concatenate([best[None], pts]), jnp.concatenate(
                [f_best[None], jax.vmap(f)(pts)]
            )

        def do_replace(_):
            return S.at[-1].set(x_new), F.at[-1].set(f_new)

        S2, F2 = jax.lax.cond(shrink, do_shrink, do_replace, None)
        order = jnp.argsort(F2)  # stable: an old vertex wins ties against a new one
        S2, F2 = S2[order], F2[order]
        num_evals = (
            state.num_evals
            + 1
            + (~accept_r).astype(jnp.int32)
            + shrink.astype(jnp.int32) * n
        )
        i32 = lambda b: b.astype(jnp.int32)
        new_state = NelderMeadState(
            simplex=S2,
            f_simplex=F2,
            num_evals=num_evals,
            num_reflections=state.num_reflections + i32(accept_r | (expand & ~take_e)),
            num_expansions=state.num_expansions + i32(take_e),
            num_contractions=state.num_contractions + i32(oc_ok | ic_ok),
            num_shrinks=state.num_shrinks + i32(shrink),
            history=state.history.record(num_evals, F2[0]),
        )
        hook = options.get("progress") if options else None
        if hook is not None:
            hook.emit(1, new_state.history.counter, num_evals, F2[0])
        return unravel(S2[0]), new_state, None

    def terminate(self, fn, y, args, options, state, tags):
        S, F = state.simplex, state.f_simplex
        x_ok = jnp.all(jnp.abs(S[1:] - S[0]) <= self.atol + self.rtol * jnp.abs(S[0]))
        f_ok = jnp.all(jnp.abs(F[1:] - F[0]) <= self.atol + self.rtol * jnp.abs(F[0]))
        nonfinite = ~jnp.isfinite(F[0])
        over_budget = (
            state.num_evals >= self.max_evals if self.max_evals is not None else False
        )
        done = (x_ok & f_ok) | nonfinite | over_budget
        result = RESULTS.where(
            nonfinite,
            RESULTS.nonfinite,
            RESULTS.where(
                over_budget & ~(x_ok & f_ok),
                RESULTS.nonlinear_max_steps_reached,
                RESULTS.successful,
            ),
        )
        return done, result

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        _, unravel = ravel_pytree(y)
        stats = {
            "num_evals": state.num_evals,
            "num_reflections": state.num_reflections,
            "num_expansions": state.num_expansions,
            "num_contractions": state.num_contractions,
            "num_shrinks": state.num_shrinks,
        }
        return unravel(state.simplex[0]), aux, stats

    # ----------------------------------------------------------- jaxfric protocol
    def progress_totals(self):
        return None, self.max_steps

    def run(self, fn, lower, upper, args, key, x0=None, progress=None, initial_step=None) -> Solution:
        if x0 is None:
            x0 = uniform_in_box(key, lower.shape, lower, upper)
        options: dict[str, Any] = {"lower": lower, "upper": upper}
        if initial_step is not None:
            options["initial_step"] = initial_step
        if progress is not None:
            options["progress"] = progress
        sol = optx.minimise(
            fn,
            self,
            x0,
            args,
            options=options,
            max_steps=self.steps_for(lower.shape[0]),
            throw=False,
        )
        st = sol.state
        return Solution(
            value=sol.value,
            f=st.f_simplex[0],
            result=sol.result,
            stats={
                "num_steps": jnp.asarray(sol.stats["num_steps"], jnp.int32),
                "num_evals": st.num_evals,
            },
            history=st.history.filled(),
        )
