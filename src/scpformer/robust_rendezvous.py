"""The chance-constrained, passively safe rendezvous in LEO (robust ART paper):
one entry point, :func:`solve` (``method="three_stage"`` by default), as in every family
(see :mod:`scpformer`).
"""

from __future__ import annotations

import scpformer.warmstart  # noqa: F401  (registers the learned warm starts by name)
from scpformer.problems.robust_rendezvous.api import METHODS, solve
from scpformer.problems.robust_rendezvous.instance import (
    RobustInstance,
    RobustSampleRanges,
    sample_instances,
)
from scpformer.problems.robust_rendezvous.scenario import (
    RobustScenario,
    RobustSolverConfig,
    RobustVerification,
)

__all__ = [
    "METHODS",
    "RobustInstance",
    "RobustSampleRanges",
    "RobustScenario",
    "RobustSolverConfig",
    "RobustVerification",
    "sample_instances",
    "solve",
]
