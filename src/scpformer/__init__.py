"""scpformer: sequential convex programming for spacecraft, with learned warm starts.

Each problem family is one module (:data:`FAMILIES`) with one entry point,
``solve(instance, config=None, *, method=..., warmstart=None, verify=True)``: the same
signature in every family (``scpformer.pdg6dof``, ``scpformer.rendezvous``,
``scpformer.robust_rendezvous``), only the default ``method`` differs. Importing a family
module registers the learned warm starts (:mod:`scpformer.warmstart`), so that their names
resolve.
"""

from __future__ import annotations

import functools
from typing import Any


@functools.cache
def _installed_version() -> str:
    from importlib.metadata import PackageNotFoundError, version  # ~30 ms: only when asked

    try:
        return version("scpformer")
    except PackageNotFoundError:  # running from a source tree without installation
        return "0.0.0+unknown"


#: the public entry points, one module per problem family, each with ``solve``
FAMILIES = ("pdg6dof", "rendezvous", "robust_rendezvous")


def __getattr__(name: str) -> Any:
    """``scpformer.__version__`` (read from the installed metadata) and the family modules
    ``scpformer.pdg6dof``, ``scpformer.rendezvous``, ``scpformer.robust_rendezvous``,
    imported on first use (PEP 562), so that ``import scpformer`` stays light."""
    if name == "__version__":
        return _installed_version()
    if name in FAMILIES:
        import importlib

        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module 'scpformer' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), "__version__", *FAMILIES})
