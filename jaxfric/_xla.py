"""Per-computation XLA compiler options for jaxfric's own jitted entry points.

jaxfric never touches JAX's global configuration or ``XLA_FLAGS``. What it does
instead is compile its *own* jitted calls ([`jaxfric.minimise`][jaxfric.optim.minimise],
[`jaxfric.minimise_many`][jaxfric.optim.minimise_many], [`jaxfric.identify`][jaxfric.identification.identify]'s stages, the models' eager
``simulate_batch``) with ``jax.jit(..., compiler_options=...)``: options that hold
for that one executable and nothing else. On CPU three options are used, chosen by
measurement on the development machine (docs/solvers.md, "What measurements decided"):

``xla_cpu_prefer_vector_width = 512``
    XLA's CPU default is 256-bit vectors. On a CPU with AVX-512 the batched rollouts ran
    faster, with outputs bit-identical; where the CPU has no 512-bit registers LLVM uses
    the widest it has, so the option is harmless there.
``xla_cpu_use_fusion_emitters = False``  (optimiser runs only)
    XLA's newer fusion code generator emits slower code for the many tiny fusions of
    MAPSO's 3×3 self-learning loop; turning it off made the rollouts slower, so the
    models' eager rollouts keep the default.
``xla_cpu_parallel_codegen_split_count = 1``  (optimiser runs only)
    XLA:CPU splits a program's machine code into several LLVM modules to compile them on
    parallel threads; an optimiser's program (many small loops) compiles faster as one,
    runs as fast and gives the same values to the bit.

On other platforms (GPU, TPU) nothing is passed. Every entry point takes
``compiler_options=``: ``"auto"`` (the default, the above and the rule below),
``"full"`` (the above at XLA's full optimisation, whatever the run), ``"fast-compile"``,
``None`` (XLA's own defaults) or a dict of XLA debug options passed as given.

``"fast-compile"`` is ``"full"`` plus ``xla_backend_optimization_level = 0`` (LLVM
without its optimisation passes): a solver's program compiles in about half the time
and runs 2–8× slower. ``"auto"`` chooses between the two for each solver run from what
is known before XLA runs, its *work*: the evaluations the run is expected to take (a
swarm's or evosax strategy's budget, two per Nelder–Mead step, a chain's stages added)
times the objective's size plus the number of parameters, the objective's size being
the array elements its jaxpr computes for one point (a ``scan``'s body times its length;
a ``while_loop``, whose trips are unknown, makes the work unknown). A run whose work is
under `CHEAP_WORK` (2·10⁶) compiles at level 0, any other at full optimisation; off
the CPU, and on a process with several local CPU devices (where level 0 would round a run laid out
over them apart from the same run on one, which full optimisation does not), nothing
changes. The line keeps a new objective's short runs, whose first call is mostly
compilation, at level 0, and programs compiled once and called many times (the speed
tables' 30-D runs, models' rollouts) at full optimisation (where the line was drawn and
why: docs/solvers.md, "A cheap run compiles at level 0 by default"). Level 0
rounds differently from full optimisation (fewer fused multiply-adds), so a cheap run's
result agrees with ``"full"``'s to rounding, not to the bit; ask/tell compiles with the
same rule (its program has no objective), so it visits the points ``minimise`` visits
for an objective of small size. Options apply only to a
top-level call: under a caller's ``jit``, ``vmap`` or ``grad`` (arguments that are
tracers) the caller's compilation decides, and the call is a plain ``jit``.
"""

from __future__ import annotations

import functools
from typing import Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp

AUTO = "auto"
#: ``"auto"`` plus LLVM at optimisation level 0 (see the module docstring)
FAST_COMPILE = "fast-compile"
#: ``"auto"``'s options at XLA's full optimisation whatever the run's work
FULL = "full"

#: Options for the CPU backend, per kind of computation (see the module docstring).
CPU_OPTIONS: dict[str, dict[str, Any]] = {
    "solver": {"xla_cpu_prefer_vector_width": 512, "xla_cpu_use_fusion_emitters": False,
               "xla_cpu_parallel_codegen_split_count": 1},
    "rollout": {"xla_cpu_prefer_vector_width": 512},
}


def compiler_options(kind: str = "solver", platform: str | None = None) -> dict[str, Any]:
    """The XLA options jaxfric compiles ``kind`` (``"solver"`` or ``"rollout"``) with.

    ``platform`` defaults to JAX's default backend; off the CPU the answer is ``{}``.
    Options the installed XLA does not know are left out (`supported`).
    Use it to compile your own code the way jaxfric does, e.g.
    ``jax.jit(f, compiler_options=jaxfric.compiler_options("rollout"))``.
    """
    if kind not in CPU_OPTIONS:
        raise ValueError(f"kind must be one of {sorted(CPU_OPTIONS)}, got {kind!r}")
    if platform is None:
        platform = jax.default_backend()
    if platform != "cpu":
        return {}
    return dict(supported(tuple(sorted(CPU_OPTIONS[kind].items())), platform))


#: ``"auto"`` compiles a solver's run with LLVM at level 0 on CPU where its estimated work
#: (`auto_level`) is below this (see the module docstring)
CHEAP_WORK = 2e6


def auto_level(work: float | None) -> int | None:
    """LLVM's optimisation level ``"auto"`` picks for a solver's run of estimated
    ``work`` (see the module docstring): ``0`` where ``work < CHEAP_WORK``, else ``None``
    (XLA's own, full optimisation); unknown work (``None``) is never cheap."""
    return 0 if work is not None and work < CHEAP_WORK else None


