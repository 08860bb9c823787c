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
in the bounds.

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

**Restarts.** When the strategy's own state turns non-finite (CMA-ES's step size
underflows some thousand generations after it has converged) the strategy restarts, as
pycma does, instead of ending the run with budget left: a distribution-based strategy
from a fresh uniform random mean with its first spread, a population-based one from its
last (evaluated) population. The best point so far is kept; ``state.restarts`` counts
the restarts.

**Cost in many dimensions.** Full CMA-ES eigendecomposes its D×D covariance every
generation (``jnp.linalg.eigh``, O(D³)). On a 2-core CPU that took 3–7 ms at D = 30 but
0.2–0.9 s at D = 180 (the 30-neuron Elman network): 40 ms per evaluation there, against
0.75 ms for ``"Sep_CMA_ES"`` (diagonal covariance, O(D) per generation) and 0.16 ms for
MAPSO's 64 agents (benchmarks/global_stages.py). For more than a few tens of parameters
use ``Evosax("Sep_CMA_ES")`` (or another diagonal strategy such as ``"SNES"``).

**Keys.** Generation ``i`` uses ``fold_in(key, i)`` (split in two for ``ask`` and
``tell``), so the same key gives the same run, chunked (checkpoints) or not.

evosax is an optional dependency: ``pip install -e ".[evosax]"``. Without it,
constructing [`Evosax`][jaxfric.optim.Evosax] raises ``ImportError`` naming that extra.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from ._base import check_positive_int, check_range, count_dtype, uniform_flat
from .chained import Chain
from .nelder_mead import NelderMead
from .contract import AbstractGenerational
from .rounds import Rounds

INSTALL_HINT = 'pip install -e ".[evosax]"'

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


def _all_finite(tree):
    leaves = [jnp.all(jnp.isfinite(a)) for a in jax.tree_util.tree_leaves(tree)
              if jnp.issubdtype(jnp.result_type(a), jnp.inexact)]
    return jnp.all(jnp.stack(leaves)) if leaves else jnp.array(True)


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


def _check_names(cls, params, over) -> None:
    unknown = sorted(set(over) - set(vars(params)))
    if unknown:
        raise ValueError(f"{cls.__name__} has no parameter(s) {unknown}; "
                         f"its parameters: {sorted(vars(params))}")


class EvosaxState(eqx.Module):
    """The strategy's own state, the best projected point and its value, the exact
    evaluation count, generations done, the run's key, and how often the strategy
    restarted after its state turned non-finite (see [`Evosax`][jaxfric.optim.Evosax])."""

    inner: Any
    x_best: Any
    f_best: Any
    num_evals: Any
    generation: Any
    key: Any
    restarts: Any


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
        **strategy_kwargs: passed to the evosax constructor (e.g. ``num_diff=2`` for DE).
    """

    strategy: Any
    # not named population_size: that is the solver contract's capability (a method)
    pop_size: int | None
    num_generations: int
    std_init: float | None
    params: tuple
    strategy_kwargs: tuple

    def __init__(self, strategy="CMA_ES", *, population_size: int | None = None,
                 num_generations: int = 1000, std_init: float | None = 0.3,
                 params: dict | None = None, **strategy_kwargs):
        self.strategy = resolve_strategy(strategy)
        self.pop_size = population_size
        self.num_generations = num_generations
        self.std_init = std_init
        self.params = tuple(sorted((params or {}).items()))
        self.strategy_kwargs = tuple(sorted(strategy_kwargs.items()))

    def __repr__(self):  # the constructor call (Fit.settings records it)
        extra = "".join(f", {k}={v!r}" for k, v in self.strategy_kwargs)
        params = f", params={dict(self.params)!r}" if self.params else ""
        return (f"Evosax({self.strategy.__name__!r}, population_size={self.pop_size}, "
                f"num_generations={self.num_generations}, std_init={self.std_init}{params}{extra})")

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

    def population_size(self) -> int | None:
        """``P`` of a population-based strategy, whatever the dimension (a start ``y0``
        may then hold up to ``P`` rows); ``None`` for a distribution-based one, which
        takes one start (its first mean)."""
        return None if self.distribution_based else self.population(1)

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
            inner = es.init(k_init, mean, params)
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
        return EvosaxState(inner, x, f, jnp.array(evals, count_dtype()),
                           jnp.array(0, jnp.int32), key, jnp.array(0, jnp.int32))

    def step_rounds(self, lower, upper, state: EvosaxState, stage=0, objective=None) -> Rounds:
        es = self._es(lower)
        params = self._es_params(es)
        k_ask, k_tell = jax.random.split(jax.random.fold_in(state.key, state.generation))
        U, inner = es.ask(k_ask, state.inner, params)
        U = jnp.clip(U.astype(lower.dtype), 0.0, 1.0)  # projection onto the box
        X = _to_box(U, lower, upper)
        F = yield X
        inner, _ = es.tell(k_tell, U, F, inner, params)
        inner = self._like(inner, state.inner)
        # After convergence CMA-ES's step size underflows to 0 and its state to NaN:
        # every later sample would be NaN, so the strategy starts again (pycma's rule).
        broken = ~_all_finite(inner)
        k_restart = jax.random.fold_in(k_tell, 1)
        if self.distribution_based:
            fresh = es.init(k_restart, jax.random.uniform(k_restart, lower.shape, lower.dtype),
                            params)
        else:
            fresh = es.init(k_restart, U, F, params)
        inner = jax.tree_util.tree_map(lambda f, i: jnp.where(broken, f, i),
                                       self._like(fresh, state.inner), inner)
        i = jnp.argmin(F)
        better = F[i] < state.f_best
        return EvosaxState(
            inner,
            jnp.where(better, X[i], state.x_best),
            jnp.where(better, F[i], state.f_best),
            state.num_evals + es.population_size,
            state.generation + 1,
            state.key,
            state.restarts + broken.astype(jnp.int32),
        )

    @staticmethod
    def _like(inner, old):
        """``inner`` in the carried state's dtypes (evosax's constants follow JAX's
        default float)."""
        return jax.tree_util.tree_map(lambda new, o: jnp.asarray(new, jnp.result_type(o)),
                                      inner, old)

    def best(self, state):
        return state.x_best, state.f_best

    def max_evaluations(self, n: int) -> int:
        return self.evaluations(n)


def cmaes_nm(*, population_size: int | None = None, num_generations: int = 1000,
             std_init: float | None = 0.3, nm_max_steps: int | None = None,
             nm_max_evals: int | None = None, **nm_kwargs) -> Chain:
    """``chain(Evosax("CMA_ES"), NelderMead())``: CMA-ES's global search, then
    Nelder–Mead from its best point (docs/algorithms.md §5.1 with CMA-ES as the global
    stage). ``nm_*`` keywords and the rest go to [`NelderMead`][jaxfric.optim.NelderMead]."""
    cma = Evosax("CMA_ES", population_size=population_size, num_generations=num_generations,
                 std_init=std_init)
    nm = NelderMead(max_steps=nm_max_steps, max_evals=nm_max_evals, **nm_kwargs)
    return Chain(cma, nm)
