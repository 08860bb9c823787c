"""``jaxfric.identify``: model + data + optimiser → :class:`jaxfric.Fit` (ALGORITHMS.md §11).

The end-to-end algorithm of §11: split and scale the record (steps 2–3), build the
cost J (step 4), run the global + local optimiser (steps 5–6, MAPSO–NMDS by
default), optionally polish with gradients (step 7, not in the paper), then
report metrics on the training, validation and whole record (step 8).

Everything the user passed is checked first (:mod:`._data`, the model's own
checks, the solver's ``check``), so bad input fails in milliseconds with a
``ValueError`` instead of after a long run.

``progress=`` goes to :func:`jaxfric.minimise`, which reports from inside the
compiled run; the gradient stage is one short call after it.
"""

from __future__ import annotations

import numbers
import warnings
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .. import _xla
from .. import models as _models
from ..fit import Fit, model_config, model_name, predict, rollout_model
from ..metrics import friction_metrics
from ..models import AbstractFrictionModel
from ..optim import MAPSO, AbstractSolver, MAPSONMDS, NelderMead, minimise
from ._data import Record, as_record
from ._objective import OutputErrorCost, cost_data, fit_scalers, search_dtype
from ._refine import as_refinement, refine_impl, result_name
from ._timing import Stopwatch

#: Defaults applied when a model is given by *name* (explicit options win).
#: The Elman context-weight box is |r| <= 1 instead of the spec's 5 (§2.4): with 5
#: about 98 % of random networks are chaotic over 1600 samples (models/elman.py), and
#: on the simulated rig (benchmarks/results/friction.md, 5 keys) no gradient-refined
#: network with |r| <= 1 diverged on the validation window, while wider boxes did on
#: some keys (worst validation MSE 0.41 % against 82 % for |r| <= 5).
NAMED_MODEL_DEFAULTS: dict[str, dict[str, Any]] = {
    "elman": {"context_weight_bound": 1.0},
}

#: MAPSO generations of the default solver for black-box models (§3.5: "300–1000 for
#: the ENN"). 300 generations (48 600 evaluations) + Nelder–Mead's 36 000 take about
#: 13 s for the 30-neuron network on an idle 2-core CPU, compile time apart. More
#: generations did not help on the simulated rig: after BFGS, 9 keys at G = 300 gave
#: validation MSE 0.15–0.28 %, 6 keys at G = 500 gave 0.24–0.46 % (a swarm that has
#: converged further hands Nelder–Mead a smaller simplex, see
#: ``MAPSONMDS.simplex_from_swarm``); benchmarks/friction.py compares 300, 500, 1000.
DEFAULT_GENERATIONS_BLACK_BOX = 300
#: MAPSO generations of the default solver for physical models (a few parameters).
DEFAULT_GENERATIONS_PHYSICAL = 200
#: Above this many parameters the default lattice is 8×8 = 64 agents (§3.5), else 5×5.
LARGE_MODEL_PARAMS = 20


def default_solver(model: AbstractFrictionModel) -> MAPSONMDS:
    """The paper's MAPSO–NMDS (§5.1) sized for ``model``.

    * more than :data:`LARGE_MODEL_PARAMS` parameters (the Elman networks): an 8×8
      lattice (64 agents, §3.5) for :data:`DEFAULT_GENERATIONS_BLACK_BOX` generations;
    * otherwise (LuGre, Dahl, static maps): a 5×5 lattice for
      :data:`DEFAULT_GENERATIONS_PHYSICAL` generations.

    Nelder–Mead gets fminsearch's budget, MaxIter = MaxFunEvals = 200·n (§5), and
    starts from a simplex sized by the swarm's final spread
    (``MAPSONMDS.simplex_from_swarm``). The evaluation cap matters in 180-D: a
    shrink costs n evaluations, and an iteration cap alone once let one run spend
    600 000 evaluations (86 s).
    """
    n = model.num_params
    if n > LARGE_MODEL_PARAMS:
        mapso = MAPSO(lattice_size=8, num_generations=DEFAULT_GENERATIONS_BLACK_BOX)
    else:
        mapso = MAPSO(lattice_size=5, num_generations=DEFAULT_GENERATIONS_PHYSICAL)
    return MAPSONMDS(mapso=mapso, nelder_mead=NelderMead(max_steps=200 * n, max_evals=200 * n))


