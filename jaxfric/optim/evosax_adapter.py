"""Any evosax (≥ 0.3) evolution strategy as a jaxfric solver.

[`Evosax`][jaxfric.optim.Evosax] runs an evosax population strategy — CMA-ES, SNES, DE, evosax's PSO, …
(``evosax.algorithms.algorithms``) — through jaxfric's step protocol
([`AbstractSolver`][jaxfric.optim.AbstractSolver]), so [`jaxfric.minimise`][jaxfric.optim.minimise] gives it
what it gives every solver: bounds, history, progress, checkpoints, warm starts and
``minimise_many``'s batched seeds; it is also a valid global stage of
[`chain`][jaxfric.optim.chain] (``cmaes_nm()`` = ``chain(Evosax("CMA_ES"), NelderMead())``)
and a ``solver=`` of [`jaxfric.identify`][jaxfric.identification.identify].

**Bounds** (one rule for every strategy). The strategy searches the unit box: a point
``u ∈ [0, 1]^D`` stands for ``x = lower + u ⊙ (upper − lower)``, so parameters of very
different scales get the same initial spread (docs/algorithms.md §5.1's box ``Ω``).
Every candidate the strategy asks for is *projected* onto the box, ``u ← clip(u, 0, 1)``
(what jaxfric's PSO does with its particles), the projected point is evaluated, and the
projected point is what the strategy is told (repair, not penalty). The map is clipped
to the box too (``lower + u·(upper − lower)`` can round past ``upper``), so every
evaluated point, every member of a population-based strategy and the reported best lie
in the bounds. With IPOP restarts (below) a distribution-based strategy uses pycma's
``BoundTransform`` instead (``bound_handling="transform"``, any strategy may ask for it):
the strategy searches unbounded genotypes ``g``, is told them unchanged, and the point
evaluated is ``u = T(g)``, pycma's linear–quadratic map (the identity on
``[0.05, 0.95]``, quadratic towards the bounds, mirrored and periodic beyond), so
nothing piles up on a bound and the covariance learns the unbounded samples.

**Start.** Distribution-based strategies (CMA-ES, SNES, …) start with their mean at a
uniform random point of the box (``y0`` when given) and, where the strategy has a
``std_init`` parameter, ``std_init = 0.3`` box widths (Hansen's advice for a box
search: ``σ₀ ≈ 0.3·(upper − lower)``); the mean is evaluated once so the run's best is
a real point from the start. Population-based strategies (DE, PSO, GAs) start from a
uniform random population (row 0 = ``y0`` when given), all evaluated.

**Counts.** Evaluations of a run are exact: ``1 + P·G`` (distribution-based) or
``P·(G + 1)`` (population-based) for population size ``P`` and ``G`` generations
([`Evosax.evaluations`][jaxfric.optim.Evosax.evaluations]). NaN and inf fitness become ``+inf`` before the strategy
sees them, so they rank last and never become the best.

**Restarts.** With ``restarts=0`` the strategy runs once: only when its own state turns
non-finite (CMA-ES's step size underflows some thousand generations after it has
converged) does it start again, as pycma does, instead of ending the run with budget
left: a distribution-based strategy from a fresh uniform random mean with its first
spread, a population-based one from its last (evaluated) population.

With ``restarts=R > 0`` (distribution-based strategies whose state does not depend on
the population size: CMA-ES, Sep-CMA-ES, SNES, …) the strategy restarts IPOP-style
(Auger & Hansen 2005; pycma's ``fmin2(..., restarts=R, incpopsize=2)``): when a
generation ends stagnant, it starts again from a fresh uniform random mean with its
first spread and **twice the population**, up to ``P·2^R`` (later restarts keep that
population). A generation is stagnant, by pycma's default termination criteria, when

* its values, and the best values of the last ``10 + ⌈30·D/λ⌉`` generations, each lie
  within ``restart_tolfun`` (pycma's ``tolfun``), or those best values within
  ``restart_tolfun/10`` (``tolfunhist``, after 10 generations), or it is the second
  generation in a row whose best value equals its ``⌊0.75·λ⌋``-th best
  (``tolflatfitness = 1``);
* the spread is below ``restart_tolx`` box widths in every coordinate: ``σ·√C_ii`` and,
  for CMA-ES, ``σ·|p_c|`` (``tolx``);
* adding ``0.2·σ·√C_ii`` leaves a coordinate of the mean unchanged (``noeffectcoord``),
  or CMA-ES's covariance has a condition number above 1e14 (``conditioncov``);
* or the strategy's state turned non-finite.

pycma's ``tolstagnation``, ``tolxstagnation``, ``tolupsigma`` and per-run ``maxiter`` are
not checked (pycma's runs on Griewank and Schwefel 2.26 in benchmarks/cmaes_restarts.py never
ended by them). After each generation the CMA-ES state is rescaled, the same distribution
``N(m, σ²·C)`` with ``C``'s largest variance 1 (``_rescaled``): evosax adds ``1e-8·I`` to
``C`` at every ask, which otherwise stalls the shrinking of ``C`` with large populations (docs/benchmarks.md).

Everything stays inside the compiled run, with fixed shapes: each step evaluates one
batch of ``P`` points, so a generation of population ``λ = P·2^j`` takes ``2^j`` steps
(the strategy asks for the whole generation at its first step, and is told at its last:
the points and values wait in buffers of ``P·2^R`` rows). For CMA-ES and Sep-CMA-ES,
five consecutive population sizes share one strategy object, of the largest of them:
it is told a smaller size's parameters (their weights padded with zeros) with the points
beyond ``λ`` valued +inf, the same update as the strategy of population ``λ`` (a test
checks it), so the program holds one ask and one tell per five sizes (two for R = 9,
chosen by ``lax.switch``), and a generation costs at most 16 times its own ask and
tell. Any other strategy has its ask, tell and start once per population size (more to
compile). The evaluation count stays exact
(``1 + P·G``) and ``num_generations`` counts steps. The best point so far is kept across
restarts; ``state.restarts`` counts them and ``state.ipop.level`` is the current ``j``.
Under ``vmap`` (``minimise_many(..., batching="vmap")``) the conditional ask and tell run
at every step, so on one CPU ``minimise_many`` runs the keys one after another
(``batching="auto"``).

**Cost in many dimensions.** Full CMA-ES eigendecomposes its D×D covariance every
generation (``jnp.linalg.eigh``, O(D³); measured in docs/benchmarks.md). For more than a
few tens of parameters use ``Evosax("Sep_CMA_ES")`` (diagonal covariance, O(D) per
generation) or another diagonal strategy such as ``"SNES"``.

**Keys.** Generation ``i`` uses ``fold_in(key, i)`` (split in two for ``ask`` and
``tell``), so the same key gives the same run, chunked (checkpoints) or not.

evosax is an optional dependency: ``pip install -e ".[evosax]"``. Without it,
constructing [`Evosax`][jaxfric.optim.Evosax] raises ``ImportError`` naming that extra.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._base import check_positive_int, check_range, count_dtype, uniform_flat
from .chained import Chain
from .nelder_mead import NelderMead
from .contract import AbstractGenerational, Capabilities
from .rounds import Rounds

INSTALL_HINT = 'pip install -e ".[evosax]"'

#: ``Evosax(restarts=...)``'s default: IPOP restarts with the population doubled up to
#: ``P·2^RESTARTS`` (benchmarks/results/cmaes_restarts.md).
RESTARTS = 9

#: Short names accepted besides evosax's own (compared case- and separator-blind).
ALIASES = {"de": "DifferentialEvolution", "cmaes": "CMA_ES", "ga": "SimpleGA"}


def _evosax():
    """``(algorithms dict, distribution-based base class)`` or a clear ImportError."""
    try:
        from evosax.algorithms import algorithms
        from evosax.algorithms.distribution_based.base import DistributionBasedAlgorithm
    except ImportError as err:
        raise ImportError(
            f"jaxfric.Evosax needs the optional package evosax (>= 0.3): {INSTALL_HINT} "
            f"(or pip install evosax). Import failed with: {err}"
        ) from err
    return algorithms, DistributionBasedAlgorithm


def _norm(name: str) -> str:
    return name.lower().replace("_", "").replace("-", "").replace(" ", "")


def resolve_strategy(strategy) -> type:
    """The evosax strategy class for a name (``"CMA_ES"``, ``"cma-es"``, ``"DE"``,
    ``"SNES"``, ``"PSO"``, …) or a class; ``ValueError`` listing the names otherwise."""
    algorithms, _ = _evosax()
    if isinstance(strategy, type):
        return strategy
    if not isinstance(strategy, str):
        raise ValueError(
            "strategy must be an evosax strategy name (e.g. 'CMA_ES', 'DE', 'SNES', 'PSO') "
            f"or class, got {type(strategy).__name__}"
        )
    by_norm = {_norm(k): v for k, v in algorithms.items()}
    key = _norm(strategy)
    key = _norm(ALIASES.get(key, key))
    if key not in by_norm:
        raise ValueError(
            f"unknown evosax strategy {strategy!r}; choose one of {sorted(algorithms)} "
            f"(aliases: {sorted(ALIASES)})"
        )
    return by_norm[key]


def _to_box(U, lower, upper):
    """``lower + U·(upper − lower)`` for ``U`` in the unit box, clipped to the box (the
    map can round past ``upper``: 1.2000000000000002 for an upper bound of 1.2)."""
    return jnp.clip(lower + U * (upper - lower), lower, upper)


#: The margin of pycma's linear–quadratic box transformation on the unit box, in box
#: widths: ``max(1, |bound|)/20`` for the bounds 0 and 1 (cma.transformations'
#: ``margin_width2``).
LINQUAD_MARGIN = 0.05


def _linquad(G):
    """pycma's ``BoundTransform`` (``BoxConstraintsLinQuadTransformation``) onto the unit
    box, elementwise: the identity on ``[a, 1 − a]`` (``a = LINQUAD_MARGIN``), quadratic
    ``(g + a)²/(4a)`` and ``1 − (g − 1 − a)²/(4a)`` towards the bounds, mirrored at
    ``−a`` and ``1 + a`` and periodic beyond (period ``2·(1 + 2a)``): every genotype ``g``
    maps into ``[0, 1]``, smoothly (C¹)."""
    a = LINQUAD_MARGIN
    r, s = 2.0 * (1.0 + 2.0 * a), -2.0 * a - 0.5
    far = (G < s) | (G > 1.0 + 2.0 * a + 0.5)
    G = jnp.where(far, G - r * jnp.floor((G - s) / r), G)
    G = jnp.where(G > 1.0 + a, G - 2.0 * (G - 1.0 - a), G)
    G = jnp.where(G < -a, G + 2.0 * (-a - G), G)
    low = (G + a) ** 2 / (4.0 * a)
    high = 1.0 - (G - 1.0 - a) ** 2 / (4.0 * a)
    return jnp.clip(jnp.where(G < a, low, jnp.where(G < 1.0 - a, G, high)), 0.0, 1.0)


def _linquad_inverse(U):
    """The genotype in ``[−a, 1 + a]`` of a point ``U`` of the unit box (``_linquad``'s
    inverse there)."""
    a = LINQUAD_MARGIN
    low = -a + 2.0 * jnp.sqrt(a * jnp.maximum(U, 0.0))
    high = 1.0 + a - 2.0 * jnp.sqrt(a * jnp.maximum(1.0 - U, 0.0))
    return jnp.where(U < a, low, jnp.where(U < 1.0 - a, U, high))


def _all_finite(tree):
    leaves = [jnp.all(jnp.isfinite(a)) for a in jax.tree_util.tree_leaves(tree)
              if jnp.issubdtype(jnp.result_type(a), jnp.inexact)]
    return jnp.all(jnp.stack(leaves)) if leaves else jnp.array(True)


def _padded(cls) -> bool:
    """Whether restarts may run ``cls`` as one strategy object of the largest population,
    with the smaller populations' parameters (weights padded with zeros) and the extra
    points valued +inf: true for evosax's CMA-ES and Sep-CMA-ES, whose ask draws
    independent points and whose tell depends on the population only through its
    parameters and the ranks' weights (tests/test_evosax_adapter.py checks a generation
    against the strategy of the smaller population)."""
    from evosax.algorithms import algorithms

    return cls in (algorithms.get("CMA_ES"), algorithms.get("Sep_CMA_ES"))


#: Population levels sharing one strategy object (``_padded`` strategies): the object of
#: the class's largest population serves the smaller ones, so a generation of the
#: smallest costs at most ``2^(CLASS_LEVELS − 1)`` times its own ask and tell; fewer
#: classes compile faster. With R = 9: two classes (levels 0–4 and 5–9).
CLASS_LEVELS = 5


def _classes(R: int, padded: bool) -> list[tuple[int, int]]:
    """Population levels ``0..R`` in classes ``(first, last)``: consecutive runs of
    ``CLASS_LEVELS`` for a padded strategy, one level each otherwise."""
    step = CLASS_LEVELS if padded else 1
    return [(lo, min(lo + step - 1, R)) for lo in range(0, R + 1, step)]


def _stacked(params, P: int, lo: int, hi: int):
    """The evosax parameters ``params`` of population levels ``lo..hi`` (population
    ``P·2^j``) stacked on a new first axis, their weights padded with zeros to level
    ``hi``'s population."""
    return jax.tree_util.tree_map(
        lambda *xs: jnp.stack([jnp.asarray(x) for x in xs]),
        *[q.replace(weights=jnp.pad(q.weights, (0, (P << hi) - (P << j))))
          if hasattr(q, "weights") and hi > lo else q
          for j, q in zip(range(lo, hi + 1), params)])


