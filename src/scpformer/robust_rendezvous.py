"""The chance-constrained, passively safe rendezvous in LEO (robust ART paper):
one entry point, :func:`solve`.

``solve(instance, config=None, *, method="three_stage", warmstart=None, verify=True)``, the
same signature in every family (``scpformer.pdg6dof``, ``scpformer.rendezvous``,
``scpformer.robust_rendezvous``). Learned warm starts are resolved by name through the
registry of :mod:`scpformer.warmstart`, imported on the first call.
"""

from __future__ import annotations

from typing import Any

from scpformer.problems.robust_rendezvous.api import METHODS
from scpformer.problems.robust_rendezvous.api import solve as _solve
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
from scpformer.scp.solution import Solution


def solve(
    instance: RobustInstance,
    config: RobustSolverConfig | None = None,
    *,
    method: str = "three_stage",
    warmstart: Any = None,
    verify: bool = True,
) -> Solution:
    """Solve ``instance`` (see the family's
    :func:`~scpformer.problems.robust_rendezvous.api.solve` for every detail).

    Parameters
    ----------
    instance
        The problem instance.
    config
        The solver configuration (default: the paper's tables).
    method
        ``"three_stage"`` (the dataset procedure, no warm start) or ``"passive_safety"``
        (passive safety straight from the warm start: PS-CVX, PS-ART).
    warmstart
        ``"passive_safety"`` only: a provider, or a name: ``"tpbvp"`` (default), ``"art"``
        (the pretrained robust ART model); or a ``Solution`` or ``Trajectory``.
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
    "RobustInstance",
    "RobustSampleRanges",
    "RobustScenario",
    "RobustSolverConfig",
    "RobustVerification",
    "sample_instances",
    "solve",
]
