"""[`jaxfric.identify`][jaxfric.identification.identify]: model + data + optimiser → [`jaxfric.Fit`][jaxfric.fit.Fit] (docs/algorithms.md §11).

The end-to-end algorithm of §11: split and scale the record (steps 2–3), build the
cost J (step 4), run the optimiser (steps 5–7), then report metrics on the
training, validation and whole record (step 8).

Two pipelines (``method=``, [`default_solver`][jaxfric.identification.default_solver]): ``"paper"`` is MAPSO–NMDS as
the paper describes (steps 5–6); ``"jaxfric"`` (default) is the best measured (docs/identify.md,
"The defaults, measured"). ``identify`` is the sequence of
[`jaxfric.identification.stages`][jaxfric.identification.stages] (docs/identify.md).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from .. import _xla
from .. import models as _models
from ..fit import Fit
from ..models import AbstractFrictionModel
from ..optim import MAPSO, AbstractSolver, MAPSONMDS, NelderMead
from ..uncertainty import assess_fit
from ._data import as_record, as_records  # noqa: F401  (re-exported: _api.as_record)
from ._objective import search_dtype
from ._refine import GradientRefinement, as_refinement
from .._timing import Stopwatch
from ..pipeline import BASELINE_LABEL, baseline_stage, check_solver
from .stages import (
    box_stage,
    least_squares_baseline,
    check_theta0,
    fit_stage,
    global_stage,
    gradient_stage,
    objective_stage,
    records_stage,
    resolve_keys,
    warn_if_divergent as _warn_if_divergent,  # noqa: F401  (tests: _api._warn_if_divergent)
)

#: Defaults applied when a model is given by *name* (explicit options win).
#: The Elman context-weight box is |r| <= 1 instead of the spec's 5 (docs/algorithms.md §2.4,
#: "jaxfric default": wider boxes diverged on validation for some keys).
NAMED_MODEL_DEFAULTS: dict[str, dict[str, Any]] = {
    "elman": {"context_weight_bound": 1.0},
}

#: MAPSO generations of the paper's solver for black-box models (§3.5: "300–1000 for
#: the ENN"; more did not help on the simulated rig: docs/algorithms.md §3.5).
DEFAULT_GENERATIONS_BLACK_BOX = 300
#: MAPSO generations of the default solver for physical models (a few parameters).
DEFAULT_GENERATIONS_PHYSICAL = 200
#: Above this many parameters the default lattice is 8×8 = 64 agents (§3.5), else 5×5.
LARGE_MODEL_PARAMS = 20

#: ``identify``'s pipelines: ``"jaxfric"`` (default, the best measured) and ``"paper"``.
METHODS = ("jaxfric", "paper")
#: Default pipeline for the networks: MAPSO generations of the global stage. With
#: the gradient stage after it, the swarm only has to find a basin (measured:
#: docs/identify.md, "The defaults, measured").
FAST_GENERATIONS_BLACK_BOX = 50
#: Default pipeline for the networks: the global stage sees at most this many
#: training samples (the first ones; coarse-to-fine; docs/identify.md, "The defaults, measured").
GLOBAL_STAGE_SAMPLES = 2000
#: Default pipeline for the networks: BFGS steps of the gradient stage on the whole
#: training window (exact gradient by the network's hand-written adjoint).
FAST_REFINE_STEPS = 500


def paper_solver(model: AbstractFrictionModel) -> MAPSONMDS:
    """The paper's MAPSO–NMDS (§5.1) sized for ``model`` (``identify(method="paper")``).

    * more than `LARGE_MODEL_PARAMS` parameters (the Elman networks): an 8×8
      lattice (64 agents, §3.5) for [`DEFAULT_GENERATIONS_BLACK_BOX`][jaxfric.identification.DEFAULT_GENERATIONS_BLACK_BOX] generations;
    * otherwise (LuGre, Dahl, static maps): a 5×5 lattice for
      [`DEFAULT_GENERATIONS_PHYSICAL`][jaxfric.identification.DEFAULT_GENERATIONS_PHYSICAL] generations.

    Nelder–Mead gets fminsearch's budget, MaxIter = MaxFunEvals = 200·n (§5), and
    starts from a simplex sized by the swarm's final spread
    (``MAPSONMDS.simplex_from_swarm``). The evaluation cap matters in 180-D, where a
    shrink costs n evaluations.
    """
    n = model.num_params
    if n > LARGE_MODEL_PARAMS:
        mapso = MAPSO(lattice_size=8, num_generations=DEFAULT_GENERATIONS_BLACK_BOX)
    else:
        mapso = MAPSO(lattice_size=5, num_generations=DEFAULT_GENERATIONS_PHYSICAL)
    return MAPSONMDS(mapso=mapso, nelder_mead=NelderMead(max_steps=200 * n, max_evals=200 * n))


def fast_pipeline(model: AbstractFrictionModel, method: str) -> bool:
    """Whether ``identify``'s ``method`` runs jaxfric's pipeline for the networks on
    ``model``: a short swarm on the first training samples, then the gradient stage
    (``method="jaxfric"`` and more than `LARGE_MODEL_PARAMS` parameters)."""
    return method == "jaxfric" and model.num_params > LARGE_MODEL_PARAMS


def default_solver(model: AbstractFrictionModel, method: str = "jaxfric") -> AbstractSolver:
    """The global (derivative-free) stage of ``identify``'s ``method`` for ``model``.

    ``method="jaxfric"`` (default): for models with more than
    `LARGE_MODEL_PARAMS` parameters (the networks) an 8×8 MAPSO for
    [`FAST_GENERATIONS_BLACK_BOX`][jaxfric.identification.FAST_GENERATIONS_BLACK_BOX] generations, on the first
    [`GLOBAL_STAGE_SAMPLES`][jaxfric.identification.GLOBAL_STAGE_SAMPLES] training samples, followed in ``identify`` by
    [`FAST_REFINE_STEPS`][jaxfric.identification.FAST_REFINE_STEPS] BFGS steps on the whole training window; for the
    physical models [`paper_solver`][jaxfric.identification.paper_solver]. ``method="paper"``: [`paper_solver`][jaxfric.identification.paper_solver].
    """
    _check_method(method)
    if fast_pipeline(model, method):
        return MAPSO(lattice_size=8, num_generations=FAST_GENERATIONS_BLACK_BOX)
    return paper_solver(model)


#: What a force-balance fit worse than the baseline should try ([`jaxfric.pipeline.warn_if_worse`][jaxfric.pipeline.warn_if_worse]).
BASELINE_ADVICE = ("the search did not reach its optimum or the model cannot express the baseline: use the "
                   "baseline, another key, a longer search (solver=...) or a gradient stage (refine=...)")


def _check_method(method) -> str:
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    return method


def resolve_model(model, options: dict | None) -> AbstractFrictionModel:
    """A model instance from an instance or a [`jaxfric.models.get`][jaxfric.models.get] name.

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
            raise ValueError(f"invalid options for model {model!r}: {', '.join(map(repr, unknown))}; "
                             f"its options are {', '.join(valid) or '(none)'}{hint}")
        try:
            return _models.get(model, **kwargs)
        except TypeError as err:
            raise ValueError(f"invalid options for model {model!r}: {err}") from None
    if isinstance(model, AbstractFrictionModel):
        if options:
            raise ValueError(f"model options ({', '.join(sorted(options))}) apply only to a model given by "
                             f"name; configure the {type(model).__name__} instance directly")
        return model
    raise ValueError(f"model must be a friction model instance or a name ({', '.join(_models.available())}), "
                     f"got {type(model).__name__}")


