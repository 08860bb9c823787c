"""Per-computation XLA compiler options for jaxfric's own jitted entry points.

jaxfric never touches JAX's global configuration or ``XLA_FLAGS``. What it does
instead is compile its *own* jitted calls (:func:`jaxfric.minimise`,
:func:`jaxfric.minimise_many`, :func:`jaxfric.identify`'s stages, the models' eager
``simulate_batch``) with ``jax.jit(..., compiler_options=...)``: options that hold
for that one executable and nothing else. On CPU two options are used, chosen by
measurement on the development machine (2-core AMD EPYC with AVX-512;
``benchmarks/compiler_options.py`` re-measures them side by side):

``xla_cpu_prefer_vector_width = 512``
    XLA's CPU default is 256-bit vectors. On a CPU with AVX-512 the batched Elman
    rollout (64 candidates × 30 neurons × 1600 samples) ran 1.2–1.5× faster in
    float32 and float64 with outputs bit-identical; where the CPU has no 512-bit
    registers LLVM uses the widest it has, so the option is harmless there.
``xla_cpu_use_fusion_emitters = False``  (optimiser runs only)
    XLA's newer fusion code generator emits slower code for the many tiny
    fusions of MAPSO's 3×3 self-learning loop: MAPSO on 30-D Rosenbrock and
    Ackley ran 1.4–1.8× faster with the older one and compiled faster; PSO and
    Nelder–Mead were unchanged, and Table 1's 450 runs gave identical values. It
    made the rollout alone 20–30 % slower, so the models' eager rollouts keep the
    default.

One more CPU measure is jaxfric's own, not an XLA option:

single-kernel loops (optimiser runs only; :data:`SINGLE_KERNEL`)
    XLA:CPU runs a program as a sequence of small compiled kernels, each costing a
    fraction of a microsecond to dispatch. A swarm generation on 100 agents is a few
    dozen such kernels over a few thousand numbers, and MAPSO's self-learning (§3.4:
    10 generations of a 3×3 lattice, each ~24 kernels over 9 agents) is almost nothing
    but dispatch. :func:`single_kernel_loop` marks a swarm's whole generation loop, and
    :func:`single_kernel` MAPSO's self-learning loop where the whole run is too large
    for one kernel, so that XLA compiles the loop, whole, into one kernel (a ``call``
    with XLA's ``xla_cpu_small_call`` attribute, which XLA's own small-while-loop pass
    uses, and ``inlineable="false"`` so it survives). On the 30-D test functions with
    100 agents a whole run got 1.2–1.4x faster for MAPSO (over the self-learning
    kernel alone, itself worth 1.2–1.45x) and 1.3–1.9x for PSO. A one-kernel program
    may sum in another order, so runs agree with the plain program to rounding, not
    always to the bit (each is reproducible on its own). It is used only where it pays
    and compiles: a single run (not vmapped, not sharded), an objective built from
    elementwise, reduction, slicing and loop primitives, and small enough: for the
    self-learning loop at most :data:`SINGLE_KERNEL_MAX_WORK` element operations per
    call, for a whole swarm loop at most :data:`SINGLE_KERNEL_LOOP_MAX_WORK` per
    generation, a population of at most :data:`SINGLE_KERNEL_LOOP_MAX_ELEMENTS`
    coordinates and no larger arrays than four times that (the Elman rollouts are far
    above these, and ran no faster). Should XLA still fail to compile it, the run is
    compiled again without (:class:`_Compiled`).

On other platforms (GPU, TPU) nothing is passed. Every entry point takes
``compiler_options=``: ``"auto"`` (the default, the above), ``None`` (XLA's own
defaults) or a dict of XLA debug options passed as given (which may also set
``"jaxfric_single_kernel_loops": True``).
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import math
from typing import Any, Callable

import equinox as eqx
import jax
from jax.experimental.xla_metadata import set_xla_metadata
from jax.extend import core as jex_core

AUTO = "auto"

#: jaxfric's own key in a resolved options tuple: trace :func:`single_kernel` loops as
#: one XLA:CPU kernel. Stripped before the options reach XLA.
SINGLE_KERNEL = "jaxfric_single_kernel_loops"

#: Most element operations (sum of output sizes over the traced loop, loop bodies times
#: their length) a :func:`single_kernel` call may have. XLA's one-kernel code is
#: scalar-ish; on the development machine it beat the many-kernel program by 1.4–1.8×
#: for MAPSO's self-learning on Rosenbrock up to D = 100 (0.9e6 operations), 1.4× at
#: D = 300 (2.8e6) and 1.0× on Ackley at D = 300 (2.6e6).
SINGLE_KERNEL_MAX_WORK = 1_000_000

#: Most element operations (as :data:`SINGLE_KERNEL_MAX_WORK`, but for one iteration) a
#: :func:`single_kernel_loop` may have. Measured on the development machine, whole swarm
#: runs as one kernel against the plain program (30-D Rosenbrock and Ackley, 10–400
#: agents, D = 10–300): 1.15–2.3x faster up to about 1.5e6 operations per generation
#: (MAPSO on a 10×10 lattice at D = 30), no faster or slower beyond about 3e6.
SINGLE_KERNEL_LOOP_MAX_WORK = 2_000_000

#: Largest population (agents × coordinates) a :func:`single_kernel_loop` may have.
#: Beyond it XLA:CPU splits a generation's larger operations across threads, which one
#: kernel cannot hold: XLA then logs "Compute function stack is not empty" and builds
#: the plain program after all (PSO from 100 × 45 on, both dtypes), compiling twice for
#: nothing.
SINGLE_KERNEL_LOOP_MAX_ELEMENTS = 4096

#: Options for the CPU backend, per kind of computation (see the module docstring).
CPU_OPTIONS: dict[str, dict[str, Any]] = {
    "solver": {"xla_cpu_prefer_vector_width": 512, "xla_cpu_use_fusion_emitters": False},
    "rollout": {"xla_cpu_prefer_vector_width": 512},
}


def compiler_options(kind: str = "solver", platform: str | None = None) -> dict[str, Any]:
    """The XLA options jaxfric compiles ``kind`` (``"solver"`` or ``"rollout"``) with.

    ``platform`` defaults to JAX's default backend; off the CPU the answer is ``{}``.
    Options the installed XLA does not know are left out (:func:`supported`).
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


