"""``jaxfric.identify``: model + data + optimiser → :class:`jaxfric.Fit` (docs/algorithms.md §11).

The end-to-end algorithm of §11: split and scale the record (steps 2–3), build the
cost J (step 4), run the optimiser (steps 5–7), then report metrics on the
training, validation and whole record (step 8).

Two pipelines (``method=``): ``"paper"`` is MAPSO–NMDS as the paper describes
(steps 5–6). ``"jaxfric"`` (default) is the best measured: for the networks a short
MAPSO on the first :data:`GLOBAL_STAGE_SAMPLES` training samples (coarse-to-fine),
then BFGS on the whole training window (step 7, not in the paper) with the exact
gradient of the network's hand-written adjoint; physical models keep MAPSO–NMDS.
On EMPS at 1 kHz the paper's pipeline spent 172–374 s, 70 % of it in Nelder–Mead
evaluating one 20 000-step rollout at a time; ``benchmarks/pipelines.py`` measures both.

Beyond the paper: several records (``train=[...]``, ``valid=...``; the cost pools
them, each rolled out from its own initial state, :mod:`._pooled`), an ensemble of K
keys in one :func:`jaxfric.minimise_many` call (``keys=K``), and the flags of
:mod:`._diagnostics` (parameters on a bound, unidentifiable parameters).

Everything the user passed is checked first (:mod:`._data`, the model's own
checks, the solver's ``check``), so bad input fails in milliseconds with a
``ValueError`` instead of after a long run.

``progress=`` goes to :func:`jaxfric.minimise`, which reports from inside the
compiled run, and to the gradient stage, which reports between compiled chunks.
"""

from __future__ import annotations

import dataclasses
import numbers
import warnings
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import _xla
from .. import models as _models
from ..fit import Fit, model_config, model_name, predict
from ..metrics import friction_metrics
from ..models import AbstractFrictionModel
from ..optim import MAPSO, AbstractSolver, MAPSONMDS, NelderMead, minimise, minimise_many
from ..uncertainty import assess_fit
from ._data import Record, RecordSet, as_record, as_records
from ._diagnostics import BoundWarning, FrictionSignWarning, friction_sign, on_bound, unidentifiable
from ._objective import OutputErrorCost, cost_data, fit_scalers, search_dtype
from ._pooled import PooledOutputErrorCost, pooled_cost_data
from ._refine import GradientRefinement, as_refinement, refine_impl, result_name
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

#: MAPSO generations of the paper's solver for black-box models (§3.5: "300–1000 for
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

#: ``identify``'s pipelines: ``"jaxfric"`` (default, the best measured) and ``"paper"``.
METHODS = ("jaxfric", "paper")
#: Default pipeline for the networks: MAPSO generations of the global stage. With
#: the gradient stage after it, the swarm only has to find a basin. Simulated rig,
#: 5 keys, validation MSE mean (max): G = 50 then 500 BFGS steps 0.233 (0.371) %;
#: G = 300 then 2000 steps 0.234 (0.361) % at about 5× the run time; G = 100 then
#: 500 steps 0.263 (0.431) %. EMPS at 1 kHz, 3 keys: G = 50 then 500 steps
#: 0.142–0.194 % against 0.251 % for least squares (benchmarks/pipelines.py).
FAST_GENERATIONS_BLACK_BOX = 50
#: Default pipeline for the networks: the global stage sees at most this many
#: training samples (the first ones; coarse-to-fine). A swarm generation rolls out
#: 162 candidates; on the 19 800-sample EMPS training window that cost 0.14 s, on
#: its first 2000 samples a tenth of it, and the start it gave BFGS was as good.
GLOBAL_STAGE_SAMPLES = 2000
#: Default pipeline for the networks: BFGS steps of the gradient stage on the whole
#: training window (exact gradient by the network's hand-written adjoint).
FAST_REFINE_STEPS = 500


