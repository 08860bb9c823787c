"""Benchmark test functions (docs/algorithms.md §9) with their standard domains and optima.

Every function takes a 1-D array ``x`` of any length ``D`` and returns a scalar; all
are jit-, vmap- and grad-safe (where the function is differentiable) and keep the
dtype of ``x``. The registry [`REGISTRY`][jaxfric.functions.REGISTRY] maps a name to a [`TestFunction`][jaxfric.functions.TestFunction]
record holding the function, its default box and its known minimiser.

Which Schwefel?  The paper says every function except Rosenbrock has its minimum 0
at the origin, which rules out Schwefel 2.26. ``schwefel`` is **Schwefel 2.22**
(Σ|x_i| + Π|x_i|, f8 in MAGA); Schwefel 1.2 (``schwefel_1_2``, Σ_i (Σ_{j≤i} x_j)²)
and Schwefel 2.21 (``schwefel_2_21``, max_i |x_i|) are available under their own
names. Bounds follow Yao, Liu & Lin (1999).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import jax.numpy as jnp
import numpy as np

__all__ = [
    "griewank",
    "ackley",
    "sphere",
    "schwefel",
    "schwefel_2_22",
    "schwefel_1_2",
    "schwefel_2_21",
    "rosenbrock",
    "rastrigin",
    "TestFunction",
    "REGISTRY",
    "get",
    "objective",
]


def sphere(x):
    """Sphere: f(x) = Σ x_i². Minimum 0 at 0; domain [−100, 100]^D."""
    return jnp.sum(x * x)


def griewank(x):
    """Griewank: f(x) = 1 + Σ x_i²/4000 − Π cos(x_i/√i), i = 1..D. Minimum 0 at 0; [−600, 600]^D."""
    i = jnp.arange(1, x.shape[0] + 1, dtype=x.dtype)
    return 1.0 + jnp.sum(x * x) / 4000.0 - jnp.prod(jnp.cos(x / jnp.sqrt(i)))


def ackley(x):
    """Ackley: f(x) = −20·exp(−0.2·√(Σx_i²/D)) − exp(Σcos(2πx_i)/D) + 20 + e.

    Minimum 0 at 0; [−32, 32]^D. The square root is guarded so the gradient at the
    origin is finite (it is zero there by symmetry of the subgradient set).
    """
    d = x.shape[0]
    ss = jnp.sum(x * x) / d
    safe = jnp.where(ss > 0, ss, 1.0)
    root = jnp.where(ss > 0, jnp.sqrt(safe), 0.0)
    return (
        -20.0 * jnp.exp(-0.2 * root)
        - jnp.exp(jnp.sum(jnp.cos(2.0 * jnp.pi * x)) / d)
        + 20.0
        + jnp.e
    )


def schwefel_2_22(x):
    """Schwefel 2.22: f(x) = Σ|x_i| + Π|x_i|. Minimum 0 at 0; [−10, 10]^D."""
    a = jnp.abs(x)
    return jnp.sum(a) + jnp.prod(a)


schwefel = schwefel_2_22


def schwefel_1_2(x):
    """Schwefel 1.2 (double sum): f(x) = Σ_i (Σ_{j≤i} x_j)². Minimum 0 at 0; [−100, 100]^D."""
    return jnp.sum(jnp.cumsum(x) ** 2)


def schwefel_2_21(x):
    """Schwefel 2.21: f(x) = max_i |x_i|. Minimum 0 at 0; [−100, 100]^D."""
    return jnp.max(jnp.abs(x))


def rosenbrock(x):
    """Rosenbrock: f(x) = Σ_{i<D} [100(x_{i+1} − x_i²)² + (1 − x_i)²]. Minimum 0 at 1; [−30, 30]^D."""
    return jnp.sum(100.0 * (x[1:] - x[:-1] ** 2) ** 2 + (1.0 - x[:-1]) ** 2)


def rastrigin(x):
    """Rastrigin: f(x) = 10D + Σ (x_i² − 10 cos 2πx_i). Minimum 0 at 0; [−5.12, 5.12]^D."""
    return 10.0 * x.shape[0] + jnp.sum(x * x - 10.0 * jnp.cos(2.0 * jnp.pi * x))


@dataclass(frozen=True)
class TestFunction:
    """A benchmark function with its default domain and known optimum.

    ``half_width`` gives the symmetric box ``[−half_width, half_width]^D``;
    ``minimiser(D)`` the known global minimiser; ``f_min`` its value.
    """

    __test__ = False  # not a pytest test class

    name: str
    fn: Callable
    half_width: float
    minimiser_value: float
    f_min: float = 0.0

    def bounds(self, dim: int, dtype=np.float64):
        hw = np.full((dim,), self.half_width, dtype)
        return -hw, hw

    def minimiser(self, dim: int, dtype=np.float64):
        return np.full((dim,), self.minimiser_value, dtype)

    def __call__(self, x):
        return self.fn(x)


REGISTRY: dict[str, TestFunction] = {
    t.name: t
    for t in [
        TestFunction("griewank", griewank, 600.0, 0.0),
        TestFunction("ackley", ackley, 32.0, 0.0),
        TestFunction("sphere", sphere, 100.0, 0.0),
        TestFunction("schwefel", schwefel_2_22, 10.0, 0.0),
        TestFunction("schwefel_2_22", schwefel_2_22, 10.0, 0.0),
        TestFunction("schwefel_1_2", schwefel_1_2, 100.0, 0.0),
        TestFunction("schwefel_2_21", schwefel_2_21, 100.0, 0.0),
        TestFunction("rosenbrock", rosenbrock, 30.0, 1.0),
        TestFunction("rastrigin", rastrigin, 5.12, 0.0),
    ]
}

PAPER_TABLE1 = ("griewank", "ackley", "sphere", "schwefel", "rosenbrock")
"""The five functions of the paper's Table 1, in its order."""


def get(name: str) -> TestFunction:
    """Look a test function up by name; unknown names raise ``ValueError``."""
    try:
        return REGISTRY[name]
    except KeyError:
        raise ValueError(
            f"unknown test function {name!r}; choose one of {sorted(REGISTRY)}"
        ) from None


def _as_objective(fn):
    def objective_fn(y, args):
        return fn(y)

    return objective_fn


_OBJECTIVES = {name: _as_objective(t.fn) for name, t in REGISTRY.items()}


def objective(name: str) -> Callable:
    """``fn(y, args)`` form of a test function, ready for [`jaxfric.minimise`][jaxfric.optim.minimise].

    The same function object is returned on every call, so jit caches are reused.
    """
    get(name)
    return _OBJECTIVES[name]
