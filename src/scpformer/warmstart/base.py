"""The warm-start interface moved to :mod:`scpformer.scp.warmstart`; this module forwards the
old imports (``from scpformer.warmstart.base import WarmStartResult``) for one release, each
with a ``DeprecationWarning`` naming the new home."""

import warnings
from typing import Any

from scpformer.scp import warmstart as _interface


def __getattr__(name: str) -> Any:
    value = getattr(_interface, name)  # AttributeError for a name the interface never had
    warnings.warn(
        f"scpformer.warmstart.base.{name} is deprecated: import it from scpformer.scp.warmstart",
        DeprecationWarning,
        stacklevel=2,
    )
    return value
