"""The ``jaxfric`` command line (console script ``jaxfric = jaxfric.cli:main``).

Sub-commands (``jaxfric COMMAND --help`` for options and examples):

- ``demo``: a simulated rig identified by jaxfric's pipeline -- ENN (30 neurons) and LuGre,
  a comparison table, a friction-compensation study and a report folder;
- ``identify FILE``: the same for a user's CSV (velocity/friction pairs or raw rig channels);
- ``predict MODEL_FILE DATA_CSV``: predictions of a saved fit, as CSV;
- ``bench table1|friction``: the benchmark scripts of ``benchmarks/``.

Start-up choices the library never makes itself: the Agg backend for matplotlib,
float64 only when ``--x64`` is given (float32 is faster and accurate enough here), and
JAX's persistent compilation cache (``--no-cache`` turns it off).
"""

from __future__ import annotations

import os
import sys

from .errors import EXIT_USER_ERROR, KEPT, UserError, debug_enabled, run_interruptible
from .parser import build_parser

__all__ = ["main", "UserError"]


def cache_dir() -> str:
    """Where compiled XLA programs are kept between runs."""
    env = os.environ.get("JAX_COMPILATION_CACHE_DIR")
    if env:
        return env
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "jaxfric", "jax")


def _configure(args) -> None:
    """Start-up choices (process-wide, hence here and never in the library)."""
    import matplotlib

    matplotlib.use("Agg")  # files only; never needs a display
    import jax

    if getattr(args, "x64", False):
        jax.config.update("jax_enable_x64", True)
    if not getattr(args, "no_cache", True):
        # Compilation is most of a default run (about 30 s of 90 s for the demo); the
        # persistent cache makes every later run with the same shapes skip it.
        jax.config.update("jax_compilation_cache_dir", cache_dir())


def main(argv: list[str] | None = None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``); returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # --help, --version, or a one-line argument error
        return int(e.code or 0) if not isinstance(e.code, str) else EXIT_USER_ERROR
    debug = getattr(args, "debug", False) or debug_enabled()

    from .commands import COMMANDS

    def work() -> int:
        from .checks import precheck

        precheck(args)  # files, columns, names: one line, before JAX is imported
        _configure(args)
        return COMMANDS[args.command](args, argv)

    return run_interruptible(work, debug=debug)
