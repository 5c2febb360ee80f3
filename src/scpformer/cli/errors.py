"""The one place where a failure of a ``scpformer`` command becomes a message and exit status.

Every failure ends with exactly one line ``scpformer: error: ...`` on stderr:

============================================  =====================================  ====
failure                                       example                                exit
============================================  =====================================  ====
usage: argparse, ``ValueError`` (also         ``--n-nominal -1``, ``"j2": "false"``,   2
``ArgumentTypeError``, ``DatasetError``)      an unwritable ``--out``, a bad shard
file system: ``OSError``, ``DiskFullError``   a full disk mid-run (names the path)   1
solver (``cvxpy.SolverError``), other bug     a conic solver crash                   1
``KeyboardInterrupt``                         Ctrl-C                                 130
``SIGTERM``                                   ``kill``                               143
============================================  =====================================  ====

``SCPFORMER_DEBUG=1`` re-raises instead, to show the traceback.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import NoReturn

USAGE, FAILURE = 2, 1
INTERRUPTED, TERMINATED = 130, 128 + signal.SIGTERM
_MAX_MESSAGE = 600  # characters of one error line


class Terminated(BaseException):
    """Raised in the main thread by SIGTERM, so that ``finally`` blocks run (workers stop)."""


class OneLineParser(argparse.ArgumentParser):
    """``ArgumentParser`` whose usage errors are one ``scpformer: error:`` line (exit 2)."""

    def error(self, message: str) -> NoReturn:
        self.exit(USAGE, f"scpformer: error: {message} (see {self.prog} --help)\n")


def one_line(text: object) -> str:
    """``text`` on one line (whitespace runs collapsed), cut to a readable length."""
    line = " ".join(str(text).split())
    return line if len(line) <= _MAX_MESSAGE else line[: _MAX_MESSAGE - 3] + "..."


def describe_os_error(err: OSError) -> str:
    """``what: path`` of a file-system error (both paths of a rename)."""
    what = err.strerror or type(err).__name__
    paths = [str(p) for p in (err.filename, err.filename2) if p is not None]
    return f"{what}: {' -> '.join(paths)}" if paths else str(err) or what


def status_and_message(err: BaseException) -> tuple[int, str]:
    """The exit status and message of a failure (see the module docstring)."""
    disk_full = _loaded_class("scpformer.data.errors", "DiskFullError")
    solver_error = _loaded_class("cvxpy.error", "SolverError")
    if isinstance(err, KeyboardInterrupt | Terminated):
        what = "interrupted" if isinstance(err, KeyboardInterrupt) else "terminated (SIGTERM)"
        status = INTERRUPTED if isinstance(err, KeyboardInterrupt) else TERMINATED
        return status, f"{what}; {err}" if str(err) else what
    if isinstance(err, disk_full):
        return FAILURE, str(err)
    if isinstance(err, ValueError):  # argument checks raise ValueError or ArgumentTypeError
        return USAGE, str(err)
    if isinstance(err, OSError):
        return FAILURE, describe_os_error(err)
    if isinstance(err, solver_error):
        return FAILURE, f"the conic solver failed: {err}"
    if isinstance(err, MemoryError):
        return FAILURE, "out of memory"
    return FAILURE, f"internal error ({type(err).__name__}: {err}); SCPFORMER_DEBUG=1 shows where"


def _loaded_class(module: str, name: str) -> type | tuple[()]:
    """Exception class ``module.name`` if that module is loaded, else ``()`` (matches nothing).

    An error of a module that was never imported cannot have been raised, and importing it
    (cvxpy takes a second) only to say so would slow every failing command down.
    """
    loaded = sys.modules.get(module)
    return getattr(loaded, name) if loaded is not None else ()


@contextmanager
def sigterm_raises() -> Iterator[None]:
    """Within the block, SIGTERM raises :class:`Terminated` in the main thread."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: object) -> None:
        raise Terminated

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def run_handler(handler: Callable[[argparse.Namespace], int], args: argparse.Namespace) -> int:
    """Run a command handler; any failure becomes one ``scpformer: error:`` line and a status."""
    try:
        with sigterm_raises():
            return handler(args)
    except (Exception, KeyboardInterrupt, Terminated) as err:
        if os.environ.get("SCPFORMER_DEBUG"):
            raise
        status, message = status_and_message(err)
        print(f"scpformer: error: {one_line(message)}", file=sys.stderr)
        return status


def run_command(parser: argparse.ArgumentParser, argv: list[str] | None) -> int:
    """Parse ``argv`` and run its handler; the exit status is returned, never raised."""
    try:
        args = parser.parse_args(argv)
    except SystemExit as stop:  # usage errors (one line, see OneLineParser), --help, --version
        return stop.code if isinstance(stop.code, int) else 0
    return run_handler(args.handler, args)