def resolve(value, kind: str, platform: str | None = None) -> tuple[tuple[str, Any], ...]:
    """Validate a user's ``compiler_options=`` and freeze it into a hashable tuple.

    ``"auto"`` → :func:`compiler_options` (which leaves out options this XLA does not
    know), plus :data:`SINGLE_KERNEL` for optimiser runs on CPU; ``None`` or ``False`` →
    no options; a mapping of option names (str) to bool/int/float/str values → those, as
    given (checked by XLA on a trivial program first, see :func:`check_known`). Raises
    ``ValueError`` for anything else, before the real computation is traced.
    """
    if isinstance(value, str) and value == AUTO:
        platform = platform or jax.default_backend()
        opts = compiler_options(kind, platform)
        if kind == "solver" and platform == "cpu":
            opts[SINGLE_KERNEL] = True
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
        if not isinstance(value.get(SINGLE_KERNEL, False), bool):
            raise ValueError(f"compiler_options[{SINGLE_KERNEL!r}] must be True or False")
        check_known(tuple(sorted((k, v) for k, v in opts.items() if k != SINGLE_KERNEL)))
    else:
        raise ValueError(
            "compiler_options must be 'auto', None or a dict of XLA option names to "
            f"values, got {value!r}"
        )
    return tuple(sorted(opts.items()))


try:  # private, but the only way to ask "is anything tracing?"; see _top_level
    from jax._src.core import trace_state_clean as _trace_state_clean
except ImportError:  # pragma: no cover - a future JAX moved it
    _trace_state_clean = None


def _top_level() -> bool:
    """True when no JAX transformation is tracing: ``compiler_options`` may only be
    given to a top-level jit (inside a caller's jit, vmap or grad the caller's
    compilation decides). Unknown JAX internals → ``False`` (no options, still correct)."""
    return _trace_state_clean is not None and bool(_trace_state_clean())


def without_single_kernel(options: tuple[tuple[str, Any], ...]) -> tuple[tuple[str, Any], ...]:
    """``options`` with :data:`SINGLE_KERNEL` switched off (vmapped or sharded runs)."""
    return tuple((k, v) for k, v in options if k != SINGLE_KERNEL)


def filter_jit(fn: Callable, options: tuple[tuple[str, Any], ...]) -> Callable:
    """``eqx.filter_jit(fn)`` compiled with ``options`` (a :func:`resolve` tuple) when
    called at top level; a plain ``eqx.filter_jit(fn)`` under a transformation.

    One wrapper per (function, options), so each keeps its own compilation cache.
    With :data:`SINGLE_KERNEL` set, ``fn`` is traced with :func:`single_kernel`
    enabled and compiled again without it if XLA cannot compile the marked loops.
    """
    return _compiled(fn, options if _top_level() else (), True)


