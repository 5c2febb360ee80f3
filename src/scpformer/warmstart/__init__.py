"""Warm starts: every way of producing an initial guess, behind one interface.

``provider.guess(instance) -> WarmStartResult`` (a trajectory and a
:class:`WarmStartRecord`); every SCP entry point accepts a provider. Providers:

* :class:`RendezvousConvexWarmStart` (ART paper Problems 1-2), :class:`RobustTpbvpWarmStart`
  (robust paper CVX), :class:`AnalyticWarmStart` (6-DoF);
* :class:`ArtWarmStart` (ART paper Algorithms 1-2, robust paper Eq. 8 post hoc check with
  fallback to the convex warm start);
* :class:`GivenWarmStart` (a fixed Trajectory / Solution / states) and
  :class:`PrecomputedWarmStart` (a result computed beforehand, e.g. by ``guess_batch``).
"""

from scpformer.warmstart.art import (
    ART_MODES,
    Acceptance,
    AcceptanceCheck,
    ArtRollout,
    ArtWarmStart,
    generate,
)
from scpformer.warmstart.base import (
    GivenWarmStart,
    PrecomputedWarmStart,
    WarmStart,
    WarmStartRecord,
    WarmStartResult,
    as_provider,
)
from scpformer.warmstart.convex import (
    AnalyticWarmStart,
    RendezvousConvexWarmStart,
    RobustTpbvpWarmStart,
)
from scpformer.warmstart.families import ART_FAMILIES, ART_FRAMES

__all__ = [
    "ART_FAMILIES",
    "ART_FRAMES",
    "ART_MODES",
    "Acceptance",
    "AcceptanceCheck",
    "AnalyticWarmStart",
    "ArtRollout",
    "ArtWarmStart",
    "GivenWarmStart",
    "PrecomputedWarmStart",
    "RendezvousConvexWarmStart",
    "RobustTpbvpWarmStart",
    "WarmStart",
    "WarmStartRecord",
    "WarmStartResult",
    "as_provider",
    "generate",
]
