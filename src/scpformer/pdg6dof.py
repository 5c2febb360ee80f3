"""The 6-DoF free-final-time Mars powered descent (T-SCvx paper):
one entry point, :func:`solve`.

``solve(instance, config=None, *, method="scvx", warmstart=None, verify=True)``, the
same signature in every family (``scpformer.pdg6dof``, ``scpformer.rendezvous``,
``scpformer.robust_rendezvous``). Importing this module registers the learned warm starts
(:mod:`scpformer.warmstart`), so that their names resolve.
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
