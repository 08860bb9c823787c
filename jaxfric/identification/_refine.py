"""Gradient refinement of a fit — beyond the paper (docs/algorithms.md §2.4 last bullet, §11 step 7).

The models are pure JAX, so ``jax.grad`` through the ``lax.scan`` rollout gives J's
exact gradient (for the Elman network by its hand-written adjoint, BPTT,
``Elman.simulate_vjp``; see ``_objective``). The default pipeline of the networks
ends here (``identify(method="jaxfric")``). After (or instead of) Nelder–Mead we
polish θ with an optimistix solver:

* ``"bfgs"`` / ``"lbfgs"``: quasi-Newton on J (``optx.minimise``);
* ``"lm"`` / ``"gauss_newton"``: Levenberg–Marquardt / Gauss–Newton on the residual
  vector (``optx.least_squares``). Each step builds the (N_train × n) Jacobian by
  forward mode, which is cheap for the 6-parameter LuGre and slow for the 180-D
  network (measured: 100 LM steps ≈ 60 s there, 2000 BFGS steps ≈ 2–5 s).

The box is kept by a smooth reparametrisation rather than clipping (a clipped
coordinate has zero gradient and stalls quasi-Newton updates):

    θ = lo + (hi − lo)·(1 + sin z)/2,       z ∈ ℝ unconstrained

(Box's sine transform). It is smooth, bounded, and never infinite; a start lying
exactly on a bound (swarms clip there) is first pulled ``edge``·(hi − lo) inside,
where the gradient is non-zero. The refined point is kept only if its J is lower.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from ..optim.progress import step_progress
from ._objective import CostData, OutputErrorCost

METHODS = ("bfgs", "lbfgs", "lm", "gauss_newton")
#: How `refine_many` lays out an ensemble's members (``GradientRefinement.batching``;
#: ``"auto"`` is resolved by ``identify``'s gradient stage, ``stages.refine_batching``).
BATCHING = ("auto", "vmap", "map")
_LEAST_SQUARES = ("lm", "gauss_newton")
_ALIASES = {"levenberg_marquardt": "lm", "levenberg-marquardt": "lm", "gauss-newton": "gauss_newton"}

#: ``refine="auto"`` (or ``True``) uses Levenberg–Marquardt up to this many
#: parameters and BFGS above (see the module docstring for the timings).
AUTO_LM_MAX_PARAMS = 20


class GradientRefinement(eqx.Module):
    """Settings of the gradient stage (all static; see the module docstring).

    Args:
        method: ``"bfgs"``, ``"lbfgs"``, ``"lm"`` or ``"gauss_newton"``.
        max_steps: iteration cap of the optimistix solver.
        rtol, atol: the solver's relative/absolute tolerances (on θ-steps and J).
        edge: fraction of the box a start on a bound is pulled inside (0 < edge < 0.5).
        batching: how an ensemble's members run (`refine_many`): ``"vmap"``
            side by side, every step one batched evaluation of all members (for the
            Elman networks one time loop over all of them); ``"map"`` one after another
            inside the same compiled call, each member the single run's program, so
            member i equals the single run from the same start to the bit; ``"auto"``
            (default): ``"vmap"`` for the networks and off the CPU, ``"map"`` for
            physical models on the CPU (``stages.refine_batching``; measured:
            docs/identify.md, "Ensembles").
    """

    method: str = eqx.field(default="bfgs", static=True)
    max_steps: int = eqx.field(default=2000, static=True)
    rtol: float = eqx.field(default=1e-7, static=True)
    atol: float = eqx.field(default=1e-10, static=True)
    edge: float = eqx.field(default=1e-4, static=True)
    batching: str = eqx.field(default="auto", static=True)

    def check(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"refine method must be one of {METHODS}, got {self.method!r}")
        if isinstance(self.max_steps, bool) or not isinstance(self.max_steps, int) or self.max_steps < 1:
            raise ValueError(f"refine max_steps must be a positive integer, got {self.max_steps!r}")
        for name in ("rtol", "atol"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and value >= 0.0):
                raise ValueError(f"refine {name} must be >= 0, got {value!r}")
        if not 0.0 < self.edge < 0.5:
            raise ValueError(f"refine edge must lie in (0, 0.5), got {self.edge!r}")
        if self.batching not in BATCHING:
            raise ValueError(f"refine batching must be one of {BATCHING}, got {self.batching!r}")

    @property
    def least_squares(self) -> bool:
        return self.method in _LEAST_SQUARES

    def solver(self):
        cls = {"bfgs": optx.BFGS, "lbfgs": optx.LBFGS, "lm": optx.LevenbergMarquardt,
               "gauss_newton": optx.GaussNewton}[self.method]
        return cls(rtol=self.rtol, atol=self.atol)


def as_refinement(refine, num_params: int) -> GradientRefinement | None:
    """Resolve the ``refine=`` argument of [`jaxfric.identify`][jaxfric.identification.identify].

    ``None``/``False``: no gradient stage (the paper). ``True``/``"auto"``: LM for
    at most `AUTO_LM_MAX_PARAMS` parameters, else BFGS. A method name, or a
    [`GradientRefinement`][jaxfric.identification.GradientRefinement] for full control.
    """
    if refine is None or refine is False:
        return None
    if refine is True:
        refine = "auto"
    if isinstance(refine, str):
        name = _ALIASES.get(refine.strip().lower(), refine.strip().lower())
        if name == "auto":
            name = "lm" if num_params <= AUTO_LM_MAX_PARAMS else "bfgs"
        refine = GradientRefinement(method=name)
    if not isinstance(refine, GradientRefinement):
        raise ValueError("refine must be None, True, 'auto', one of "
                         f"{METHODS}, or a GradientRefinement, got {refine!r}")
    refine.check()
    return refine


# ------------------------------------------------------------ reparametrisation
def to_box(z, lower, upper):
    """θ = lo + (hi − lo)·(1 + sin z)/2."""
    return lower + (upper - lower) * 0.5 * (1.0 + jnp.sin(z))


def from_box(theta, lower, upper, edge):
    """Inverse of `to_box` on [−π/2, π/2], after pulling θ ``edge`` inside the box."""
    frac = jnp.clip((theta - lower) / (upper - lower), edge, 1.0 - edge)
    return jnp.arcsin(2.0 * frac - 1.0)


# Module-level objectives with everything in ``args``: optimistix and jit see the
# same function object on every call, so their caches hit.
def _cost_z(z, args):
    cost, lower, upper, data = args
    return cost(to_box(z, lower, upper), data)


def _residuals_z(z, args):
    cost, lower, upper, data = args
    return cost.residuals(to_box(z, lower, upper), data)


class RefineOutcome(eqx.Module):
    """Result of `refine_impl`: the kept θ and its J, the solver's J, result code and steps."""

    theta: jax.Array
    f: jax.Array
    f_refined: jax.Array
    improved: jax.Array
    result: optx.RESULTS
    num_steps: jax.Array


