"""The bad-input catalogue: every way of calling jaxfric wrongly that we know of, in one place.

Each case names the exception type *and* words of its message. API cases run with

* an objective that counts its evaluations through ``jax.debug.callback``, and
* the compiled optimiser runs (``minimise``'s ``_run``/``_run_many``) and
  ``identify``'s call to ``minimise`` replaced by functions that fail the test,

so every error is shown to come before any optimisation (and, for the optimiser, before
any objective evaluation). Command-line cases run ``python -m jaxfric`` as a subprocess
(all at once, a few in parallel) and need a non-zero exit, exactly one stderr line that
starts with ``jaxfric: error:``, no traceback and no file written.

Cases marked ``xfail(strict=True)`` are known gaps in code this file's owner does not
maintain; each reason says what the fix is. When the fix lands the case passes, strict
xfail turns that into a failure, and the marker has to go.

Many cases are also tested where their feature lives (test_optim_api.py, test_identify.py,
test_rig_*.py, test_models_*.py, test_fit.py, test_cli.py); this file is the list.
"""

from __future__ import annotations

import concurrent.futures
import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from processes import jax_subprocess

import jaxfric as jf
from jaxfric import models, rig
from jaxfric.fit import Fit
from jaxfric import pipeline

ROOT = Path(__file__).resolve().parents[1]
# the driver module (every compiled optimiser run goes through its _run / _run_many)
minimise_module = importlib.import_module("jaxfric.optim.driver")


# ----------------------------------------------------------------- guards
class Evaluations:
    """Objective evaluations seen on the host (through ``jax.debug.callback``)."""

    count = 0


def _seen(_):
    Evaluations.count += 1


def counted(y, args):
    """A sphere that reports every evaluation; tracing alone (eval_shape) reports nothing."""
    jax.debug.callback(_seen, y)
    return jnp.sum(y**2)


class StartedComputing(AssertionError):
    pass


def _forbidden(*args, **kwargs):
    raise StartedComputing("an optimisation started before the bad input was rejected")


@pytest.fixture
def guarded(monkeypatch):
    """No compiled optimiser run and no identify → minimise call may happen."""
    monkeypatch.setattr(minimise_module, "_chunk", _forbidden)
    monkeypatch.setattr(minimise_module, "_run_many", _forbidden)
    monkeypatch.setattr(pipeline, "minimise", _forbidden)
    Evaluations.count = 0
    yield
    assert Evaluations.count == 0, "the objective was evaluated before the error"


# ---------------------------------------------------------------- inputs
KEY = jax.random.key(0)
LO, HI = np.zeros(3), np.ones(3)
PSO = jf.PSO(num_particles=4, num_generations=2)
N = 50
T = np.arange(N) / 100.0
V = 0.01 * np.sin(2 * np.pi * T)
F = 50.0 * np.tanh(V / 1e-3) + 2e3 * V


def _with(arr, i, value):
    arr = np.array(arr, dtype=float)
    arr[i] = value
    return arr


def _meas(n=100):
    t = np.arange(n) / 100.0
    return rig.Measurements.from_arrays(t, 0.01 * np.sin(t), 1e6 + 0 * t, 5e5 + 0 * t, 10 + 0 * t)


def _csv(path, header, rows):
    path.write_text(header + "\n" + "\n".join(",".join(str(c) for c in r) for r in rows) + "\n")
    return path


def _fit():
    return Fit(model=jf.Coulomb(), theta=np.array([40.0, 3.0]), velocity_scaler=None,
               friction_scaler=None, dt=0.01, n_train=40, n_samples=N,
               metrics={"train": None, "valid": None, "all": None})


