"""Warm starts: every way of producing an initial guess, behind one interface.

``provider.guess(instance) -> WarmStartResult`` (a trajectory and a
:class:`WarmStartRecord`); every SCP entry point accepts a provider. Providers:

* :class:`RendezvousConvexWarmStart` (ART paper Problems 1-2), :class:`RobustTpbvpWarmStart`
  (robust paper CVX), :class:`AnalyticWarmStart` (6-DoF): the non-learned providers, defined
  beside their families (``scpformer.problems.<family>.warmstart``) and re-exported here;
* :class:`ArtWarmStart` (ART paper Algorithms 1-2, robust paper Eq. 8 post hoc check with
  fallback to the convex warm start);
* :class:`GivenWarmStart` (a fixed Trajectory / Solution / states) and
  :class:`PrecomputedWarmStart` (a result computed beforehand, e.g. by ``guess_batch``).

Importing this package registers the learned names (``"art"``, ``"tscvx"``, ``"kdtree"``,
``"interp"``) with :func:`scpformer.scp.warmstart.register` (:mod:`.registry`).
"""

from typing import Any

from scpformer.scp.warmstart import (
    GivenWarmStart,
    PrecomputedWarmStart,
    WarmStart,
    WarmStartRecord,
    WarmStartResult,
    as_provider,
)
from scpformer.warmstart.art import (
    ART_MODES,
    Acceptance,
    AcceptanceCheck,
    ArtPrefix,
    ArtRollout,
    ArtWarmStart,
    FlownHistory,
    flown_prefix,
    generate,
    preferred_guess,
)
from scpformer.warmstart.families import ART_FAMILIES, ART_FRAMES
from scpformer.warmstart.registry import register_learned

register_learned()

#: the families' own providers, re-exported here and imported on first use (PEP 562): the
#: 6-DoF family's loads numba, which a rendezvous solve does not need
_FAMILY_PROVIDERS = {
    "AnalyticWarmStart": "scpformer.problems.pdg6dof.warmstart",
    "RendezvousConvexWarmStart": "scpformer.problems.rendezvous.warmstart",
    "RobustTpbvpWarmStart": "scpformer.problems.robust_rendezvous.warmstart",
}


def __getattr__(name: str) -> Any:
    if name in _FAMILY_PROVIDERS:
        import importlib

        return getattr(importlib.import_module(_FAMILY_PROVIDERS[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "ART_FAMILIES",
    "ART_FRAMES",
    "ART_MODES",
    "Acceptance",
    "AcceptanceCheck",
    "AnalyticWarmStart",
    "ArtPrefix",
    "ArtRollout",
    "ArtWarmStart",
    "FlownHistory",
    "GivenWarmStart",
    "PrecomputedWarmStart",
    "RendezvousConvexWarmStart",
    "RobustTpbvpWarmStart",
    "WarmStart",
    "WarmStartRecord",
    "WarmStartResult",
    "as_provider",
    "flown_prefix",
    "generate",
    "preferred_guess",
]
