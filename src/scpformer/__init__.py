"""scpformer: sequential convex programming for spacecraft, with learned warm starts."""

from __future__ import annotations

import functools


@functools.cache
def _installed_version() -> str:
    from importlib.metadata import PackageNotFoundError, version  # ~30 ms: only when asked

    try:
        return version("scpformer")
    except PackageNotFoundError:  # running from a source tree without installation
        return "0.0.0+unknown"


def __getattr__(name: str) -> str:
    """``scpformer.__version__``, read from the installed metadata on first use (PEP 562)."""
    if name == "__version__":
        return _installed_version()
    raise AttributeError(f"module 'scpformer' has no attribute {name!r}")
