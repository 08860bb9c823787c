"""Shared test helpers. Tests never change global JAX configuration: float64 checks
use the ``jax.enable_x64(True)`` context manager. The tests compile as users do.
(Measured and not taken: XLA's ``--xla_backend_optimization_level=0`` compiles a solver
program 40-55 % faster, but the whole suite ran only 7 % faster, 11 min 43 s against
12 min 33 s, since the unoptimised programs run slower, and 11 tests failed: the same run
compiled as another program (in checkpoint chunks, with other compiler options, batched)
no longer agreed with it bit for bit or to 1e-5.)"""

import atexit
import ctypes
import ctypes.util
import gc
import os
import shutil
import tempfile

# One persistent XLA compilation cache per test session (issue 20.14), in a temporary
# folder. Set before JAX is imported, as environment variables, so the xdist workers and
# the command-line and notebook subprocesses inherit it; removed when the session ends.
# It keeps the session's programs out of the user's own cache (the in-process command-line
# tests switch JAX's cache on, and would otherwise read and write ~/.cache/jaxfric, so a
# later run reused programs of earlier ones) and shares what repeats across processes
# (measured: few programs, about 15 s of compilation). Every program is cached, however
# quick to compile: the many small eager operations (jnp on concrete arrays) are compiled
# again after a worker drops its programs (`jax.clear_caches()` below), and reading them back is
# cheaper (measured on six model modules run serially: 5 % less wall time than caching only
# programs of 0.1 s or more). A cached program is the executable XLA would build again, so
# results do not change. A folder the user set (JAX_COMPILATION_CACHE_DIR) is used as it
# is and kept.
if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
    _cache = tempfile.mkdtemp(prefix="jaxfric-tests-xla-")
    os.environ["JAX_COMPILATION_CACHE_DIR"] = _cache
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
    atexit.register(shutil.rmtree, _cache, ignore_errors=True)

# One lock file per test session for tests/processes.py (the workers inherit its name).
from processes import LOCK_ENV, jax_subprocess  # noqa: E402

