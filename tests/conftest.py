"""Shared test helpers. Tests never change global JAX configuration: float64 checks
use the ``jax.enable_x64(True)`` context manager."""

import jax
import numpy as np
import pytest


class CallCounter:
    """Counts objective evaluations on the host, independently of the solvers.

    ``wrap(fn)`` returns ``fn(y, args)`` that reports every evaluated point through a
    ``pure_callback`` (sequential under vmap), so points and counts are seen exactly
    as XLA computes them.
    """

    def __init__(self):
        self.points = []

    def _record(self, x):
        x = np.asarray(x)
        self.points.append(x.reshape(-1, x.shape[-1]).copy())
        return np.zeros(np.asarray(x).shape[:-1], np.asarray(x).dtype)

    def wrap(self, fn):
        def counted(y, args):
            zero = jax.pure_callback(
                self._record,
                jax.ShapeDtypeStruct((), y.dtype),
                y,
                vmap_method="expand_dims",
            )
            return fn(y, args) + zero

        return counted

    @property
    def count(self):
        return int(sum(p.shape[0] for p in self.points))

    def all_points(self):
        return np.concatenate(self.points) if self.points else np.zeros((0, 0))


@pytest.fixture
def counter():
    return CallCounter()


@pytest.fixture
def run_cache_size():
    """Number of compilations cached for ``minimise``'s single-run executable (with the
    default ``compiler_options``): a test counts recompilations with it."""
    from jaxfric import _xla
    from jaxfric.optim.driver import _run

    def size():
        return _xla.filter_jit(_run, _xla.resolve("auto", "solver"))._cached._cache_size()

    return size
