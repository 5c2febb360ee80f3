"""The convex warm starts of the rendezvous: Problem 1 (``"tpbvp"``) or Problem 2
(``"convex"``) of the ART paper, the CVX warm starts of its Sec. 5.

Each records the cost and the constraint-to-go ``C(t_1)`` of its guess (Eqs. 20-21), the
``C_CVX(t_1)`` the paper bins its results by.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

from scpformer.problems.rendezvous.constraints import constraint_to_go
from scpformer.problems.rendezvous.instance import RendezvousInstance
from scpformer.problems.rendezvous.linear_model import linear_model
from scpformer.problems.rendezvous.scenario import RendezvousSolverConfig
from scpformer.problems.rendezvous.scp import solve_convex
from scpformer.scp.solution import Solution
from scpformer.scp.warmstart import WarmStartRecord, WarmStartResult, check_instance

RENDEZVOUS_CONVEX = ("tpbvp", "convex")  # the ART paper's Problems 1 and 2


def convex_result(source: str, solution: Solution, ctg: float, start: float) -> WarmStartResult:
    """The result of a convex warm start whose solve is ``solution`` and whose guess has the
    constraint-to-go ``ctg``; ``start`` is when the guess began (``time.perf_counter``)."""
    ok = solution.trajectory is not None
    record = WarmStartRecord(
        source=source,
        time_s=time.perf_counter() - start,
        cost=solution.cost if ok else math.nan,
        constraint_to_go=ctg,
        accepted=ok,
        reason="" if ok else solution.message,
    )
    return WarmStartResult(solution.trajectory, record, solution)


@dataclass(frozen=True)
class RendezvousConvexWarmStart:
    """Problem 1 (``kind="tpbvp"``) or Problem 2 (``kind="convex"``) of the ART paper."""

    kind: str = "convex"
    config: RendezvousSolverConfig | None = None

    def __post_init__(self) -> None:
        if self.kind not in RENDEZVOUS_CONVEX:
            raise ValueError(f"kind must be one of {RENDEZVOUS_CONVEX}, got {self.kind!r}")

    def guess(self, instance: RendezvousInstance) -> WarmStartResult:
        check_instance(instance, RendezvousInstance, "rendezvous")
        start = time.perf_counter()
        config = self.config or RendezvousSolverConfig()
        solution = solve_convex(instance, self.kind, config, verify=False)
        ctg = initial_constraint_to_go(instance, solution)
        return convex_result(self.kind, solution, ctg, start)


def initial_constraint_to_go(instance: RendezvousInstance, solution: Solution) -> float:
    """``C(t_1)`` of ``solution``'s trajectory (the ART paper's constraint-to-go at the first
    node, Eq. 5), NaN without a trajectory."""
    if solution.trajectory is None:
        return math.nan
    rtn = linear_model(instance).rtn(solution.trajectory.x)
    return float(constraint_to_go(rtn, instance.scenario)[0])
