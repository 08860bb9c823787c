"""The stages of [`jaxfric.identify`][jaxfric.identification.identify], each a function of what the stage before it made.

docs/algorithms.md §11. ``identify`` is this sequence::

    records   = records_stage(data, train, valid)                    # split and check (steps 2-3)
    bounds    = box_stage(model, records, box, data_bounds)          # the search box
    objective = objective_stage(model, records, dtype, head)         # J and its data (step 4)
    found     = global_stage(objective, solver, bounds, keys, ...)   # derivative-free (steps 5-6)
    polished  = gradient_stage(refine, objective, found, bounds, ...) # optional (step 7)
    fit       = fit_stage(...)                                       # metrics, diagnostics (step 8)
    baseline  = least_squares_baseline(records)                      # beside the fit (jaxfric.pipeline)

Every stage takes and returns plain values (a [`RecordSet`][jaxfric.identification.RecordSet], a [`Bounds`][jaxfric.identification.stages.Bounds],
an [`Objective`][jaxfric.identification.stages.Objective], a [`jaxfric.Solution`][jaxfric.optim.Solution], a `RefineOutcome`), so each
can be run and tested alone. The stages ``identify_motion`` runs too (keys, the global
search, member selection, the run's record) are [`jaxfric.pipeline`][jaxfric.pipeline]'s; these are
the force balance's own.

Ensembles (``keys=K``): the global stage runs the K members in one
[`jaxfric.minimise_many`][jaxfric.optim.minimise_many] call ([`ensemble_batching`][jaxfric.identification.stages.ensemble_batching]) and the
gradient stage their iterations side by side (`refine_many`); how the members share the
machine and when member ``i`` is the run with key ``i`` to the bit: docs/identify.md, "Ensembles".
"""

from __future__ import annotations

import dataclasses
import warnings
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import _xla
from ..fit import Fit, model_config, model_name, predict
from ..metrics import friction_metrics
from ..models import AbstractFrictionModel, Coulomb
from ..optim import AbstractSolver, Solution
from ..pipeline import Keys, best_member, global_search, history, key_record, solver_stages
from ..pipeline import resolve_keys  # noqa: F401  (the key stage, with identify's: stages.resolve_keys)
from ._data import Record, RecordSet, as_records
from ._diagnostics import BoundWarning, FrictionSignWarning, friction_sign, on_bound, unidentifiable
from ._objective import OutputErrorCost, cost_data, fit_scalers
from ._pooled import PooledOutputErrorCost, pooled_cost_data
from ._refine import GradientRefinement, RefineOutcome, refine_impl, refine_many, result_name
from .._timing import Stopwatch

__all__ = ["BASELINE_MODEL", "Bounds", "Objective", "box_stage", "ensemble_batching", "fit_stage",
           "global_stage", "gradient_stage", "least_squares_baseline", "objective_stage", "records_stage",
           "refine_batching"]


# ------------------------------------------------------------------ records
def records_stage(data=None, train=None, valid=None, *, stacklevel: int = 2) -> RecordSet:
    """The records of a call ([`as_records`][jaxfric.identification.as_records]), checked, with a
    [`FrictionSignWarning`][jaxfric.identification.FrictionSignWarning] when the training friction mostly pushes along the
    motion (a crossed sign convention)."""
    records = as_records(data, train, valid)
    crossed = friction_sign(records.train_velocity, records.train_friction)
    if crossed is not None:
        warnings.warn(crossed, FrictionSignWarning, stacklevel=stacklevel + 1)
    return records


# ---------------------------------------------------------------------- box
@dataclasses.dataclass(frozen=True)
class Bounds:
    """The search box of one identification.

    ``box``: the model's [`SearchBox`][jaxfric.models.SearchBox] (``None`` for the networks,
    whose box is part of the model); ``lower``, ``upper``: its bounds in search
    coordinates; ``inputs``: each record's ``(C, T)`` measured channels for the model
    (``None`` per record for a model without ``input_names``)."""

    box: Any
    lower: np.ndarray
    upper: np.ndarray
    inputs: list