def _no_spread(inner, tolx) -> Any:
    """pycma's ``tolx``, ``noeffectcoord`` and ``conditioncov`` on a distribution-based
    strategy's state (unit-box coordinates), from what it holds: ``std`` (σ), a full or
    diagonal covariance ``C``, CMA-ES's path ``p_c`` and root eigenvalues ``D``. False for
    a state without ``std``."""
    std = getattr(inner, "std", None)
    if std is None:
        return jnp.array(False)
    C = getattr(inner, "C", None)
    var = jnp.ones_like(inner.mean) if C is None else (jnp.diag(C) if C.ndim == 2 else C)
    spread = std * jnp.sqrt(jnp.maximum(var, 0.0))
    small = jnp.all(spread < tolx)
    p_c = getattr(inner, "p_c", None)
    if p_c is not None:
        small &= jnp.all(jnp.abs(std * p_c) < tolx)
    no_effect = jnp.any(inner.mean + 0.2 * spread == inner.mean)
    out = small | no_effect
    D = getattr(inner, "D", None)
    if D is not None and C is not None and C.ndim == 2:
        out |= (jnp.max(D) / jnp.min(D)) ** 2 > 1e14
    return out


def _rescaled(inner):
    """The same search distribution ``N(m, σ²·C)`` with ``C``'s largest variance 1: ``C``
    divided by ``c = max_i C_ii``, ``σ`` multiplied by ``√c``, and CMA-ES's path ``p_c``
    and root eigenvalues ``D`` divided by ``√c`` (``p_σ`` is whitened, unchanged). CMA-ES's
    update is equivariant under this rescaling, but evosax adds ``1e-8·I`` to ``C`` at
    every ask and floors ``D`` at ``1e-4``: with a large population ``C`` shrinks to that
    floor within a few generations and from then on only ``σ`` can shrink (measured:
    docs/benchmarks.md, "CMA-ES restarts against pycma"). A state without ``std`` and
    ``C`` is returned as it is."""
    C, std = getattr(inner, "C", None), getattr(inner, "std", None)
    if C is None or std is None:
        return inner
    c = jnp.max(jnp.diag(C)) if C.ndim == 2 else jnp.max(C)
    c = jnp.where(jnp.isfinite(c) & (c > 0), c, 1.0)
    r = jnp.sqrt(c)
    new = {"C": C / c, "std": std * r}
    for name in ("p_c", "D"):
        if getattr(inner, name, None) is not None:
            new[name] = getattr(inner, name) / r
    return inner.replace(**new)


