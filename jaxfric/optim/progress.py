"""Progress displays for long runs, updated on the host between chunks of the run.

A run with a display goes in chunks ([`jaxfric.optim.driver`][jaxfric.optim.driver]
calls its one compiled program again and again, as a checkpointed run does); after each
chunk the host hands the display ``(phase, step, evals, f_best)``. Nothing calls back
from inside the compiled program, so the program is the one a run without a display
compiles, and JAX's persistent compilation cache keeps it (a program holding a host
callback is never written there). Chunks end about every 1 % of a global stage's
generations and every 50 local steps (``Chunks``); a
chunked run takes exactly the steps of a whole one.
"""

from __future__ import annotations

import time

PHASES = ("global", "local", "gradient")
"""Phase 0 is a swarm's generations, phase 1 Nelder–Mead's steps, phase 2 the steps of
[`jaxfric.identify`][jaxfric.identification.identify]'s gradient stage."""

#: Phase number of the reports of a stage counted in steps: the gradient stage of
#: [`jaxfric.identify`][jaxfric.identification.identify] and each Levenberg–Marquardt stage
#: of [`jaxfric.identify_motion`][jaxfric.motion.identify_motion] (`step_progress`).
GRADIENT_PHASE = 2

_STAGE_LABEL = {1: (" (Nelder–Mead)", "step"), 2: (" (gradient)", "step")}

#: Local (Nelder–Mead) steps between two reports.
EVERY_STEP = 50


class Chunks:
    """How many steps a chunk of a run with a display takes: about 1 % of the global
    stage's ``total`` generations (at least 1) while in phase 0, ``EVERY_STEP``
    otherwise."""

    def __init__(self, total: int | None):
        self.every_generation = max(1, (total or 100) // 100)
        self.first_phase = 0 if total is not None else 1

    def length(self, phase: int) -> int:
        return self.every_generation if phase == 0 else EVERY_STEP


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


def step_progress(progress, desc: str, total: int):
    """``(update(step, f), close(step=None))`` of one stage counted in steps (the gradient
    stage, a Levenberg–Marquardt stage) for ``progress``: ``None`` or ``False`` shows
    nothing; ``True`` draws a tqdm bar labelled ``desc`` of ``total`` steps with J beside
    it, which ``close(step)`` ends at 100 % (saying "converged at step N" when the stage
    stopped early) and ``close()`` simply closes; a callable sink is told
    ``(GRADIENT_PHASE, step, step, f)``."""
    if progress is None or progress is False:
        return (lambda step, f: None), (lambda step=None: None)
    if progress is True:
        from tqdm.auto import tqdm

        bar = tqdm(total=total, desc=desc, unit="step", leave=True)

        def update(step, f):
            bar.update(step - bar.n)
            bar.set_postfix(J=f"{f:.4g}", refresh=False)

        def close(step=None):
            if step is not None:
                if step < total:
                    bar.set_postfix_str(f"converged at step {step}", refresh=False)
                bar.update(bar.total - bar.n)
            bar.close()

        return update, close
    if callable(progress):
        # ``evals`` carries the step count
        return (lambda step, f: progress(GRADIENT_PHASE, step, step, f)), (lambda step=None: None)
    raise ValueError(f"progress must be None, True (a tqdm bar) or a callable, got {progress!r}")
