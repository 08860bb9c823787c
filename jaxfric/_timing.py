"""Split a call's wall time into compilation and run time, without running anything twice.

JAX reports every trace, lowering and XLA compile as a time span through
``jax.monitoring``. `Stopwatch` listens only while it is active (the
listener is removed on exit, and no configuration is touched), merges the spans
(nested ``jit`` traces overlap) and reports ``compile_s`` = their union and
``run_s`` = wall − compile. A call served from the jit cache has ``compile_s ≈ 0``.
"""

from __future__ import annotations

import threading
import time

import jax

_COMPILE_EVENTS = (
    "/jax/core/compile/jaxpr_trace_duration",
    "/jax/core/compile/jaxpr_to_mlir_module_duration",
    "/jax/core/compile/backend_compile_duration",
)
_BACKEND_COMPILE = "/jax/core/compile/backend_compile_duration"


class Stopwatch:
    """Context manager: ``with Stopwatch() as sw: ...``, then ``sw.wall_s``,
    ``sw.compile_s``, ``sw.run_s`` and ``sw.num_compiles`` (XLA compilations seen)."""

    def __init__(self):
        self._spans: list[tuple[float, float]] = []
        self._thread = threading.get_ident()
        self.num_compiles = 0
        self.wall_s = 0.0

    def _listener(self, event, start_time, end_time, **kwargs):
        # Spans from other threads belong to someone else's computation.
        if event in _COMPILE_EVENTS and threading.get_ident() == self._thread:
            self._spans.append((float(start_time), float(end_time)))
            if event == _BACKEND_COMPILE:
                self.num_compiles += 1

    def __enter__(self):
        self._thread = threading.get_ident()
        jax.monitoring.register_event_time_span_listener(self._listener)
        self._t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        self.wall_s = time.perf_counter() - self._t0
        jax.monitoring.unregister_event_time_span_listener(self._listener)
        return False

    @property
    def compile_s(self) -> float:
        total, end = 0.0, float("-inf")
        for a, b in sorted(self._spans):
            if b <= end:
                continue
            total += b - max(a, end)
            end = b
        return min(total, self.wall_s) if self.wall_s else total

    @property
    def run_s(self) -> float:
        return max(self.wall_s - self.compile_s, 0.0)