@functools.lru_cache(maxsize=64)
def _build(cls, population_size: int, num_dims: int, dtype: str, kwargs: tuple):
    """One evosax strategy object per configuration: its ``init/ask/tell`` are jitted
    with the object as a static argument, so reusing it reuses their compilations."""
    # Built eagerly even when first asked for inside a trace: the cached object must
    # not hold tracers of that trace.
    with jax.ensure_compile_time_eval():
        return cls(population_size=population_size,
                   solution=jnp.zeros((num_dims,), dtype), **dict(kwargs))


@functools.lru_cache(maxsize=64)
def _check_strategy(cls, population_size: int, kwargs: tuple, names: tuple) -> None:
    """Build the strategy on a 2-parameter problem, so a wrong keyword or parameter
    name fails in ``check`` and not inside a traced run. Only the parameters' names are
    needed, so their values are traced abstractly: evosax computes them op by op, which
    for CMA-ES took 1.0 s eagerly (each new small operation compiled) and 16 ms as shapes.
    Cached per configuration, since ``minimise`` checks its solver on every call."""
    try:
        es = _build(cls, population_size, 2, "float32", kwargs)
    except (TypeError, AssertionError) as err:
        raise ValueError(f"{cls.__name__} refused its settings: {err}") from None
    _check_names(cls, jax.eval_shape(lambda: es.default_params), names)


