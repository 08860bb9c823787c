"""The test session's subprocesses and its peak memory (issue 20.14).

A notebook kernel holds about 0.75 GB while it runs; a ``jaxfric`` command or a script
started by a test about 0.25-0.4 GB. Run beside each other on the two xdist workers they
made the suite's peak (all processes together) about 2.0 GiB. Tests therefore start
their subprocesses inside :func:`jax_subprocess`: a notebook kernel runs while no other
test subprocess does, the others may run together. The lock is a file named by
:data:`LOCK_ENV`, which ``conftest.py`` sets once for the whole session (the workers
inherit it); without it (a test file run on its own, or no ``fcntl``) nothing waits.
"""

from __future__ import annotations

import contextlib
import os

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX
    fcntl = None

#: environment variable naming the session's lock file
LOCK_ENV = "JAXFRIC_TESTS_SUBPROCESS_LOCK"


@contextlib.contextmanager
def jax_subprocess(*, notebook: bool = False):
    """Hold around a subprocess that imports JAX: ``notebook=True`` waits until no other
    test subprocess runs and keeps the others waiting (an exclusive lock); otherwise the
    lock is shared, so only a running notebook kernel makes it wait."""
    path = os.environ.get(LOCK_ENV)
    if fcntl is None or not path:
        yield
        return
    with open(path, "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX if notebook else fcntl.LOCK_SH)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)
