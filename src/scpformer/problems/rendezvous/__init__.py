"""Spacecraft rendezvous with the ISS in relative orbital elements (ART paper, Sec. 4, Table 1).

Problem 1 (two-point boundary value), Problem 2 (convex: waypoint and approach cone) and
Problem 3 (keep-out ellipsoid, solved by the SCP of Section 4), with the fuel cost
``sum |dv|_2``; reward- and constraint-to-go; verification by nonlinear replay.
"""

from scpformer.problems.rendezvous.constraints import constraint_to_go, reward_to_go
from scpformer.problems.rendezvous.instance import (
    RendezvousInstance,
    SampleRanges,
    sample_instances,
)
from scpformer.problems.rendezvous.linear_model import linear_model
from scpformer.problems.rendezvous.problem import solve  # the old spelling, deprecated
from scpformer.problems.rendezvous.scenario import (
    RendezvousScenario,
    RendezvousSolverConfig,
    SCPParameters,
    TargetOrbit,
    VerificationTolerances,
)
from scpformer.problems.rendezvous.verification import verify_solution

__all__ = [
    "RendezvousInstance",
    "RendezvousScenario",
    "RendezvousSolverConfig",
    "SCPParameters",
    "SampleRanges",
    "TargetOrbit",
    "VerificationTolerances",
    "constraint_to_go",
    "linear_model",
    "reward_to_go",
    "sample_instances",
    "solve",
    "verify_solution",
]