def resolve_model(model, options: dict | None) -> AbstractFrictionModel:
    """A model instance from an instance or a :func:`jaxfric.models.get` name."""
    if isinstance(model, str):
        key = model.strip().lower().replace("-", "_")
        kwargs = dict(NAMED_MODEL_DEFAULTS.get(key, {}))
        kwargs.update(options or {})
        try:
            return _models.get(model, **kwargs)
        except TypeError as err:
            raise ValueError(f"invalid options for model {model!r}: {err}") from None
    if isinstance(model, AbstractFrictionModel):
        if options:
            raise ValueError(
                "model_options apply only to a model given by name; configure the "
                f"{type(model).__name__} instance directly"
            )
        return model
    raise ValueError(
        f"model must be a friction model instance or a name ({', '.join(_models.available())}), "
        f"got {type(model).__name__}"
    )


def _as_key(key):
    if key is None:
        raise ValueError("key is required: pass jax.random.key(seed) (or an int seed)")
    if isinstance(key, numbers.Integral) and not isinstance(key, bool):
        return jax.random.key(int(key)), int(key)
    k = jnp.asarray(key)
    typed = jnp.issubdtype(k.dtype, jax.dtypes.prng_key)
    if not ((typed and k.shape == ()) or (k.dtype == jnp.uint32 and k.shape == (2,))):
        raise ValueError(
            f"key must be one JAX PRNG key (jax.random.key(seed)) or an int seed, got "
            f"{'a batch of keys of shape ' + str(k.shape) if typed else repr(key)}"
        )
    return key, None


def _key_record(key):
    k = jnp.asarray(key)
    if jnp.issubdtype(k.dtype, jax.dtypes.prng_key):
        return np.asarray(jax.random.key_data(k)).ravel().tolist(), str(jax.random.key_impl(k))
    return np.asarray(k).ravel().tolist(), None


def _check_theta0(model, theta0, lower, upper):
    if theta0 is None:
        return None
    theta0 = model.check_theta(theta0)
    if theta0.ndim != 1:
        raise ValueError(f"theta0 must be one parameter vector, got shape {theta0.shape}")
    outside = np.flatnonzero((theta0 < lower) | (theta0 > upper))
    if outside.size:
        i = int(outside[0])
        raise ValueError(
            f"theta0 lies outside the search box: {model.param_names[i]} = {theta0[i]!r} not in "
            f"[{lower[i]!r}, {upper[i]!r}] ({outside.size} such parameter(s))"
        )
    return theta0


def _stages(sol, solver) -> list[dict]:
    stats = {k: int(v) if np.issubdtype(np.asarray(v).dtype, np.integer) else float(v)
             for k, v in sol.stats.items()}
    if "f_global" in stats:
        n_global = stats["num_evals_global"]
        # the chain's own global stage (MAPSO, PSO, Evosax, ...), not always MAPSO
        g_name = type(solver.global_solver).__name__.lower()
        return [
            {"stage": g_name, "J": stats["f_global"], "num_evals": n_global},
            {"stage": "nelder_mead", "J": float(sol.f), "num_evals": stats["num_evals"] - n_global},
        ]
    return [{"stage": type(solver).__name__.lower(), "J": float(sol.f),
             "num_evals": stats["num_evals"]}]


def _history(sol) -> dict[str, np.ndarray]:
    n = int(sol.history.length)
    return {"evals": np.asarray(sol.history.evals)[:n], "f": np.asarray(sol.history.f)[:n]}


def _window_metrics(y_hat, record: Record) -> dict:
    """§6 metrics in newtons on the training, validation and whole record (free run
    over the whole record, so the validation window continues the training state)."""
    y_hat = np.asarray(y_hat, np.float64)
    if not np.all(np.isfinite(y_hat)):
        # Bounded models cannot get here; an exotic one might. Report, do not crash.
        return {"train": None, "valid": None, "all": None, "prediction_finite": False}
    n, f = record.n_train, record.friction
    return {
        "train": friction_metrics(f[:n], y_hat[:n]),
        "valid": friction_metrics(f[n:], y_hat[n:]) if np.ptp(f[n:]) > 0 else None,
        "all": friction_metrics(f, y_hat),
    }


