"""A sweep shared by two processes equals the same sweep in one process.

Two ways to share it, each with two local CPU processes writing into one folder:

* JAX's distributed runtime: ``jax.distributed.initialize`` with a coordinator on
  127.0.0.1, the runs split by ``jax.process_index()``, a barrier at the end and the
  table written by process 0 (XLA:CPU's cross-process collectives are gloo's);
* a job array without JAX's runtime: ``process_index`` / ``process_count`` given, as
  ``jaxfric sweep --process-index $SLURM_ARRAY_TASK_ID`` does. Its two processes are this
  test process (index 0) and a subprocess (index 1), running at the same time: a job array's
  tasks are independent processes, and one fewer start of Python and JAX saves the suite
  about 3 s of CPU.

This file is also the worker script (``python tests/test_multihost.py worker ...``), so the
records and the solver are defined once. The subprocesses' timeouts are subprocess
timeouts, not assertions on time.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np

try:
    import pytest
except ImportError:  # pragma: no cover - the worker needs no pytest
    pytest = None

ROOT = Path(__file__).resolve().parents[1]
MODELS = ["coulomb", "dahl"]
SEEDS = [0, 1]
LAYOUT_DEFECT = "LAYOUT-DEFECT:"


def records():
    from jaxfric.records import FrictionData

    out = {}
    for label, phase in (("a", 0.0), ("b", 0.7)):
        t = np.arange(250) * 0.01
        v = 0.05 * np.sin(2 * np.pi * 0.5 * t + phase)
        f = 20 * np.tanh(v / 0.002) + 100 * v + 0.3 * np.sin(7 * t + phase)
        out[label] = FrictionData.from_arrays(v, f, 0.01)
    return out


def solver():
    import jaxfric

    return jaxfric.MAPSONMDS(mapso=jaxfric.MAPSO(lattice_size=3, num_generations=4),
                             nelder_mead=jaxfric.NelderMead(max_steps=20))


def run_sweep(out, **processes):
    from jaxfric.sweeps import sweep

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the tiny budget's fits warn about their validation error
        return sweep(MODELS, records(), SEEDS, out, progress=False, solver=solver(), **processes)


def _worker(mode: str, out: str, index: int, count: int, port: int) -> int:
    import jax

    if mode == "distributed":
        # a start-up choice of this script, never of the library
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
        jax.distributed.initialize(f"127.0.0.1:{port}", num_processes=count, process_id=index,
                                   initialization_timeout=120)
        assert jax.process_count() == count and jax.process_index() == index
        try:
            result = run_sweep(out)
        except RuntimeError as err:
            if "lays a run's population over every process's devices" not in str(err):
                raise
            print(LAYOUT_DEFECT, err, flush=True)
            return 3
        jax.distributed.shutdown()
    else:
        result = run_sweep(out, process_index=index, process_count=count)
    print("computed", [run.index for run in result.computed], flush=True)
    return 0


# -------------------------------------------------------------------- tests
if pytest is not None:

    @pytest.fixture(scope="module")
    def single(tmp_path_factory):
        """The sweep in this one process."""
        return run_sweep(tmp_path_factory.mktemp("single") / "sweep", process_index=0, process_count=1)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _two_processes(mode: str, out: Path, *, here: bool = False):
    """``(exit status, stdout, stderr)`` of the two processes, by index. ``here``: process 0
    is this one (the job array only: JAX's distributed runtime cannot start in a process
    that has already computed), process 1 a subprocess running at the same time."""
    from processes import jax_subprocess

    env = dict(os.environ, PYTHONPATH=str(ROOT), JAXFRIC_DEBUG="")
    port = _free_port()
    cmd = [sys.executable, str(Path(__file__).resolve()), "worker", mode, str(out)]
    first = 1 if here else 0
    with jax_subprocess():
        procs = [subprocess.Popen(cmd + [str(i), "2", str(port)], env=env, stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True) for i in range(first, 2)]
        try:
            mine = []
            if here:  # what _worker("array", ...) does and prints, in this process
                result = run_sweep(out, process_index=0, process_count=2)
                mine = [(0, f"computed {[run.index for run in result.computed]}\n", "")]
            outs = [p.communicate(timeout=600) for p in procs]
        finally:
            for p in procs:
                if p.poll() is None:
                    p.kill()
    return mine + [(p.returncode, o, e) for p, (o, e) in zip(procs, outs)]


def _rows(result_rows):
    return [{k: v for k, v in r.items() if k != "run_s"} for r in result_rows]


def _check_against_single(single, out: Path, outcomes):
    from jaxfric import load_fit
    from jaxfric.sweeps import read_table

    computed = []
    for rc, stdout, stderr in outcomes:
        assert rc == 0, f"exit {rc}\nstdout:\n{stdout}\nstderr:\n{stderr}"
        line = next(x for x in stdout.splitlines() if x.startswith("computed"))
        computed.append(eval(line.split(" ", 1)[1]))
    n = len(single.runs)
    assert computed == [list(range(0, n, 2)), list(range(1, n, 2))]  # each run once, split by process
    for run in single.runs:
        np.testing.assert_array_equal(load_fit(out / run.fit_file).theta,
                                      single.fit(run.model, run.record, run.seed).theta)
    return read_table(out / "results.csv")


@pytest.mark.slow
def test_jax_distributed_two_processes_equal_one(single, tmp_path):
    out = tmp_path / "distributed"
    outcomes = _two_processes("distributed", out)
    # each process lays its runs over its own devices (jax.local_devices()); a layout over
    # both processes would exit 3 with LAYOUT_DEFECT and fail the equality check below
    table = _check_against_single(single, out, outcomes)
    # process 0 wrote the whole table after the barrier
    assert _rows(table) == _rows(single.rows)


@pytest.mark.slow
def test_job_array_two_processes_equal_one(single, tmp_path):
    from jaxfric.sweeps import read_table

    out = tmp_path / "array"
    _check_against_single(single, out, _two_processes("array", out, here=True))
    # the later process's table holds whatever was finished when it ended; a rerun in one
    # process collects every run without computing any
    again = run_sweep(out, process_index=0, process_count=1)
    assert again.computed == [] and _rows(again.rows) == _rows(single.rows)
    assert _rows(read_table(out / "results.csv")) == _rows(single.rows)


if __name__ == "__main__" and len(sys.argv) > 1 and sys.argv[1] == "worker":
    _mode, _out, _index, _count, _port = sys.argv[2:7]
    sys.exit(_worker(_mode, _out, int(_index), int(_count), int(_port)))