def record_inputs(model: AbstractFrictionModel, records: RecordSet) -> list:
    """Each record's ``(C, T)`` measured channels for ``model`` (``None`` per record for a
    model without ``input_names``); ``ValueError`` naming the record that lacks them."""
    out = []
    for r in records.records:
        try:
            out.append(model.inputs_from(r, r.n_samples))
        except ValueError as e:
            if records.single is not None:
                raise
            raise ValueError(f"{r.name}: {e}") from None
    return out


def _train_inputs(records: RecordSet, inputs: list):
    """The training samples of every training record's channels, side by side (for the
    search box), or ``None`` for a model without them."""
    parts = [x[:, : r.n_train] for r, x in zip(records.records, inputs) if x is not None and r.n_train > 0]
    return np.concatenate(parts, axis=1) if parts else None


def box_stage(model: AbstractFrictionModel, records: RecordSet, box=None,
              data_bounds: bool = True) -> Bounds:
    """The search box: the user's ``box`` entries over the data-centred ones
    (``data_bounds``) or the §8.5 defaults ([`search_box`][jaxfric.models.AbstractPhysicalModel.search_box])."""
    inputs = record_inputs(model, records)  # fails early, naming the record
    box = model.search_box(box, *(
        (records.train_velocity, records.train_friction, _train_inputs(records, inputs))
        if data_bounds else ()))
    lower, upper = model.bounds(box)
    return Bounds(box=box, lower=lower, upper=upper, inputs=inputs)


def check_theta0(model: AbstractFrictionModel, theta0, bounds: Bounds):
    """``theta0`` checked (finite, one vector, inside the box), or ``None``."""
    if theta0 is None:
        return None
    lower, upper = bounds.lower, bounds.upper
    theta0 = model.check_theta(theta0)
    if theta0.ndim != 1:
        raise ValueError(f"theta0 must be one parameter vector, got shape {theta0.shape}")
    outside = np.flatnonzero((theta0 < lower) | (theta0 > upper))
    if outside.size:
        i = int(outside[0])
        raise ValueError(f"theta0 lies outside the search box: {model.param_names[i]} = {theta0[i]!r} not in "
                         f"[{lower[i]!r}, {upper[i]!r}] ({outside.size} such parameter(s))")
    return theta0


# ---------------------------------------------------------------- objective
@dataclasses.dataclass(frozen=True)
class Objective:
    """The cost J of §2.4 and its data: ``cost(theta, data)``; ``data`` holds the whole
    training window(s), ``data_global`` what the global stage sees (the first
    samples only under coarse-to-fine); ``scalers`` the networks' input/output maps
    (``(None, None)`` for physical models)."""

    cost: Any
    data: Any
    data_global: Any
    scalers: tuple


def objective_stage(model: AbstractFrictionModel, records: RecordSet, dtype,
                    head: int | None = None) -> Objective:
    """J for ``model`` on ``records`` in the search ``dtype``.

    ``head``: the global stage sees only the first ``head`` training samples of a
    single record (coarse-to-fine); ``None``: the whole window. The cost holds the
    model as a static field (its jit cache key) and the data travel as arrays, so a
    new record of the same length, or a new box, does not recompile.
    """
    scalers = fit_scalers(model, records)
    if records.single is not None:
        data = cost_data(model, records.single, scalers, dtype)
        cost = OutputErrorCost(model)
    else:
        data = pooled_cost_data(model, records, scalers, dtype)
        cost = PooledOutputErrorCost(model)
    data_global = data
    if head is not None and records.single is not None and records.single.n_train > head:
        data_global = eqx.tree_at(lambda d: (d.u, d.y), data, (data.u[:head], data.y[:head]))
    return Objective(cost=cost, data=data, data_global=data_global, scalers=scalers)


# ------------------------------------------------------------- global stage
#: On a CPU an ensemble's members share one batched evaluation only while a member's
#: population is smaller than this: from a few tens of candidates up the rollout is bound
#: by arithmetic, and batching the members buys nothing (measured: docs/identify.md, "Ensembles").
CPU_BATCH_SATURATION = 32


