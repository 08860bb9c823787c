"""Models, solvers and budgets for the command line, and the calls to [`jaxfric.identify`][jaxfric.identification.identify].

Each model's fit is one [`jaxfric.cli.spec.FitSpec`][jaxfric.cli.spec.FitSpec] (arguments -> specification ->
[`jaxfric.identify`][jaxfric.identification.identify]). Models are passed by *name* (with ``model_options``), so the command
line gets the library's named-model defaults; without ``--generations`` / ``--nm-evals``
the library's [`jaxfric.identification.default_solver`][jaxfric.identification.default_solver] is used unchanged, and a budget the
user gives replaces only that field of it. ``--quick`` shrinks the budget to a smoke test
(3 generations, 200 Nelder–Mead evaluations), which compiles exactly the same programs, so
it also warms the compilation cache.
"""

from __future__ import annotations

import time
import warnings

from .errors import UserError, print_warning
from .spec import FitSpec

REFINE_CHOICES = ("none", "auto", "bfgs", "lbfgs", "lm", "gauss_newton")

LABELS = {"elman": "ENN", "elman_full": "ENN (full context)", "lugre": "LuGre", "dahl": "Dahl",
          "stribeck": "Stribeck", "coulomb": "Coulomb", "gms": "GMS", "cylinder": "Cylinder"}


def check_models(names, box=None) -> list[str]:
    """Validate model names, and that every ``--box`` entry is searched by one of them
    and is a range [`jaxfric.models.SearchBox`][jaxfric.models.SearchBox] accepts (one-line errors). The names
    were checked before JAX was imported ([`jaxfric.cli.checks.check_model_names`][jaxfric.cli.checks.check_model_names]);
    the box needs the models."""
    from jaxfric import models

    from .checks import check_model_names

    check_model_names(names)
    used = {k for name in names for k in models.get(name).box_keys}
    for key, rng in box or ():
        if key not in used:
            raise UserError(f"--box {key}: none of the models {', '.join(names)} has this parameter"
                            + (f" (theirs: {', '.join(sorted(used))})" if used else ""))
        try:
            models.SearchBox({key: rng})
        except ValueError as err:
            raise UserError(f"--box {key}={rng[0]:g},{rng[1]:g}: {err}") from None
    return list(names)


