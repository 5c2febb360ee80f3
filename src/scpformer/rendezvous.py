"""The rendezvous with the ISS in relative orbital elements (ART paper):
one entry point, :func:`solve` (``method="scp"`` by default), as in every family (see
:mod:`scpformer`).
"""

from __future__ import annotations

import scpformer.warmstart  # noqa: F401  (registers the learned warm starts by name)
from scpformer.problems.rendezvous.api import METHODS, solve
from scpformer.problems.rendezvous.instance import (
    RendezvousInstance,
    SampleRanges,
    sample_instances,
)
from scpformer.problems.rendezvous.scenario import (
    RendezvousScenario,
    RendezvousSolverConfig,
    VerificationTolerances,
)

__all__ = [
    "METHODS",
    "RendezvousInstance",
    "RendezvousScenario",
    "RendezvousSolverConfig",
    "SampleRanges",
    "VerificationTolerances",
    "sample_instances",
    "solve",
]