def jit(fn: Callable, options: tuple[tuple[str, Any], ...]) -> Callable:
    """As :func:`filter_jit` with ``jax.jit``: for functions of arrays and static-only
    modules, where equinox's per-call filtering is not needed."""
    return _compiled(fn, options if _top_level() else (), False)


_SINGLE_KERNEL_ON = contextvars.ContextVar("jaxfric_single_kernel", default=False)


@contextlib.contextmanager
def _single_kernel_enabled(on: bool):
    token = _SINGLE_KERNEL_ON.set(on)
    try:
        yield
    finally:
        _SINGLE_KERNEL_ON.reset(token)


def no_single_kernel(fn: Callable) -> Callable:
    """``fn`` traced with :func:`single_kernel` disabled (e.g. inside ``vmap``, where
    the batched loop gained nothing and grew past what XLA compiles into one kernel)."""

    @functools.wraps(fn)
    def traced(*args, **kwargs):
        with _single_kernel_enabled(False):
            return fn(*args, **kwargs)

    return traced


class _Compiled:
    """A jitted ``fn`` for one options tuple; see :func:`filter_jit`."""

    def __init__(self, fn, options, filtered):
        xla = dict(without_single_kernel(options)) or None
        self.single = dict(options).get(SINGLE_KERNEL, False)
        make = eqx.filter_jit if filtered else jax.jit

        @functools.wraps(fn)
        def target(*args, **kwargs):
            with _single_kernel_enabled(self.single):
                return fn(*args, **kwargs)

        self.jitted = make(target, compiler_options=xla)
        self._cached = getattr(self.jitted, "_cached", None)  # equinox's cache (tests)
        self.fallback = (
            _compiled(fn, without_single_kernel(options), filtered) if self.single else None
        )
        self.failed: set = set()

    def __call__(self, *args, **kwargs):
        if not self.single:
            return self.jitted(*args, **kwargs)
        sig = _signature(args, kwargs)
        if sig in self.failed:
            return self.fallback(*args, **kwargs)
        try:
            return self.jitted(*args, **kwargs)
        except jax.errors.JaxRuntimeError as e:
            if not _emitter_failure(e):
                raise
            self.failed.add(sig)
            return self.fallback(*args, **kwargs)

    def lower(self, *args, **kwargs):
        return self.jitted.lower(*args, **kwargs)


@functools.lru_cache(maxsize=None)
def _compiled(fn, options, filtered):
    return _Compiled(fn, options, filtered)


def _emitter_failure(e: Exception) -> bool:
    """Does ``e`` say XLA:CPU's one-kernel emitter met an operation it cannot emit?"""
    msg = str(e)
    return any(s in msg for s in ("UNIMPLEMENTED", "not implemented on CPU",
                                  "Failed to materialize symbols"))


def _signature(args, kwargs):
    """A hashable stand-in for what a jit cache keys on: tree structure, array
    shapes and dtypes, other leaves themselves (or their id when unhashable)."""

    def leaf(x):
        if hasattr(x, "shape") and hasattr(x, "dtype"):
            return (tuple(x.shape), str(x.dtype), bool(getattr(x, "weak_type", False)))
        try:
            hash(x)
            return x
        except TypeError:
            return ("id", id(x))

    leaves, treedef = jax.tree_util.tree_flatten((args, kwargs))
    return treedef, tuple(leaf(x) for x in leaves)


# Primitives XLA:CPU's one-kernel emitter handles (checked on jax 0.10: dot products,
# sort, scatter and custom calls such as the linear-algebra routines fail to compile).
_SINGLE_KERNEL_PRIMITIVES = frozenset("""
    abs acos acosh add and asin asinh atan atan2 atanh cbrt ceil clamp
    convert_element_type bitcast_convert_type cos cosh digamma div eq erf erf_inv erfc
    exp exp2 expm1 floor ge gt integer_pow is_finite le lgamma log log1p logistic lt
    max min mul ne neg nextafter not or pow reduce_precision rem round rsqrt select_n
    shift_left shift_right_arithmetic shift_right_logical sign sin sinh sqrt square sub
    tan tanh xor population_count clz copy copy_p
    broadcast_in_dim concatenate dynamic_slice dynamic_update_slice expand_dims gather
    iota pad reshape rev slice squeeze stack transpose split
    reduce_sum reduce_max reduce_min reduce_prod reduce_and reduce_or reduce_xor
    argmin argmax cumsum cummax cummin cumprod cumlogsumexp
    scan cond pjit jit closed_call core_call custom_jvp_call custom_vjp_call remat
    checkpoint random_unwrap
""".split())


