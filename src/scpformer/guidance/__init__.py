"""Closed-loop guidance: the planners of the problem families flown through the truth models.

A layer above the families' public ``solve`` and the warm starts (DESIGN.md layers, below
``experiments``). :mod:`.rendezvous_mpc`: shrinking-horizon model predictive control of the
ISS rendezvous (ART paper, Problem 3) under the navigation, actuation and process errors of
the robust ART paper (Table 2). :mod:`.pdg6dof_mpc`: re-planned free-final-time SCvx of the
6-DoF Mars landing (T-SCvx paper) under thrust, vehicle, navigation and initial-state errors
(its names are used through the module: ``from scpformer.guidance import pdg6dof_mpc``).
:mod:`.robust_rendezvous_mpc`: shrinking-horizon MPC of the chance-constrained, passively
safe rendezvous (robust ART paper), flown through the rendezvous loop's truth flight (used
through the module, like the landing's). :mod:`.campaign`: seeded runs of any of the three
into a folder (``runs.csv`` resumed, one ``run-NNNN.npz`` per run), the engine of
``scpformer simulate``.
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
