"""File writing shared by the problem families' solution files."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np


def save_npz_atomic(path: str | Path, arrays: dict[str, Any]) -> Path:
    """Write ``arrays`` to the ``.npz`` file ``path`` through a temporary name and a rename.

    A reader never sees a half-written file and an existing file at ``path`` survives a
    failed write (full disk, bad value). Parent folders are created. Returns the path.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp.npz")
    try:
        np.savez(tmp, **arrays)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path
