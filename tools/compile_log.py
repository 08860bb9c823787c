"""A pytest plugin that writes, per test, its wall and CPU seconds and what JAX spent
compiling: tracing, lowering and XLA compilation (summed from ``jax.monitoring``
events), the number of XLA compilations and of persistent-cache hits. One CSV per
process (xdist workers included) at ``$COMPILE_LOG.<pid>``::

    PYTHONPATH=tools COMPILE_LOG=/tmp/cl python -m pytest -q -p compile_log -n 2 --dist loadfile

Columns: nodeid, wall_s, cpu_s, xla_s, trace_s, lower_s, programs, cache_hits.
"""

from __future__ import annotations

import csv
import os
import time

import pytest

_EVENTS = {
    "/jax/core/compile/backend_compile_duration": "xla",
    "/jax/core/compile/jaxpr_trace_duration": "trace",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
}
_acc: dict[str, float] = {}
_installed = False


def _on_duration(event, duration, **_):
    name = _EVENTS.get(event)
    if name is not None:
        _acc[name] = _acc.get(name, 0.0) + duration
        if name == "xla":
            _acc["programs"] = _acc.get("programs", 0) + 1


def _on_event(event, **_):
    if event == "/jax/compilation_cache/cache_hits":
        _acc["hits"] = _acc.get("hits", 0) + 1


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    global _installed
    if not _installed:
        import jax.monitoring

        jax.monitoring.register_event_duration_secs_listener(_on_duration)
        jax.monitoring.register_event_listener(_on_event)
        _installed = True
    _acc.clear()
    t0, c0 = time.perf_counter(), time.process_time()
    yield
    row = [item.nodeid, f"{time.perf_counter() - t0:.3f}", f"{time.process_time() - c0:.3f}",
           *(f"{_acc.get(k, 0.0):.3f}" for k in ("xla", "trace", "lower")),
           int(_acc.get("programs", 0)), int(_acc.get("hits", 0))]
    with open(f"{os.environ.get('COMPILE_LOG', 'compile_log.csv')}.{os.getpid()}", "a", newline="") as fh:
        csv.writer(fh).writerow(row)
