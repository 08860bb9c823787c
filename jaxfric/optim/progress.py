"""Progress display for long runs, without leaving the compiled program.

The jitted run calls one fixed host function (``_dispatch``) through
``jax.debug.callback`` every few generations. Which display receives the call is
looked up by an integer *token* passed as an ordinary array argument, so showing
a new progress bar never recompiles: the program only knows "progress on, every K
generations". Under ``vmap`` the callback fires once per batch member; displays
keep the best value seen for each step.
"""

from __future__ import annotations

import itertools
import threading
import time
from typing import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

PHASES = ("global", "local", "gradient")
"""Phase 0 is a swarm's generations, phase 1 Nelder–Mead's steps, phase 2 the steps of
[`jaxfric.identify`][jaxfric.identification.identify]'s gradient stage."""

_STAGE_LABEL = {1: (" (Nelder–Mead)", "step"), 2: (" (gradient)", "step")}

_SINKS: dict[int, Callable] = {}
_LOCK = threading.Lock()
_COUNTER = itertools.count(1)


def _dispatch(token, phase, step, evals, f_best):
    sink = _SINKS.get(int(token))
    if sink is not None:
        sink(int(phase), int(step), int(evals), float(f_best))


class ProgressHook(eqx.Module):
    """Traced side of progress reporting: a token and how often to report."""

    token: Array
    every_generation: int = eqx.field(static=True, default=1)
    every_step: int = eqx.field(static=True, default=50)

    def emit(self, phase, step, evals, f_best, force: bool = False):
        """Report ``(step, evals, f_best)`` when ``step`` is a multiple of the phase's
        period, or always with ``force`` (a stage's last step, so displays end there)."""
        phase = jnp.asarray(phase, jnp.int32)
        step = jnp.asarray(step)
        every = jnp.where(phase == 0, self.every_generation, self.every_step)

        def call():
            jax.debug.callback(_dispatch, self.token, phase, step, evals, f_best)

        if force:
            call()
        else:
            jax.lax.cond(step % every == 0, call, lambda: None)


class register:
    """Context manager: route a host ``sink(phase, step, evals, f_best)`` to a token."""

    def __init__(self, sink: Callable):
        self.sink = sink

    def __enter__(self) -> Array:
        with _LOCK:
            self.token = next(_COUNTER)
            _SINKS[self.token] = self.sink
        return jnp.asarray(self.token, jnp.int32)

    def __exit__(self, *exc):
        with _LOCK:
            _SINKS.pop(self.token, None)
        close = getattr(self.sink, "close", None)
        if close is not None:
            close()
        return False


class TqdmProgress:
    """A tqdm bar: generation (or Nelder–Mead step), best f so far, evaluations, elapsed.

    Args:
        total: number of generations of the global phase (``None`` if unknown).
        local_total: Nelder–Mead's step cap, shown once the local phase starts.
        desc: bar label.
        gradient_total: the gradient stage's step cap (``None``: count only).

    Each stage draws its own bar, labelled by the stage, whose clock starts at the
    stage's first report.
    """

    def __init__(self, total=None, local_total=None, desc="jaxfric", gradient_total=None,
                 **tqdm_kwargs):
        from tqdm.auto import tqdm

        self._tqdm = tqdm
        self.totals = {1: local_total, 2: gradient_total}
        self.kwargs = dict(desc=desc, dynamic_ncols=True, leave=True, **tqdm_kwargs)
        self.bar = tqdm(total=total, unit="gen", **self.kwargs)
        self.phase = 0
        self.best = float("inf")
        self.start = time.perf_counter()
        self._started = False

    def _start_clock(self, step):
        """Start the bar's clock at the first report of a stage, counting ``step`` as done
        before it: that report comes after compilation (or after the previous stage), so
        a rate measured from the bar's creation would include it and the first ETA would
        be several times too long."""
        self.bar.reset(total=self.bar.total)
        self.bar.initial = self.bar.n = self.bar.last_print_n = step
        self._started = True

    def _finish_bar(self):
        """A stage that ended early (stall, tolerance, budget) ends its bar at 100 %."""
        if self.bar.total is not None and self.bar.n < self.bar.total:
            self.bar.total = self.bar.n
            self.bar.refresh()
        self.bar.close()

    def __call__(self, phase, step, evals, f_best):
        if phase != self.phase:
            self._finish_bar()
            self.phase = phase
            suffix, unit = _STAGE_LABEL[phase]
            self.bar = self._tqdm(
                total=self.totals[phase], unit=unit,
                **{**self.kwargs, "desc": self.kwargs["desc"] + suffix},
            )
            self._started = False
        self.best = min(self.best, f_best)
        if not self._started:
            self._start_clock(step)
        elif step > self.bar.n:
            self.bar.update(step - self.bar.n)
        self.bar.set_postfix(best=f"{self.best:.4g}", evals=evals, refresh=False)

    def close(self):
        self._finish_bar()


class RecordingProgress:
    """Collects every report (for tests and for callers that draw their own display)."""

    def __init__(self):
        self.reports = []

    def __call__(self, phase, step, evals, f_best):
        self.reports.append((PHASES[phase], step, evals, f_best))