#: Solver steps per compiled call of the gradient stage. The stage always runs in
#: chunks of this size, with or without a progress display, so showing progress
#: never changes the result; between chunks the display is updated.
REFINE_CHUNK = 50

_TAGS = frozenset()


def _fn(settings: GradientRefinement):
    # optimistix's solver protocol: fn(y, args) -> (output, aux).
    if settings.least_squares:
        return lambda z, args: (_residuals_z(z, args), None)
    return lambda z, args: (_cost_z(z, args), None)


def _start(settings: GradientRefinement, cost, theta0, lower, upper, data):
    args = (cost, lower, upper, data)
    fn = _fn(settings)
    z0 = from_box(theta0, lower, upper, settings.edge)
    f_struct = jax.eval_shape(lambda z: fn(z, args)[0], z0)
    solver = settings.solver()
    state = solver.init(fn, z0, args, {}, f_struct, None, _TAGS)
    done, result = solver.terminate(fn, z0, args, {}, state, _TAGS)
    return z0, state, done, result, cost(theta0, data)


def _advance(settings: GradientRefinement, cost, z, state, steps, done, result, lower, upper, data):
    """Up to `REFINE_CHUNK` more solver steps (never past ``max_steps``), as
    ``optimistix``'s own loop runs them (``step``, then ``terminate`` on the new state)."""
    args = (cost, lower, upper, data)
    fn = _fn(settings)
    solver = settings.solver()
    limit = jnp.minimum(steps + REFINE_CHUNK, settings.max_steps)
    dynamic, static = eqx.partition(state, eqx.is_array)

    def cond(carry):
        _, _, k, stop, res = carry
        return (k < limit) & jnp.invert(stop) & (res == optx.RESULTS.successful)

    def body(carry):
        y, dyn, k, _, _ = carry
        st = eqx.combine(static, dyn)
        y_new, st_new, _ = solver.step(fn, y, args, {}, st, _TAGS)
        stop, res = solver.terminate(fn, y, args, {}, st_new, _TAGS)
        finite = jnp.all(jnp.isfinite(y_new))
        res = optx.RESULTS.where(finite, res, optx.RESULTS.nonfinite)
        return y_new, eqx.partition(st_new, eqx.is_array)[0], k + 1, stop, res

    z, dynamic, steps, done, result = jax.lax.while_loop(cond, body, (z, dynamic, steps, done, result))
    return z, eqx.combine(static, dynamic), steps, done, result, cost(to_box(z, lower, upper), data)


