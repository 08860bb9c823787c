"""The lock that keeps a notebook kernel from running beside other test subprocesses
(tests/processes.py, issue 20.14): exclusive for a kernel, shared for the rest."""

from __future__ import annotations

import subprocess
import sys

import pytest

import processes
from processes import jax_subprocess

pytest.importorskip("fcntl")

#: tries the lock without waiting, in another process (flock locks are per open file,
#: so a probe in this process would not see this process's own lock)
PROBE = """
import fcntl, sys
with open(sys.argv[1], "a") as fh:
    try:
        fcntl.flock(fh, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        print("waits")
    else:
        print("runs")
"""


def _other_subprocess(path) -> str:
    return subprocess.run([sys.executable, "-c", PROBE, str(path)], capture_output=True, text=True,
                          timeout=60, check=True).stdout.strip()


def test_a_notebook_kernel_runs_alone_and_other_subprocesses_together(tmp_path, monkeypatch):
    path = tmp_path / "subprocess.lock"
    monkeypatch.setenv(processes.LOCK_ENV, str(path))
    with jax_subprocess(notebook=True):
        assert _other_subprocess(path) == "waits"
    assert _other_subprocess(path) == "runs"
    with jax_subprocess():
        assert _other_subprocess(path) == "runs"

