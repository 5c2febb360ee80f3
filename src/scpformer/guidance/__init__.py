"""Closed-loop guidance: the planners of the problem families flown through the truth models.

A layer above the families' public ``solve`` and the warm starts (DESIGN.md layers, below
``experiments``). :mod:`.rendezvous_mpc`: shrinking-horizon model predictive control of the
ISS rendezvous (ART paper, Problem 3) under the navigation, actuation and process errors of
the robust ART paper (Table 2). :mod:`.campaign`: seeded runs into a folder (``runs.csv``
resumed, one ``run-NNNN.npz`` per run), the engine of ``scpformer simulate``.
"""

from scpformer.guidance.rendezvous_mpc import (
    UNSUPPORTED,
    WARMSTARTS,
    ClosedLoopResult,
    DockingTolerance,
    ErrorModels,
    MPCConfig,
    ReplanRecord,
    fly,
    open_loop_plan,
    remaining_instance,
)

__all__ = [
    "UNSUPPORTED",
    "WARMSTARTS",
    "ClosedLoopResult",
    "DockingTolerance",
    "ErrorModels",
    "MPCConfig",
    "ReplanRecord",
    "fly",
    "open_loop_plan",
    "remaining_instance",
]