@functools.lru_cache(maxsize=64)
def _check_restartable(cls, population_size: int, kwargs: tuple) -> None:
    """Restarts with a larger population keep the strategy's state: refuse a strategy
    whose state's shapes depend on the population size (its shapes, on 2 parameters)."""
    def shapes(p):
        es = _build(cls, p, 2, "float32", kwargs)
        state = jax.eval_shape(lambda: es.init(jax.random.key(0), jnp.zeros(2), es.default_params))
        leaves, tree = jax.tree_util.tree_flatten(state)
        return tree, [(a.shape, a.dtype) for a in leaves]

    if shapes(population_size) != shapes(2 * population_size):
        raise ValueError(f"restarts need a strategy whose state does not depend on its "
                         f"population size; {cls.__name__}'s does (use restarts=0)")


def _check_names(cls, params, over) -> None:
    unknown = sorted(set(over) - set(vars(params)))
    if unknown:
        raise ValueError(f"{cls.__name__} has no parameter(s) {unknown}; "
                         f"its parameters: {sorted(vars(params))}")


class IPOPState(eqx.Module):
    """IPOP restarts' bookkeeping (``restarts > 0``, see [`Evosax`][jaxfric.optim.Evosax]):
    the population level ``j`` (population ``P·2^j``), the batch of ``P`` points the
    generation is at, the generation's points (unit box) and values in buffers of the
    largest population's rows, and the best value of each generation since the last
    restart (a ring of ``count`` entries), and how many generations in a row were flat
    (best value equal to the ``⌊0.75·λ⌋``-th best)."""

    level: Any
    batch: Any
    U: Any
    F: Any
    bests: Any
    count: Any
    flat: Any


