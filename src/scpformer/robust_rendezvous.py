"""The chance-constrained, passively safe rendezvous in LEO (robust ART paper):
one entry point, :func:`solve`.

``solve(instance, config=None, *, method="three_stage", warmstart=None, verify=True)``, the
same signature in every family (``scpformer.pdg6dof``, ``scpformer.rendezvous``,
``scpformer.robust_rendezvous``). Importing this module registers the learned warm starts
(:mod:`scpformer.warmstart`), so that their names resolve.
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