def _work(jaxpr, per_iteration: bool = False) -> float:
    """Element operations of ``jaxpr`` (sum of output sizes; a scan's body times its
    length, a cond's dearest branch), or ``inf`` if it holds a primitive outside
    :data:`_SINGLE_KERNEL_PRIMITIVES`. With ``per_iteration``, scans at the top level
    (not inside another scan) count their body once: the work of one iteration."""
    total = 0.0
    for eqn in jaxpr.eqns:
        name = eqn.primitive.name
        if name not in _SINGLE_KERNEL_PRIMITIVES:
            return math.inf
        total += sum(math.prod(getattr(v.aval, "shape", ())) for v in eqn.outvars)
        subs = [getattr(j, "jaxpr", j) for j in jex_core.jaxprs_in_params(eqn.params)]
        if not subs:
            continue
        if name == "scan":
            total += (1 if per_iteration else eqn.params["length"]) * sum(_work(j) for j in subs)
        elif name == "cond":
            total += max(_work(j, per_iteration) for j in subs)
        else:
            total += sum(_work(j, per_iteration) for j in subs)
    return total


def _largest(jaxpr) -> int:
    """Elements of the largest array any equation of ``jaxpr`` (nested ones included)
    produces."""
    sizes = [0]
    for eqn in jaxpr.eqns:
        sizes += [math.prod(getattr(v.aval, "shape", ())) for v in eqn.outvars]
        sizes += [_largest(getattr(j, "jaxpr", j)) for j in jex_core.jaxprs_in_params(eqn.params)]
    return max(sizes)


def _scan_lengths(jaxpr) -> list[int]:
    """Lengths of every ``scan`` in ``jaxpr``, nested ones included."""
    out = []
    for eqn in jaxpr.eqns:
        if eqn.primitive.name == "scan":
            out.append(int(eqn.params["length"]))
        for sub in jex_core.jaxprs_in_params(eqn.params):
            out += _scan_lengths(getattr(sub, "jaxpr", sub))
    return out


def single_kernel(fn: Callable, *args):
    """``fn(*args)``, traced as one XLA:CPU kernel when the enclosing jaxfric entry
    point enabled it (:data:`SINGLE_KERNEL`) and ``fn`` qualifies: only primitives the
    one-kernel emitter handles, at most :data:`SINGLE_KERNEL_MAX_WORK` element
    operations, and a loop to gain from: some scan of length >= 1 and none of length 0.
    The last rule is not only about speed. ``MAPSO(sl_generations=0)``, whose
    self-learning then holds no loop, aborted the whole process inside XLA:CPU (jax
    0.10: "Check failed: slice_to_buffer_table_index_.empty()"). An abort cannot be
    caught, so the fall-back of :class:`_Compiled` cannot help there. Otherwise a plain
    call. The same computation either way; the one kernel may sum in another order, so
    values agree to rounding."""
    return _mark(fn, args, SINGLE_KERNEL_MAX_WORK, per_iteration=False)


def single_kernel_loop(fn: Callable, *args, elements: int):
    """As :func:`single_kernel` for a function that is one long loop (a swarm's
    generations), with limits that fit it: one iteration of its top-level scans may
    have at most :data:`SINGLE_KERNEL_LOOP_MAX_WORK` element operations; ``elements``
    (a swarm's ``P·D`` coordinates) must be at most
    :data:`SINGLE_KERNEL_LOOP_MAX_ELEMENTS` and no array in the loop more than four
    times that (an objective's own intermediates, e.g. ``P × samples`` residuals)."""
    if elements > SINGLE_KERNEL_LOOP_MAX_ELEMENTS:
        return fn(*args)
    return _mark(fn, args, SINGLE_KERNEL_LOOP_MAX_WORK, per_iteration=True,
                 max_array=4 * SINGLE_KERNEL_LOOP_MAX_ELEMENTS)


def _mark(fn: Callable, args, max_work: float, per_iteration: bool,
          max_array: float = math.inf):
    if not _SINGLE_KERNEL_ON.get():
        return fn(*args)
    jaxpr = jax.make_jaxpr(fn)(*args).jaxpr
    lengths = _scan_lengths(jaxpr)
    if (not lengths or min(lengths) < 1 or _work(jaxpr, per_iteration) > max_work
            or _largest(jaxpr) > max_array):
        return fn(*args)
    # Loops marked inside fn would nest one kernel in another: trace them plain.
    with set_xla_metadata(xla_cpu_small_call="true", inlineable="false"):
        return jax.jit(no_single_kernel(fn))(*args)


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
