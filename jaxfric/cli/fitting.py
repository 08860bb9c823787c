"""Models, solvers and budgets for the command line, and the calls to ``jaxfric.identify``.

Models are passed to ``identify`` by *name* (with ``model_options``), so the command
line gets the library's named-model defaults (e.g. the Elman context-weight box).

Budget: without ``--generations`` / ``--nm-evals`` the library's
:func:`jaxfric.identify.default_solver` is used (MAPSO–NMDS sized for the model: an 8×8
lattice and 300 generations for the ENN, 5×5 and 200 for LuGre; Nelder–Mead with
fminsearch's 200·n iterations). ``jaxfric demo`` with those finishes in about 1.5 min
on a 2-core laptop, compilation included. ``--generations`` / ``--nm-evals`` change
the budget of the same solver; ``--quick`` shrinks it to a smoke test (3 generations,
200 Nelder–Mead evaluations), which compiles exactly the same programs, so it also
warms the compilation cache.
"""

from __future__ import annotations

import inspect
import sys
import time
import warnings
from dataclasses import dataclass

from .errors import UserError

QUICK_GENERATIONS = 3
QUICK_NM_EVALS = 200
REFINE_CHOICES = ("none", "auto", "bfgs", "lbfgs", "lm", "gauss_newton")

LABELS = {"elman": "ENN", "elman_full": "ENN (full context)", "lugre": "LuGre", "dahl": "Dahl",
          "stribeck": "Stribeck", "coulomb": "Coulomb"}


@dataclass(frozen=True)
class Budget:
    """Solver budget; ``None`` fields keep the library default."""

    generations: int | None
    nm_evals: int | None

    @property
    def is_default(self) -> bool:
        return self.generations is None and self.nm_evals is None


def check_models(names) -> list[str]:
    """Validate model names against :func:`jaxfric.models.available` (one-line error)."""
    from jaxfric import models

    known = models.available()
    for name in names:
        if name not in known:
            raise UserError(f"unknown model {name!r}; choose from {', '.join(known)}")
    return list(names)


def model_options(name: str, args) -> dict | None:
    """``model_options`` for :func:`jaxfric.identify` (the neuron count of the networks)."""
    return {"neurons": args.neurons} if name in ("elman", "elman_full") else None


def build_model(name: str, args):
    """The model ``identify`` will build for ``name`` (named defaults + options)."""
    from jaxfric import models
    from jaxfric.identify import NAMED_MODEL_DEFAULTS

    kwargs = dict(NAMED_MODEL_DEFAULTS.get(name, {}))
    kwargs.update(model_options(name, args) or {})
    return models.get(name, **kwargs)


def label(name: str, model) -> str:
    base = LABELS.get(name, name)
    n = getattr(model, "neurons", None)
    return f"{base} ({n} neurons)" if n is not None else base


def budget_for(args) -> Budget:
    if args.quick:
        return Budget(args.generations or QUICK_GENERATIONS, args.nm_evals or QUICK_NM_EVALS)
    return Budget(args.generations, args.nm_evals)


def build_solver(kind: str, model, budget: Budget):
    """The optimiser for ``--solver`` at ``budget``; ``None`` = ``identify``'s default.

    ``mapso-nmds`` starts from :func:`jaxfric.identify.default_solver` (so the lattice
    stays sized for the model) and changes only the budget.
    """
    import jaxfric as jf
    from jaxfric.identify import default_solver

    if kind == "mapso-nmds":
        if budget.is_default:
            return None
        # Same lattice as the library default for this model; only the budget changes.
        # (solver_expression below prints this very call for the report.)
        base = default_solver(model)
        g = budget.generations if budget.generations is not None else base.mapso.num_generations
        nm = {"nm_max_evals": budget.nm_evals} if budget.nm_evals is not None else {}
        return jf.mapso_nmds(lattice_size=base.mapso.lattice_size, num_generations=g, **nm)
    if kind == "mapso":
        lattice = default_solver(model).mapso.lattice_size
        return jf.MAPSO(lattice_size=lattice, num_generations=budget.generations or 300)
    if kind == "pso":
        return jf.PSO(num_generations=budget.generations or 500)
    if kind == "nelder-mead":
        return jf.NelderMead(max_steps=budget.generations, max_evals=budget.nm_evals)
    raise UserError(f"unknown solver {kind!r}")


def describe_solver(solver, model) -> str:
    """One phrase for stage messages and reports."""
    from jaxfric.identify import default_solver

    s = default_solver(model) if solver is None else solver
    if hasattr(s, "mapso"):
        nm = s.nelder_mead.max_evals
        nm_text = f"<= {nm} evaluations" if nm is not None else f"<= {s.nelder_mead.steps_for(model.num_params)} steps"
        return (f"MAPSO ({s.mapso.lattice_size}x{s.mapso.lattice_size} agents, G = {s.mapso.num_generations}) "
                f"-> Nelder-Mead ({nm_text})")
    if hasattr(s, "lattice_size"):
        return f"MAPSO ({s.lattice_size}x{s.lattice_size} agents, G = {s.num_generations})"
    if hasattr(s, "num_particles"):
        return f"PSO ({s.num_particles} particles, G = {s.num_generations})"
    return f"Nelder-Mead (<= {s.steps_for(model.num_params)} steps)"