def ensemble_batching(model: AbstractFrictionModel, solver: AbstractSolver) -> str:
    """How [`global_stage`][jaxfric.identification.stages.global_stage] lays out an ensemble's members (``minimise_many``'s
    ``batching``).

    ``"vmap"`` (side by side) where that is cheaper than one member after another:
    off the CPU, and on the CPU for a one-stage population solver on a network whose
    population is smaller than [`CPU_BATCH_SATURATION`][jaxfric.identification.stages.CPU_BATCH_SATURATION] agents. ``"map"``
    otherwise on the CPU, which runs member i as the single run with key i, to the
    bit: a physical model's rollout costs no less per candidate in a larger batch, the
    default ENN swarm is already past the batch size where the network's rollout stops
    getting cheaper (docs/identify.md, "Ensembles"), and a vmapped Nelder–Mead stage
    computes every conditional batch (a shrink's n points) on every step.
    """
    if jax.default_backend() != "cpu":
        return "vmap"
    caps = solver.capabilities(model.num_params)
    small_swarm = (caps.population_size is not None and caps.population_size < CPU_BATCH_SATURATION
                   and caps.num_stages == 1)
    return "vmap" if model.needs_scaling and small_swarm else "map"


def global_stage(objective: Objective, solver: AbstractSolver, bounds: Bounds, keys: Keys, *,
                 theta0=None, dtype=None, progress=None, compiler_options="auto",
                 batching: str | None = None) -> tuple[Solution, dict]:
    """The derivative-free search on ``objective.data_global``: one
    [`jaxfric.minimise`][jaxfric.optim.minimise] run, or one [`jaxfric.minimise_many`][jaxfric.optim.minimise_many] call for an
    ensemble (``batching`` as there; default [`ensemble_batching`][jaxfric.identification.stages.ensemble_batching]). Returns the
    solution (fields with a leading member axis for an ensemble) and its
    ``{"compile_s", "run_s"}``."""
    if batching is None:
        # one member: "map" runs exactly the single run's program
        batching = ("map" if keys.members is None or keys.size == 1
                    else ensemble_batching(objective.cost.model, solver))
    return global_search(objective.cost, objective.data_global, bounds.lower, bounds.upper, solver, keys,
                         theta0=theta0, dtype=dtype, progress=progress,
                         compiler_options=compiler_options, batching=batching)


# ----------------------------------------------------------- gradient stage
def refine_batching(model: AbstractFrictionModel, settings: GradientRefinement) -> GradientRefinement:
    """``settings`` with ``batching="auto"`` resolved for ``model``: ``"vmap"`` for the
    networks, whose batched adjoint runs K members' J and gradient in one time loop, and
    off the CPU; ``"map"`` for physical models on the CPU (the same per-candidate cost
    at any batch size, [`ensemble_batching`][jaxfric.identification.stages.ensemble_batching]), which makes member i the single run
    to the bit."""
    if settings.batching != "auto":
        return settings
    side_by_side = model.needs_scaling or jax.default_backend() != "cpu"
    return dataclasses.replace(settings, batching="vmap" if side_by_side else "map")


def gradient_stage(settings: GradientRefinement | None, objective: Objective, thetas,
                   bounds: Bounds, dtype, *, ensemble: bool = False, progress=None,
                   compiler_options="auto") -> tuple[RefineOutcome | None, dict]:
    """Quasi-Newton or least-squares polish of ``thetas`` on the whole training window
    (docs/algorithms.md §11 step 7), or nothing when ``settings`` is ``None``.

    ``thetas``: ``(n,)`` for one run, ``(K, n)`` for an ensemble (``ensemble=True``),
    whose members run side by side or one after another (`refine_many`,
    [`refine_batching`][jaxfric.identification.stages.refine_batching]). Returns the
    `RefineOutcome` (with a leading member axis for an ensemble) and its
    ``{"refine_compile_s", "refine_run_s"}``."""
    if settings is None:
        return None, {}
    options = _xla.resolve(compiler_options, "rollout")
    lo, hi = jnp.asarray(bounds.lower, dtype), jnp.asarray(bounds.upper, dtype)
    with Stopwatch() as sw:
        if ensemble and jnp.shape(thetas)[0] > 1:
            out = refine_many(refine_batching(objective.cost.model, settings), objective.cost,
                              jnp.asarray(thetas), lo, hi, objective.data,
                              progress=progress, compiler_options=options)
        elif ensemble:  # one member: the single run's program, with a member axis
            out = refine_impl(settings, objective.cost, thetas[0], lo, hi, objective.data,
                              progress=progress, compiler_options=options)
            out = jax.tree_util.tree_map(lambda a: jnp.asarray(a)[None], out)
        else:
            out = refine_impl(settings, objective.cost, thetas, lo, hi, objective.data,
                              progress=progress, compiler_options=options)
        out = jax.block_until_ready(out)
    return out, {"refine_compile_s": sw.compile_s, "refine_run_s": sw.run_s}


