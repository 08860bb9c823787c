"""One specification object per fit: command-line arguments -> [`FitSpec`][jaxfric.cli.spec.FitSpec] -> the library.

The command line holds no copy of a library default. Every field left ``None`` means
"what the library chooses": the solver starts from [`jaxfric.identification.default_solver`][jaxfric.identification.default_solver]
for the model (lattice size, generations, Nelder–Mead budget) and a budget the user gave
replaces only that field. ``repr(spec)`` is the report's "Reproduce" line: evaluating it
with ``from jaxfric.cli.spec import FitSpec`` and calling [`FitSpec.identify`][jaxfric.cli.spec.FitSpec.identify] repeats
the fit.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

#: ``--quick``: a smoke-test budget (the same programs compile, so it also warms the cache).
QUICK_GENERATIONS = 3
QUICK_NM_EVALS = 200

SOLVERS = ("mapso-nmds", "mapso", "pso", "nelder-mead")

#: Models with direction-dependent levels and an offset (``asymmetric=True, offset=True``).
ASYMMETRIC_MODELS = ("coulomb", "stribeck", "lugre", "dahl", "gms")


@dataclass(frozen=True)
class FitSpec:
    """What one fit asks of [`jaxfric.identify`][jaxfric.identification.identify].

    Args:
        model: a [`jaxfric.models.get`][jaxfric.models.get] name (``"elman"``, ``"lugre"``, ...).
        neurons: hidden neurons of the Elman networks (``None``: the model's default).
        solver: ``"mapso-nmds"`` (the library's default solver), ``"mapso"``, ``"pso"``
            or ``"nelder-mead"``.
        generations: swarm generations (Nelder–Mead alone: its step cap); ``None`` keeps
            the library's choice.
        nm_evals: Nelder–Mead evaluation budget; ``None`` keeps the library's choice.
        refine: the gradient stage after the search: ``"default"`` = the method's own
            (BFGS, 500 steps, for the networks under jaxfric's pipeline; none for the
            physical models and for ``paper``), ``"none"`` = off, or a
            ``jaxfric.identify(refine=...)`` name (``"bfgs"``, ``"lm"``, ...).
        paper: the paper's method exactly (``identify(method="paper")``: MAPSO–NMDS, no
            gradient stage) instead of the library's default pipeline.
        seed: the key is ``jax.random.key(seed)`` unless a key is passed to [`identify`][jaxfric.cli.spec.FitSpec.identify].
        box: search-box entries ``((name, (low, high)), ...)`` (``--box``) handed to
            ``identify(box=...)``; the rest of the box is the library's (data-centred).
        asymmetric: fit a physical model with direction-dependent levels and a force
            offset (``asymmetric=True, offset=True``; [`ASYMMETRIC_MODELS`][jaxfric.cli.spec.ASYMMETRIC_MODELS]), the form
            asymmetric data need; ignored by the networks and the cylinder model.
    """

    model: str
    neurons: int | None = None
    solver: str = "mapso-nmds"
    generations: int | None = None
    nm_evals: int | None = None
    refine: str = "default"
    paper: bool = False
    seed: int = 0
    box: tuple = ()
    asymmetric: bool = False

    def __post_init__(self):
        if self.solver not in SOLVERS:
            raise ValueError(f"unknown solver {self.solver!r}; choose from {', '.join(SOLVERS)}")

    @classmethod
    def from_args(cls, name: str, args) -> FitSpec:
        """The specification of model ``name`` from parsed ``demo``/``identify`` arguments."""
        generations, nm_evals = args.generations, args.nm_evals
        if args.quick:
            generations = generations or QUICK_GENERATIONS
            nm_evals = nm_evals or QUICK_NM_EVALS
        neurons = args.neurons if name in ("elman", "elman_full") else None
        spec = cls(model=name, neurons=neurons, solver=args.solver, generations=generations,
                   nm_evals=nm_evals, refine=getattr(args, "refine", "default"),
                   paper=getattr(args, "paper", False), seed=args.seed,
                   asymmetric=bool(getattr(args, "asymmetric", False)) and name in ASYMMETRIC_MODELS)
        entries = dict(getattr(args, "box", None) or ())
        keys = spec.build_model().box_keys  # each model takes the entries it searches
        return dataclasses.replace(spec, box=tuple((k, r) for k, r in entries.items() if k in keys))

    @property
    def model_options(self) -> dict | None:
        options = {"neurons": self.neurons} if self.neurons is not None else {}
        if self.asymmetric:
            options.update(asymmetric=True, offset=True)
        return options or None

    @property
    def default_budget(self) -> bool:
        return self.generations is None and self.nm_evals is None

    def build_model(self):
        """The model ``identify`` builds for this name (its named defaults + options)."""
        from jaxfric.identification import resolve_model  # the model identify() builds from a name

        return resolve_model(self.model, self.model_options)

    def build_solver(self, model=None):
        """The optimiser; ``None`` when ``identify``'s default solver is used unchanged."""
        import jaxfric as jf
        from jaxfric.identification import paper_solver

        if self.solver == "mapso-nmds" and self.default_budget:
            return None
        model = self.build_model() if model is None else model
        base = paper_solver(model)  # MAPSO–NMDS sized for the model; a budget replaces a field
        g, nm = self.generations, self.nm_evals
        if self.solver == "mapso-nmds":
            mapso = base.mapso if g is None else dataclasses.replace(base.mapso, num_generations=g)
            local = base.nelder_mead if nm is None else dataclasses.replace(base.nelder_mead, max_evals=nm)
            return dataclasses.replace(base, mapso=mapso, nelder_mead=local)
        if self.solver == "mapso":
            return base.mapso if g is None else dataclasses.replace(base.mapso, num_generations=g)
        if self.solver == "pso":
            return jf.PSO() if g is None else jf.PSO(num_generations=g)
        changes = {k: v for k, v in (("max_steps", g), ("max_evals", nm)) if v is not None}
        return dataclasses.replace(base.nelder_mead, **changes)

    def options(self) -> dict:
        """The ``jaxfric.identify`` keywords of this specification besides the data, key and
        progress: ``model_options`` and ``solver`` (``None``: the library's), then ``box``,
        ``refine`` and ``method`` where they differ from the library's choice."""
        out = {"model_options": self.model_options, "solver": self.build_solver()}
        if self.box:
            out["box"] = dict(self.box)
        if self.refine != "default":
            out["refine"] = False if self.refine == "none" else self.refine
        if self.paper:
            out["method"] = "paper"
        return out

    def python(self, data: str = "data", key: str = "key", valid: str | None = None,
               train_name: str = "train") -> str:
        """The ``jf.identify(...)`` call (``import jaxfric as jf``) that [`identify`][jaxfric.cli.spec.FitSpec.identify]
        makes, as Python source in the public API only: the report's "Reproduce" block.
        ``data``, ``key`` and ``valid`` are the names of variables holding the record, the
        key and the validation records (``valid`` given: ``train={train_name: data}``)."""
        args = [repr(self.model)]
        args += ([f"train={{{train_name!r}: {data}}}", f"valid={valid}"] if valid else [data])
        args.append(f"key={key}")
        args += [f"{k}={python_source(v) if k == 'solver' else repr(v)}"
                 for k, v in self.options().items() if v is not None]
        return f"jf.identify({', '.join(args)})"

    def identify(self, data, *, key=None, progress=None, valid=None, train_name="train"):
        """``jaxfric.identify(model, data, ...)`` as this specification says; with ``valid``
        (name -> record, from ``--valid``) ``identify(model, train={train_name: data},
        valid=valid, ...)``: ``data`` is used whole for estimation."""
        import jax

        from jaxfric.identification import identify

        kwargs = {**self.options(), "key": jax.random.key(self.seed) if key is None else key}
        if progress is not None:
            kwargs["progress"] = progress
        if valid:
            return identify(self.model, train={train_name: data}, valid=valid, **kwargs)
        return identify(self.model, data, **kwargs)


def python_source(obj) -> str:
    """``jf.ClassName(field=value, ...)`` for a solver of jaxfric's public API (a dataclass,
    e.g. [`jaxfric.MAPSONMDS`][jaxfric.optim.MAPSONMDS]), with the fields that differ from the defaults;
    nested solvers likewise."""
    import jaxfric as jf

    name = type(obj).__name__
    if getattr(jf, name, None) is not type(obj):
        raise ValueError(f"{name} is not in jaxfric's public API")
    parts = []
    for f in dataclasses.fields(obj):
        if not f.init:
            continue
        value = getattr(obj, f.name)
        if f.default is not dataclasses.MISSING:
            default = f.default
        elif f.default_factory is not dataclasses.MISSING:
            default = f.default_factory()
        else:
            default = dataclasses.MISSING
        if default is not dataclasses.MISSING and type(value) is type(default) and value == default:
            continue
        parts.append(f"{f.name}={python_source(value) if dataclasses.is_dataclass(value) else repr(value)}")
    return f"jf.{name}({', '.join(parts)})"
