"""Errors of the dataset engine.

Every error a user can cause (a wrong folder, a corrupt shard, a full disk, a missing optional
package) is a :class:`DatasetError`. It subclasses ``ValueError`` so that the ``scpformer``
command prints it as one ``error:`` line (see :mod:`scpformer.cli.errors`).
"""

from __future__ import annotations

import errno
from collections.abc import Iterator
from contextlib import contextmanager


class DatasetError(ValueError):
    """Bad dataset input or state, with a message that says what to do about it."""


class DiskFullError(DatasetError):
    """The disk filled up while writing; finished shards are kept and the run can resume."""


def is_disk_full(err: BaseException) -> bool:
    """Whether ``err`` reports a full disk (``ENOSPC``/``EDQUOT``, also as h5py words it)."""
    if isinstance(err, OSError) and err.errno in (errno.ENOSPC, errno.EDQUOT):
        return True
    text = str(err)
    return "No space left on device" in text or "errno = 28" in text or "Disk quota" in text


RESUME_HINT = "finished shards are kept: free space and re-run the same command to resume"


@contextmanager
def disk_full_as_error(where: object, then: str) -> Iterator[None]:
    """Within the block, an error that reports a full disk (:func:`is_disk_full`) becomes a
    :class:`DiskFullError` ``"disk full while writing {where}; {then}"``; others pass."""
    try:
        yield
    except OSError as err:
        if is_disk_full(err):
            raise DiskFullError(f"disk full while writing {where}; {then}") from None
        raise


def short_message(err: BaseException) -> str:
    """The first line of ``err``'s message (at most 200 characters), or its class name."""
    return str(err).splitlines()[0][:200] if str(err) else type(err).__name__