# ----------------------------------------------------------------- baseline
#: The least-squares baseline every force-balance fit is shown beside: Coulomb + viscous +
#: offset, ``F = Fc tanh(v / v_eps) + sigma2 v + F_off`` (docs/algorithms.md §13.1).
BASELINE_MODEL = Coulomb(offset=True)


def least_squares_baseline(records: RecordSet) -> dict:
    """The least-squares baseline's §6 metrics, scored like a fit's (`record_metrics`).

    [`BASELINE_MODEL`][jaxfric.identification.stages.BASELINE_MODEL]'s exact least-squares
    solution on the pooled training windows (`Coulomb.fit_least_squares`, §13.1), its
    friction on every record (the least-squares projection, [`Coulomb.regressors`][jaxfric.models.Coulomb.regressors];
    NumPy, nothing to compile); ``"params"`` holds the solution.
    """
    model = BASELINE_MODEL
    params = model.fit_least_squares(records.train_velocity, records.train_friction)
    predictions = [sum(params[n] * col for n, col in model.regressors(r.velocity).items())
                   for r in records.records]
    return {**record_metrics(predictions, records), "params": params}


# ------------------------------------------------------------------ the fit
def _window_metrics(y_hat, record: Record) -> dict:
    """§6 metrics in newtons on the training, validation and whole record (free run
    over the whole record, so the validation window continues the training state)."""
    y_hat = np.asarray(y_hat, np.float64)
    if not np.all(np.isfinite(y_hat)):
        # Bounded models cannot get here; an exotic one might. Report, do not crash.
        return {"train": None, "valid": None, "all": None, "prediction_finite": False}
    n, f = record.n_train, record.friction
    return {
        "train": friction_metrics(f[:n], y_hat[:n]) if n and np.ptp(f[:n]) > 0 else None,
        "valid": friction_metrics(f[n:], y_hat[n:]) if n < f.size and np.ptp(f[n:]) > 0 else None,
        "all": friction_metrics(f, y_hat) if np.ptp(f) > 0 else None,
    }


def record_metrics(predictions, records: RecordSet) -> dict:
    """§6 metrics in newtons, per record and pooled over records.

    Each record is rolled out from its own initial state (``predictions[i]`` is
    record ``i``'s free run). ``train``/``valid``/``all`` pool the samples of the
    training windows, the validation windows and everything; ``records`` lists each
    record's own ``train``/``valid``/``all``. One split record gives the classic
    windows (its validation window continues the training state).
    """
    one = records.single
    if one is not None:
        out = _window_metrics(predictions[0], one)
    else:
        y_hats = [np.asarray(p, np.float64) for p in predictions]
        if not all(np.all(np.isfinite(p)) for p in y_hats):
            return {"train": None, "valid": None, "all": None, "prediction_finite": False, "records": []}

        def pooled(part):
            f = np.concatenate([r.friction[part(r)] for r in records.records])
            p = np.concatenate([y[part(r)] for y, r in zip(y_hats, records.records)])
            return friction_metrics(f, p) if f.size and np.ptp(f) > 0 else None

        out = {"train": pooled(lambda r: slice(0, r.n_train)),
               "valid": pooled(lambda r: slice(r.n_train, None)),
               "all": pooled(lambda r: slice(None))}
    per = []
    for y_hat, r in zip(predictions, records.records):
        m = _window_metrics(y_hat, r) if np.all(np.isfinite(np.asarray(y_hat))) else {}
        per.append({"name": r.name or "record", "role": r.role, "n_samples": r.n_samples,
                    "n_train": r.n_train, **{w: m.get(w) for w in ("train", "valid", "all")}})
    out["records"] = per
    return out


