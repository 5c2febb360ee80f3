"""File writing shared by the problem families' solution files, figures, CSVs and datasets.

Outputs are checked before the work that produces them (:func:`check_output_file`,
:func:`check_output_folder`), so that a solve is not lost to a path that cannot be written,
and written through a temporary name and a rename (:func:`atomic_path`, the one way a file is
written), so that a failed write (full disk) leaves any earlier file at the path untouched.
"""

from __future__ import annotations

import errno
import os
import signal
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

FIGURE_FORMATS = ("png", "pdf", "svg")  # --plot suffixes (matplotlib writes each natively)


def _existing_ancestor(path: Path) -> Path:
    """The nearest folder-or-file that exists among ``path``'s ancestors."""
    parent = path.absolute().parent
    while not parent.exists():
        parent = parent.parent
    return parent


def _check_can_create_in(folder: Path, what: str, path: Path) -> None:
    """Raise ``ValueError`` unless a file can be created in ``folder`` (tried, then removed)."""
    if not folder.is_dir():
        raise ValueError(f"{what} {path}: {folder} is a file, not a folder")
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as err:
        raise ValueError(f"{what} {path}: cannot write in {folder} ({err.strerror})") from None


def check_output_file(path: str | Path, what: str, formats: tuple[str, ...] | None = None) -> Path:
    """``path`` after checking that a file can be written there; nothing is created.

    Parameters
    ----------
    path
        The file to be written later (missing parent folders are created then).
    what
        How the user named it (e.g. ``--out``), for the message.
    formats
        Accepted suffixes without the dot (e.g. :data:`FIGURE_FORMATS`); ``None``: any.

    Raises
    ------
    ValueError
        Naming ``what`` and the path: an existing folder, device, pipe or socket, a parent that
        is a file, a folder without write permission (or on a read-only file system), an
        unknown suffix.
    """
    path = Path(path)
    if formats is not None and path.suffix.lower().lstrip(".") not in formats:
        shown = ", ".join(f".{f}" for f in formats)
        raise ValueError(f"{what} {path}: unknown figure format {path.suffix!r}; use {shown}")
    if path.is_dir():
        raise ValueError(f"{what} {path} is a folder; give a file name")
    if path.exists() and not path.is_file():
        raise ValueError(f"{what} {path} is not a regular file (a device, pipe or socket)")
    if path.exists() and not os.access(path, os.W_OK):
        raise ValueError(f"{what} {path}: the file is not writable")
    parent = path.absolute().parent
    _check_can_create_in(parent if parent.exists() else _existing_ancestor(path), what, path)
    return path


def check_output_folder(path: str | Path, what: str) -> Path:
    """``path`` after checking that it is, or can become, a writable folder; nothing created.

    Raises
    ------
    ValueError
        Naming ``what`` and the path when it is a file, lies under a file, or cannot be
        written.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ValueError(f"{what} {path} is a file, not a folder")
    folder = path if path.is_dir() else _existing_ancestor(path)
    _check_can_create_in(folder, what, path)
    return path


def require_model_path(model: str | Path) -> Path:
    """``--model``: ``model`` as a path after checking that it exists (a run folder or a
    checkpoint file), so that every command words a missing run the same way."""
    path = Path(model)
    if not path.exists():
        raise ValueError(f"--model {path}: no such run folder or checkpoint file")
    return path


@contextmanager
def atomic_path(path: str | Path, suffix: str = "") -> Iterator[Path]:
    """A temporary name beside ``path`` to write to; renamed over ``path`` when the block ends.

    The one way scpformer writes a file: whatever writes it (bytes, text, HDF5, ``torch.save``,
    ``savefig``, an ONNX exporter) writes the yielded temporary path; on a clean exit the file
    is fsynced and renamed over ``path``, so a reader never sees a half-written file and an
    earlier file at ``path`` survives a failed write (full disk, bad value, a check that
    fails inside the block). The temporary file is removed on every way out. A symbolic link
    is written through (its target replaced, the link kept); parent folders are created.

    Parameters
    ----------
    path
        The file to write.
    suffix
        Ending of the temporary name, for writers that choose the format by it (``".png"``).

    Raises
    ------
    OSError
        Naming ``path`` (not the temporary name), e.g. ``ENOSPC``.
    FileExistsError
        When ``path`` is there but is not a regular file (a device, pipe or socket would be
        replaced by the rename).
    """
    path = Path(path)
    if path.is_symlink():
        path = path.resolve()
    if path.exists() and not path.is_file():
        raise FileExistsError(errno.EEXIST, "exists and is not a regular file", str(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp{suffix}")
    with _naming(path, tmp):
        yield tmp
        with tmp.open("rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
        _fsync_folder(path.parent)


def _fsync_folder(folder: Path) -> None:
    """Make a rename in ``folder`` durable; a file system that cannot fsync a folder is fine."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_bytes_atomic(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` through :func:`atomic_path`; returns the path written."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` through :func:`atomic_path`; returns the path."""
    return write_bytes_atomic(path, text.encode())


@contextmanager
def _naming(path: Path, tmp: Path) -> Iterator[None]:
    """Remove ``tmp`` on the way out; an ``OSError`` inside names ``path``, not ``tmp``."""
    try:
        yield
    except OSError as err:
        raise type(err)(err.errno, err.strerror or str(err), str(path)) from None
    finally:
        tmp.unlink(missing_ok=True)


@contextmanager
def interrupts_deferred() -> Iterator[None]:
    """Within the block, SIGINT and SIGTERM wait: they take effect when the block ends.

    For steps that must not be cut in two, like a shard written but not yet listed in the
    manifest. A signal that arrives inside is recorded and raised again once the previous
    handlers are back, so Ctrl-C and ``kill`` still stop the run, only a moment later. Python
    runs signal handlers in the main thread only; elsewhere the block defers nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    kinds = (signal.SIGINT, signal.SIGTERM)
    previous = {
        kind: signal.signal(kind, lambda signum, frame: pending.append(signum)) for kind in kinds
    }
    try:
        yield
    finally:
        for kind, handler in previous.items():
            signal.signal(kind, handler)
        for signum in dict.fromkeys(pending):
            signal.raise_signal(signum)


def save_npz_atomic(path: str | Path, arrays: dict[str, Any]) -> Path:
    """Write ``arrays`` to the ``.npz`` file ``path`` through :func:`atomic_path`.

    A reader never sees a half-written file and an existing file at ``path`` survives a
    failed write (full disk, bad value). Parent folders are created. Returns the path.
    """
    with atomic_path(path, suffix=".npz") as tmp:
        np.savez(tmp, **arrays)
    return Path(path)
