"""On-disk cache of expensive, deterministic build products (compiled convex subproblems).

Files live in ``$SCPFORMER_CACHE_DIR`` (default ``~/.cache/scpformer``); setting it to an
empty string disables the cache. A file's name carries a digest of the package version, the
cvxpy version and the source of the module that builds the object, so any code change misses
the cache instead of loading a stale object. Only files this module wrote are read (pickle),
written atomically (temporary name, then rename); an unreadable file is rebuilt and replaced.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import cvxpy as cp

from scpformer import __version__

T = TypeVar("T")


def cache_dir() -> Path | None:
    """The cache folder, or ``None`` when caching is disabled."""
    configured = os.environ.get("SCPFORMER_CACHE_DIR")
    if configured == "":
        return None
    return Path(configured) if configured else Path.home() / ".cache" / "scpformer"


def _digest(source: str | None) -> str:
    text = f"{__version__}|{cp.__version__}|"
    if source is not None:
        text += Path(source).read_text()
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def cached_pickle(key: str, build: Callable[[], T], source: str | None = None) -> T:
    """Load ``key`` from the cache, or ``build()`` it and store it.

    Parameters
    ----------
    key
        A file-name-safe description of what is built.
    build
        Deterministic constructor of the object.
    source
        Path of the module whose code defines the object; its text is part of the digest.
    """
    folder = cache_dir()
    if folder is None:
        return build()
    path = folder / f"{key}-{_digest(source)}.pkl"
    try:
        with path.open("rb") as fh:
            return pickle.load(fh)
    except FileNotFoundError:
        pass
    except Exception:  # a corrupt or incompatible file: rebuild and replace it
        path.unlink(missing_ok=True)
    obj = build()
    tmp: Path | None = None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=folder, delete=False, suffix=".tmp") as fh:
            tmp = Path(fh.name)
            pickle.dump(obj, fh, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(tmp, path)
    except OSError:  # a read-only or full disk only costs the next process a rebuild
        if tmp is not None:
            tmp.unlink(missing_ok=True)
    return obj