def paper_solver(model: AbstractFrictionModel) -> MAPSONMDS:
    """The paper's MAPSO–NMDS (§5.1) sized for ``model`` (``identify(method="paper")``).

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


def _fast_pipeline(model: AbstractFrictionModel, method: str) -> bool:
    return method == "jaxfric" and model.num_params > LARGE_MODEL_PARAMS


def default_solver(model: AbstractFrictionModel, method: str = "jaxfric") -> AbstractSolver:
    """The global (derivative-free) stage of ``identify``'s ``method`` for ``model``.

    ``method="jaxfric"`` (default): for models with more than
    :data:`LARGE_MODEL_PARAMS` parameters (the networks) an 8×8 MAPSO for
    :data:`FAST_GENERATIONS_BLACK_BOX` generations, on the first
    :data:`GLOBAL_STAGE_SAMPLES` training samples, followed in ``identify`` by
    :data:`FAST_REFINE_STEPS` BFGS steps on the whole training window; for the
    physical models :func:`paper_solver`. ``method="paper"``: :func:`paper_solver`.
    """
    _check_method(method)
    if _fast_pipeline(model, method):
        return MAPSO(lattice_size=8, num_generations=FAST_GENERATIONS_BLACK_BOX)
    return paper_solver(model)


def _check_method(method) -> str:
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    return method


def resolve_model(model, options: dict | None) -> AbstractFrictionModel:
    """A model instance from an instance or a :func:`jaxfric.models.get` name.

    ``options`` go to the constructor of a named model; an unknown one is a
    ``ValueError`` listing the options the model has.
    """
    if isinstance(model, str):
        key = model.strip().lower().replace("-", "_")
        kwargs = dict(NAMED_MODEL_DEFAULTS.get(key, {}))
        kwargs.update(options or {})
        valid = [f.name for f in dataclasses.fields(type(_models.get(model)))]
        unknown = sorted(set(options or {}) - set(valid))
        if unknown:
            ranges = [k[: -len("_range")] for k in unknown
                      if k.endswith("_range") and k[: -len("_range")] in _models.DEFAULT_RANGES]
            hint = (f"; a search range is not a model option but the box: pass box={{{ranges[0]!r}: "
                    "(low, high)}" if ranges else "")
            raise ValueError(
                f"invalid options for model {model!r}: {', '.join(map(repr, unknown))}; "
                f"its options are {', '.join(valid) or '(none)'}{hint}"
            )
        try:
            return _models.get(model, **kwargs)
        except TypeError as err:
            raise ValueError(f"invalid options for model {model!r}: {err}") from None
    if isinstance(model, AbstractFrictionModel):
        if options:
            raise ValueError(
                f"model options ({', '.join(sorted(options))}) apply only to a model given by "
                f"name; configure the {type(model).__name__} instance directly"
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


def _as_keys(key, keys):
    """The members' keys of ``identify(..., keys=K)``: ``K`` keys split from ``key``, or
    the given batch. Returns ``(typed key batch, K)``."""
    if isinstance(keys, numbers.Integral) and not isinstance(keys, bool):
        if keys < 1:
            raise ValueError(f"keys must be a number of members >= 1 or a batch of keys, got {keys}")
        return jax.random.split(_as_key(key)[0], int(keys)), int(keys)
    if key is not None:
        raise ValueError("give key= (one run, or the root of keys=K) or a batch keys=[...], not both")
    k = jnp.asarray(keys)
    if jnp.issubdtype(k.dtype, jax.dtypes.prng_key) and k.ndim == 1 and k.shape[0] >= 1:
        return k, int(k.shape[0])
    if k.dtype == jnp.uint32 and k.ndim == 2 and k.shape[1] == 2 and k.shape[0] >= 1:
        return jax.random.wrap_key_data(k), int(k.shape[0])
    raise ValueError(
        "keys must be a number of members K (split from key=) or a 1-D batch of JAX PRNG keys "
        f"(jax.random.split(key, K)), got {keys!r}"
    )


def _key_record(key):
    k = jnp.asarray(key)
    if jnp.issubdtype(k.dtype, jax.dtypes.prng_key):
        return np.asarray(jax.random.key_data(k)).ravel().tolist(), str(jax.random.key_impl(k))
    return np.asarray(k).ravel().tolist(), None


def _record_inputs(model: AbstractFrictionModel, records: RecordSet) -> list:
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
    parts = [x[:, : r.n_train] for r, x in zip(records.records, inputs)
             if x is not None and r.n_train > 0]
    return np.concatenate(parts, axis=1) if parts else None


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
        "train": friction_metrics(f[:n], y_hat[:n]) if n and np.ptp(f[:n]) > 0 else None,
        "valid": friction_metrics(f[n:], y_hat[n:]) if n < f.size and np.ptp(f[n:]) > 0 else None,
        "all": friction_metrics(f, y_hat) if np.ptp(f) > 0 else None,
    }


def _record_metrics(predictions, records: RecordSet) -> dict:
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
            return {"train": None, "valid": None, "all": None, "prediction_finite": False,
                    "records": []}

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
    data=None,
    *,
    solver: AbstractSolver | None = None,
    key=None,
    keys=None,
    train=None,
    valid=None,
    refine=None,
    theta0=None,
    dtype=None,
    box=None,
    data_bounds: bool = True,
    model_options: dict | None = None,
    progress=None,
    compiler_options="auto",
    method: str = "jaxfric",
    **options,
) -> Fit:
    """Identify a friction model from a velocity/friction record (docs/algorithms.md §11).

    Args:
        model: a model instance (:class:`jaxfric.models.Elman`, :class:`~jaxfric.models.LuGre`,
            ...) or its name (``"elman"``, ``"lugre"``, ...; see
            :func:`jaxfric.models.available`). Names get :data:`NAMED_MODEL_DEFAULTS`
            (Elman: ``context_weight_bound=1``) unless ``model_options`` override them.
        data: a :class:`jaxfric.FrictionData` (the one record type, what every loader of
            :mod:`jaxfric.rig` returns) or ``(velocity, friction, dt)`` [m/s, N, s],
            split into a training and a validation window by ``train``. Leave it out to
            train on whole records (``train=[...]``, ``valid=...``).
            Its chamber pressures ``.p1``, ``.p2`` [Pa], when present, reach models that
            name them in ``input_names`` (:class:`~jaxfric.models.Cylinder`), as do
            those of each record in ``train=[...]``/``valid=...``; such a model on data
            without them raises ``ValueError`` before any optimisation, naming the record.
        solver: any jaxfric solver; default :func:`default_solver` for ``method``. ``MAPSONMDS(num_starts=k)`` refines the k best agents.
        key: a JAX PRNG key (or an int seed). Same key, same data, same fit.
        keys: an ensemble: ``K`` (an int; the members' keys are
            ``jax.random.split(key, K)``) or a batch of keys (then no ``key``). The K
            runs go through :func:`jaxfric.minimise_many` in one vmapped call; the
            returned fit is the member with the lowest training cost J, and
            ``fit.ensemble`` holds every member (``theta``, ``J``, keys, validation
            MSE %, the spread of each parameter); ``fit.predict_band(v)`` is the
            members' min-max prediction band. Member ``i`` equals
            ``identify(..., key=keys[i])`` (up to floating-point reassociation).
        train: with ``data``: training samples (int) or fraction; default the data's
            ``n_train``, else 0.8 (the paper's 1600/2000); the rest is the validation
            window and must hold at least :data:`~jaxfric.identification.MIN_VALID_SAMPLES`
            samples. Without ``data``: one record, a list of records or a mapping
            name -> record, each used whole for training; the cost pools the squared
            errors over the records, each rolled out from its own initial state.
        valid: with ``train=[...]``: one record, a list or a mapping name -> record,
            each rolled out whole from its own initial state for validation. Metrics
            per record are in ``fit.metrics["records"]``; ``train``/``valid``/``all``
            pool the samples. All records need the same sample time.
        refine: gradient stage after the solver — not in the paper. ``None`` (default):
            ``method``'s choice (BFGS, :data:`FAST_REFINE_STEPS` steps, for the networks
            under ``"jaxfric"``; none otherwise); ``False``: none; ``"bfgs"``,
            ``"lbfgs"``, ``"lm"``, ``"gauss_newton"``, ``True``/``"auto"`` (LM for small
            models, BFGS for the networks), or a :class:`GradientRefinement`.
        theta0: optional start in search coordinates (Nelder–Mead's start; one agent
            of a swarm). Must be finite and inside the box.
        dtype: floating dtype of the search; default JAX's default float (float32
            unless the caller enabled x64).
        box: the search box of a physical model, a mapping physical name -> (low, high)
            in SI units (a :class:`jaxfric.models.SearchBox`; ``"Fs_ratio"`` for Fs/Fc,
            ``"k"`` for every GMS element stiffness), e.g. ``box={"vs": (1e-4, 1.0)}``.
            May be partial: its entries replace those of the data-centred (or default)
            box, :meth:`~jaxfric.models.AbstractPhysicalModel.search_box`. The box is data,
            not part of the model, so fits with different boxes share one compiled cost.
            The Elman networks take none (their bounds are model options).
        data_bounds: centre the entries of the box the user left out on the training
            data (:func:`jaxfric.models.data_ranges`); else they are the §8.5 defaults.
            No effect on the Elman networks.
        model_options: constructor options for a model given by name
            (e.g. ``{"neurons": 20}``).
        **options: the same, as keywords: ``identify("elman", data, key=0, neurons=20)``,
            ``identify("lugre", data, key=0, stribeck_exponent=1.0)``. Unknown ones are a
            ``ValueError`` listing the model's options.
        progress: passed to :func:`jaxfric.minimise`: ``True`` for a progress bar of
            the optimiser run, a callable ``sink(phase, step, evals, f_best)``, or
            ``None`` (silent). A new display never recompiles. The gradient stage
            shows its own bar (or calls ``sink(1, step, step, J)``), which ends
            at 100 % also when the solver converges early.
        compiler_options: XLA options for the optimiser run and the gradient stage
            (their executables only): ``"auto"`` (default, see
            :func:`jaxfric.compiler_options`), ``None`` (XLA's defaults) or a dict.

        method: ``"jaxfric"`` (default, the best measured) or ``"paper"``. For the
            networks (more than :data:`LARGE_MODEL_PARAMS` parameters) ``"jaxfric"``
            runs a short MAPSO (:data:`FAST_GENERATIONS_BLACK_BOX` generations) on the
            first :data:`GLOBAL_STAGE_SAMPLES` training samples, then BFGS on the
            whole training window (benchmarks/friction.py, benchmarks/emps.py);
            ``"paper"`` runs MAPSO–NMDS exactly as the paper describes
            (:func:`paper_solver`, no gradient stage). For physical models both are
            :func:`paper_solver`. An explicit ``solver`` or ``refine`` wins.

    Cost (§2.4): J = mean squared training error of the free-run prediction, on
    [−1, 1]-scaled data for the networks, divided by the friction variance for
    physical models (so J = training MSE % / 100 there).

    Devices: the run goes where JAX puts it. One identification is mostly sequential (its
    Nelder–Mead stage evaluates one rollout at a time), so on a GPU every step is a kernel
    launch: the default ENN fit took 42 s on an H100 against 8–10 s on a 2-core CPU
    (``benchmarks/results/peers_gpu.md``). For a single fit on a GPU machine, use
    ``with jax.default_device(jax.devices("cpu")[0]): identify(...)``.

    Parameters on a bound: for physical models every parameter that ends on an edge
    of its search box is named with a :class:`BoundWarning` (which box entry to widen,
    e.g. ``box={"vs": ...}``) and in ``fit.diagnostics["on_bound"]``; parameters the model
    declares unidentifiable from these data go to ``fit.diagnostics["unidentifiable"]``.

    Returns:
        a :class:`jaxfric.Fit`.

    Raises:
        ValueError: before any optimisation, for an unknown model name, invalid model
            options (e.g. ``neurons < 1``), velocity and friction of different lengths,
            NaN/inf in the data, a record shorter than the split or a validation
            window shorter than ``MIN_VALID_SAMPLES``, records with different sample
            times, zero-variance friction, an invalid ``box`` entry or one the model does
            not search (the message names it), a non-finite or out-of-box ``theta0``, an
            invalid solver, refinement or key.
    """
    if model_options and options and set(model_options) & set(options):
        raise ValueError(
            f"model option(s) {sorted(set(model_options) & set(options))} given twice "
            "(in model_options and as keywords)"
        )
    with Stopwatch() as total:
        records = as_records(data, train, valid)
        crossed = friction_sign(records.train_velocity, records.train_friction)
        if crossed is not None:
            warnings.warn(crossed, FrictionSignWarning, stacklevel=2)
        model = resolve_model(model, {**(model_options or {}), **options})
        inputs = _record_inputs(model, records)  # fails early, naming the record
        box = model.search_box(box, *(
            (records.train_velocity, records.train_friction, _train_inputs(records, inputs))
            if data_bounds else ()))
        _check_method(method)
        coarse = solver is None and _fast_pipeline(model, method)
        if solver is None:
            solver = default_solver(model, method)
        if refine is None and _fast_pipeline(model, method):
            refine = GradientRefinement(method="bfgs", max_steps=FAST_REFINE_STEPS)
        if not isinstance(solver, AbstractSolver):
            raise ValueError(
                f"solver must be a jaxfric solver (MAPSONMDS, MAPSO, PSO, NelderMead), "
                f"got {type(solver).__name__}"
            )
        solver.check()
        settings_refine = as_refinement(refine, model.num_params)
        refine_options = _xla.resolve(compiler_options, "rollout")
        lower, upper = model.bounds(box)
        theta0 = _check_theta0(model, theta0, lower, upper)
        if keys is None:
            key, seed = _as_key(key)
            member_keys = None
        else:
            seed = key if isinstance(key, numbers.Integral) and not isinstance(key, bool) else None
            member_keys, _ = _as_keys(key, keys)
        dtype = search_dtype(dtype)

        scalers = fit_scalers(model, records)
        # The cost holds the model as a static field (its jit cache key); the box
        # travels as the (lower, upper) arrays, so a new box does not recompile.
        if records.single is not None:
            data_j = cost_data(model, records.single, scalers, dtype)
            cost = OutputErrorCost(model)
        else:
            data_j = pooled_cost_data(model, records, scalers, dtype)
            cost = PooledOutputErrorCost(model)
        # Coarse-to-fine: the default pipeline's swarm sees the first samples only.
        data_global = data_j
        if coarse and records.single is not None and records.single.n_train > GLOBAL_STAGE_SAMPLES:
            data_global = eqx.tree_at(lambda d: (d.u, d.y), data_j,
                                      (data_j.u[:GLOBAL_STAGE_SAMPLES], data_j.y[:GLOBAL_STAGE_SAMPLES]))

        def run_predictions(theta):
            return [predict(model, theta, scalers, r.velocity, r.dt, x)
                    for r, x in zip(records.records, inputs)]

        with Stopwatch() as sw:
            if member_keys is None:
                sol = minimise(cost, solver, (lower, upper), args=data_global, key=key, y0=theta0,
                               dtype=dtype, progress=progress, compiler_options=compiler_options)
            else:
                sol = minimise_many(cost, solver, (lower, upper), keys=member_keys, args=data_global,
                                    y0=theta0, dtype=dtype, progress=progress,
                                    compiler_options=compiler_options)
            sol = jax.block_until_ready(sol)
        timings = {"compile_s": sw.compile_s, "run_s": sw.run_s}
        thetas = jnp.atleast_2d(sol.value)
        f_final = jnp.atleast_1d(sol.f)

        refined = None
        if settings_refine is not None:
            lo, hi = jnp.asarray(lower, dtype), jnp.asarray(upper, dtype)
            with Stopwatch() as swr:
                # One member after another: the gradient stage runs in compiled chunks
                # between progress reports, the same program for every member.
                outs = [refine_impl(settings_refine, cost, th, lo, hi, data_j,
                                    progress=progress if member_keys is None else None,
                                    compiler_options=refine_options) for th in thetas]
                refined = jax.block_until_ready(
                    jax.tree_util.tree_map(lambda *a: jnp.stack([jnp.asarray(x) for x in a]), *outs))
            thetas, f_final = refined.theta, refined.f
            timings.update(refine_compile_s=swr.compile_s, refine_run_s=swr.run_s)

        f_np = np.asarray(f_final, np.float64)
        best = int(np.argmin(np.where(np.isfinite(f_np), f_np, np.inf)))
        sol_best = sol if member_keys is None else jax.tree_util.tree_map(lambda a: a[best], sol)
        stages = _stages(sol_best, solver)
        theta_opt = sol_best.value
        if refined is not None:
            stages[-1].update(_stage_mse(_record_metrics(run_predictions(theta_opt), records)))
            r = jax.tree_util.tree_map(lambda a: a[best], refined)
            theta = r.theta
            metrics = _record_metrics(run_predictions(theta), records)
            stages.append({
                "stage": settings_refine.method,
                "J": float(r.f),
                "J_refined": float(r.f_refined),
                "improved": bool(r.improved),
                "num_steps": int(r.num_steps),
                "result": result_name(r.result),
                **_stage_mse(metrics),
            })
        else:
            theta = theta_opt
            metrics = _record_metrics(run_predictions(theta), records)
            stages[-1].update(_stage_mse(metrics))

        ensemble = None
        if member_keys is not None:
            ensemble = _ensemble_summary(model, thetas, f_np, member_keys, best, run_predictions, records)
        key_used = key if member_keys is None else member_keys[best]
        key_data, key_impl = _key_record(key_used)
        _warn_if_divergent(metrics)
        diagnostics = {
            "on_bound": on_bound(model, theta, box),
            "unidentifiable": list(unidentifiable(model, records.train_velocity)),
        }
        for d in diagnostics["on_bound"]:
            warnings.warn(f"{type(model).__name__}: {d['message']}", BoundWarning, stacklevel=2)
        fit = Fit(
            model=model,
            theta=np.asarray(theta),
            velocity_scaler=scalers[0],
            friction_scaler=scalers[1],
            dt=records.dt,
            n_train=records.n_train,
            n_samples=records.n_samples,
            metrics={**metrics, "num_params": model.num_params, "cost": float(stages[-1]["J"])},
            stages=stages,
            history=_history(sol_best),
            solution=sol,
            key_data=key_data,
            key_impl=key_impl,
            seed=seed if member_keys is None else None,
            velocity_range=(float(records.train_velocity.min()), float(records.train_velocity.max())),
            diagnostics=diagnostics,
            ensemble=ensemble,
            box=box,
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
                "method": method,
                "global_stage_samples": (int(data_global.y.shape[0]) if records.single is not None
                                         else None),
                "theta0_given": theta0 is not None,
                "cost": "mean squared scaled error" if model.needs_scaling
                        else "mean squared error / var(F_train)",
                "records": [{"name": r.name or "record", "role": r.role, "n_samples": r.n_samples}
                            for r in records.records],
                **({"ensemble_size": int(thetas.shape[0]),
                    "ensemble_root_seed": seed} if member_keys is not None else {}),
            },
        )
    assess_fit(fit, records)  # plausibility now, parameter uncertainty on first use
    fit.timings = {**timings, "total_s": total.wall_s}
    return fit


def _ensemble_summary(model, thetas, f_np, member_keys, best, run_predictions, records) -> dict:
    """``Fit.ensemble``: members, their costs and validation errors, parameter spread."""
    thetas = np.asarray(thetas)
    valid_mse = []
    for th in thetas:
        m = _record_metrics(run_predictions(jnp.asarray(th)), records)
        valid_mse.append((m.get("valid") or {}).get("mse_percent"))
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
