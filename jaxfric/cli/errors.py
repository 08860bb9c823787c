"""How the command line fails and stops: one-line user errors, clean Ctrl-C.

Users see ``jaxfric: error: <what is wrong>`` on stderr and a non-zero exit status,
never a traceback, for anything they can fix on the command line (a missing file, an
unknown column, a bad number, an unknown model). ``--debug`` (or the environment
variable ``JAXFRIC_DEBUG=1``) re-raises instead, for bug reports.

Ctrl-C: a jitted XLA computation does not return to the Python interpreter until it
has finished, so a ``KeyboardInterrupt`` raised in the thread that runs it would wait
for the whole optimisation. The work therefore runs in a worker thread while the main
thread waits in short slices; Ctrl-C reaches the main thread at once, which says what
was kept ([`Kept`][jaxfric.cli.errors.Kept]), removes temporaries of unfinished writes and exits with 130.
"""

from __future__ import annotations

import os
import sys
import threading
from pathlib import Path
from typing import Callable

EXIT_USER_ERROR = 2
EXIT_INTERRUPTED = 130


class UserError(Exception):
    """A problem the user can fix on the command line; shown as one line, no traceback."""


class Kept:
    """What a command has written so far (for the Ctrl-C message), thread-safe.

    Writers call [`add`][jaxfric.cli.errors.Kept.add] once a file is complete (atomically moved into place)
    and [`watch`][jaxfric.cli.errors.Kept.watch] on the folders they write to, so that an interrupt can remove
    the temporaries of a write that was cut short (see [`jaxfric.report.remove_temporaries`][jaxfric.report.remove_temporaries]).
    """

    def __init__(self):
        self._lock = threading.Lock()
        self.files: list[Path] = []
        self.folders: list[Path] = []
        self.otherwise = "nothing was written"  # said when no file was recorded

    def add(self, path) -> None:
        with self._lock:
            if Path(path) not in self.files:  # a file rewritten (e.g. a fit saved again) counts once
                self.files.append(Path(path))

    def watch(self, folder) -> None:
        with self._lock:
            self.folders.append(Path(folder))

    def remove_temps(self) -> None:
        from jaxfric.report import remove_temporaries

        with self._lock:
            folders = list(self.folders)
        for folder in folders:
            remove_temporaries(folder)

    def describe(self) -> str:
        with self._lock:
            files = list(self.files)
        if not files:
            return self.otherwise
        folders = sorted({str(p.parent) for p in files})
        names = ", ".join(p.name for p in files[:6]) + (f" and {len(files) - 6} more" if len(files) > 6 else "")
        where = folders[0] if len(folders) == 1 else ", ".join(folders)
        return f"kept {len(files)} finished file(s) in {where}: {names}"


KEPT = Kept()
"""The running command's record (one command per process)."""


def debug_enabled() -> bool:
    return os.environ.get("JAXFRIC_DEBUG", "").strip() not in ("", "0", "false", "no")


def error_line(message: str) -> str:
    """``jaxfric: error: <message>`` on one line (newlines in library messages folded)."""
    text = " ".join(str(message).split())
    return f"jaxfric: error: {text}"


def print_error(message: str) -> None:
    print(error_line(message), file=sys.stderr, flush=True)


def print_warning(message: str) -> None:
    """``jaxfric: warning: <message>`` on stderr (said also under ``--quiet``)."""
    print(f"jaxfric: warning: {message}", file=sys.stderr, flush=True)


def run_interruptible(work: Callable[[], int], *, debug: bool = False) -> int:
    """Run ``work()`` in a worker thread; map errors and Ctrl-C to exit statuses.

    Returns ``work``'s status, [`EXIT_USER_ERROR`][jaxfric.cli.errors.EXIT_USER_ERROR] after a [`UserError`][jaxfric.cli.UserError]
    (or a ``ValueError``/``OSError`` from the library's input checks), and does not
    return on Ctrl-C: it prints what was kept and ends the process with 130 (the
    worker may be inside XLA and cannot be stopped politely).
    """
    outcome: dict = {}

    def target():
        try:
            outcome["status"] = work()
        except BaseException as exc:  # handed to the main thread below
            outcome["error"] = exc

    worker = threading.Thread(target=target, name="jaxfric-cli", daemon=True)
    try:
        worker.start()
        while worker.is_alive():
            worker.join(0.1)
    except KeyboardInterrupt:
        interrupted()
    exc = outcome.get("error")
    if exc is None:
        status = outcome.get("status", 0)
        return 0 if status is None else int(status)
    if isinstance(exc, KeyboardInterrupt):
        interrupted()
    if debug:
        raise exc
    if isinstance(exc, (UserError, ValueError, FileNotFoundError, IsADirectoryError, PermissionError)):
        print_error(_message(exc))
        return EXIT_USER_ERROR
    if isinstance(exc, OSError):
        print_error(f"{exc.strerror or exc}: {exc.filename}" if exc.filename else str(exc))
        return 1
    if isinstance(exc, SystemExit):
        return int(exc.code or 0) if not isinstance(exc.code, str) else 1
    # A bug, not a user error: still one line, with a hint to get the traceback.
    print_error(f"unexpected {type(exc).__name__}: {exc} (run with --debug for the traceback)")
    return 1


def _message(exc: BaseException) -> str:
    if isinstance(exc, FileNotFoundError) and exc.filename:
        return f"file not found: {exc.filename}"
    if isinstance(exc, (IsADirectoryError, PermissionError)) and exc.filename:
        return f"{exc.strerror}: {exc.filename}"
    return str(exc)


def interrupted() -> None:
    """Report what was kept and end the process with status 130."""
    KEPT.remove_temps()
    print(f"\njaxfric: interrupted; {KEPT.describe()}", file=sys.stderr, flush=True)
    sys.stdout.flush()
    os._exit(EXIT_INTERRUPTED)


# ------------------------------------------------- helpers of every command
def _say(args):
    def say(msg: str) -> None:
        if not args.quiet:
            print(f"jaxfric: {msg}", file=sys.stderr, flush=True)

    return say


def _prepare_out(path: str) -> Path:
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise UserError(f"--out {path} exists and is not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise UserError(f"cannot create the report folder {path}: {e.strerror}") from None
    if not os.access(out, os.W_OK):
        raise UserError(f"the report folder {path} is not writable")
    KEPT.watch(out)
    return out
