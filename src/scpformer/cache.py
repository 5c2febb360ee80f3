"""On-disk cache of expensive, deterministic build products (compiled convex subproblems).

Files live in ``$SCPFORMER_CACHE_DIR`` (default ``~/.cache/scpformer``); setting it to an
empty string disables the cache. A file's name carries a digest of the package version, the
cvxpy version and the source of the module that builds the object, so any code change misses
the cache instead of loading a stale object. Only files this module wrote are read (pickle),
written atomically (temporary name, then rename) inside an envelope ``(magic, key, object)``;
an unreadable file, or one that unpickles to anything else, is a miss: rebuilt and replaced.
A cache folder that cannot be used (a file, read-only) only costs rebuilding; when
``$SCPFORMER_CACHE_DIR`` names a file (or lies under one), one warning line says so on stderr,
once per process.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import pickle
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import cvxpy as cp

from scpformer import __version__
from scpformer.files import atomic_path

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
    if folder is None or not _usable(folder):
        return build()
    path = folder / f"{key}-{_digest(source)}-{_MAGIC}.pkl"  # never read by older versions
    found = _load(path, key)
    if found is not _MISS:
        return found
    obj = build()
    _store(folder, path, key, obj)
    return obj


_MISS = object()
_warned: set[Path] = set()  # cache folders already reported unusable by this process


def _usable(folder: Path) -> bool:
    """Whether ``folder`` is, or can become, a folder: not a file, nor under one.

    An unusable folder is reported once per process by one warning line on stderr (each
    subproblem is then rebuilt on every run instead of loaded).
    """
    existing = next((p for p in (folder, *folder.parents) if p.exists()), None)
    if existing is None or existing.is_dir():
        return True
    if folder not in _warned:
        _warned.add(folder)
        where = "is a file" if existing == folder else f"lies under the file {existing}"
        print(
            f"scpformer: warning: the cache folder {folder} (SCPFORMER_CACHE_DIR) {where}, "
            "not a folder: nothing is cached (compiled subproblems are rebuilt every run)",
            file=sys.stderr,
            flush=True,
        )
    return False


_MAGIC = "scpformer-cache-1"  # first item of every entry's envelope (magic, key, object)


def _load(path: Path, key: str) -> Any:
    """The cached object, or ``_MISS``: absent, unreadable, foreign or for another key.

    A bad entry (truncated, written by something else, unpickling to another object) is
    removed so that it is rebuilt once; a cache folder that is a file is simply a miss.
    """
    try:
        with path.open("rb") as fh:
            envelope = pickle.load(fh)
    except FileNotFoundError:
        return _MISS
    except NotADirectoryError:  # SCPFORMER_CACHE_DIR (or a parent) names a file
        return _MISS
    except Exception:  # a corrupt or incompatible file: rebuild and replace it
        _discard(path)
        return _MISS
    if not (isinstance(envelope, tuple) and len(envelope) == 3 and envelope[:2] == (_MAGIC, key)):
        _discard(path)
        return _MISS
    return envelope[2]


def _discard(path: Path) -> None:
    with contextlib.suppress(OSError):
        path.unlink(missing_ok=True)


def _store(folder: Path, path: Path, key: str, obj: Any) -> None:
    """Write the entry atomically; any file-system failure only costs a later rebuild."""
    # a read-only or full disk, a cache folder that is a file: nothing stored
    with contextlib.suppress(OSError), atomic_path(path) as tmp, tmp.open("wb") as fh:
        pickle.dump((_MAGIC, key, obj), fh, protocol=pickle.HIGHEST_PROTOCOL)
