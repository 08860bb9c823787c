"""The stages [`jaxfric.identify`][jaxfric.identification.identify] and [`jaxfric.identify_motion`][jaxfric.motion.identify_motion] share,
once, as functions of plain values: the keys of a run or an ensemble, the solver's global
search and its record, member selection, the baseline beside a fit. What differs between
the two problems (records, objective, local stage, score) is each problem's own
([`jaxfric.problem.AbstractProblem`][jaxfric.problem.AbstractProblem]); the stage list and who implements what:
docs/architecture.md, "Pipeline".
"""

from __future__ import annotations

import dataclasses
import numbers
import warnings
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ._timing import Stopwatch
from ._warnings import BaselineWarning
from .optim import AbstractSolver, Solution, minimise, minimise_many

__all__ = ["BASELINE_MARGIN", "ENSEMBLE_DROP", "Keys", "as_key", "as_member_keys", "baseline_stage",
           "best_member", "check_solver", "global_search", "history", "kept_members", "key_record", "resolve_keys",
           "solver_stages", "warn_if_worse"]


# --------------------------------------------------------------------- keys
@dataclasses.dataclass(frozen=True)
class Keys:
    """The keys of one identification: ``key`` for one run, or ``members`` (a batch of
    K typed keys) for an ensemble; ``seed`` is the int seed when one was given."""

    key: Any
    seed: int | None
    members: Any = None

    @property
    def size(self) -> int | None:
        return None if self.members is None else int(self.members.shape[0])


def as_key(key):
    """``(JAX PRNG key, int seed or None)`` from a key or an int seed."""
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


def as_member_keys(key, keys):
    """The members' keys of an ensemble (``keys=K``): ``K`` keys split from ``key``, or
    the given batch. Returns ``(typed key batch, K)``."""
    if isinstance(keys, numbers.Integral) and not isinstance(keys, bool):
        if keys < 1:
            raise ValueError(f"keys must be a number of members >= 1 or a batch of keys, got {keys}")
        return jax.random.split(as_key(key)[0], int(keys)), int(keys)
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


def resolve_keys(key, keys=None) -> Keys:
    """[`Keys`][jaxfric.pipeline.Keys] from an identification's ``key=`` and ``keys=`` (checked)."""
    if keys is None:
        key, seed = as_key(key)
        return Keys(key=key, seed=seed)
    seed = key if isinstance(key, numbers.Integral) and not isinstance(key, bool) else None
    members, _ = as_member_keys(key, keys)
    return Keys(key=None, seed=seed, members=members)


def key_record(key):
    """``(key data as a list, key implementation name or None)`` for a fit's record."""
    k = jnp.asarray(key)
    if jnp.issubdtype(k.dtype, jax.dtypes.prng_key):
        return np.asarray(jax.random.key_data(k)).ravel().tolist(), str(jax.random.key_impl(k))
    return np.asarray(k).ravel().tolist(), None


# ------------------------------------------------------------ global search
def check_solver(solver) -> AbstractSolver:
    """``solver``, a jaxfric solver whose own ``check`` passed, or a ``ValueError``."""
    if not isinstance(solver, AbstractSolver):
        raise ValueError(f"solver must be a jaxfric solver (MAPSONMDS, MAPSO, PSO, NelderMead), "
                         f"got {type(solver).__name__}")
    solver.check()
    return solver


def global_search(cost, data, lower, upper, solver, keys: Keys, *, theta0=None, dtype=None,
                  progress=None, compiler_options="auto", batching: str = "map") -> tuple[Solution, dict]:
    """A solver's derivative-free search of ``cost(y, data)`` in ``[lower, upper]``: one
    [`jaxfric.minimise`][jaxfric.optim.minimise] run (``keys.key``), or one
    [`jaxfric.minimise_many`][jaxfric.optim.minimise_many] call over ``keys.members`` (``batching`` as
    there). Returns the solution (fields with a leading member axis for an ensemble) and its
    ``{"compile_s", "run_s"}``."""
    with Stopwatch() as sw:
        if keys.members is None:
            sol = minimise(cost, solver, (lower, upper), args=data, key=keys.key, y0=theta0, dtype=dtype,
                           progress=progress, compiler_options=compiler_options)
        else:
            sol = minimise_many(cost, solver, (lower, upper), keys=keys.members, args=data, y0=theta0,
                                dtype=dtype, progress=progress, compiler_options=compiler_options,
                                batching=batching)
        sol = jax.block_until_ready(sol)
    return sol, {"compile_s": sw.compile_s, "run_s": sw.run_s}


