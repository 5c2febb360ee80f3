"""The rendezvous with the ISS in relative orbital elements (ART paper):
one entry point, :func:`solve`.

``solve(instance, config=None, *, method="scp", warmstart=None, verify=True)``, the
same signature in every family (``scpformer.pdg6dof``, ``scpformer.rendezvous``,
``scpformer.robust_rendezvous``). Learned warm starts are resolved by name through the
registry of :mod:`scpformer.warmstart`, imported on the first call.
"""

from __future__ import annotations

from typing import Any

from scpformer.problems.rendezvous.api import METHODS
from scpformer.problems.rendezvous.api import solve as _solve
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
from scpformer.scp.solution import Solution


def solve(
    instance: RendezvousInstance,
    config: RendezvousSolverConfig | None = None,
    *,
    method: str = "scp",
    warmstart: Any = None,
    verify: bool = True,
) -> Solution:
    """Solve ``instance`` (see the family's
    :func:`~scpformer.problems.rendezvous.api.solve` for every detail).

    Parameters
    ----------
    instance
        The problem instance.
    config
        The solver configuration (default: the paper's tables).
    method
        ``"tpbvp"`` (Problem 1), ``"convex"`` (Problem 2), both from no warm start, or
        ``"scp"`` (Problem 3 by the SCP of Section 4).
    warmstart
        ``"scp"`` only: a provider, or a name: ``"convex"`` (default), ``"tpbvp"``, ``"art"``
        (the pretrained ART model); or a ``Solution``, ``Trajectory`` or ROE states.
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
    "RendezvousInstance",
    "RendezvousScenario",
    "RendezvousSolverConfig",
    "SampleRanges",
    "VerificationTolerances",
    "sample_instances",
    "solve",
]
