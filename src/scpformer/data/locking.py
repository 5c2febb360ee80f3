"""One writer per dataset folder: an exclusive ``flock`` on ``DIR/.lock`` while writing."""

from __future__ import annotations

import fcntl
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from scpformer.data.errors import DatasetError

LOCK_NAME = ".lock"


@contextmanager
def locked_folder(folder: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``folder/.lock`` while writing a dataset into ``folder``.

    Raises
    ------
    DatasetError
        When another process holds it (two runs writing one folder).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    with (folder / LOCK_NAME).open("a") as fh:
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise DatasetError(
                f"{folder} is being written by another scpformer run (it holds "
                f"{folder / LOCK_NAME}); wait for it to finish or choose another folder"
            ) from None
        try:
            yield
        finally:
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
