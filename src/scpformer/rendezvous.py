"""The rendezvous with the ISS in relative orbital elements (ART paper):
one entry point, :func:`solve`.

``solve(instance, config=None, *, method="scp", warmstart=None, verify=True)``, the
same signature in every family (``scpformer.pdg6dof``, ``scpformer.rendezvous``,
``scpformer.robust_rendezvous``). Importing this module registers the learned warm starts
(:mod:`scpformer.warmstart`), so that their names resolve.
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
