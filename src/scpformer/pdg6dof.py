"""The 6-DoF free-final-time Mars powered descent (T-SCvx paper):
one entry point, :func:`solve`.

``solve(instance, config=None, *, method="scvx", warmstart=None, verify=True)``, the
same signature in every family (``scpformer.pdg6dof``, ``scpformer.rendezvous``,
``scpformer.robust_rendezvous``). Learned warm starts are resolved by name through the
registry of :mod:`scpformer.warmstart`, imported on the first call.
"""

from __future__ import annotations

from typing import Any

from scpformer.problems.pdg6dof.api import METHODS
from scpformer.problems.pdg6dof.api import solve as _solve
from scpformer.problems.pdg6dof.config import PDGSolverConfig, PDGVerificationTolerances
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.sampling import PDGSampleRanges, sample_instances
from scpformer.scp.solution import Solution


def solve(
    instance: PDGInstance,
    config: PDGSolverConfig | None = None,
    *,
    method: str = "scvx",
    warmstart: Any = None,
    verify: bool = True,
) -> Solution:
    """Solve ``instance`` (see the family's
    :func:`~scpformer.problems.pdg6dof.api.solve` for every detail).

    Parameters
    ----------
    instance
        The problem instance.
    config
        The solver configuration (default: the paper's tables).
    method
        ``"scvx"`` (SCvx, Algorithm 1) or ``"tscvx"`` (T-SCvx, Algorithm 2: its predictor is
        the warm start's, the pretrained networks by default).
    warmstart
        A provider, or a name: ``"cubic_profile"`` (default of SCvx), ``"straight_line"``,
        ``"tscvx"`` (default of T-SCvx), ``"kdtree"``, ``"interp"``; or a ``Trajectory``.
    verify
        Check the result in the nonlinear model; ``False`` leaves ``verification`` None.

    Raises
    ------
    ValueError
        An unknown method or warm start, or a warm start the method cannot use.
    """
    import scpformer.warmstart  # noqa: F401  (registers the learned warm-start names)

    return _solve(instance, config, method=method, warmstart=warmstart, verify=verify)


__all__ = [
    "METHODS",
    "PDGInstance",
    "PDGSampleRanges",
    "PDGSolverConfig",
    "PDGVerificationTolerances",
    "sample_instances",
    "solve",
]