if LOCK_ENV not in os.environ:
    _locks = tempfile.mkdtemp(prefix="jaxfric-tests-lock-")
    os.environ[LOCK_ENV] = os.path.join(_locks, "subprocess.lock")
    atexit.register(shutil.rmtree, _locks, ignore_errors=True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402

# JAX is imported where it is used, not here: xdist's controller process loads this file
# but runs no test, and importing JAX there cost it about 120 MB of the suite's memory.


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
        import jax

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
def interruptible():
    """``Popen`` keywords for a subprocess the test interrupts with SIGINT: Ctrl-C's
    default action is restored in the child. A shell that starts the suite as a
    background job (``pytest ... &``) ignores SIGINT in it, every child inherits that,
    and the interrupted run would finish with status 0 instead of 130."""
    import signal

    return {"preexec_fn": lambda: signal.signal(signal.SIGINT, signal.SIG_DFL)}


@pytest.fixture
def subprocess_slot():
    """Held for the whole test, which starts a subprocess importing JAX: it waits while a
    notebook kernel runs (tests/processes.py, issue 20.14)."""
    with jax_subprocess():
        yield


@pytest.fixture
def run_cache_size():
    """Number of compilations cached for ``minimise``'s single-run executable (the chunk
    program every call runs, with the default ``compiler_options``): a test counts
    recompilations with it."""
    from jaxfric import _xla
    from jaxfric.optim import template
    from jaxfric.optim.loop import _chunk

    def size():  # "auto" picks one of two option sets by the run's work: both counted
        traced = sum(_xla.filter_jit(_chunk, _xla.resolve("auto", "solver", work=w))._cached._cache_size()
                     for w in (0.0, None))
        # and the programs filled in from a template (jaxfric.optim.template), per objective
        return traced + sum(program._cache_size() for per_fn in list(template._PROGRAMS.values())
                            for program, _, _ in per_fn.values())

    return size


# Tests that take more than ~10 s on an idle 2-core runner (issue 20.14), marked in one place
# so the quick subset is `python -m pytest -q -n 2 -m "not slow"`. Measured with
# `pytest --durations` (see the house branch's report); node ids without parameters.
SLOW_TESTS = {
    # share the module's `jaxfric demo --quick` subprocess (about 25 s idle) or run their own
    "tests/test_cli.py::test_demo_quick_writes_the_report",
    "tests/test_cli.py::test_demo_prints_the_comparison_table",
    "tests/test_cli.py::test_identify_csv_reproduces_the_python_api",
    "tests/test_cli.py::test_saved_fit_predicts_the_same_through_the_cli",
    "tests/test_cli.py::test_identify_raw_rig_channels_runs_the_pipeline",
    "tests/test_cli.py::test_ctrl_c_exits_130_and_says_what_was_kept",
    # each executes a notebook in a kernel (the percent sources are checked by a fast test)
    "tests/test_notebooks.py::test_notebook_runs_with_the_small_budget",
    "tests/test_notebooks.py::test_real_recordings_notebook_skips_without_data",
    # compile several solver programs each, or run subprocesses
    "tests/test_compiler_options.py::test_options_change_speed_not_results",
    "tests/test_compiler_options.py::test_large_swarms_compile_once_without_xla_warnings",
    "tests/test_compiler_options.py::test_minimise_many_takes_options",
    "tests/test_compiler_options.py::test_mapso_without_self_learning_generations_runs_with_auto_options",
    "tests/test_reliability.py::test_lugre_with_overflowing_parameters_is_never_reported_as_best",
    "tests/test_reliability.py::test_identify_never_reports_nan_or_inf",
    "tests/test_reliability.py::test_interrupted_identify_exits_130_and_says_what_was_kept",
    # share test_identify's module-scoped ENN fit (about 115 s to set up on the loaded machine)
    "tests/test_identify.py::test_enn_scalers_cost_and_metrics_match_independent_recomputation",
    "tests/test_identify.py::test_stages_never_get_worse_and_record_their_work",
    "tests/test_identify.py::test_real_fit_saves_loads_and_summarises",
    "tests/test_identify.py::test_lugre_recovered_from_noise_free_lugre_data",
    "tests/test_identify.py::test_multi_start_nelder_mead_from_the_best_agents",
    "tests/test_reproducibility.py::test_identify_same_key_bit_identical",
    "tests/test_reproducibility.py::test_minimise_many_is_reproducible_and_matches_single_runs",
    "tests/test_reproducibility.py::test_cli_identify_twice_with_the_same_seed_is_bit_identical",
    "tests/test_optim_properties.py::test_optimisers_on_random_functions_and_boxes",
    "tests/test_optim_properties.py::test_hybrid_refines_global_phase_and_multistart_counts",
}


# Test files in order of their measured time (issue 20.14; `pytest --durations=0`, summed per
# file, two workers, no real data): under `-n 2 --dist loadfile` the longest files are handed
# out first and the short ones fill in at the end, so the two workers finish together (the
# longest-first rule). Files not listed follow in their usual order; a stale list only
# costs balance, never a test. test_notebooks goes first: its kernels hold the exclusive
# subprocess lock (tests/processes.py) while the other worker runs test_optim_protocol
# and test_identify_stages, which start no subprocess, instead of stalling that worker's
# subprocess tests (test_cli's waited 10-20 s for the lock when it came second, and when
# it came third, after test_optim_protocol's 47 s alone: 64 s of waits in all).
# Added later, placed by each file's CPU seconds run alone (`-n 0`, children included):
# test_progress_cache 35, test_models_greybox 27, test_motion_judge 26, test_pipeline_stages
# 23, test_docs 19, test_export 11, test_verdicts 10 (test_sharding 34 and
# test_identify_pipeline 33 on the same runs); unlisted, they came last in alphabetical
# order, where one of them can keep a worker busy while the other has nothing left.
# The tail placed again by the worker's CPU seconds in one serial run (`-n 0`, no
# subprocess among them but test_export's, which keeps its place): test_ensembles 31 (it came
# twelfth from the end), test_rng 19, test_nelder_mead 16, test_nelder_mead_vs_scipy 14,
# test_report 13, test_models_base 13, test_asktell_many 11, test_models_realdrive 11,
# test_models_gms 11, test_uncertainty_report 10, test_models_lugre 10, test_motion_costs 8,
# test_identify_baseline 8, test_search_box 8, test_models_elman 6, test_verdicts 6,
# test_functions 5; the files left unlisted take under 5 s each.
LONGEST_FIRST = [
    "test_notebooks.py", "test_optim_protocol.py", "test_identify_stages.py", "test_cli.py",
    "test_reproducibility.py", "test_motion_api.py", "test_motion_dependable.py", "test_evosax_adapter.py",
    "test_compiler_options.py", "test_readme.py", "test_multihost.py",
    "test_optim_api.py", "test_nelder_mead_optimistix.py", "test_optim_properties.py",
    "test_identify.py", "test_sharding.py", "test_progress_cache.py", "test_reliability.py", "test_motion.py",
    "test_records.py", "test_rig_simulator.py", "test_identify_pipeline.py", "test_models_greybox.py",
    "test_motion_judge.py", "test_ensembles.py", "test_pipeline_stages.py", "test_docs.py", "test_rng.py",
    "test_uncertainty.py", "test_checkpoint.py", "test_models_scan.py", "test_sweep.py",
    "test_bad_input_catalogue.py", "test_nelder_mead.py", "test_nelder_mead_vs_scipy.py", "test_report.py",
    "test_models_base.py", "test_export.py", "test_asktell_many.py", "test_models_realdrive.py",
    "test_models_gms.py", "test_uncertainty_report.py", "test_models_lugre.py", "test_motion_costs.py",
    "test_identify_baseline.py", "test_search_box.py", "test_models_elman.py", "test_verdicts.py",
    "test_functions.py",
]


def pytest_configure(config):
    # xdist would otherwise reorder the files by their number of tests (test_sharding.py,
    # two tests, one of 36 s, then ran last while the other worker idled)
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False
    gc.set_threshold(*GC_THRESHOLDS)


#: Python's cyclic garbage collector in the test processes: a young collection every
#: 50 000 allocations instead of 700. Tracing and lowering allocate millions of short-lived
#: objects, and every 100th young collection walked the whole heap, which grows with the
#: worker's cached programs: measured over the whole suite (two workers, ``gc.callbacks``
#: timing), 15.7 s and 18.2 s of collection per worker, 44 and 57 full collections of about
#: 0.3 s each; with these thresholds 3.2 s and 2.8 s, and the suite's memory peaked where it
#: did (2.74 GB summed over its processes, 1.20 GB the largest). Reference counting frees
#: everything without cycles at once, so only cyclic garbage waits longer.
GC_THRESHOLDS = (50_000, 10, 10)


def pytest_collection_finish(session):
    # The modules, fixtures and test objects collected here live for the whole session:
    # moved out of the collector's reach, so the full collections no longer walk them.
    gc.collect()
    gc.freeze()


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.nodeid.split("[")[0] in SLOW_TESTS:
            item.add_marker(pytest.mark.slow)
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: order within a file kept


#: A test that leaves its worker above this resident size (MB) drops JAX's compiled
#: programs (see :func:`_bounded_memory`); ``JAXFRIC_TEST_RESIDENT_MB`` sets another limit.
RESIDENT_LIMIT_MB = int(os.environ.get("JAXFRIC_TEST_RESIDENT_MB", "1200"))


@pytest.fixture(autouse=True)
def _x64_as_it_was():
    """A test that runs the command line in this process (``main([..., "--x64"])``) makes
    the CLI's start-up choice of float64 for the whole process; put it back, so that the
    tests after it in the same worker run in the precision they were written for."""
    import jax

    before = bool(jax.config.jax_enable_x64)
    yield
    if bool(jax.config.jax_enable_x64) != before:
        jax.config.update("jax_enable_x64", before)


@pytest.fixture(autouse=True)
def _bounded_memory():
    """Compiled programs stay in memory from test to test and module to module, so a
    program that several test files build (the same identify stage, solver or rollout on
    the same shapes) compiles once per worker; a test that leaves its worker above
    :data:`RESIDENT_LIMIT_MB` drops them all (``jax.clear_caches()``), and those needed
    again come back from the session's compilation cache on disk (programs with a host
    callback are never written there, and compile again).

    Measured on the whole suite (two workers, 2 cores, 1 123 tests): dropping every
    module's programs at its end and after any test above 600 MB took 628 s; a limit of
    2000 MB with the drops at module ends 538 s (largest process 1.20 GB); this rule at
    1200 MB 495 s (1.27 GB). Without any limit the suite's memory grows with
    every module (6.6 GB once, over all processes)."""
    yield
    resident = _resident_mb()
    if resident is not None and resident > RESIDENT_LIMIT_MB:
        _drop_compiled_programs()


def _drop_compiled_programs():
    import jax

    jax.clear_caches()
    gc.collect()
    _return_freed_memory()


def _resident_mb():
    """This process's resident memory in MB (Linux's /proc), or None elsewhere."""
    try:
        with open("/proc/self/statm") as fh:
            pages = int(fh.read().split()[1])
    except (OSError, ValueError, IndexError):
        return None
    return pages * os.sysconf("SC_PAGE_SIZE") / 1e6


def _return_freed_memory():
    """Hand the heap pages freed by the module back to the system (glibc's
    ``malloc_trim``; elsewhere nothing). Without it a worker's resident memory only grows:
    four heavy modules run one after another ended at 1.04 GB resident, with it 0.45 GB
    (peak 1.05 → 0.97 GB)."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


@pytest.fixture(scope="session")
def rig_record():
    """The default rig simulated once with key 0 (2000 samples at 128 Hz, ground truth)."""
    import jax

    from jaxfric import rig

    return rig.simulate(rig.Rig(), jax.random.key(0))


@pytest.fixture(scope="session")
def make_fit():
    """Builds a real :class:`jaxfric.Fit` directly, without an identification run:
    ``make_fit(model, theta, dt=..., n_train=..., n_samples=...)`` with a two-stage
    optimiser record (MAPSO then Nelder-Mead), a 20-point history and timings
    (``total_s`` 3.5 s), for the tests of the report and the figures."""
    from jaxfric import Fit

    def build(model, theta, *, dt=0.01, n_train=400, n_samples=500, **fields):
        defaults = dict(
            metrics={},
            stages=[{"stage": "mapso", "J": 0.1, "num_evals": 120},
                    {"stage": "nelder_mead", "J": 1e-3, "num_evals": 80}],
            history={"evals": np.arange(1, 21) * 10, "f": np.geomspace(1.0, 1e-3, 20)},
            timings={"compile_s": 1.0, "run_s": 2.0, "total_s": 3.5},
        )
        return Fit(model=model, theta=np.asarray(theta, dtype=np.float64), velocity_scaler=None,
                   friction_scaler=None, dt=dt, n_train=n_train, n_samples=n_samples, **{**defaults, **fields})

    return build


def coulomb_drive(n=600, dt=1e-3):
    """A Coulomb + viscous axis (Fc 12 N, 60 N s/m, 2.5 kg) driven by two tones, simulated in
    float64: motion data whose friction is known (tests of identify_motion)."""
    import jax
    import jax.numpy as jnp

    from jaxfric import models
    from jaxfric.motion import MotionData, friction_step, simulate_motion

    model = models.Coulomb(v_eps=1e-3)
    t = np.arange(n) * dt
    u = 30 * np.sin(2 * np.pi * 1.3 * t) + 12 * np.sin(2 * np.pi * 3.1 * t + 1.0)
    with jax.enable_x64(True):
        out = simulate_motion(friction_step(model), jnp.asarray(model.from_physical(Fc=12.0, sigma2=60.0)),
                              2.5, u, dt, 0.0, 0.0)
    return MotionData.from_arrays(u, np.asarray(out["x"]), dt)
