"""The convex warm start of the robust rendezvous: the TPBVP (the robust ART paper's "CVX",
the warm start of PS-CVX and the lower bound of the cost), with the Eq. 7 constraint-to-go
``C(t_1)`` of its guess, the ``C_CVX(t_1)`` the paper bins its results by."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

from scpformer.problems.rendezvous.warmstart import convex_result
from scpformer.problems.robust_rendezvous.instance import RobustInstance
from scpformer.problems.robust_rendezvous.safety import trajectory_violations
from scpformer.problems.robust_rendezvous.scenario import RobustSolverConfig, check_mode
from scpformer.problems.robust_rendezvous.tpbvp import solve_tpbvp
from scpformer.scp.solution import Solution
from scpformer.scp.warmstart import WarmStartResult, check_instance


@dataclass(frozen=True)
class RobustTpbvpWarmStart:
    """The convex TPBVP of the robust family; ``C(t_1)`` is its Eq. 7 budget under ``mode``
    (default: the configuration's, ``"chance"`` without one)."""

    config: RobustSolverConfig | None = None
    mode: str | None = None

    def __post_init__(self) -> None:
        config = self.config or RobustSolverConfig()
        mode = self.mode if self.mode is not None else config.safety_mode
        object.__setattr__(self, "mode", check_mode(mode))

    def guess(self, instance: RobustInstance) -> WarmStartResult:
        check_instance(instance, RobustInstance, "robust-rendezvous")
        start = time.perf_counter()
        solution = solve_tpbvp(instance, self.config)
        ctg = initial_budget(instance, solution, self.mode)
        return convex_result("tpbvp", solution, ctg, start)


def initial_budget(instance: RobustInstance, solution: Solution, mode: str) -> float:
    """``C(t_1)`` of ``solution``'s trajectory: its Eq. 7 constraint-violation budget under
    ``mode`` (``chance`` or ``deterministic``), NaN without a trajectory."""
    if solution.trajectory is None:
        return math.nan
    z = solution.trajectory
    return float(trajectory_violations(instance, z.x, z.u, check_mode(mode))[0])