def _rewrite_fit(src, dst, edit_header=None, edit_arrays=None):
    with np.load(src) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(arrays["header"].tobytes().decode())
    if edit_header:
        edit_header(header)
    if edit_arrays:
        edit_arrays(arrays)
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), np.uint8)
    np.savez(dst, **arrays)
    return dst


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Bad (and one good) data and model files, shared by the API and command-line cases."""
    d = tmp_path_factory.mktemp("bad-inputs")
    rows = list(zip(T, V, F))
    out = {
        "good": _csv(d / "good.csv", "t,v,F", rows),
        "text": _csv(d / "text.csv", "t,v,F", [(a, "abc" if i == 7 else b, c) for i, (a, b, c) in enumerate(rows)]),
        "blank": _csv(d / "blank.csv", "t,v,F", [(a, "" if i == 7 else b, c) for i, (a, b, c) in enumerate(rows)]),
        "ragged": _csv(d / "ragged.csv", "t,v,F", [(a, b, c, 9) if i == 7 else (a, b, c) for i, (a, b, c) in enumerate(rows)]),
        "unsorted": _csv(d / "unsorted.csv", "t,v,F", [(a, b, c) for a, b, c in zip(T[::-1], V, F)]),
        "irregular": _csv(d / "irregular.csv", "t,v,F", [(a, b, c) for a, b, c in zip(T**2, V, F)]),
        "constant": _csv(d / "constant.csv", "t,v,F", [(a, b, 7.0) for a, b, _ in rows]),
        "one": _csv(d / "one.csv", "t,v,F", rows[:1]),
        "header_only": _csv(d / "header_only.csv", "t,v,F", []),
        "empty": d / "empty.csv",
        "binary": d / "binary.csv",
        "folder": d / "a-folder",
        "missing": d / "no-such-file.csv",
    }
    out["empty"].write_text("")
    out["binary"].write_bytes(bytes(range(256)) * 8)
    out["folder"].mkdir()
    fit_path = d / "fit.npz"
    _fit().save(fit_path)
    raw = fit_path.read_bytes()
    out["fit"] = fit_path
    out["truncated"] = d / "truncated.npz"
    out["truncated"].write_bytes(raw[: len(raw) // 2])
    out["newer"] = _rewrite_fit(fit_path, d / "newer.npz", lambda h: h.update(format_version=2))
    out["version0"] = _rewrite_fit(fit_path, d / "version0.npz", lambda h: h.update(format_version=0))
    out["magic_class"] = _rewrite_fit(fit_path, d / "magic.npz", lambda h: h["model"].update({"class": "Magic"}))
    out["no_theta"] = _rewrite_fit(fit_path, d / "no_theta.npz", edit_arrays=lambda a: a.pop("theta"))
    out["long_theta"] = _rewrite_fit(fit_path, d / "long_theta.npz",
                                     edit_arrays=lambda a: a.update(theta=np.zeros(5)))
    enn = jf.models.Elman(neurons=2)
    enn_fit = Fit(model=enn, theta=np.zeros(enn.num_params, np.float32),
                  velocity_scaler=jf.models.Scaler.fit(V), friction_scaler=jf.models.Scaler.fit(F),
                  dt=0.01, n_train=40, n_samples=N, metrics={"train": None, "valid": None, "all": None})
    enn_fit.save(d / "enn.npz")
    out["nan_scaler"] = _rewrite_fit(d / "enn.npz", d / "nan_scaler.npz",
                                     edit_arrays=lambda a: a.update(friction_scaler=np.array([np.nan, 1.0])))
    out["inf_theta"] = _rewrite_fit(d / "enn.npz", d / "inf_theta.npz",
                                    edit_arrays=lambda a: a.update(theta=np.full(enn.num_params, np.inf, np.float32)))
    out["pickle"] = d / "pickled.npy"
    np.save(out["pickle"], np.array([{"a": 1}], dtype=object), allow_pickle=True)
    out["dup_header"] = _csv(d / "dup_header.csv", "t,v,v,F", [(a, b, b, c) for a, b, c in rows])
    np.savez(d / "other.npz", weights=np.zeros(3))
    out["other_npz"] = d / "other.npz"
    out["garbage_checkpoint"] = d / "checkpoint.npz"
    out["garbage_checkpoint"].write_bytes(b"not a checkpoint")
    return {k: Path(v) for k, v in out.items()}


def _xfail(reason):
    return pytest.mark.xfail(strict=True, reason=reason)


C = rig.load_friction_pairs
COLS = {"t": "t", "velocity": "v", "friction": "F"}

# (id, call(files), exception type, words of the message[, marks])
API_CASES = [
    # ---------------------------------------------------------------- optimiser: bounds
    ("minimise/bounds-inverted", lambda f: jf.minimise(counted, PSO, (HI, LO), key=KEY), ValueError,
     ["every lower bound must be < its upper bound", "parameter 0"]),
    ("minimise/bounds-zero-width", lambda f: jf.minimise(counted, PSO, (LO, LO), key=KEY), ValueError,
     ["every lower bound must be < its upper bound", "3 such parameter(s)"]),
    ("minimise/bounds-nan", lambda f: jf.minimise(counted, PSO, (_with(LO, 1, np.nan), HI), key=KEY),
     ValueError, ["bounds must be finite", "NaN or inf"]),
    ("minimise/bounds-inf", lambda f: jf.minimise(counted, PSO, (LO, _with(HI, 2, np.inf)), key=KEY),
     ValueError, ["bounds must be finite"]),
    ("minimise/bounds-shapes-differ", lambda f: jf.minimise(counted, PSO, (LO, HI[:2]), key=KEY),
     ValueError, ["different shapes", "(3,)", "(2,)"]),
    ("minimise/bounds-not-a-pair", lambda f: jf.minimise(counted, PSO, HI, key=KEY), ValueError,
     ["bounds must be a pair (lower, upper)"]),
    ("minimise/bounds-empty", lambda f: jf.minimise(counted, PSO, (np.zeros(0), np.zeros(0)), key=KEY),
     ValueError, ["zero parameters"]),
    ("minimise/bounds-text", lambda f: jf.minimise(counted, PSO, (["a"] * 3, ["b"] * 3), key=KEY),
     ValueError, ["lower bound must be numeric"]),
    ("minimise/bounds-complex", lambda f: jf.minimise(counted, PSO, (LO + 0j, HI), key=KEY), ValueError,
     ["lower bound must be numeric", "complex"]),
    pytest.param(
        "minimise/bounds-width-overflows-float32",
        lambda f: jf.minimise(counted, PSO, (np.full(3, -3e38, np.float32), np.full(3, 3e38, np.float32)),
                              key=KEY),
        ValueError, ["upper - lower", "float32"],
    ),
    pytest.param(
        "minimise/bounds-collapse-in-float32",
        lambda f: jf.minimise(counted, PSO, (np.array([1.0, 0.0]), np.array([1.0 + 1e-12, 1.0])), key=KEY),
        ValueError, ["float32", "lower bound must be < its upper bound"],
    ),
    # ------------------------------------------------------------ optimiser: budgets, names
    ("minimise/pso-zero-generations", lambda f: jf.minimise(counted, jf.PSO(num_generations=0), (LO, HI), key=KEY),
     ValueError, ["num_generations must be >= 1, got 0"]),
    ("minimise/pso-zero-particles", lambda f: jf.minimise(counted, jf.PSO(num_particles=0), (LO, HI), key=KEY),
     ValueError, ["num_particles must be >= 1"]),
    ("minimise/mapso-zero-lattice", lambda f: jf.minimise(counted, jf.MAPSO(lattice_size=0), (LO, HI), key=KEY),
     ValueError, ["lattice_size must be >= 1"]),
    ("minimise/nelder-mead-zero-evals", lambda f: jf.minimise(counted, jf.NelderMead(max_evals=0), (LO, HI), key=KEY),
     ValueError, ["max_evals must be >= 1, got 0"]),
    ("minimise/nelder-mead-zero-steps", lambda f: jf.minimise(counted, jf.NelderMead(max_steps=0), (LO, HI), key=KEY),
     ValueError, ["max_steps must be >= 1"]),
    ("minimise/hybrid-zero-generations",
     lambda f: jf.minimise(counted, jf.mapso_nmds(num_generations=0), (LO, HI), key=KEY), ValueError,
     ["num_generations must be >= 1"]),
    ("minimise/budget-not-whole", lambda f: jf.minimise(counted, jf.PSO(num_generations=2.5), (LO, HI), key=KEY),
     ValueError, ["num_generations must be an integer", "2.5"]),
    ("minimise/hyperparameter-nan", lambda f: jf.minimise(counted, jf.PSO(w_max=float("nan")), (LO, HI), key=KEY),
     ValueError, ["w_max must be finite"]),
    ("minimise/unknown-option-value", lambda f: jf.minimise(counted, jf.MAPSO(social="ring"), (LO, HI), key=KEY),
     ValueError, ["social must be 'gbest' or 'lbest'", "'ring'"]),
    ("minimise/unknown-simplex", lambda f: jf.minimise(counted, jf.NelderMead(initial_simplex="random"), (LO, HI), key=KEY),
     ValueError, ["initial_simplex must be 'bounds' or 'fminsearch'"]),
    ("minimise/solver-name-string", lambda f: jf.minimise(counted, "pso", (LO, HI), key=KEY), ValueError,
     ["solver must be a jaxfric solver", "got str"]),
    ("minimise/solver-class-not-instance", lambda f: jf.minimise(counted, jf.PSO, (LO, HI), key=KEY), ValueError,
     ["solver must be a jaxfric solver"]),
    ("minimise/hybrid-with-pso", lambda f: jf.minimise(counted, jf.MAPSONMDS(mapso=jf.PSO()), (LO, HI), key=KEY),
     ValueError, ["mapso must be a jaxfric.MAPSO"]),
    ("minimise/hybrid-too-many-starts",
     lambda f: jf.minimise(counted, jf.mapso_nmds(lattice_size=2, num_starts=5), (LO, HI), key=KEY), ValueError,
     ["num_starts (5) exceeds the number of agents (4)"]),
    # ------------------------------------------------------------ optimiser: fn, key, y0
    ("minimise/fn-returns-vector", lambda f: jf.minimise(lambda y, a: y ** 2, PSO, (LO, HI), key=KEY), ValueError,
     ["must return a floating-point scalar", "(3,)"]),
    ("minimise/fn-returns-int", lambda f: jf.minimise(lambda y, a: jnp.sum(y > 0), PSO, (LO, HI), key=KEY),
     ValueError, ["must return a floating-point scalar", "int32"]),
    ("minimise/fn-not-callable", lambda f: jf.minimise(3.0, PSO, (LO, HI), key=KEY), ValueError,
     ["fn must be callable fn(y, args)"]),
    ("minimise/fn-fails-on-args", lambda f: jf.minimise(lambda y, a: y @ a, PSO, (LO, HI), key=KEY), ValueError,
     ["calling fn(y, args) on the bounds' shape failed"]),
    ("minimise/key-missing", lambda f: jf.minimise(counted, PSO, (LO, HI)), ValueError,
     ["key is required", "jax.random.key(seed)"]),
    ("minimise/key-float", lambda f: jf.minimise(counted, PSO, (LO, HI), key=np.zeros(2, np.float32)), ValueError,
     ["key must be a JAX PRNG key", "float32"]),
    pytest.param(
        "minimise/key-batch", lambda f: jf.minimise(counted, PSO, (LO, HI), key=jax.random.split(KEY, 3)),
        ValueError, ["one key", "minimise_many"],
    ),
    ("minimise/y0-nan", lambda f: jf.minimise(counted, PSO, (LO, HI), key=KEY, y0=_with(LO, 0, np.nan)),
     ValueError, ["y0 must be finite"]),
    ("minimise/y0-outside-box", lambda f: jf.minimise(counted, PSO, (LO, HI), key=KEY, y0=_with(LO, 1, HI[1] + 1.0)),
     ValueError, ["y0 lies outside the bounds", "flat index 1", "never clipped"]),
    ("minimise/y0-shape", lambda f: jf.minimise(counted, PSO, (LO, HI), key=KEY, y0=np.zeros(2)), ValueError,
     ["y0 must have the same structure and shapes as the bounds"]),
    ("minimise/compiler-option-unknown",
     lambda f: jf.minimise(counted, PSO, (LO, HI), key=KEY, compiler_options={"xla_cpu_warp_speed": True}),
     ValueError, ["XLA rejected compiler_options", "xla_cpu_warp_speed"]),
    ("minimise_many/compiler-options-not-a-dict",
     lambda f: jf.minimise_many(counted, PSO, (LO, HI), keys=jax.random.split(KEY, 2), compiler_options="fast"),
     ValueError, ["compiler_options must be 'auto', None or a dict"]),
    ("identify/compiler-option-value",
     lambda f: jf.identify("lugre", (V, F, 0.01), key=0, compiler_options={"xla_cpu_prefer_vector_width": [512]}),
     ValueError, ["compiler_options['xla_cpu_prefer_vector_width'] must be a bool, int, float or str"]),
    pytest.param(
        "minimise/dtype-int", lambda f: jf.minimise(counted, PSO, (LO, HI), key=KEY, dtype=np.int32), ValueError,
        ["dtype must be a floating"],
    ),
    ("minimise/progress-bad", lambda f: jf.minimise(counted, PSO, (LO, HI), key=KEY, progress="yes"), ValueError,
     ["progress must be None, True (a tqdm bar) or a callable"]),
    # (0.6.0 refused checkpoints for Nelder-Mead; every solver checkpoints now:
    # tests/test_checkpoint.py)
    # ------------------------------------------------------------ issue 20: 2, 3, 7, 8
    ("minimise/dtype-float16",
     lambda f: jf.minimise(counted, PSO, (LO, HI), key=KEY, dtype=np.float16), ValueError,
     ["dtype float16 is too narrow", "float32 or float64"]),
    ("minimise/budget-overflows-int32-counter",
     lambda f: jf.minimise(counted, jf.PSO(num_particles=100_000, num_generations=30_000), (LO, HI), key=KEY),
     ValueError, ["3,000,100,000 objective evaluations", "int32", "jax.enable_x64(True)"]),
    ("minimise/key-three-words",
     lambda f: jf.minimise(counted, PSO, (LO, HI), key=np.array([1, 2, 3], np.uint32)), ValueError,
     ["raw uint32 array of shape (3,)", "a raw key has 2 words"]),
    ("minimise/key-bool", lambda f: jf.minimise(counted, PSO, (LO, HI), key=True), ValueError,
     ["key must be a JAX PRNG key (or an int seed)", "bool"]),
    ("minimise_many/keys-int", lambda f: jf.minimise_many(counted, PSO, (LO, HI), keys=8), ValueError,
     ["keys must be a batch of keys", "not an int"]),
    ("minimise/bounds-two-lists-read-as-scipy-pairs",
     lambda f: jf.minimise(counted, PSO, ([0.0, 0.0], [1.0, 1.0]), key=KEY), ValueError,
     ["parameter 0 has lower=0.0 >= upper=0.0", "read as SciPy's (lo, hi) pairs",
      "(np.array(lower), np.array(upper))"]),
    ("minimise/y0-population-for-nelder-mead",
     lambda f: jf.minimise(counted, jf.NelderMead(), (LO, HI), key=KEY, y0=np.full((2, 3), 0.5)),
     ValueError, ["this solver takes one start"]),
    ("minimise/warm-start-not-a-solution",
     lambda f: jf.minimise(counted, PSO, (LO, HI), key=KEY, warm_start={"x": 1}), ValueError,
     ["warm_start must be a Solution"]),
    ("minimise/stall-zero",
     lambda f: jf.minimise(counted, jf.PSO(stall_generations=0), (LO, HI), key=KEY), ValueError,
     ["stall_generations must be >= 1"]),
    ("minimise/checkpoint-every-zero",
     lambda f: jf.minimise(counted, PSO, (LO, HI), key=KEY, checkpoint=f["folder"] / "c.npz", checkpoint_every=0),
     ValueError, ["checkpoint_every must be >= 1"]),
    ("minimise/checkpoint-corrupted",
     lambda f: jf.minimise(counted, PSO, (LO, HI), key=KEY, checkpoint=f["garbage_checkpoint"]),
     ValueError, ["is unreadable or corrupted"]),
    ("minimise_many/one-key", lambda f: jf.minimise_many(counted, PSO, (LO, HI), keys=KEY), ValueError,
     ["keys must be a batch of keys", "jax.random.split"]),
    ("minimise_many/keys-missing", lambda f: jf.minimise_many(counted, PSO, (LO, HI), keys=None), ValueError,
     ["keys is required"]),
    ("minimise_many/bounds-inverted",
     lambda f: jf.minimise_many(counted, PSO, (HI, LO), keys=jax.random.split(KEY, 2)), ValueError,
     ["every lower bound must be < its upper bound"]),
    ("minimise_many/zero-budget",
     lambda f: jf.minimise_many(counted, jf.MAPSO(num_generations=0), (LO, HI), keys=jax.random.split(KEY, 2)),
     ValueError, ["num_generations must be >= 1"]),
    pytest.param(
        "minimise_many/no-keys",
        lambda f: jf.minimise_many(counted, PSO, (LO, HI), keys=jax.random.split(KEY, 0)), ValueError,
        ["keys", "empty"],
    ),
    pytest.param(
        "minimise_many/devices-bad",
        lambda f: jf.minimise_many(counted, PSO, (LO, HI), keys=jax.random.split(KEY, 2), devices="gpu"),
        ValueError, ["devices"],
    ),
    # ---------------------------------------------------------------------------- identify
    ("identify/unknown-model", lambda f: jf.identify("magic", (V, F, 0.01), key=0), ValueError,
     ["unknown friction model 'magic'", "lugre"]),
    ("identify/unknown-model-option", lambda f: jf.identify("elman", (V, F, 0.01), key=0, model_options={"nerons": 3}),
     ValueError, ["invalid options for model 'elman'", "nerons"]),
    ("identify/zero-neurons", lambda f: jf.identify("elman", (V, F, 0.01), key=0, model_options={"neurons": 0}),
     ValueError, ["neurons must be >= 1"]),
    ("identify/lengths-differ", lambda f: jf.identify("lugre", (V, F[:-1], 0.01), key=0), ValueError,
     ["same length", "50", "49"]),
    ("identify/nan-friction", lambda f: jf.identify("lugre", (V, _with(F, 7, np.nan), 0.01), key=0), ValueError,
     ["friction has 1 non-finite samples", "NaN first at index 7"]),
    ("identify/inf-velocity", lambda f: jf.identify("lugre", (_with(V, 3, -np.inf), F, 0.01), key=0), ValueError,
     ["velocity has 1 non-finite samples", "inf"]),
    pytest.param(
        "identify/empty-record", lambda f: jf.identify("lugre", (np.zeros(0), np.zeros(0), 0.01), key=0),
        ValueError, ["0 samples", "at least 3"],
    ),
    pytest.param(
        "identify/one-sample-record", lambda f: jf.identify("lugre", (V[:1], F[:1], 0.01), key=0),
        ValueError, ["1 sample", "at least 3"],
    ),
    ("identify/constant-friction", lambda f: jf.identify("lugre", (V, np.full(N, 7.0), 0.01), key=0), ValueError,
     ["friction has zero variance over the training window"]),
    ("identify/constant-velocity", lambda f: jf.identify("lugre", (np.full(N, 0.01), F, 0.01), key=0), ValueError,
     ["velocity is constant over the training window"]),
    ("identify/dt-zero", lambda f: jf.identify("lugre", (V, F, 0.0), key=0), ValueError,
     ["dt must be a positive, finite sample time"]),
    ("identify/dt-array", lambda f: jf.identify("lugre", (V, F, T), key=0), ValueError,
     ["dt must be a scalar sample time", "FrictionData.from_arrays"]),
    ("identify/velocity-2d", lambda f: jf.identify("lugre", (V[:, None], F, 0.01), key=0), ValueError,
     ["velocity must be a 1-D time series", "(50, 1)"]),
    ("identify/velocity-text", lambda f: jf.identify("lugre", (["fast"] * N, F, 0.01), key=0), ValueError,
     ["velocity is not numeric"]),
    pytest.param(
        "identify/velocity-complex", lambda f: jf.identify("lugre", (V + 1j, F, 0.01), key=0), ValueError,
        ["velocity", "complex"],
    ),
    ("identify/train-fraction-too-big", lambda f: jf.identify("lugre", (V, F, 0.01), key=0, train=1.5), ValueError,
     ["a train fraction must lie in (0, 1)"]),
    ("identify/train-longer-than-record", lambda f: jf.identify("lugre", (V, F, 0.01), key=0, train=80), ValueError,
     ["shorter than the training split"]),
    ("identify/solver-name-string", lambda f: jf.identify("lugre", (V, F, 0.01), key=0, solver="pso"), ValueError,
     ["solver must be a jaxfric solver", "got str"]),
    ("identify/solver-zero-budget",
     lambda f: jf.identify("lugre", (V, F, 0.01), key=0, solver=jf.mapso_nmds(num_generations=0)), ValueError,
     ["num_generations must be >= 1"]),
    ("identify/key-batch",
     lambda f: jf.identify("lugre", (V, F, 0.01), key=jax.random.split(KEY, 3)), ValueError,
     ["one JAX PRNG key", "batch"]),
    ("identify/key-missing", lambda f: jf.identify("lugre", (V, F, 0.01), key=None), ValueError, ["key is required"]),
    ("identify/theta0-nan", lambda f: jf.identify("lugre", (V, F, 0.01), key=0, theta0=np.full(6, np.nan)),
     ValueError, ["theta holds non-finite values"]),
    ("identify/theta0-length", lambda f: jf.identify("lugre", (V, F, 0.01), key=0, theta0=np.zeros(3)),
     ValueError, ["3 entries", "6 parameters"]),
    ("identify/theta0-outside-box",
     lambda f: jf.identify("lugre", (V, F, 0.01), key=0, theta0=jf.LuGre().bounds()[1] + 1, data_bounds=False),
     ValueError, ["theta0 lies outside the search box"]),
    ("identify/refine-unknown", lambda f: jf.identify("lugre", (V, F, 0.01), key=0, refine="adam"), ValueError,
     ["refine method must be one of", "'adam'"]),
    ("identify/data-dict", lambda f: jf.identify("lugre", {"v": V}, key=0), ValueError,
     ["FrictionData-like", "(velocity, friction, dt)"]),
    ("identify/data-rig-record",
     # a record as rig.simulate returns it (built directly: simulating one costs a compilation)
     lambda f: jf.identify("lugre", jf.rig.RigRecord(*[np.linspace(0.0, 1.0, 64)] * 13), key=0), ValueError,
     ["RigRecord", "jaxfric.rig.estimate_friction(record.measurements(), rig.cylinder)",
      "synthetic_friction_data"]),
    ("identify/data-two-items", lambda f: jf.identify("lugre", (V, F), key=0), ValueError,
     ["(velocity, friction, dt)", "2 items"]),
    ("identify/dtype-int", lambda f: jf.identify("lugre", (V, F, 0.01), key=0, dtype=np.int32), ValueError,
     ["dtype must be a floating dtype"]),
    # ------------------------------------------------------------------------------ models
    ("models/elman-zero-neurons", lambda f: jf.Elman(neurons=0), ValueError, ["neurons must be >= 1"]),
    ("models/elman-alpha-one", lambda f: jf.Elman(alpha_max=1.0), ValueError, ["alpha_max must lie in (0, 1.0)"]),
    ("box/lugre-range-inverted", lambda f: jf.identify("lugre", (V, F, 0.01), key=0, box={"sigma0": (1e5, 1e4)}),
     ValueError, ["sigma0 range must satisfy low < high"]),
    ("box/lugre-range-zero-width", lambda f: jf.identify("lugre", (V, F, 0.01), key=0, box={"Fc": (10.0, 10.0)}),
     ValueError, ["Fc range must satisfy low < high"]),
    ("box/lugre-range-nan", lambda f: models.SearchBox(Fc=(float("nan"), 10.0)), ValueError,
     ["Fc range must satisfy low < high (finite)"]),
    ("box/lugre-range-three-values", lambda f: jf.LuGre().bounds({"sigma0": (1.0, 2.0, 3.0)}), ValueError,
     ["sigma0 must be a (low, high) pair"]),
    ("box/entry-the-model-lacks", lambda f: jf.identify("coulomb", (V, F, 0.01), key=0, box={"sigma0": (1e4, 1e6)}),
     ValueError, ["Coulomb has no parameter 'sigma0'", "its box entries are Fc, sigma2"]),
    ("box/unknown-entry", lambda f: jf.identify("lugre", (V, F, 0.01), key=0, box={"Fv": (1.0, 2.0)}),
     ValueError, ["unknown parameter 'Fv'"]),
    ("box/ratio-below-one", lambda f: jf.identify("lugre", (V, F, 0.01), key=0, box={"Fs_ratio": (0.5, 2.0)}),
     ValueError, ["Fs_ratio range must start at >= 1"]),
    ("box/a-0.7-range-option", lambda f: jf.identify("lugre", (V, F, 0.01), key=0, vs_range=(1e-4, 1.0)),
     ValueError, ["'vs_range'", "pass box={'vs': (low, high)}"]),
    ("box/elman-takes-none", lambda f: jf.identify("elman", (V, F, 0.01), key=0, box={"Fc": (1.0, 2.0)}),
     ValueError, ["Elman takes no search box", "context_weight_bound"]),
    ("models/lugre-theta-length", lambda f: jf.LuGre().simulate(np.zeros(3), V, 0.01), ValueError,
     ["3 entries", "6 parameters"]),
    ("models/lugre-dt-missing", lambda f: jf.LuGre().simulate(np.ones(6), V, None), ValueError,
     ["pass the sample time dt in seconds"]),
    ("models/lugre-dt-negative", lambda f: jf.LuGre().simulate(np.ones(6), V, -0.01), ValueError,
     ["dt must be a positive, finite sample time"]),
    ("models/dahl-dt-zero", lambda f: jf.Dahl().simulate_batch(np.ones((2, 2)), V, 0.0), ValueError,
     ["dt must be a positive, finite sample time"]),
    ("models/empty-velocity", lambda f: jf.LuGre().simulate(np.ones(6), np.zeros(0), 0.01), ValueError,
     ["velocity is empty"]),
    ("models/velocity-2d", lambda f: jf.Coulomb().simulate(np.ones(2), V[:, None]), ValueError,
     ["velocity must be a 1-D time series"]),
    ("models/get-unknown", lambda f: models.get("gms2"), ValueError, ["unknown friction model 'gms2'", "valid names"]),
    ("models/check-theta-nan", lambda f: jf.LuGre().check_theta(np.full(6, np.nan)), ValueError,
     ["non-finite values"]),
    ("models/data-bounds-zero-friction", lambda f: jf.LuGre().search_box(None, V, np.zeros(N)), ValueError,
     ["friction is (almost) identically zero"]),
    # ----------------------------------------------------------------------------- metrics
    ("metrics/shapes-differ", lambda f: jf.friction_metrics(F, F[:5]), ValueError,
     ["same shape", "(50,)", "(5,)"]),
    ("metrics/empty", lambda f: jf.friction_metrics([], []), ValueError, ["must not be empty"]),
    ("metrics/nan", lambda f: jf.friction_metrics(F, _with(F, 3, np.nan)), ValueError,
     ["y_hat holds NaN or inf"]),
    ("metrics/constant-friction", lambda f: jf.friction_metrics(np.ones(N), F), ValueError, ["zero variance"]),
    ("metrics/one-sample", lambda f: jf.friction_metrics([3.0], [2.0]), ValueError, ["zero variance"]),
    ("metrics/text", lambda f: jf.friction_metrics(["a"] * N, F), ValueError, ["y is not numeric"]),
    ("metrics/complex", lambda f: jf.friction_metrics(F + 1j, F), ValueError, ["y holds complex numbers"]),
    ("metrics/error-beyond-float64", lambda f: jf.friction_metrics(F, F * 1e300), ValueError,
     ["exceed the float64 range", "diverged"]),
    # ------------------------------------------------------------------------ FrictionData
    ("rig/from-arrays-lengths", lambda f: rig.FrictionData.from_arrays(V, F[:-1], 0.01), ValueError,
     ["channel 'friction' has 49 samples, expected 50"]),
    ("rig/from-arrays-unsorted-time", lambda f: rig.FrictionData.from_arrays(V, F, _with(T, 3, 0.5)), ValueError,
     ["time stamps in 't' are not sorted", "t[3] = 0.5 > t[4] = 0.04"]),
    ("rig/from-arrays-duplicate-time", lambda f: rig.FrictionData.from_arrays(V, F, _with(T, 4, 0.03)), ValueError,
     ["duplicate time stamps", "t[3] == t[4] == 0.03"]),
    ("rig/from-arrays-irregular-time", lambda f: rig.FrictionData.from_arrays(V, F, T**2 + T), ValueError,
     ["time stamps are not uniform", "resample"]),
    ("rig/from-arrays-nan", lambda f: rig.FrictionData.from_arrays(V, _with(F, 7, np.nan), 0.01), ValueError,
     ["channel 'friction' has 1 non-finite samples (NaN first at index 7)"]),
    ("rig/from-arrays-dt-zero", lambda f: rig.FrictionData.from_arrays(V, F, 0.0), ValueError,
     ["dt must be positive and finite, got 0.0"]),
    ("rig/from-arrays-dt-text", lambda f: rig.FrictionData.from_arrays(V, F, "fast"), ValueError,
     ["dt_or_t must be the sample interval", "'fast'"]),
    ("rig/from-arrays-empty", lambda f: rig.FrictionData.from_arrays([], [], 0.01), ValueError,
     ["channel 'velocity' is empty"]),
    ("rig/from-arrays-one-sample", lambda f: rig.FrictionData.from_arrays([0.1], [3.0], 0.01), ValueError,
     ["needs at least 2 samples, got 1"]),
    ("rig/from-arrays-complex", lambda f: rig.FrictionData.from_arrays(V + 1j, F, 0.01), ValueError,
     ["channel 'velocity' holds complex numbers"]),
    ("rig/from-arrays-text", lambda f: rig.FrictionData.from_arrays(["a"] * N, F, 0.01), ValueError,
     ["channel 'velocity' is not numeric"]),
    ("rig/from-arrays-train-fraction-zero", lambda f: rig.FrictionData.from_arrays(V, F, 0.01, 0.0), ValueError,
     ["train_fraction must lie in (0, 1]"]),
    # ------------------------------------------------------------------------------ loaders
    ("rig/load-pairs-missing-file", lambda f: C(f["missing"], COLS), ValueError, ["file not found", "no-such-file.csv"]),
    ("rig/load-pairs-folder", lambda f: C(f["folder"], COLS), ValueError, ["is a folder, not a data file"]),
    ("rig/load-pairs-binary", lambda f: C(f["binary"], COLS), ValueError, ["is not a text (CSV) file"]),
    ("rig/load-pairs-text-in-column", lambda f: C(f["text"], COLS), ValueError,
     ["line 9, column 'v' (channel 'velocity') holds 'abc', not a number"]),
    ("rig/load-pairs-empty-cell", lambda f: C(f["blank"], COLS), ValueError,
     ["line 9, column 'v' (channel 'velocity') is empty"]),
    ("rig/load-pairs-ragged", lambda f: C(f["ragged"], COLS), ValueError, ["line 9 has 4 columns, expected 3"]),
    ("rig/load-pairs-empty-file", lambda f: C(f["empty"], COLS), ValueError, ["empty file"]),
    ("rig/load-pairs-header-only", lambda f: C(f["header_only"], COLS), ValueError, ["no data rows"]),
    ("rig/load-pairs-one-row", lambda f: C(f["one"], COLS), ValueError, ["needs at least 2 samples, got 1"]),
    ("rig/load-pairs-missing-column", lambda f: C(f["good"], {**COLS, "velocity": "speed"}), ValueError,
     ["column 'speed' (for channel 'velocity') is missing", "the header has ['t', 'v', 'F']"]),
    ("rig/load-pairs-column-index", lambda f: C(f["good"], {"t": 0, "velocity": 7, "friction": 2}), ValueError,
     ["column index 7 (for channel 'velocity') is missing; the file has 3 columns"]),
    ("rig/load-pairs-unsorted", lambda f: C(f["unsorted"], COLS), ValueError, ["are not sorted"]),
    ("rig/load-pairs-irregular-raise", lambda f: C(f["irregular"], COLS, on_irregular="raise"), ValueError,
     ["time stamps are irregular", "on_irregular='resample'"]),
    ("rig/load-pairs-no-columns", lambda f: C(f["good"]), ValueError, ["columns= is required for files"]),
    ("rig/load-pairs-unknown-channel", lambda f: C(f["good"], {**COLS, "x": "v"}), ValueError,
     ["unknown channel name(s) ['x']"]),
    ("rig/load-pairs-scale-text", lambda f: C(f["good"], COLS, scale={"velocity": "mm"}), ValueError,
     ["scale for channel 'velocity' must be a number", "'mm'"]),
    ("rig/load-pairs-scale-nan", lambda f: C(f["good"], COLS, scale={"velocity": float("nan")}), ValueError,
     ["scale for channel 'velocity' must be a finite, non-zero number"]),
    ("rig/load-pairs-skip-negative", lambda f: C(f["good"], COLS, skip_rows=-1), ValueError,
     ["skip_rows must be a whole number >= 0"]),
    ("rig/load-measurements-missing-channels", lambda f: rig.load_measurements({"t": T, "x": V}), ValueError,
     ["missing channel(s) ['p1', 'p2', 'load']"]),
    ("rig/load-measurements-lengths",
     lambda f: rig.load_measurements({"t": T, "x": V, "p1": V, "p2": V[:5], "load": V}), ValueError,
     ["channel 'p2' has 5 samples, expected 50"]),
    ("rig/load-measurements-fill-nan",
     lambda f: rig.load_measurements({"t": T, "x": V, "p1": V, "p2": V}, fill={"load": float("nan")}), ValueError,
     ["fill for channel 'load' must be a finite number"]),
    # --------------------------------------------------------------- simulator and pipeline
    ("rig/simulate-key-missing", lambda f: rig.simulate(rig.Rig(), None, n_samples=10), ValueError,
     ["key must be a JAX PRNG key"]),
    ("rig/simulate-key-int", lambda f: rig.simulate(rig.Rig(), 0, n_samples=10), ValueError,
     ["key must be a JAX PRNG key"]),
    ("rig/simulate-zero-samples", lambda f: rig.simulate(rig.Rig(), KEY, n_samples=0), ValueError,
     ["n_samples must be a whole number >= 2, got 0"]),
    ("rig/simulate-fs-zero", lambda f: rig.simulate(rig.Rig(), KEY, n_samples=10, fs=0.0), ValueError,
     ["fs must be positive and finite"]),
    ("rig/simulate-substeps-zero", lambda f: rig.simulate(rig.Rig(), KEY, n_samples=10, substeps=0), ValueError,
     ["substeps must be a whole number >= 1"]),
    ("rig/simulate-settle-negative", lambda f: rig.simulate(rig.Rig(), KEY, n_samples=10, settle_time=-1.0),
     ValueError, ["settle_time must be non-negative and finite"]),
    ("rig/simulate-reference-nan",
     lambda f: rig.simulate(rig.Rig(), KEY, n_samples=10, velocity_reference=np.full(10, np.nan)), ValueError,
     ["velocity_reference holds NaN or inf"]),
    ("rig/simulate-reference-shape",
     lambda f: rig.simulate(rig.Rig(), KEY, n_samples=10, velocity_reference=np.zeros(5)), ValueError,
     ["velocity_reference must have shape (10,), got (5,)"]),
    ("rig/cylinder-negative-bore", lambda f: rig.Cylinder(bore=-1.0), ValueError,
     ["bore diameter must be positive and finite"]),
    ("rig/estimate-too-short", lambda f: rig.estimate_friction(_meas(15), bore=0.1, rod=0.05, mass=1.0),
     ValueError, ["record too short for the order-4 filter", "padlen = 15"]),
    ("rig/estimate-rod-too-thick", lambda f: rig.estimate_friction(_meas(), bore=0.05, rod=0.06, mass=1.0),
     ValueError, ["rod diameter (0.06 m) must be smaller than the bore (0.05 m)"]),
    ("rig/estimate-cutoff-above-nyquist",
     lambda f: rig.estimate_friction(_meas(), bore=0.1, rod=0.05, mass=1.0, cutoff=60.0), ValueError,
     ["must be below the Nyquist frequency"]),
    ("rig/estimate-geometry-missing", lambda f: rig.estimate_friction(_meas()), ValueError,
     ["'bore' is required"]),
    ("rig/estimate-not-measurements", lambda f: rig.estimate_friction({"t": T}, bore=0.1, rod=0.0, mass=1.0),
     ValueError, ["meas must be a Measurements record"]),
    # ---------------------------------------------------------------------------- load_fit
    ("load_fit/missing", lambda f: jf.load_fit(f["missing"]), FileNotFoundError, ["No such file"]),
    ("load_fit/truncated", lambda f: jf.load_fit(f["truncated"]), ValueError,
     ["is not a readable jaxfric fit file (corrupted or truncated?)"]),
    ("load_fit/newer-version", lambda f: jf.load_fit(f["newer"]), ValueError,
     ["fit format version 2", "reads up to version 1", "upgrade jaxfric"]),
    ("load_fit/unknown-version", lambda f: jf.load_fit(f["version0"]), ValueError,
     ["unknown fit format version 0"]),
    ("load_fit/not-a-fit", lambda f: jf.load_fit(f["other_npz"]), ValueError, ["is not a jaxfric fit file"]),
    ("load_fit/a-csv-file", lambda f: jf.load_fit(f["good"]), ValueError, ["is not a readable jaxfric fit file"]),
    ("load_fit/unknown-model-class", lambda f: jf.load_fit(f["magic_class"]), ValueError,
     ["unknown friction model class 'Magic'"]),
    ("load_fit/member-missing", lambda f: jf.load_fit(f["no_theta"]), ValueError,
     ["the fit file is incomplete or corrupted", "theta"]),
    ("load_fit/theta-wrong-length", lambda f: jf.load_fit(f["long_theta"]), ValueError,
     ["5 entries", "2 parameters"]),
    ("load_fit/nan-scaler", lambda f: jf.load_fit(f["nan_scaler"]), ValueError,
     ["friction scaler holds NaN or inf", "would predict NaN"]),
    ("load_fit/inf-weights", lambda f: jf.load_fit(f["inf_theta"]), ValueError,
     ["weights (theta) holds NaN or inf"]),
    ("load_fit/pickle-file", lambda f: jf.load_fit(f["pickle"]), ValueError,
     ["is not a readable jaxfric fit file", "not an .npz archive"]),
    ("load_fit/int-is-not-a-file-descriptor", lambda f: jf.load_fit(3), ValueError,
     ["path must be a file name", "int 3"]),
    # ------------------------------------------------------- issue 17.4/17.7, 20.5, 20.12
    ("identify/validation-window-too-short", lambda f: jf.identify("coulomb", (V, F, 0.01), key=0, train=0.97),
     ValueError, ["the validation window has 2 sample(s)", "at least 10"]),
    ("identify/unknown-model-keyword", lambda f: jf.identify("elman", (V, F, 0.01), key=0, nerons=3),
     ValueError, ["invalid options for model 'elman'", "'nerons'", "its options are", "neurons"]),
    ("identify/records-different-dt",
     lambda f: jf.identify("coulomb", train=[(V, F, 0.01)], valid=[(V, F, 0.02)], key=0), ValueError,
     ["different sample times", "valid[0] 0.02 s"]),
    ("identify/valid-with-a-split-record", lambda f: jf.identify("coulomb", (V, F, 0.01), valid=(V, F, 0.01), key=0),
     ValueError, ["valid= needs the training records as train=[record, ...]"]),
    ("identify/keys-zero", lambda f: jf.identify("coulomb", (V, F, 0.01), key=0, keys=0), ValueError,
     ["keys must be a number of members >= 1"]),
    ("identify/key-and-key-batch",
     lambda f: jf.identify("coulomb", (V, F, 0.01), key=0, keys=jax.random.split(KEY, 2)), ValueError,
     ["not both"]),
    ("rig/load-pairs-duplicate-header", lambda f: C(f["dup_header"], COLS), ValueError,
     ["column 'v' (for channel 'velocity') appears 2 times", "columns 1, 2"]),
    ("fit/predict-at-lengths-differ", lambda f: _fit().predict_at(T, V[:-1]), ValueError,
     ["t and velocity must have the same length"]),
]


def _values(case) -> tuple:
    return tuple(case.values) if hasattr(case, "marks") else case  # a pytest.param or a plain tuple


def _param(case):
    return pytest.param(*_values(case), id=_values(case)[0], marks=getattr(case, "marks", ()))


@pytest.mark.filterwarnings("ignore::numpy.exceptions.ComplexWarning")
@pytest.mark.parametrize("name, call, exc, words", [_param(c) for c in API_CASES])
def test_api_rejects_bad_input_before_computing(guarded, files, name, call, exc, words):
    with pytest.raises(exc) as info:
        call(files)
    message = str(info.value)
    for w in words:
        assert w in message, f"{name}: {w!r} not in {message!r}"


def test_load_fit_never_suggests_allow_pickle(files):
    for name in ("pickle", "good", "binary"):
        with pytest.raises(ValueError) as info:
            jf.load_fit(files[name])
        assert "allow_pickle" not in str(info.value), str(info.value)


def test_catalogue_is_long_and_names_are_unique():
    names = [_values(c)[0] for c in API_CASES] + [c[0] for c in CLI_CASES]
    assert len(names) == len(set(names))
    assert len(names) >= 30


# ------------------------------------------------------------------------ command line
QUIET = ["--quiet", "--no-cache"]
PAIRS = ["--velocity-col", "v", "--friction-col", "F", "--time-col", "t", "--model", "coulomb", "--quick"]

# (id, arguments ("{name}" = a file of the fixture), words of the error line[, xfail reason])
CLI_CASES = [
    ("cli identify/missing-file", ["identify", "{missing}", *PAIRS, *QUIET], ["file not found", "no-such-file.csv"]),
    ("cli identify/folder", ["identify", "{folder}", *PAIRS, *QUIET], ["is a folder, not a data file"]),
    ("cli identify/binary-file", ["identify", "{binary}", *PAIRS, *QUIET], ["is not a text (CSV) file"]),
    ("cli identify/empty-file", ["identify", "{empty}", *PAIRS, *QUIET], ["is empty"]),
    ("cli identify/text-in-numeric-column", ["identify", "{text}", *PAIRS, *QUIET],
     ["data row 8 holds a non-number 'abc'"]),
    ("cli identify/empty-cell", ["identify", "{blank}", *PAIRS, *QUIET],
     ["--velocity-col: column 'v'", "1 empty or NaN cell(s), first in data row 8"]),
    ("cli identify/unsorted-time", ["identify", "{unsorted}", *PAIRS, *QUIET], ["time stamps in 't' are not sorted"]),
    ("cli identify/one-sample", ["identify", "{one}", *PAIRS, *QUIET], ["needs at least 2 samples, got 1"]),
    ("cli identify/constant-friction", ["identify", "{constant}", *PAIRS, *QUIET],
     ["friction has zero variance over the training window"]),
    ("cli identify/constant-friction-with-progress", ["identify", "{constant}", *PAIRS, "--no-cache"],
     ["friction has zero variance"]),
    ("cli identify/unknown-column", ["identify", "{good}", *PAIRS[:1], "speed", *PAIRS[2:], *QUIET],
     ["--velocity-col: no column 'speed'"]),
    ("cli identify/unknown-model", ["identify", "{good}", *PAIRS, "--model", "magic", *QUIET],
     ["unknown model 'magic'", "lugre"]),
    ("cli identify/unknown-solver", ["identify", "{good}", *PAIRS, "--solver", "annealing", *QUIET],
     ["argument --solver: invalid choice: 'annealing'"]),
    ("cli identify/zero-generations", ["identify", "{good}", *PAIRS, "--generations", "0", *QUIET],
     ["argument --generations: must be >= 1"]),
    ("cli identify/dt-zero", ["identify", "{good}", *PAIRS[:4], "--dt", "0", *QUIET], ["argument --dt: must be > 0"]),
    ("cli predict/truncated-model", ["predict", "{truncated}", "{good}", "--velocity-col", "v", "--time-col", "t", *QUIET],
     ["cannot load the fit", "corrupted or truncated"]),
    ("cli predict/model-from-newer-version", ["predict", "{newer}", "{good}", "--velocity-col", "v", "--time-col", "t",
                                          *QUIET], ["fit format version 2", "upgrade jaxfric"]),
    ("cli predict/missing-data", ["predict", "{fit}", "{missing}", "--velocity-col", "v", "--time-col", "t", *QUIET],
     ["file not found"]),
    ("cli predict/out-is-a-folder", ["predict", "{fit}", "{good}", "--velocity-col", "v", "--time-col", "t",
                                 "--out", "{folder}", *QUIET], ["--out", "a-folder", "folder"]),
    ("cli demo/unknown-model", ["demo", "--model", "magic", *QUIET], ["unknown model 'magic'"]),
    ("cli predict/nan-scaler-model", ["predict", "{nan_scaler}", "{good}", "--velocity-col", "v", "--time-col", "t",
                                      *QUIET], ["cannot load the fit", "friction scaler holds NaN or inf"]),
    ("cli identify/duplicate-header", ["identify", "{dup_header}", *PAIRS, *QUIET],
     ["--velocity-col", "column 'v' (--velocity-col) appears 2 times", "(columns 1, 2)"]),
    ("cli identify/validation-window-too-short", ["identify", "{good}", *PAIRS, "--train-fraction", "0.97", *QUIET],
     ["the validation window has 2 sample(s)"]),
    ("cli demo/negative-seed", ["demo", "--seed", "-1", *QUIET], ["argument --seed: must be >= 0"]),
    # ------------------------------------------- refused before JAX, or before any stage
    ("cli identify/reversed-box", ["identify", "{good}", *PAIRS, "--box", "Fc=10,1", *QUIET],
     ["argument --box: Fc range must satisfy low < high, got 10,1"]),
    ("cli identify/box-breaks-its-rule", ["identify", "{good}", *PAIRS, "--box", "Fc=-1,5", *QUIET],
     ["--box Fc=-1,5", "Fc range must be positive"]),
    ("cli identify/box-of-no-model", ["identify", "{good}", *PAIRS, "--box", "sigma0=1,5", *QUIET],
     ["--box sigma0: none of the models coulomb has this parameter"]),
    ("cli demo/model-too-large-for-memory", ["demo", "--model", "elman", "--neurons", "100000", *QUIET],
     ["ENN (100000 neurons) has 600 000 parameters", "BFGS's dense Hessian (600 000 x 600 000 x 4 bytes)",
      "needs 1.44 TB, more than the", "of memory available; use fewer neurons"]),
    ("cli demo/out-is-a-file", ["demo", "--out", "{good}", *QUIET], ["--out", "exists and is not a folder"]),
    ("cli predict/filter-without-a-saved-filter", ["predict", "{fit}", "{good}", "--velocity-col", "v",
                                                   "--time-col", "t", "--filter-velocity", *QUIET],
     ["--filter-velocity: the fit records no velocity filter", "--cutoff HZ"]),
]

#: Cases refused before JAX is imported (checked in one subprocess by
#: test_command_line_refuses_before_importing_jax).
BEFORE_JAX = [
    "cli identify/missing-file", "cli identify/folder", "cli identify/binary-file", "cli identify/empty-file",
    "cli identify/text-in-numeric-column", "cli identify/empty-cell", "cli identify/unknown-column",
    "cli identify/unknown-model", "cli identify/unknown-solver", "cli identify/zero-generations",
    "cli identify/dt-zero", "cli identify/duplicate-header", "cli identify/reversed-box",
    "cli predict/missing-data", "cli predict/out-is-a-folder", "cli demo/unknown-model",
    "cli demo/negative-seed", "cli demo/out-is-a-file",
]


# Run as real subprocesses (``python -m jaxfric ...``): one of each kind of failure
# (file, parsing, data, options, model files, names) and the exit status of a prediction
# that would be NaN. The rest call ``jaxfric.cli.main`` in this process, which is the same
# code path without paying ~1.5 CPU-seconds of interpreter and JAX start-up per case.
SUBPROCESS = {
    "cli identify/missing-file", "cli identify/text-in-numeric-column", "cli identify/unsorted-time",
    "cli identify/unknown-model", "cli identify/zero-generations", "cli predict/truncated-model",
    "cli predict/nan-scaler-model",
}


def _cli_params():
    out = []
    for case in CLI_CASES:
        marks = [_xfail(case[3])] if len(case) > 3 else []
        out.append(pytest.param(case[0], id=case[0], marks=marks))
    return out


def _argv(case, files):
    return [a.format(**{k: str(v) for k, v in files.items()}) for a in case[1]]


@pytest.fixture(scope="module")
def cli_runs(files, tmp_path_factory):
    """The :data:`SUBPROCESS` cases, each run once as ``python -m jaxfric``, two at a time
    (four at a time, 4 x 180 MB beside both workers, made the suite's memory peak)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), JAXFRIC_DEBUG="",
               JAX_COMPILATION_CACHE_DIR=str(tmp_path_factory.mktemp("cache")))

    def run(case):
        cwd = tmp_path_factory.mktemp("cwd")
        proc = subprocess.run([sys.executable, "-m", "jaxfric", *_argv(case, files)], cwd=cwd, env=env,
                              capture_output=True, text=True, timeout=300)
        return case[0], (proc.returncode, proc.stdout, proc.stderr, cwd)

    with jax_subprocess(), concurrent.futures.ThreadPoolExecutor(max_workers=2) as pool:
        return dict(pool.map(run, [c for c in CLI_CASES if c[0] in SUBPROCESS]))