def _finish(cost, theta0, f_old, z, steps, done, result, lower, upper, data, max_steps):
    result = optx.RESULTS.where(
        (result == optx.RESULTS.successful) & jnp.invert(done) & (steps >= max_steps),
        optx.RESULTS.nonlinear_max_steps_reached, result)
    theta_new = to_box(z, lower, upper)
    f_new = cost(theta_new, data)
    f_new_safe = jnp.where(jnp.isfinite(f_new), f_new, jnp.inf)
    improved = f_new_safe < f_old
    return RefineOutcome(theta=jnp.where(improved, theta_new, theta0), f=jnp.where(improved, f_new_safe, f_old),
                         f_refined=f_new, improved=improved, result=result, num_steps=steps)


def refine_impl(settings: GradientRefinement, cost: OutputErrorCost, theta0, lower, upper,
                data: CostData, *, progress=None, compiler_options=()) -> RefineOutcome:
    """Polish ``theta0`` with ``settings`` inside the box ``[lower, upper]``.

    The optimistix solver (``init``/``step``/``terminate``) runs in compiled chunks of
    `REFINE_CHUNK` steps; ``progress`` (``True`` for a tqdm bar, or a callable
    ``sink(GRADIENT_PHASE, step, step, J)``, ``jaxfric.optim.progress``) is told after each
    chunk. ``compiler_options``:
    a `jaxfric._xla.resolve` tuple for the compiled chunks.

    ``cost(theta, data)`` is J; the start's own J is evaluated too, so the
    returned θ is never worse than ``theta0`` (a non-finite refined J counts as worse).
    """
    from .. import _xla

    update, close = step_progress(progress, f"gradient ({settings.method})", settings.max_steps)
    start = _xla.filter_jit(_start, compiler_options)
    advance = _xla.filter_jit(_advance, compiler_options)
    finish = _xla.filter_jit(_finish, compiler_options)
    z, state, done, result, f_old = start(settings, cost, theta0, lower, upper, data)
    steps = jnp.asarray(0)
    try:
        while int(steps) < settings.max_steps and not bool(done) and \
                bool(result == optx.RESULTS.successful):
            z, state, steps, done, result, f = advance(settings, cost, z, state, steps, done, result,
                                                       lower, upper, data)
            update(int(steps), float(f))
    finally:
        close(int(steps))
    return finish(cost, theta0, f_old, z, steps, done, result, lower, upper, data, settings.max_steps)