def stage_mse(metrics: dict) -> dict:
    """MSE %, MAX and FIT % per window of one stage's θ (so a report can compare stages)."""
    return {f"{k}_{w}": (metrics.get(w) or {}).get(k)
            for k in ("mse_percent", "max_abs", "fit_percent") for w in ("train", "valid", "all")}


def warn_if_divergent(metrics: dict, stacklevel: int = 3) -> None:
    """Warn when the free run fits the training window but not the validation window.

    A recurrent model can have several attractors; one that the training data never
    visit may capture the free run later (seen once with the Elman network at
    |r| <= 2: training 0.2 %, validation 231 %). The fit is still returned.
    """
    tr, va = metrics.get("train"), metrics.get("valid")
    if not (tr and va):
        return
    if va["mse_percent"] > max(10.0 * tr["mse_percent"], 5.0):
        warnings.warn(f"validation MSE {va['mse_percent']:.3g} % is far above training MSE "
                      f"{tr['mse_percent']:.3g} %: the free-run prediction leaves the training "
                      "behaviour (for the Elman network try another key or a smaller "
                      "context_weight_bound)", RuntimeWarning, stacklevel=stacklevel)


def members_valid_mse(member_predictions, records: RecordSet) -> list:
    """Every member's validation MSE % (§6: 100·Σe²/Σ(F − F̄)², pooled over the records'
    validation windows, as [`record_metrics`][jaxfric.identification.stages.record_metrics]' ``valid``), ``None`` for a member
    whose free run is not finite or where there is no validation window.

    ``member_predictions``: per record, the ``(K, T)`` free runs. One vectorised pass for
    all members, not the full metrics table per member (docs/scale.md)."""
    k = int(np.shape(member_predictions[0])[0])
    y = np.concatenate([np.asarray(r.friction, np.float64)[r.n_train:] for r in records.records])
    if y.size == 0 or not np.ptp(y) > 0:
        return [None] * k
    preds = [np.asarray(p, np.float64) for p in member_predictions]
    finite = np.all(np.stack([np.all(np.isfinite(p), axis=1) for p in preds]), axis=0)
    e = y - np.concatenate([p[:, r.n_train:] for p, r in zip(preds, records.records)], axis=1)
    dev = y - y.mean()
    with np.errstate(over="ignore", invalid="ignore"):
        mse = 100.0 * np.einsum("kt,kt->k", e, e) / (dev @ dev)
    return [float(m) if ok and np.isfinite(m) else None for m, ok in zip(mse, finite)]


def ensemble_summary(model, thetas, f_np, member_keys, best, member_predictions, records) -> dict:
    """``Fit.ensemble``: members, their costs and validation errors, parameter spread.

    ``member_predictions``: per record, the ``(K, T)`` free runs of the K members."""
    thetas = np.asarray(thetas)
    valid_mse = members_valid_mse(member_predictions, records)
    if model.needs_scaling:
        named = {}
    else:
        named = {k: np.asarray(v, np.float64).reshape(len(thetas))
                 for k, v in model.to_physical(jnp.asarray(thetas)).items()}
    spread = {k: {"min": float(v.min()), "p5": float(np.percentile(v, 5)),
                  "median": float(np.median(v)), "p95": float(np.percentile(v, 95)),
                  "max": float(v.max())} for k, v in named.items()}
    key_data = np.asarray(jax.random.key_data(member_keys)).reshape(len(thetas), -1).tolist()
    return {"theta": thetas, "J": [float(x) for x in f_np], "best": best,
            "valid_mse_percent": valid_mse, "keys": key_data, "spread": spread,
            "params": {k: v.tolist() for k, v in named.items()}}