class LazyBar:
    """A progress sink that draws its tqdm bar only when the first report arrives.

    ``identify`` checks the data before it optimises; a bar drawn up front would be left
    half-drawn on the terminal (and glued to the error line) when that check fails.
    """

    def __init__(self, total, local_total, desc: str):
        self.args = (total, local_total)
        self.desc = desc
        self.bar = None

    def __call__(self, phase, step, evals, f_best):
        if self.bar is None:
            from jaxfric.optim.progress import TqdmProgress

            self.bar = TqdmProgress(*self.args, desc=self.desc)
        self.bar(phase, step, evals, f_best)

    def close(self):
        if self.bar is not None:
            self.bar.close()


def progress_bar(solver, model, desc: str):
    """A lazily drawn tqdm bar named after the model (see :class:`LazyBar`), or ``None``
    when tqdm is not installed (it is not a declared dependency of jaxfric: the bar is
    then left out rather than failing inside the compiled run's callback)."""
    import importlib.util

    from jaxfric.identify import default_solver

    if importlib.util.find_spec("tqdm") is None:
        return None
    s = default_solver(model) if solver is None else solver
    total, local_total = s.progress_totals()
    return LazyBar(total, local_total, desc)


def run_identify(name, data, *, solver, key, args, progress, valid=None):
    """``jaxfric.identify(name, data, solver=..., key=..., ...)``; with ``valid`` (name ->
    record, from ``--valid``) ``identify(name, train={file: data}, valid=valid, ...)``.

    ``progress`` (a tqdm bar updated from inside the jitted run, or ``None``) is passed
    only when ``identify`` accepts it; the CLI also prints a line per model, before and after.
    """
    from jaxfric.identify import identify

    kwargs = {"solver": solver, "key": key, "model_options": model_options(name, args)}
    refine = getattr(args, "refine", "none")
    if refine != "none":
        kwargs["refine"] = refine
    params = inspect.signature(identify).parameters
    if "progress" in params:
        kwargs["progress"] = progress
    if valid:
        return identify(name, train={args.file: data}, valid=valid, **kwargs)
    return identify(name, data, **kwargs)


def fit_all(data, args, key, *, say, kept_fit=None, notes=None, valid=None) -> dict:
    """Identify every model of ``args.models`` on ``data`` with ``key``; ``name -> Fit``.

    Every model gets the same ``key`` (they are independent problems), so a model's
    result does not depend on which other models were asked for. ``say(msg)`` prints
    stage messages (silent with ``--quiet``); ``kept_fit(name, fit)`` runs as soon as a
    model is done (the CLI saves it there, so Ctrl-C keeps it). Warnings from ``identify``
    (e.g. a free run that diverges on validation) become one ``jaxfric: warning:`` line each,
    shown even with ``--quiet``, and are appended to ``notes`` for the report.
    """
    fits = {}
    for name in check_models(args.models):
        model = build_model(name, args)
        solver = build_solver(args.solver, model, budget_for(args))
        say(f"identifying {label(name, model)}: {model.num_params} parameters, "
            f"{describe_solver(solver, model)}")
        t0 = time.perf_counter()
        bar = None if args.quiet else progress_bar(solver, model, label(name, model))
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                fit = run_identify(name, data, solver=solver, key=key, args=args, progress=bar, valid=valid)
        finally:
            if bar is not None:
                bar.close()  # also when identify raises: the error line must start a line of its own
        for w in caught:
            if issubclass(w.category, (RuntimeWarning, UserWarning)):
                text = " ".join(str(w.message).split())
                print(f"jaxfric: warning: {label(name, model)}: {text}", file=sys.stderr, flush=True)
                if notes is not None:
                    notes.append(f"{label(name, model)}: {text}")
        m = (fit.metrics.get("valid") or fit.metrics.get("all") or {})
        say(f"  done in {time.perf_counter() - t0:.1f} s (validation MSE {m.get('mse_percent', float('nan')):.4g} %)")
        fits[name] = fit
        if kept_fit is not None:
            kept_fit(name, fit)
    return fits


def solver_expression(kind: str, model, budget: Budget) -> str:
    """Python source of :func:`build_solver`'s result, for the report's "Reproduce"."""
    from jaxfric.identify import default_solver

    if kind == "mapso-nmds":
        if budget.is_default:
            return "None"
        s = default_solver(model)
        g = budget.generations if budget.generations is not None else s.mapso.num_generations
        nm = f", nm_max_evals={budget.nm_evals}" if budget.nm_evals is not None else ""
        return f"jf.mapso_nmds(lattice_size={s.mapso.lattice_size}, num_generations={g}{nm})"
    if kind == "mapso":
        return (f"jf.MAPSO(lattice_size={default_solver(model).mapso.lattice_size}, "
                f"num_generations={budget.generations or 300})")
    if kind == "pso":
        return f"jf.PSO(num_generations={budget.generations or 500})"
    return f"jf.NelderMead(max_steps={budget.generations}, max_evals={budget.nm_evals})"