@pytest.mark.parametrize("name", _cli_params())
def test_command_line_rejects_bad_input_in_one_line(cli_runs, files, tmp_path, monkeypatch, capsys, name):
    case = next(c for c in CLI_CASES if c[0] == name)
    if name in SUBPROCESS:
        status, stdout, stderr, cwd = cli_runs[name]
    else:
        from jaxfric.cli import main

        monkeypatch.chdir(tmp_path)
        status = main(_argv(case, files))
        stdout, stderr = capsys.readouterr()
        cwd = tmp_path
    assert status == 2, (status, stderr)
    assert "Traceback" not in stderr
    lines = stderr.strip().splitlines()
    errors = [ln for ln in lines if "jaxfric: error:" in ln]
    assert len(errors) == 1, stderr
    # the error is a line of its own (other lines are stage messages without --quiet)
    assert errors[0].startswith("jaxfric: error: ") and lines[-1] == errors[0], stderr
    if "--quiet" in case[1]:
        assert len(lines) == 1, stderr
    for w in case[2]:
        assert w in errors[0], (w, errors[0])
    written = [p for p in Path(cwd).rglob("*") if p.is_file()]
    assert not written, f"files written before the error: {written}"
    assert stdout == ""


_BEFORE_JAX_SCRIPT = """
import json, sys
from jaxfric.cli import main
out = []
for argv in json.loads(sys.argv[1]):
    out.append([main(argv), "jax" in sys.modules])
print(json.dumps(out))
"""