def solver_stages(sol, solver) -> list[dict]:
    """``Fit.stages`` rows of a solver run: each stage's J and evaluations."""
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


def history(sol) -> dict[str, np.ndarray]:
    """The best-so-far J against evaluations of a solver run (empty without one)."""
    if sol is None:
        return {"evals": np.zeros(0), "f": np.zeros(0)}
    n = int(sol.history.length)
    return {"evals": np.asarray(sol.history.evals)[:n], "f": np.asarray(sol.history.f)[:n]}


# ---------------------------------------------------------------- selection
#: Ensemble members whose score exceeds this factor times the best member's are dropped
#: from the ensemble's prediction ([`kept_members`][jaxfric.pipeline.kept_members]).
ENSEMBLE_DROP = 1.5


def best_member(scores) -> int:
    """The index of the lowest finite score (a member's training cost J, or its training
    RMSE); the first member when none is finite."""
    s = np.asarray(scores, np.float64)
    return int(np.argmin(np.where(np.isfinite(s), s, np.inf)))


def kept_members(scores, drop: float = ENSEMBLE_DROP) -> list:
    """Indices of the members whose score is finite and at most ``drop`` times the best
    one's ([`ENSEMBLE_DROP`][jaxfric.pipeline.ENSEMBLE_DROP])."""
    s = np.asarray(scores, np.float64)
    best = np.min(np.where(np.isfinite(s), s, np.inf))
    return [i for i in range(s.size) if np.isfinite(s[i]) and s[i] <= drop * best]


# ----------------------------------------------------------------- baseline
#: A fit counts as worse than its baseline when its training score exceeds the
#: baseline's by more than this fraction.
BASELINE_MARGIN = 1e-3
#: How the least-squares Coulomb + viscous + offset baseline is named in tables, figures and warnings.
BASELINE_LABEL = "least squares (Coulomb + viscous + offset)"
#: The windows of a baseline's metrics shown beside the fit's.
BASELINE_WINDOWS = ("train", "valid")


def baseline_stage(fit, baseline: dict, *, label: str, advice: str, stacklevel: int = 2):
    """``fit`` with ``metrics["baseline"]``: the ``"train"`` and ``"valid"`` rows of
    ``baseline`` (the metrics of a reference scored like ``fit``, on the same windows), and a
    [`BaselineWarning`][jaxfric.motion.BaselineWarning] when ``fit`` is worse on its training data
    ([`warn_if_worse`][jaxfric.pipeline.warn_if_worse])."""
    rows = {w: baseline[w] for w in BASELINE_WINDOWS if baseline.get(w) is not None}
    fit = fit.replace(metrics={**fit.metrics, "baseline": rows})
    warn_if_worse(fit, label=label, advice=advice, stacklevel=stacklevel + 1)
    return fit


def warn_if_worse(fit, *, label: str, advice: str, margin: float = BASELINE_MARGIN,
                  stacklevel: int = 2) -> bool:
    """[`BaselineWarning`][jaxfric.motion.BaselineWarning] when ``fit``'s training score (its problem's
    ``metric``, lower is better: a motion fit's RMSE [mm], a force-balance fit's MSE %) exceeds
    its ``metrics["baseline"]``'s by more than ``margin``. Returns whether it warned."""
    problem = fit.problem()
    mine = fit.metrics["train"][problem.metric]
    base = fit.metrics["baseline"]["train"][problem.metric]
    if mine <= (1.0 + margin) * base:
        return False
    unit = problem.metric_unit
    warnings.warn(
        f"the {fit.settings['model_name']} fit simulates its training data worse than the {label}: "
        f"{problem.metric_label} {mine:.4g} {unit} against {base:.4g} {unit}; {advice}",
        BaselineWarning, stacklevel=stacklevel + 1)
    return True