def fit_stage(model: AbstractFrictionModel, records: RecordSet, bounds: Bounds,
              objective: Objective, solver: AbstractSolver, sol: Solution,
              refined: RefineOutcome | None, keys: Keys, settings: dict,
              refine: GradientRefinement | None = None, theta0_given: bool = False,
              stacklevel: int = 3) -> Fit:
    """The [`jaxfric.Fit`][jaxfric.fit.Fit]: the best member (lowest finite J), its stages, §6
    metrics per window and record, diagnostics (parameters on a bound, with a
    [`BoundWarning`][jaxfric.identification.BoundWarning] each; unidentifiable parameters), the ensemble's members."""
    scalers = objective.scalers
    ensemble = keys.members is not None

    def run_predictions(theta, batched=False):
        # members: one batched free run per record (vmap over θ reaches the model's batched
        # rollout), not K runs one after another (on a GPU each run is a sequence of kernel launches)
        return [np.asarray(jax.vmap(lambda th, r=r, x=x: predict(model, th, scalers, r.velocity, r.dt, x))(theta))
                if batched else predict(model, theta, scalers, r.velocity, r.dt, x)
                for r, x in zip(records.records, bounds.inputs)]

    thetas = jnp.atleast_2d(sol.value if refined is None else refined.theta)
    f_final = jnp.atleast_1d(sol.f if refined is None else refined.f)
    f_np = np.asarray(f_final, np.float64)
    best = best_member(f_np)
    sol_best = jax.tree_util.tree_map(lambda a: a[best], sol) if ensemble else sol
    stages = solver_stages(sol_best, solver)
    theta_opt = sol_best.value
    if refined is not None:
        stages[-1].update(stage_mse(record_metrics(run_predictions(theta_opt), records)))
        r = jax.tree_util.tree_map(lambda a: a[best], refined) if ensemble else refined
        theta = r.theta
        metrics = record_metrics(run_predictions(theta), records)
        stages.append({"stage": refine.method, "J": float(r.f), "J_refined": float(r.f_refined),
                       "improved": bool(r.improved), "num_steps": int(r.num_steps),
                       "result": result_name(r.result), **stage_mse(metrics)})
    else:
        theta = theta_opt
        metrics = record_metrics(run_predictions(theta), records)
        stages[-1].update(stage_mse(metrics))

    members = None
    if ensemble:
        members = ensemble_summary(model, thetas, f_np, keys.members, best,
                                   run_predictions(thetas, batched=True), records)
    key_data, key_impl = key_record(keys.members[best] if ensemble else keys.key)
    warn_if_divergent(metrics, stacklevel=stacklevel + 1)
    diagnostics = {"on_bound": on_bound(model, theta, bounds.box),
                   "unidentifiable": list(unidentifiable(model, records.train_velocity))}
    for d in diagnostics["on_bound"]:
        warnings.warn(f"{type(model).__name__}: {d['message']}", BoundWarning, stacklevel=stacklevel)
    return Fit(
        model=model, theta=np.asarray(theta), velocity_scaler=scalers[0], friction_scaler=scalers[1],
        dt=records.dt, n_train=records.n_train, n_samples=records.n_samples,
        metrics={**metrics, "num_params": model.num_params, "cost": float(stages[-1]["J"])},
        stages=stages, history=history(sol_best), solution=sol, key_data=key_data, key_impl=key_impl,
        seed=None if ensemble else keys.seed,
        velocity_range=(float(records.train_velocity.min()), float(records.train_velocity.max())),
        diagnostics=diagnostics, ensemble=members, box=bounds.box,
        settings={
            "model_name": model_name(model), "model_config": model_config(model), "solver": repr(solver),
            "refine": None if refine is None else {
                "method": refine.method, "max_steps": refine.max_steps,
                "rtol": refine.rtol, "atol": refine.atol, "edge": refine.edge,
                **({"batching": refine_batching(model, refine).batching} if ensemble else {})},
            **settings,
            "global_stage_samples": (int(objective.data_global.y.shape[0])
                                     if records.single is not None else None),
            "theta0_given": theta0_given,
            "cost": "mean squared scaled error" if model.needs_scaling
                    else "mean squared error / var(F_train)",
            "records": [{"name": r.name or "record", "role": r.role, "n_samples": r.n_samples}
                        for r in records.records],
            **({"ensemble_size": int(thetas.shape[0]),
                "ensemble_root_seed": keys.seed} if ensemble else {}),
        },
    )