def available_memory() -> int | None:
    """Bytes of memory available to this process (Linux's MemAvailable, else the
    physical memory), ``None`` when unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        import os

        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def _bytes(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if n < 1000 or unit == "PB":
            return f"{n:.3g} {unit}"
        n /= 1000.0


def _n(n: int) -> str:
    return f"{n:,}".replace(",", " ")


def memory_need(spec, model, *, x64: bool) -> tuple[int, str]:
    """The largest matrix a fit of ``model`` as ``spec`` says holds, in bytes, and what
    it is: BFGS's dense ``n x n`` inverse Hessian (the networks' default gradient stage,
    ``--refine bfgs``/``lm``/``gauss_newton``/``auto``) or Nelder-Mead's ``(n+1) x n``
    simplex; 0 when neither runs (a swarm alone, L-BFGS)."""
    from jaxfric.identification import fast_pipeline

    n = int(model.num_params)
    item = 8 if x64 else 4
    dense = spec.refine in ("bfgs", "lm", "gauss_newton", "auto") or (
        spec.refine == "default" and fast_pipeline(model, "paper" if spec.paper else "jaxfric"))
    if dense:
        what = "BFGS's dense Hessian" if spec.refine in ("default", "bfgs", "auto") else "the Gauss-Newton matrix"
        return n * n * item, f"{what} ({_n(n)} x {_n(n)} x {item} bytes)"
    solver = spec.build_solver(model)
    uses_nm = spec.solver in ("mapso-nmds", "nelder-mead") and not (
        solver is None and fast_pipeline(model, "paper" if spec.paper else "jaxfric"))
    if uses_nm:
        return (n + 1) * n * item, f"Nelder-Mead's simplex ({_n(n + 1)} x {_n(n)} x {item} bytes)"
    return 0, ""


def check_memory(spec, model, *, x64: bool, available: int | None = None, say=None) -> None:
    """Refuse a fit whose largest matrix ([`memory_need`][jaxfric.cli.fitting.memory_need]) exceeds the memory
    available, and warn (through ``say``) past a quarter of it, with the figures."""
    need, what = memory_need(spec, model, x64=x64)
    available = available_memory() if available is None else available
    if not need or available is None:
        return
    name = label(spec.model, model)
    if need > available:
        fewer = "; use fewer neurons" if getattr(model, "neurons", None) is not None else ""
        raise UserError(f"{name} has {_n(model.num_params)} parameters: {what} needs {_bytes(need)}, more than "
                        f"the {_bytes(available)} of memory available{fewer}")
    if need > available / 4 and say is not None:
        print_warning(f"{name}: {what} needs {_bytes(need)} of the {_bytes(available)} of memory available")


def label(name: str, model) -> str:
    base = LABELS.get(name, name)
    n = getattr(model, "neurons", None)
    if n is not None:
        return f"{base} ({n} neurons)"
    return f"{base} (asymmetric + offset)" if getattr(model, "asymmetric", False) else base


def describe_solver(solver, model, paper: bool = False, refine: str = "default",
                    n_train: int | None = None) -> str:
    """One phrase for the stage lines, the report's settings and ``--help`` (``solver=None``:
    ``identify``'s default for the method, the paper's with ``paper=True``), with the
    gradient stage ``refine`` adds (``"default"``: the method's own, BFGS for the networks
    under jaxfric's pipeline; ``"none"``: none). ``n_train``: the training samples of the
    one record the fit sees, so that the phrase says how many the global stage searches on
    (``identify`` gives it the first ``GLOBAL_STAGE_SAMPLES`` of them); ``None`` (several
    records, used whole): not said."""
    from jaxfric.identification import FAST_REFINE_STEPS, GLOBAL_STAGE_SAMPLES, default_solver, fast_pipeline

    method = "paper" if paper else "jaxfric"
    s = default_solver(model, method) if solver is None else solver
    text = _describe(s, model)
    if refine == "default" and fast_pipeline(model, method):  # identify adds the gradient stage
        where = ""
        if solver is None and n_train is not None:
            head = GLOBAL_STAGE_SAMPLES
            where = (f" on the {n_train} training samples" if n_train <= head
                     else f" on the first {head} of the {n_train} training samples")
        text += f"{where} -> BFGS (<= {FAST_REFINE_STEPS} steps)"
    elif refine not in ("default", "none"):
        text += f" -> gradient stage {refine!r}"
    return text


def physical_form(data, *, threshold: float = 0.05) -> tuple[bool, str]:
    """Whether the physical models need direction-dependent levels and an offset, and why:
    the direction-wise mean friction while sliding (``|v|`` above a tenth of its maximum;
    [`jaxfric.rig.coulomb_levels`][jaxfric.rig.coulomb_levels]) differs between the directions by more than
    ``threshold`` of its half-range. Returns ``(asymmetric, sentence for the report)``."""
    import numpy as np

    from jaxfric import rig

    v = np.asarray(data.velocity[: data.n_train], dtype=np.float64)
    f = np.asarray(data.friction[: data.n_train], dtype=np.float64)
    try:
        lev = rig.coulomb_levels(v, f, 0.1 * float(np.max(np.abs(v))))
    except ValueError as err:  # e.g. a record that slides one way only
        return False, f"the physical models are fitted symmetric: the training data do not show a direction ({err})"
    ratio = abs(lev.offset) / abs(lev.halfrange) if lev.halfrange else 0.0
    levels = (f"the training data's sliding friction averages {lev.mean_pos:+.4g} N moving forward and "
              f"{lev.mean_neg:+.4g} N moving back")
    if ratio > threshold:
        return True, (f"{levels}, {100 * ratio:.0f} % apart from symmetric, so the physical models are fitted "
                      "with direction-dependent levels and an offset (asymmetric=True, offset=True)")
    return False, (f"{levels}, within {100 * threshold:.0f} % of symmetric, so the physical models are fitted "
                   "symmetric")


def _describe(s, model) -> str:
    from jaxfric import MAPSO, MAPSONMDS, PSO

    if isinstance(s, MAPSONMDS):
        nm = s.nelder_mead.max_evals
        nm_text = (f"<= {nm} evaluations" if nm is not None else
                   f"<= {s.nelder_mead.capabilities(model.num_params).max_steps} steps")
        return (f"MAPSO ({s.mapso.lattice_size}x{s.mapso.lattice_size} agents, G = {s.mapso.num_generations}) "
                f"-> Nelder-Mead ({nm_text})")
    if isinstance(s, MAPSO):
        return f"MAPSO ({s.lattice_size}x{s.lattice_size} agents, G = {s.num_generations})"
    if isinstance(s, PSO):
        return f"PSO ({s.num_particles} particles, G = {s.num_generations})"
    return f"Nelder-Mead (<= {s.capabilities(model.num_params).max_steps} steps)"


class LazyBar:
    """A progress sink that draws its tqdm bar only when the first report arrives.

    ``identify`` checks the data before it optimises; a bar drawn up front would be left
    half-drawn on the terminal (and glued to the error line) when that check fails.
    """

    def __init__(self, total, local_total, desc: str, gradient_total=None):
        self.args = (total, local_total)
        self.desc = desc
        self.gradient_total = gradient_total
        self.bar = None

    def __call__(self, phase, step, evals, f_best):
        if self.bar is None:
            from jaxfric.optim.progress import TqdmProgress

            self.bar = TqdmProgress(*self.args, desc=self.desc, gradient_total=self.gradient_total)
        self.bar(phase, step, evals, f_best)

    def close(self):
        if self.bar is not None:
            self.bar.close()


def progress_bar(solver, model, desc: str, paper: bool = False, refine=None):
    """A lazily drawn tqdm bar named after the model (see [`LazyBar`][jaxfric.cli.fitting.LazyBar]), or ``None``
    when tqdm is not installed (it is not a declared dependency of jaxfric: the bar is
    then left out rather than failing inside the compiled run's callback). The gradient
    stage's bar knows its step cap when ``identify`` chooses the stage itself
    (``refine=None`` on a model whose method has one)."""
    import importlib.util

    from jaxfric.identification import FAST_REFINE_STEPS, default_solver, fast_pipeline

    if importlib.util.find_spec("tqdm") is None:
        return None
    method = "paper" if paper else "jaxfric"
    s = default_solver(model, method) if solver is None else solver
    total, local_total = s.capabilities(model.num_params).progress_totals
    gradient_total = FAST_REFINE_STEPS if refine is None and fast_pipeline(model, method) else None
    return LazyBar(total, local_total, desc, gradient_total)


def check_fits(args, say=None) -> list[str]:
    """Every check of the requested fits that needs the models, before any data are made
    or any stage starts: names, ``--box`` entries and each model's memory."""
    names = check_models(args.models, getattr(args, "box", None))
    for name in names:
        spec = FitSpec.from_args(name, args)
        check_memory(spec, spec.build_model(), x64=bool(getattr(args, "x64", False)), say=say)
    return names


def fit_all(data, args, key, *, say, kept_fit=None, notes=None, valid=None) -> dict:
    """Identify every model of ``args.models`` on ``data`` with ``key``; ``name -> Fit``.

    Every model gets the same ``key`` (they are independent problems), so a model's
    result does not depend on which other models were asked for. ``say(msg)`` prints
    stage messages (silent with ``--quiet``); ``kept_fit(name, fit)`` (returning the fit kept) runs as soon as a
    model is done (the CLI saves it there, so Ctrl-C keeps it). Warnings from ``identify``
    (e.g. a free run that diverges on validation) become one ``jaxfric: warning:`` line each,
    shown even with ``--quiet``, and are appended to ``notes`` for the report.
    """
    from jaxfric.identification import BoundWarning, bound_message
    from jaxfric.uncertainty import cli_lines

    names = check_models(args.models, getattr(args, "box", None))
    fits = {}
    for name in names:
        spec = FitSpec.from_args(name, args)
        model = spec.build_model()
        solver = spec.build_solver(model)
        say(f"identifying {label(name, model)}: {model.num_params} parameters, "
            f"{describe_solver(solver, model, spec.paper, spec.refine, None if valid else data.n_train)}")
        t0 = time.perf_counter()
        bar = None if args.quiet else progress_bar(
            solver, model, label(name, model), spec.paper,
            None if spec.refine == "default" else (False if spec.refine == "none" else spec.refine))
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                # `jaxfric demo` has no FILE argument: its record keeps the default name
                fit = spec.identify(data, key=key, progress=bar, valid=valid,
                                    train_name=getattr(args, "file", None) or "train")
        finally:
            if bar is not None:
                bar.close()  # also when identify raises: the error line must start a line of its own
        texts = [" ".join(str(w.message).split()) for w in caught
                 if issubclass(w.category, (RuntimeWarning, UserWarning))
                 and not issubclass(w.category, BoundWarning)]
        # a parameter on a bound: the wider range as this command takes it (--box NAME=LO,HI)
        texts += [bound_message(d, "cli") for d in fit.diagnostics.get("on_bound", [])]
        for text in texts:
            own = f"{type(model).__name__}: "
            text = text[len(own):] if text.startswith(own) else text  # the label says it
            print_warning(f"{label(name, model)}: {text}")
            if notes is not None:
                notes.append(f"{label(name, model)}: {text}")
        m = (fit.metrics.get("valid") or fit.metrics.get("all") or {})
        say(f"  done in {time.perf_counter() - t0:.1f} s (validation MSE {m.get('mse_percent', float('nan')):.4g} %)")
        for line in cli_lines(fit):
            say(line)
        if kept_fit is not None:
            fit = kept_fit(name, fit)
        fits[name] = fit
    return fits