def test_command_line_refuses_before_importing_jax(files, tmp_path):
    """Files, columns, NaN cells, model and solver names, box order and the report folder
    are refused before JAX is imported: every case of :data:`BEFORE_JAX`, run in turn in
    one fresh interpreter, exits 2 with ``jax`` still absent from ``sys.modules``."""
    cases = [c for c in CLI_CASES if c[0] in BEFORE_JAX]
    assert len(cases) == len(BEFORE_JAX)
    env = dict(os.environ, PYTHONPATH=str(ROOT), JAXFRIC_DEBUG="")
    proc = subprocess.run([sys.executable, "-c", _BEFORE_JAX_SCRIPT, json.dumps([_argv(c, files) for c in cases])],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    results = json.loads(proc.stdout.strip().splitlines()[-1])
    for case, (status, jax_loaded) in zip(cases, results):
        assert status == 2, case[0]
        assert not jax_loaded, f"{case[0]}: JAX was imported before the refusal"
    assert len(proc.stderr.strip().splitlines()) == len(cases), proc.stderr
    assert not list(tmp_path.iterdir())


def test_interrupted_first_stage_leaves_no_folder(files, tmp_path, interruptible, subprocess_slot):
    """Ctrl-C during the first model's search: exit 130, "nothing was written", and no
    report folder (it is made once the first fit is done)."""
    import signal
    import time

    out = tmp_path / "report"
    env = dict(os.environ, PYTHONPATH=str(ROOT), JAXFRIC_DEBUG="")
    proc = subprocess.Popen(
        [sys.executable, "-m", "jaxfric", "identify", str(files["good"]), *PAIRS[:6], "--model", "elman",
         "--neurons", "3", "--generations", "100000", "--no-cache", "--out", str(out)],
        cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **interruptible)
    seen = ""
    deadline = time.monotonic() + 300
    while "identifying ENN" not in seen and proc.poll() is None and time.monotonic() < deadline:
        seen += proc.stderr.readline()
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    _, rest = proc.communicate(timeout=60)
    assert proc.returncode == 130, seen + rest
    assert "jaxfric: interrupted; nothing was written" in rest
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == []


# ------------------------------------------------ issue 20: behaviour that must be right
def test_checkpoint_for_another_objective_or_data_is_refused(tmp_path):
    """Issue 20.1: 0.6.0 resumed a checkpoint written for another objective or other
    args (reporting f = 0.019 where the objective gives 3.5)."""
    path = tmp_path / "c.ckpt"
    jf.minimise(lambda y, a: jnp.sum((y - a) ** 2), PSO, (LO, HI), args=jnp.full(3, 0.2), key=KEY,
                checkpoint=path, checkpoint_every=1)
    with pytest.raises(ValueError, match="the objective changed"):
        jf.minimise(lambda y, a: jnp.sum(jnp.abs(y - a)) + 3.0, PSO, (LO, HI), args=jnp.full(3, 0.2),
                    key=KEY, checkpoint=path)
    with pytest.raises(ValueError, match="the args changed"):
        jf.minimise(lambda y, a: jnp.sum((y - a) ** 2), PSO, (LO, HI), args=jnp.full(3, 0.7), key=KEY,
                    checkpoint=path)


def test_float16_bounds_and_data_search_correctly():
    """Issue 20.2: float16 bounds search in float32 (in float16 the draws overflowed and
    the swarm stalled), and an objective returning float16 is taken as it is."""
    lo, hi = np.full(3, -2.0, np.float16), np.full(3, 2.0, np.float16)
    data = jnp.asarray([0.25, -0.5, 1.0], jnp.float16)
    sol = jf.minimise(lambda y, a: jnp.sum((y.astype(jnp.float16) - a) ** 2), jf.PSO(num_generations=60),
                      (lo, hi), args=data, key=KEY)
    assert sol.value.dtype == jnp.float32
    np.testing.assert_allclose(sol.value, np.asarray(data, np.float32), atol=2e-2)


def test_large_budgets_count_in_int64_under_x64():
    """Issue 20.3: under 64-bit mode the counters are int64, so budgets of 2**31 and
    more are accepted (checked on the counter, not by running them)."""
    from jaxfric.optim._base import count_dtype
    from jaxfric.optim.problem import check_budget

    big = jf.PSO(num_particles=100_000, num_generations=30_000)
    with jax.enable_x64(True):
        assert count_dtype() == jnp.int64
        check_budget(big, 3)  # no error
        sol = jf.minimise(counted, jf.PSO(num_particles=4, num_generations=2), (LO, HI), key=KEY,
                          dtype=np.float32)
        assert sol.stats["num_evals"].dtype == jnp.int64 and sol.value.dtype == jnp.float32


def test_scipy_style_bounds_are_read_as_scipy_reads_them():
    """A sequence of (lo, hi) pairs, or scipy.optimize.Bounds, is one pair per parameter,
    also for two parameters (SciPy's Branin01 box); the result lies in the box the user
    meant, and (lower, upper) arrays keep their meaning."""
    import scipy.optimize

    pairs = [(-1.0, 1.0), (2.0, 3.0), (0.0, 5.0)]
    for bounds in (pairs, scipy.optimize.Bounds([-1.0, 2.0, 0.0], [1.0, 3.0, 5.0])):
        sol = jf.minimise(lambda y, a: jnp.sum(y**2), PSO, bounds, key=KEY)
        v = np.asarray(sol.value)
        assert np.all(v >= [-1.0, 2.0, 0.0]) and np.all(v <= [1.0, 3.0, 5.0])
    # Branin01's box in SciPy's benchmark suite: x1 in [-5, 10], x2 in [0, 15]
    def branin(y, a):
        x1, x2 = y[0], y[1]
        return ((x2 - 5.1 / (4 * jnp.pi**2) * x1**2 + 5 / jnp.pi * x1 - 6) ** 2
                + 10 * (1 - 1 / (8 * jnp.pi)) * jnp.cos(x1) + 10)

    sol = jf.minimise(branin, jf.PSO(num_generations=60), [(-5, 10), (0, 15)], key=KEY)
    v = np.asarray(sol.value)
    assert v.shape == (2,) and -5 <= v[0] <= 10 and 0 <= v[1] <= 15
    # Branin's minimum 0.397887 (three global minimisers, all inside this box)
    assert abs(float(sol.f) - 0.3978873577) < 1e-3
    # the same box as (lower, upper) arrays, and as scipy.optimize.Bounds: the same run
    for same in ((np.array([-5.0, 0.0]), np.array([10.0, 15.0])),
                 scipy.optimize.Bounds([-5.0, 0.0], [10.0, 15.0])):
        other = jf.minimise(branin, jf.PSO(num_generations=60), same, key=KEY)
        np.testing.assert_array_equal(np.asarray(other.value), v)


def test_one_key_rule():
    """Issue 20.7 / 20.12: int seeds (and numpy integer scalars such as np.uint32(3)) are
    accepted everywhere a key is, as identify does: key=3 is jax.random.key(3)."""
    a = jf.minimise(counted, PSO, (LO, HI), key=3)
    b = jf.minimise(counted, PSO, (LO, HI), key=np.uint32(3))
    c = jf.minimise(counted, PSO, (LO, HI), key=jax.random.key(3))
    assert float(a.f) == float(b.f) == float(c.f)