class EvosaxState(eqx.Module):
    """The strategy's own state, the best projected point and its value, the exact
    evaluation count, generations (steps) done, the run's key, how often the strategy
    restarted, and IPOP's bookkeeping (``None`` without restarts; see
    [`Evosax`][jaxfric.optim.Evosax])."""

    inner: Any
    x_best: Any
    f_best: Any
    num_evals: Any
    generation: Any
    key: Any
    restarts: Any
    ipop: Any = None


def _advanced(state: EvosaxState, inner, X, F, evals, restarted, ipop=None) -> EvosaxState:
    """The state after a step that evaluated the points ``X`` (values ``F``, ``evals`` of
    them): the new strategy state, the best point so far, the counts advanced."""
    i = jnp.argmin(F)
    better = F[i] < state.f_best
    return EvosaxState(inner, jnp.where(better, X[i], state.x_best), jnp.where(better, F[i], state.f_best),
                       state.num_evals + evals, state.generation + 1, state.key,
                       state.restarts + restarted.astype(jnp.int32), ipop)


class Evosax(AbstractGenerational):
    """An evosax evolution strategy under jaxfric's driver (see the module docstring).

    Args:
        strategy: an evosax strategy name (``"CMA_ES"``, ``"SNES"``, ``"Sep_CMA_ES"``,
            ``"DE"`` = ``"DifferentialEvolution"``, ``"PSO"``, ``"SimpleGA"``, …; case and
            ``-``/``_`` do not matter) or class.
        population_size: ``P``; ``None`` takes CMA-ES's ``4 + ⌊3 ln D⌋`` for
            distribution-based strategies and 25 (jaxfric's PSO) for population-based ones.
        num_generations: ``G`` (ask/tell rounds after the start).
        std_init: initial standard deviation in box widths, for strategies with a
            ``std_init`` parameter (0.3); ``None`` keeps evosax's default (1.0, i.e. a
            box width, which puts most CMA-ES samples on the bounds).
        params: overrides of the strategy's evosax ``Params`` (e.g.
            ``{"crossover_rate": 0.5}`` for DE).
        restarts: ``R``, IPOP restarts: how often a stagnant strategy starts again with
            twice the population (up to ``P·2^R``; later restarts keep it); ``0``: one run
            (restarted only when its state breaks down). Distribution-based strategies
            whose state does not depend on the population size only (CMA-ES,
            Sep-CMA-ES, SNES, …). Default (``None``): ``RESTARTS`` (9) for CMA-ES and
            Sep-CMA-ES (benchmarks/results/cmaes_restarts.md), 0 for the others.
            Memory: a buffer of ``P·2^R`` points.
        restart_tolfun: the stagnation tolerance on values (pycma's ``tolfun``).
        restart_tolx: the stagnation tolerance on the spread, in box widths (pycma's
            ``tolx``).
        bound_handling: ``"clip"`` (project onto the box, tell the projected points) or
            ``"transform"`` (pycma's ``BoundTransform``; distribution-based strategies);
            default ``"transform"`` with restarts, ``"clip"`` without (the one-run results
            stay those of earlier versions).
        **strategy_kwargs: passed to the evosax constructor (e.g. ``num_diff=2`` for DE).
    """

    strategy: Any
    # not named population_size: that is the capabilities record's field (see capabilities)
    pop_size: int | None
    num_generations: int
    std_init: float | None
    params: tuple
    strategy_kwargs: tuple
    restarts: int
    restart_tolfun: float
    restart_tolx: float
    bound_handling: str

    def __init__(self, strategy="CMA_ES", *, population_size: int | None = None,
                 num_generations: int = 1000, std_init: float | None = 0.3,
                 params: dict | None = None, restarts: int | None = None,
                 restart_tolfun: float = 1e-11, restart_tolx: float = 1e-11,
                 bound_handling: str | None = None, **strategy_kwargs):
        self.strategy = resolve_strategy(strategy)
        self.pop_size = population_size
        self.num_generations = num_generations
        self.std_init = std_init
        self.params = tuple(sorted((params or {}).items()))
        self.strategy_kwargs = tuple(sorted(strategy_kwargs.items()))
        self.restarts = (RESTARTS if _padded(self.strategy) else 0) if restarts is None else restarts
        self.restart_tolfun = restart_tolfun
        self.restart_tolx = restart_tolx
        self.bound_handling = ("transform" if self.restarts else "clip") if bound_handling is None else bound_handling

    def __repr__(self):  # the constructor call (Fit.settings records it)
        extra = "".join(f", {k}={v!r}" for k, v in self.strategy_kwargs)
        params = f", params={dict(self.params)!r}" if self.params else ""
        tols = ""
        if (self.restart_tolfun, self.restart_tolx) != (1e-11, 1e-11):
            tols = f", restart_tolfun={self.restart_tolfun}, restart_tolx={self.restart_tolx}"
        if self.bound_handling != ("transform" if self.restarts else "clip"):
            tols += f", bound_handling={self.bound_handling!r}"
        return (f"Evosax({self.strategy.__name__!r}, population_size={self.pop_size}, "
                f"num_generations={self.num_generations}, std_init={self.std_init}{params}, "
                f"restarts={self.restarts}{tols}{extra})")

    # ------------------------------------------------------------------ configuration
    @property
    def distribution_based(self) -> bool:
        _, base = _evosax()
        return issubclass(self.strategy, base)

    def population(self, n: int) -> int:
        """Population size ``P`` for ``n`` parameters."""
        if self.pop_size is not None:
            return self.pop_size
        return 4 + int(math.floor(3 * math.log(n))) if self.distribution_based else 25

    def capabilities(self, n: int) -> Capabilities:
        """``population_size``: ``P`` of a population-based strategy (a start ``y0`` may
        then hold up to ``P`` rows), ``None`` for a distribution-based one, which takes
        one start (its first mean). ``batches_runs`` only without restarts: with them a
        vmapped step runs every population size's ask and tell, so on one CPU
        [`minimise_many`][jaxfric.optim.minimise_many] runs keys in turn."""
        return dataclasses.replace(
            super().capabilities(n),
            population_size=None if self.distribution_based else self.population(1),
            max_evaluations=self.evaluations(n), batches_runs=self.restarts == 0)

    def evaluations(self, n: int) -> int:
        """Exact objective evaluations of a run on ``n`` parameters."""
        start = 1 if self.distribution_based else self.population(n)
        return start + self.population(n) * self.num_generations

    def check(self):
        if self.pop_size is not None:
            check_positive_int("population_size", self.pop_size, minimum=2)
        check_positive_int("num_generations", self.num_generations)
        if self.std_init is not None:
            check_range("std_init", self.std_init, 0.0, lo_open=True)
        try:
            hash((self.params, self.strategy_kwargs))
        except TypeError:
            raise ValueError("params and strategy keyword values must be hashable "
                             "(numbers, strings, functions)") from None
        _check_strategy(self.strategy, self.population(2), self.strategy_kwargs, tuple(dict(self.params)))
        check_positive_int("restarts", self.restarts, minimum=0)
        check_range("restart_tolfun", self.restart_tolfun, 0.0)
        check_range("restart_tolx", self.restart_tolx, 0.0)
        if self.bound_handling not in ("clip", "transform"):
            raise ValueError(f"bound_handling must be 'clip' or 'transform', got "
                             f"{self.bound_handling!r}")
        if self.bound_handling == "transform" and not self.distribution_based:
            raise ValueError(f"bound_handling='transform' needs a distribution-based strategy; "
                             f"{self.strategy.__name__} keeps a population (use 'clip')")
        if self.restarts:
            if not self.distribution_based:
                raise ValueError(
                    f"restarts need a distribution-based strategy (CMA_ES, Sep_CMA_ES, SNES, "
                    f"...); {self.strategy.__name__} keeps a population (use restarts=0)")
            _check_restartable(self.strategy, self.population(2), self.strategy_kwargs)

    def _es(self, lower):
        n = lower.shape[0]
        return _build(self.strategy, self.population(n), n, str(lower.dtype),
                      self.strategy_kwargs)

    def _es_params(self, es):
        params = es.default_params
        over = dict(self.params)
        if self.std_init is not None and hasattr(params, "std_init") and "std_init" not in over:
            over["std_init"] = self.std_init
        _check_names(self.strategy, params, over)
        return params.replace(**{k: jnp.asarray(v) if k == "std_init" else v
                                 for k, v in over.items()})

    # ------------------------------------------------------------------ rounds protocol
    def init_rounds(self, lower, upper, key, x0=None, objective=None) -> Rounds:
        es, n = self._es(lower), lower.shape[0]
        params = self._es_params(es)
        k_init, k_start, key = jax.random.split(key, 3)
        width = upper - lower
        u0 = None if x0 is None else (jnp.atleast_2d(x0) - lower) / width
        if self.distribution_based:
            mean = jax.random.uniform(k_start, (n,), lower.dtype) if u0 is None else u0[0]
            inner = es.init(k_init, self._genotype(mean), params)
            x = _to_box(mean, lower, upper)
            f = (yield x[None])[0]
            evals = 1
        else:
            P = self.population(n)
            U = uniform_flat(k_start, (P, n), lower.dtype)
            if u0 is not None:
                U = U.at[: u0.shape[0]].set(u0)
            X = _to_box(U, lower, upper)
            F = yield X
            inner = es.init(k_init, U, F, params)
            i = jnp.argmin(F)
            x, f, evals = X[i], F[i], P
        ipop = None
        if self.restarts:
            P, R = self.population(n), self.restarts
            ipop = IPOPState(
                level=jnp.array(0, jnp.int32), batch=jnp.array(0, jnp.int32),
                U=jnp.zeros((P << R, n), lower.dtype), F=jnp.full((P << R,), jnp.inf, lower.dtype),
                bests=jnp.full((self._windows(n)[0],), jnp.inf, lower.dtype),
                count=jnp.array(0, jnp.int32), flat=jnp.array(0, jnp.int32))
        return EvosaxState(inner, x, f, jnp.array(evals, count_dtype()),
                           jnp.array(0, jnp.int32), key, jnp.array(0, jnp.int32), ipop)

    def _windows(self, n: int) -> list[int]:
        """Generations of the best-value history checked for stagnation, per population
        level: pycma's ``10 + ⌈30·D/λ⌉``."""
        P = self.population(n)
        return [10 + math.ceil(30 * n / (P << j)) for j in range(self.restarts + 1)]

    def step_rounds(self, lower, upper, state: EvosaxState, stage=0, objective=None) -> Rounds:
        if self.restarts:
            return (yield from self._ipop_step(lower, upper, state))
        es = self._es(lower)
        params = self._es_params(es)
        k_ask, k_tell = jax.random.split(jax.random.fold_in(state.key, state.generation))
        U, inner = es.ask(k_ask, state.inner, params)
        U = self._repair(U.astype(lower.dtype))
        X = _to_box(self._phenotype(U), lower, upper)
        F = yield X
        inner, _ = es.tell(k_tell, U, F, inner, params)
        inner = self._like(inner, state.inner)
        # After convergence CMA-ES's step size underflows to 0 and its state to NaN:
        # every later sample would be NaN, so the strategy starts again (pycma's rule).
        broken = ~_all_finite(inner)
        k_restart = jax.random.fold_in(k_tell, 1)
        if self.distribution_based:
            fresh = es.init(k_restart, self._genotype(
                jax.random.uniform(k_restart, lower.shape, lower.dtype)), params)
        else:
            fresh = es.init(k_restart, U, F, params)
        inner = jax.tree_util.tree_map(lambda f, i: jnp.where(broken, f, i),
                                       self._like(fresh, state.inner), inner)
        return _advanced(state, inner, X, F, es.population_size, broken)

    def _ipop_step(self, lower, upper, state: EvosaxState) -> Rounds:
        """One batch of ``P`` points of the current generation (see the module
        docstring's **Restarts**): ask for the whole generation at its first batch, tell
        it at its last, then restart with twice the population if it ended stagnant."""
        n, P, R, ip = lower.shape[0], self.population(lower.shape[0]), self.restarts, state.ipop
        levels = [_build(self.strategy, P << j, n, str(lower.dtype), self.strategy_kwargs)
                  for j in range(R + 1)]
        params = [self._es_params(es) for es in levels]
        k_ask, k_tell = jax.random.split(jax.random.fold_in(state.key, state.generation))
        inner0 = self._like(state.inner, state.inner)
        lam = jnp.left_shift(P, ip.level)
        valid = jnp.arange(P << R) < lam

        # Population sizes in classes, each run by one strategy object of its class's
        # largest population: every size's parameters stacked (weights padded with
        # zeros) and the points beyond λ valued +inf (ranked last, weight 0); a class per
        # size for strategies where that is not the same update (_padded).
        classes = _classes(R, _padded(self.strategy))
        member = np.concatenate([np.full(hi - lo + 1, c) for c, (lo, hi) in enumerate(classes)])
        objects = [levels[hi] for _, hi in classes]
        stacked = [_stacked(params[lo:hi + 1], P, lo, hi) for lo, hi in classes]

        def at(c, level):
            i = level - int(classes[c][0])
            return jax.tree_util.tree_map(lambda a: a[i], stacked[c])

        def by_class(level, fn):
            branches = [functools.partial(fn, c) for c in range(len(classes))]
            if len(branches) == 1:
                return branches[0]()
            return jax.lax.switch(jnp.asarray(member)[level], branches)

        def ask_all():
            def one(c):
                U, inner = objects[c].ask(k_ask, inner0, at(c, ip.level))
                U = self._repair(U.astype(lower.dtype))
                return ip.U.at[: U.shape[0]].set(U), self._like(inner, inner0)
            return by_class(ip.level, one)

        def tell_all(U_all, F_all, inner):
            def one(c):
                size = objects[c].population_size
                F_c = jnp.where(valid[:size], F_all[:size], jnp.inf)
                new, _ = objects[c].tell(k_tell, U_all[:size], F_c, inner, at(c, ip.level))
                return self._like(_rescaled(new), inner0)
            return by_class(ip.level, one)

        def init_at(k, mean, level):
            return by_class(level, lambda c: self._like(
                objects[c].init(k, mean, at(c, level)), inner0))

        U_all, inner = jax.lax.cond(ip.batch == 0, ask_all, lambda: (ip.U, inner0))
        U = jax.lax.dynamic_slice_in_dim(U_all, ip.batch * P, P)
        X = _to_box(self._phenotype(U), lower, upper)
        F = yield X
        F_all = jax.lax.dynamic_update_slice_in_dim(ip.F, F.astype(ip.F.dtype), ip.batch * P, 0)
        ends = ip.batch + 1 == jnp.left_shift(1, ip.level)
        told = jax.lax.cond(ends, lambda: tell_all(U_all, F_all, inner), lambda: inner)

        # stagnation, judged when the generation ends
        stagnant, bests, count, flat = self._stagnation(ip, F_all, valid, lam, told, n)
        stagnant &= ends

        def restart():
            k = jax.random.fold_in(k_tell, 1)
            level = jnp.minimum(ip.level + 1, R)
            mean = self._genotype(jax.random.uniform(k, lower.shape, lower.dtype))
            return init_at(k, mean, level), level

        inner, level = jax.lax.cond(stagnant, restart, lambda: (told, ip.level))
        ipop = IPOPState(
            level=level,
            batch=jnp.where(ends, 0, ip.batch + 1),
            U=U_all, F=F_all,
            bests=jnp.where(ends, bests, ip.bests),
            count=jnp.where(stagnant, 0, jnp.where(ends, count, ip.count)),
            flat=jnp.where(stagnant, 0, jnp.where(ends, flat, ip.flat)),
        )
        return _advanced(state, inner, X, F, P, stagnant, ipop)

    def _stagnation(self, ip: IPOPState, F_all, valid, lam, told, n: int):
        """``(stagnant, bests, count, flat)``: whether a generation with the values ``F_all``
        (those where ``valid``, ``lam`` of them) and the told state ``told`` is stagnant by
        pycma's criteria (module docstring's **Restarts**), and the best-value history and
        flat count as the generation's end leaves them."""
        g_best = jnp.min(jnp.where(valid, F_all, jnp.inf))
        g_worst = jnp.max(jnp.where(valid, F_all, -jnp.inf))
        H = ip.bests.shape[0]
        bests = ip.bests.at[ip.count % H].set(g_best)
        count = ip.count + 1
        window = jnp.asarray(self._windows(n), jnp.int32)[ip.level]
        age = (count - 1 - jnp.arange(H)) % H
        recent = age < jnp.minimum(window, count)
        hist_range = (jnp.max(jnp.where(recent, bests, -jnp.inf))
                      - jnp.min(jnp.where(recent, bests, jnp.inf)))
        tol = jnp.asarray(self.restart_tolfun, g_best.dtype)
        stagnant = ((count >= window) & (hist_range < tol) & (g_worst - g_best < tol))
        stagnant |= (jnp.minimum(count, window) > 9) & (hist_range < tol / 10)  # tolfunhist
        # flat (pycma's tolflatfitness = 1): a second generation in a row whose best value
        # equals its ⌊0.75·λ⌋-th best, i.e. more than ⌊0.75·λ⌋ of its values equal the
        # best (counted, not sorted: a sort of the P·2^R buffer at every step cost more
        # than the step)
        flat_now = jnp.sum(valid & (F_all <= g_best)) > (lam * 3) // 4
        flat = jnp.where(flat_now, ip.flat + 1, 0)
        stagnant |= flat > 1
        stagnant |= _no_spread(told, self.restart_tolx)
        stagnant |= ~_all_finite(told)
        return stagnant, bests, count, flat

    # ------------------------------------------------------------------ bound handling
    def _repair(self, U):
        """The points the strategy asked for, as it is told them: projected onto the box
        (``"clip"``) or as they are (``"transform"``, its genotypes)."""
        return jnp.clip(U, 0.0, 1.0) if self.bound_handling == "clip" else U

    def _phenotype(self, U):
        """The unit-box points evaluated for the told points ``U``."""
        return U if self.bound_handling == "clip" else _linquad(U)

    def _genotype(self, u):
        """The strategy's mean for a start ``u`` in the unit box."""
        return u if self.bound_handling == "clip" else _linquad_inverse(u)

    @staticmethod
    def _like(inner, old):
        """``inner`` in the carried state's dtypes (evosax's constants follow JAX's
        default float)."""
        return jax.tree_util.tree_map(lambda new, o: jnp.asarray(new, jnp.result_type(o)),
                                      inner, old)

    def best(self, state):
        return state.x_best, state.f_best


def cmaes_nm(*, population_size: int | None = None, num_generations: int = 1000,
             std_init: float | None = 0.3, restarts: int | None = None,
             nm_max_steps: int | None = None, nm_max_evals: int | None = None,
             **nm_kwargs) -> Chain:
    """``chain(Evosax("CMA_ES"), NelderMead())``: CMA-ES's global search (with
    ``restarts`` IPOP restarts), then Nelder–Mead from its best point (docs/algorithms.md
    §5.1 with CMA-ES as the global stage). ``nm_*`` keywords and the rest go to
    [`NelderMead`][jaxfric.optim.NelderMead]."""
    cma = Evosax("CMA_ES", population_size=population_size, num_generations=num_generations,
                 std_init=std_init, restarts=restarts)
    nm = NelderMead(max_steps=nm_max_steps, max_evals=nm_max_evals, **nm_kwargs)
    return Chain(cma, nm)
