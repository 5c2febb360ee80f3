"""Chance-constrained, passively safe rendezvous in LEO (robust ART paper, Secs. 2 and 4).

Public API (used by the dataset engine):

* :class:`RobustInstance`, :func:`sample_instances` (robust Table 1);
* :func:`~scpformer.problems.robust_rendezvous.api.solve` (``scpformer.robust_rendezvous.solve``:
  the three-stage procedure TPBVP -> collision avoidance -> passive safety, or passive safety
  straight from a warm start; the stage that produced the trajectory is
  ``solution.extras["stage"]``), :func:`solve_tpbvp`, :func:`solve_safety`;
* :func:`trajectory_violations` / :func:`constraint_violation_budget` (Eq. 7);
* :func:`monte_carlo` (verification of the chance constraint).
"""

from scpformer.problems.robust_rendezvous.api import legacy_solve as solve  # deprecated spelling
from scpformer.problems.robust_rendezvous.instance import (
    RobustInstance,
    RobustSampleRanges,
    sample_instances,
)
from scpformer.problems.robust_rendezvous.montecarlo import MonteCarloConfig, monte_carlo
from scpformer.problems.robust_rendezvous.problem import solve_safety, solve_tpbvp
from scpformer.problems.robust_rendezvous.safety import (
    constraint_violation_budget,
    trajectory_violations,
)
from scpformer.problems.robust_rendezvous.scenario import (
    RobustScenario,
    RobustSolverConfig,
    RobustVerification,
)

__all__ = [
    "MonteCarloConfig",
    "RobustInstance",
    "RobustSampleRanges",
    "RobustScenario",
    "RobustSolverConfig",
    "RobustVerification",
    "constraint_violation_budget",
    "monte_carlo",
    "sample_instances",
    "solve",
    "solve_safety",
    "solve_tpbvp",
    "trajectory_violations",
]