def resolve(value, kind: str, platform: str | None = None,
            work: float | None = None) -> tuple[tuple[str, Any], ...]:
    """Validate a user's ``compiler_options=`` and freeze it into a hashable tuple.

    ``"auto"`` → [`compiler_options`][jaxfric._xla.compiler_options] (which leaves out options this XLA does not
    know), plus ``xla_backend_optimization_level = 0`` on CPU for a solver whose run's
    estimated ``work`` is cheap (`auto_level`; ``None``: unknown, never cheap);
    ``"fast-compile"`` → those plus ``xla_backend_optimization_level = 0`` on CPU
    whatever the work (nothing elsewhere); ``None`` or ``False`` →
    no options; a mapping of option names (str) to bool/int/float/str values → those, as
    given (checked by XLA on a trivial program first, see `check_known`). Raises
    ``ValueError`` for anything else, before the real computation is traced.
    """
    if isinstance(value, str) and value in (AUTO, FAST_COMPILE, FULL):
        platform = platform or jax.default_backend()
        opts = compiler_options(kind, platform)
        # one local device only: level 0 rounds a program laid out over several devices
        # and the same program on one apart, while at full optimisation they agree; local,
        # as runs are laid out over a process's own devices (jax.distributed's processes
        # then compile what one process alone compiles)
        cheap = (value == AUTO and kind == "solver" and auto_level(work) == 0
                 and platform == "cpu" and jax.local_device_count(platform) == 1)
        if (value == FAST_COMPILE or cheap) and platform == "cpu":
            opts = {**opts, **dict(supported((("xla_backend_optimization_level", 0),), platform))}
    elif value is None or value is False:
        opts = {}
    elif isinstance(value, dict):
        for k, v in value.items():
            if not isinstance(k, str) or not k:
                raise ValueError(f"compiler_options keys must be XLA option names, got {k!r}")
            if not isinstance(v, (bool, int, float, str)):
                raise ValueError(
                    f"compiler_options[{k!r}] must be a bool, int, float or str, "
                    f"got {type(v).__name__}"
                )
        opts = value
        check_known(tuple(sorted(opts.items())))
    else:
        raise ValueError(
            "compiler_options must be 'auto', None or a dict of XLA option names to "
            f"values (or 'fast-compile', 'full'), got {value!r}")
    return tuple(sorted(opts.items()))


def _traced(args, kwargs) -> bool:
    """Is any argument a tracer (a call inside someone else's ``jit``/``vmap``/``grad``),
    where ``compiler_options`` may not be given?"""
    if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves((args, kwargs))):
        return True
    # Under a caller's jit (or eval_shape) every new array is staged: a tracer, even
    # when no argument is one (the caller closed over concrete arrays).
    return isinstance(jnp.zeros(()), jax.core.Tracer)


class _Compiled:
    """``fn`` jitted with ``options`` for top-level calls, and plain for traced ones."""

    def __init__(self, fn, options, filtered):
        make = eqx.filter_jit if filtered else jax.jit
        self.jitted = make(fn, compiler_options=dict(options) or None)
        self.plain = make(fn) if options else self.jitted
        self._cached = getattr(self.jitted, "_cached", None)  # equinox's cache (tests)

    def __call__(self, *args, **kwargs):
        target = self.plain if _traced(args, kwargs) else self.jitted
        return target(*args, **kwargs)

    def lower(self, *args, **kwargs):
        return self.jitted.lower(*args, **kwargs)


@functools.lru_cache(maxsize=None)
def _compiled(fn, options, filtered):
    return _Compiled(fn, options, filtered)


def filter_jit(fn: Callable, options: tuple[tuple[str, Any], ...]) -> Callable:
    """``eqx.filter_jit(fn)`` compiled with ``options`` (a `resolve` tuple); one
    wrapper per (function, options), so each keeps its own compilation cache."""
    return _compiled(fn, options, True)


def jit(fn: Callable, options: tuple[tuple[str, Any], ...]) -> Callable:
    """As `filter_jit` with ``jax.jit``: for functions of arrays and static-only
    modules, where equinox's per-call filtering is not needed."""
    return _compiled(fn, options, False)


@functools.lru_cache(maxsize=None)
def supported(options: tuple[tuple[str, Any], ...], platform: str) -> tuple[tuple[str, Any], ...]:
    """The subset of ``options`` that this XLA accepts on ``platform``.

    ``"auto"`` must never make a run fail: XLA versions add and remove options (jax
    0.11's XLA no longer has ``xla_cpu_use_fusion_emitters``, and rejects the whole
    compilation if it is passed). Each option is tried once per process on a trivial
    program compiled for ``platform``; the ones XLA rejects are left out, and the
    computation is then compiled as if they had never been chosen.
    """
    if not options:
        return ()
    try:
        device = jax.devices(platform)[0]
    except RuntimeError:  # no such platform in this process: nothing to compile for
        return ()
    x = jax.device_put(0.0, device)
    kept = []
    for name, value in options:
        try:
            jax.jit(lambda y: y + 1.0, compiler_options={name: value}).lower(x).compile()
        except Exception:  # XlaRuntimeError: INVALID_ARGUMENT: No such compile option
            continue
        kept.append((name, value))
    return tuple(kept)


@functools.lru_cache(maxsize=64)
def check_known(options: tuple[tuple[str, Any], ...]) -> None:
    """Compile a trivial program with ``options`` so an unknown option name or a
    value of the wrong type fails at once with ``ValueError``, before the real
    (long) compilation. Cached: each distinct set is checked once per process."""
    if not options:
        return
    try:
        jax.jit(lambda: 0, compiler_options=dict(options)).lower().compile()
    except Exception as e:  # XlaRuntimeError: INVALID_ARGUMENT: No such compile option
        raise ValueError(f"XLA rejected compiler_options {dict(options)!r}: {e}") from None