def _over_members(settings: GradientRefinement, fn, *batched):
    """``fn`` applied to each member's slice of ``batched``: side by side (``vmap``) or
    one after another (``lax.map``, each member the single run's program)."""
    if settings.batching != "map":  # "vmap"; "auto" is resolved before, by the caller
        return eqx.filter_vmap(fn)(*batched)
    # lax.map carries arrays only: the solver state's static leaves ride outside.
    dynamic, static = eqx.partition(batched, eqx.is_array)
    out_static = []

    def one(d):
        out_dynamic, s = eqx.partition(fn(*eqx.combine(d, static)), eqx.is_array)
        out_static.append(s)
        return out_dynamic

    out = jax.lax.map(one, dynamic)
    return eqx.combine(out, out_static[0])


def _start_many(settings, cost, thetas, lower, upper, data):
    return _over_members(settings, lambda t: _start(settings, cost, t, lower, upper, data), thetas)


def _advance_many(settings, cost, z, state, steps, done, result, lower, upper, data):
    # A member that has stopped keeps its state: its own while loop does not run (map),
    # or, under vmap, the loop runs while any member runs and selects the stopped
    # members' carry unchanged.
    return _over_members(settings, lambda *c: _advance(settings, cost, *c, lower, upper, data),
                         z, state, steps, done, result)


def _finish_many(settings, cost, thetas, f_old, z, steps, done, result, lower, upper, data,
                 max_steps):
    return _over_members(
        settings, lambda t, f, *c: _finish(cost, t, f, *c, lower, upper, data, max_steps),
        thetas, f_old, z, steps, done, result)


def refine_many(settings: GradientRefinement, cost: OutputErrorCost, thetas, lower, upper,
                data: CostData, *, progress=None, compiler_options=()) -> RefineOutcome:
    """`refine_impl` for a batch of starts ``thetas`` (``(K, n)``), side by side.

    One compiled program advances every member. With ``settings.batching == "vmap"``
    (``"auto"`` here) each step rolls out all K members in one batched evaluation; a member
    that has stopped is carried unchanged until the last one stops, so member ``i`` takes the
    steps of ``refine_impl(..., thetas[i], ...)`` up to floating-point reassociation in the
    batched sums. With ``"map"`` each member runs the single run's program, one after another
    in the same compiled call: member ``i`` is that run, to the bit, at K times its cost
    (docs/identify.md, "Ensembles").
    ``progress`` is told the furthest member's step count after each chunk.
    Returns a `RefineOutcome` whose fields have a leading axis of length K.
    """
    from .. import _xla

    update, close = step_progress(progress, f"gradient ({settings.method})", settings.max_steps)
    start = _xla.filter_jit(_start_many, compiler_options)
    advance = _xla.filter_jit(_advance_many, compiler_options)
    finish = _xla.filter_jit(_finish_many, compiler_options)
    z, state, done, result, f_old = start(settings, cost, thetas, lower, upper, data)
    steps = jnp.zeros(thetas.shape[0], jnp.int32)

    def running(steps, done, result):
        return bool(jnp.any((steps < settings.max_steps) & jnp.invert(done) & (result == optx.RESULTS.successful)))

    top = 0
    try:
        while running(steps, done, result):
            z, state, steps, done, result, f = advance(settings, cost, z, state, steps, done,
                                                       result, lower, upper, data)
            top = int(jnp.max(steps))
            update(top, float(jnp.min(jnp.where(jnp.isfinite(f), f, jnp.inf))))
    finally:
        close(top)
    return finish(settings, cost, thetas, f_old, z, steps, done, result, lower, upper, data, settings.max_steps)


_RESULT_NAMES = ("successful", "nonlinear_max_steps_reached", "max_steps_reached", "nonlinear_divergence",
                 "nonfinite", "nonfinite_input", "singular", "breakdown", "stagnation", "conlim")


def result_name(result) -> str:
    """Readable name of an optimistix ``RESULTS`` item (``"successful"``, ...)."""
    for name in _RESULT_NAMES:
        item = getattr(optx.RESULTS, name, None)
        if item is not None and bool(result == item):
            return name
    return "unknown"