def identify(model, data=None, *, solver: AbstractSolver | None = None, key=None, keys=None, train=None,
             valid=None, refine=None, theta0=None, dtype=None, box=None, data_bounds: bool = True,
             model_options: dict | None = None, progress=None, compiler_options="auto", method: str = "jaxfric",
             **options) -> Fit:
    """Identify a friction model from a velocity/friction record (docs/algorithms.md §11).

    Args:
        model: a model instance ([`jaxfric.models.Elman`][jaxfric.models.Elman], [`LuGre`][jaxfric.models.LuGre],
            ...) or its name (``"elman"``, ``"lugre"``, ...; see
            [`jaxfric.models.available`][jaxfric.models.available]). Names get [`NAMED_MODEL_DEFAULTS`][jaxfric.identification.NAMED_MODEL_DEFAULTS]
            (Elman: ``context_weight_bound=1``) unless ``model_options`` override them.
        data: a [`jaxfric.FrictionData`][jaxfric.rig.FrictionData] (the one record type, what every loader of
            [`jaxfric.rig`][jaxfric.rig] returns) or ``(velocity, friction, dt)`` [m/s, N, s],
            split into a training and a validation window by ``train``. Leave it out to
            train on whole records (``train=[...]``, ``valid=...``).
            Its chamber pressures ``.p1``, ``.p2`` [Pa], when present, reach models that
            name them in ``input_names`` ([`Cylinder`][jaxfric.models.Cylinder]), as do
            those of each record in ``train=[...]``/``valid=...``; such a model on data
            without them raises ``ValueError`` before any optimisation, naming the record.
        solver: any jaxfric solver; default [`default_solver`][jaxfric.identification.default_solver] for ``method``. ``MAPSONMDS(num_starts=k)`` refines the k best agents.
        key: a JAX PRNG key (or an int seed). Same key, same data, same fit.
        keys: an ensemble: ``K`` (an int; the members' keys are
            ``jax.random.split(key, K)``) or a batch of keys (then no ``key``). The
            global stage runs the K members in one [`jaxfric.minimise_many`][jaxfric.optim.minimise_many] call
            and the gradient stage runs their iterations side by side (docs/identify.md);
            the returned fit is the member with the lowest finite training cost J, and
            ``fit.ensemble`` holds every member (``theta``, ``J``, keys, validation
            MSE %, the spread of each parameter); ``fit.predict_band(v)`` is the
            members' min-max prediction band. Member ``i`` equals
            ``identify(..., key=keys[i])`` (when to the bit: docs/identify.md).
        train: with ``data``: training samples (int) or fraction; default the data's
            ``n_train``, else 0.8 (the paper's 1600/2000); the rest is the validation
            window and must hold at least [`MIN_VALID_SAMPLES`][jaxfric.identification.MIN_VALID_SAMPLES]
            samples. Without ``data``: one record, a list of records or a mapping
            name -> record, each used whole for training; the cost pools the squared
            errors over the records, each rolled out from its own initial state.
        valid: with ``train=[...]``: one record, a list or a mapping name -> record,
            each rolled out whole from its own initial state for validation. Metrics
            per record are in ``fit.metrics["records"]``; ``train``/``valid``/``all``
            pool the samples. All records need the same sample time.
        refine: gradient stage after the solver — not in the paper. ``None`` (default):
            ``method``'s choice (BFGS, [`FAST_REFINE_STEPS`][jaxfric.identification.FAST_REFINE_STEPS] steps, for the networks
            under ``"jaxfric"``; none otherwise); ``False``: none; ``"bfgs"``,
            ``"lbfgs"``, ``"lm"``, ``"gauss_newton"``, ``True``/``"auto"`` (LM for small
            models, BFGS for the networks), or a [`GradientRefinement`][jaxfric.identification.GradientRefinement].
        theta0: optional start in search coordinates (Nelder–Mead's start; one agent
            of a swarm). Must be finite and inside the box.
        dtype: floating dtype of the search; default JAX's default float (float32
            unless the caller enabled x64).
        box: the search box of a physical model, a mapping physical name -> (low, high)
            in SI units (a [`jaxfric.models.SearchBox`][jaxfric.models.SearchBox]; ``"Fs_ratio"`` for Fs/Fc,
            ``"k"`` for every GMS element stiffness), e.g. ``box={"vs": (1e-4, 1.0)}``.
            May be partial: its entries replace those of the data-centred (or default)
            box, [`search_box`][jaxfric.models.AbstractPhysicalModel.search_box]. The box is data,
            not part of the model, so fits with different boxes share one compiled cost.
            The Elman networks take none (their bounds are model options).
        data_bounds: centre the entries of the box the user left out on the training
            data ([`jaxfric.models.data_ranges`][jaxfric.models.data_ranges]); else they are the §8.5 defaults.
            No effect on the Elman networks.
        model_options: constructor options for a model given by name
            (e.g. ``{"neurons": 20}``).
        **options: the same, as keywords: ``identify("elman", data, key=0, neurons=20)``,
            ``identify("lugre", data, key=0, stribeck_exponent=1.0)``. Unknown ones are a
            ``ValueError`` listing the model's options.
        progress: passed to [`jaxfric.minimise`][jaxfric.optim.minimise]: ``True`` for a progress bar of
            the optimiser run, a callable ``sink(phase, step, evals, f_best)``, or
            ``None`` (silent). A new display never recompiles. The gradient stage
            shows its own bar (or calls ``sink(1, step, step, J)``), which ends
            at 100 % also when the solver converges early.
        compiler_options: XLA options for the optimiser run and the gradient stage
            (their executables only): ``"auto"`` (default, see
            [`jaxfric.compiler_options`][jaxfric._xla.compiler_options]), ``"fast-compile"`` (LLVM
            at level 0: less compilation, slower runs), ``None`` (XLA's defaults) or a dict.
        method: ``"jaxfric"`` (default, the best measured) or ``"paper"`` (MAPSO–NMDS exactly
            as the paper describes, no gradient stage): what each runs is
            [`default_solver`][jaxfric.identification.default_solver]'s. An explicit ``solver`` or ``refine`` wins.

    Cost (§2.4): J = mean squared training error of the free-run prediction, on
    [−1, 1]-scaled data for the networks, divided by the friction variance for
    physical models (so J = training MSE % / 100 there).

    Devices: the run goes where JAX puts it; one fit is mostly sequential and runs faster
    on a CPU than on a GPU (docs/scale.md, "Time loops per platform").

    The baseline: every fit carries the least-squares Coulomb + viscous + offset solution,
    scored on the same windows, in ``fit.metrics["baseline"]`` (its parameters in
    ``fit.settings["baseline"]``); a fit worse on its training data warns
    ([`BaselineWarning`][jaxfric.motion.BaselineWarning]; docs/identify.md, "The baseline").

    Parameters on a bound: for physical models every parameter that ends on an edge
    of its search box is named with a [`BoundWarning`][jaxfric.identification.BoundWarning] (which box entry to widen,
    e.g. ``box={"vs": ...}``) and in ``fit.diagnostics["on_bound"]``; parameters the model
    declares unidentifiable from these data go to ``fit.diagnostics["unidentifiable"]``.

    Returns:
        a [`jaxfric.Fit`][jaxfric.fit.Fit].

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
        raise ValueError(f"model option(s) {sorted(set(model_options) & set(options))} given twice "
                         "(in model_options and as keywords)")
    with Stopwatch() as total:
        # Every check first, so bad input fails before any long computation.
        records = records_stage(data, train, valid, stacklevel=3)
        model = resolve_model(model, {**(model_options or {}), **options})
        bounds = box_stage(model, records, box, data_bounds)
        solver, refine, head = _plan(model, method, solver, refine)
        theta0 = check_theta0(model, theta0, bounds)
        keys = resolve_keys(key, keys)
        dtype = search_dtype(dtype)
        _xla.resolve(compiler_options, "rollout")  # checked here; each stage resolves its own

        objective = objective_stage(model, records, dtype, head)
        sol, timings = global_stage(objective, solver, bounds, keys, theta0=theta0, dtype=dtype,
                                    progress=progress, compiler_options=compiler_options)
        refined, refine_timings = gradient_stage(
            refine, objective, sol.value, bounds, dtype, ensemble=keys.members is not None,
            progress=progress, compiler_options=compiler_options)
        base = least_squares_baseline(records)
        fit = fit_stage(model, records, bounds, objective, solver, sol, refined, keys,
                        settings={"dtype": str(np.dtype(dtype)), "data_bounds": bool(data_bounds),
                                  "method": method,
                                  "baseline": {"model": BASELINE_LABEL, "params": base["params"]}},
                        refine=refine, theta0_given=theta0 is not None)
        fit = baseline_stage(fit, base, label=BASELINE_LABEL, advice=BASELINE_ADVICE, stacklevel=2)
    fit = assess_fit(fit, records)  # plausibility now, parameter uncertainty on first use
    return fit.replace(timings={**timings, **refine_timings, "total_s": total.wall_s})


def _plan(model: AbstractFrictionModel, method: str, solver, refine):
    """``identify``'s stages for ``method``: ``(solver, gradient-stage settings or None,
    samples the global stage sees or None)``, the user's ``solver`` and ``refine``
    winning over the method's; checked."""
    _check_method(method)
    fast = fast_pipeline(model, method)
    head = GLOBAL_STAGE_SAMPLES if solver is None and fast else None
    if solver is None:
        solver = default_solver(model, method)
    if refine is None and fast:
        refine = GradientRefinement(method="bfgs", max_steps=FAST_REFINE_STEPS)
    return check_solver(solver), as_refinement(refine, model.num_params), head