def _stage_mse(metrics: dict) -> dict:
    """MSE %, MAX and FIT % per window of one stage's θ (so a report can compare stages)."""
    return {f"{k}_{w}": (metrics.get(w) or {}).get(k)
            for k in ("mse_percent", "max_abs", "fit_percent") for w in ("train", "valid", "all")}


def _warn_if_divergent(metrics: dict) -> None:
    """Warn when the free run fits the training window but not the validation window.

    A recurrent model can have several attractors; one that the training data never
    visit may capture the free run later (seen once with the Elman network at
    |r| <= 2: training 0.2 %, validation 231 %). The fit is still returned.
    """
    tr, va = metrics.get("train"), metrics.get("valid")
    if not (tr and va):
        return
    if va["mse_percent"] > max(10.0 * tr["mse_percent"], 5.0):
        warnings.warn(
            f"validation MSE {va['mse_percent']:.3g} % is far above training MSE "
            f"{tr['mse_percent']:.3g} %: the free-run prediction leaves the training "
            "behaviour (for the Elman network try another key or a smaller "
            "context_weight_bound)",
            RuntimeWarning,
            stacklevel=3,
        )


def identify(
    model,
    data,
    *,
    solver: AbstractSolver | None = None,
    key,
    train: int | float | None = None,
    refine=None,
    theta0=None,
    dtype=None,
    data_bounds: bool = True,
    model_options: dict | None = None,
    progress=None,
    compiler_options="auto",
) -> Fit:
    """Identify a friction model from a velocity/friction record (ALGORITHMS.md §11).

    Args:
        model: a model instance (:class:`jaxfric.models.Elman`, :class:`~jaxfric.models.LuGre`,
            ...) or its name (``"elman"``, ``"lugre"``, ...; see
            :func:`jaxfric.models.available`). Names get :data:`NAMED_MODEL_DEFAULTS`
            (Elman: ``context_weight_bound=1``) unless ``model_options`` override them.
        data: a ``jaxfric.rig.FrictionData`` (or any object with ``.velocity`` [m/s],
            ``.friction`` [N], ``.dt`` [s] and ``.n_train``) or ``(velocity, friction, dt)``.
        solver: any jaxfric solver; default :func:`default_solver` (the paper's
            MAPSO–NMDS). ``MAPSONMDS(num_starts=k)`` refines the k best agents.
        key: a JAX PRNG key (or an int seed). Same key, same data, same fit.
        train: training samples (int) or fraction; default the data's ``n_train``,
            else 0.8 (the paper's 1600/2000). The rest is the validation window.
        refine: gradient stage after the solver — not in the paper. ``None`` (default,
            the paper's method), ``"bfgs"``, ``"lbfgs"``, ``"lm"``, ``"gauss_newton"``,
            ``True``/``"auto"`` (LM for small models, BFGS for the networks), or a
            :class:`GradientRefinement`.
        theta0: optional start in search coordinates (Nelder–Mead's start; one agent
            of a swarm). Must be finite and inside the box.
        dtype: floating dtype of the search; default JAX's default float (float32
            unless the caller enabled x64).
        data_bounds: centre the unset search ranges of physical models on the training
            data (``model.with_data_bounds``); no effect on the Elman networks.
        model_options: constructor options for a model given by name
            (e.g. ``{"neurons": 20}``).
        progress: passed to :func:`jaxfric.minimise`: ``True`` for a progress bar of
            the optimiser run, a callable ``sink(phase, step, evals, f_best)``, or
            ``None`` (silent). A new display never recompiles.
        compiler_options: XLA options for the optimiser run and the gradient stage
            (their executables only): ``"auto"`` (default, see
            :func:`jaxfric.compiler_options`), ``None`` (XLA's defaults) or a dict.

    Cost (§2.4): J = mean squared training error of the free-run prediction, on
    [−1, 1]-scaled data for the networks, divided by the friction variance for
    physical models (so J = training MSE % / 100 there).

    Devices: the run goes where JAX puts it. One identification is mostly sequential (its
    Nelder–Mead stage evaluates one rollout at a time), so on a GPU every step is a kernel
    launch: the default ENN fit took 42 s on an H100 against 8–10 s on a 2-core CPU
    (``benchmarks/results/peers_gpu.md``). For a single fit on a GPU machine, use
    ``with jax.default_device(jax.devices("cpu")[0]): identify(...)``.

    Returns:
        a :class:`jaxfric.Fit`.

    Raises:
        ValueError: before any optimisation, for an unknown model name, invalid model
            options (e.g. ``neurons < 1``), velocity and friction of different lengths,
            NaN/inf in the data, a record shorter than the split or an empty validation
            window, zero-variance friction, a non-finite or out-of-box ``theta0``, an
            invalid solver, refinement or key.
    """
    with Stopwatch() as total:
        record = as_record(data, train)
        model = resolve_model(model, model_options)
        if data_bounds:
            model = model.with_data_bounds(record.train_velocity, record.train_friction)
        if solver is None:
            solver = default_solver(model)
        if not isinstance(solver, AbstractSolver):
            raise ValueError(
                f"solver must be a jaxfric solver (MAPSONMDS, MAPSO, PSO, NelderMead), "
                f"got {type(solver).__name__}"
            )
        solver.check()
        settings_refine = as_refinement(refine, model.num_params)
        refine_options = _xla.resolve(compiler_options, "rollout")
        lower, upper = model.bounds()
        theta0 = _check_theta0(model, theta0, lower, upper)
        key, seed = _as_key(key)
        dtype = search_dtype(dtype)

        scalers = fit_scalers(model, record)
        data_j = cost_data(model, record, scalers, dtype)
        # The cost holds the model as a *static* field (its jit cache key). Search
        # ranges shape only the box, which travels as arrays, so the cost gets the
        # model with its ranges cleared: a new record (new data-centred box) does
        # not recompile.
        cost = OutputErrorCost(rollout_model(model))

        with Stopwatch() as sw:
            sol = minimise(cost, solver, (lower, upper), args=data_j, key=key, y0=theta0,
                           dtype=dtype, progress=progress, compiler_options=compiler_options)
            sol = jax.block_until_ready(sol)
        stages = _stages(sol, solver)
        timings = {"compile_s": sw.compile_s, "run_s": sw.run_s}
        theta = sol.value
        metrics = _window_metrics(predict(model, theta, scalers, record.velocity, record.dt), record)
        stages[-1].update(_stage_mse(metrics))

        if settings_refine is not None:
            lo, hi = jnp.asarray(lower, dtype), jnp.asarray(upper, dtype)
            with Stopwatch() as swr:
                run_refine = _xla.filter_jit(refine_impl, refine_options)
                out = jax.block_until_ready(run_refine(settings_refine, cost, theta, lo, hi, data_j))
            theta = out.theta
            metrics = _window_metrics(
                predict(model, theta, scalers, record.velocity, record.dt), record)
            stages.append({
                "stage": settings_refine.method,
                "J": float(out.f),
                "J_refined": float(out.f_refined),
                "improved": bool(out.improved),
                "num_steps": int(out.num_steps),
                "result": result_name(out.result),
                **_stage_mse(metrics),
            })
            timings.update(refine_compile_s=swr.compile_s, refine_run_s=swr.run_s)

        key_data, key_impl = _key_record(key)
        _warn_if_divergent(metrics)
        fit = Fit(
            model=model,
            theta=np.asarray(theta),
            velocity_scaler=scalers[0],
            friction_scaler=scalers[1],
            dt=record.dt,
            n_train=record.n_train,
            n_samples=record.n_samples,
            metrics={**metrics, "num_params": model.num_params, "cost": float(stages[-1]["J"])},
            stages=stages,
            history=_history(sol),
            solution=sol,
            key_data=key_data,
            key_impl=key_impl,
            seed=seed,
            settings={
                "model_name": model_name(model),
                "model_config": model_config(model),
                "solver": repr(solver),
                "refine": None if settings_refine is None else {
                    "method": settings_refine.method, "max_steps": settings_refine.max_steps,
                    "rtol": settings_refine.rtol, "atol": settings_refine.atol,
                    "edge": settings_refine.edge},
                "dtype": str(np.dtype(dtype)),
                "data_bounds": bool(data_bounds),
                "theta0_given": theta0 is not None,
                "cost": "mean squared scaled error" if model.needs_scaling
                        else "mean squared error / var(F_train)",
            },
        )
    fit.timings = {**timings, "total_s": total.wall_s}
    return fit
