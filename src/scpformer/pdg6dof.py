"""The 6-DoF free-final-time Mars powered descent (T-SCvx paper):
one entry point, :func:`solve` (``method="scvx"`` by default), as in every family (see
:mod:`scpformer`).
"""

from __future__ import annotations

import scpformer.warmstart  # noqa: F401  (registers the learned warm starts by name)
from scpformer.problems.pdg6dof.api import METHODS, solve
from scpformer.problems.pdg6dof.config import PDGSolverConfig, PDGVerificationTolerances
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.sampling import PDGSampleRanges, sample_instances

__all__ = [
    "METHODS",
    "PDGInstance",
    "PDGSampleRanges",
    "PDGSolverConfig",
    "PDGVerificationTolerances",
    "sample_instances",
    "solve",
]
