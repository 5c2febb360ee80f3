"""Convex-relaxation warm starts of the rendezvous families, and the 6-DoF straight line.

* :class:`RendezvousConvexWarmStart`: Problem 1 (``"tpbvp"``) or Problem 2 (``"convex"``)
  of the ART paper, the CVX warm starts of its Sec. 5;
* :class:`RobustTpbvpWarmStart`: the convex TPBVP of the robust ART paper (its "CVX", the
  warm start of PS-CVX and the lower bound of the cost);
* :class:`AnalyticWarmStart`: the analytic guesses of the 6-DoF problem, the cubic profile
  (the solver's default) and the straight line (Szmuk & Acikmese 2018, Sec. IV).

Each records the cost and the constraint-to-go ``C(t_1)`` of its guess (Eqs. 20-21 of the
ART paper, Eq. 7 of the robust paper), the ``C_CVX(t_1)`` the papers bin their results by.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from scpformer.problems.rendezvous.instance import RendezvousInstance
from scpformer.problems.rendezvous.problem import constraint_to_go, linear_model
from scpformer.problems.rendezvous.problem import solve as solve_rendezvous
from scpformer.problems.rendezvous.scenario import RendezvousSolverConfig
from scpformer.scp.solution import Solution
from scpformer.warmstart.base import WarmStartRecord, WarmStartResult

if TYPE_CHECKING:  # the robust family is imported when used: a rendezvous solve needs none of it
    from scpformer.problems.robust_rendezvous.instance import RobustInstance
    from scpformer.problems.robust_rendezvous.scenario import RobustSolverConfig

RENDEZVOUS_CONVEX = ("tpbvp", "convex")  # the ART paper's Problems 1 and 2


def check_instance(instance: Any, cls: type, family: str) -> None:
    """``ValueError`` naming the family when ``instance`` is not a ``cls``."""
    if not isinstance(instance, cls):
        raise ValueError(
            f"instance must be a {cls.__name__} ({family}), got {type(instance).__name__}"
        )


def _result(source: str, solution: Solution, ctg: float, start: float) -> WarmStartResult:
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
        solution = solve_rendezvous(instance, self.kind, config=self.config, verify=False)
        ctg = math.nan
        if solution.trajectory is not None:
            rtn = linear_model(instance).rtn(solution.trajectory.x)
            ctg = float(constraint_to_go(rtn, instance.scenario)[0])
        return _result(self.kind, solution, ctg, start)


@dataclass(frozen=True)
class RobustTpbvpWarmStart:
    """The convex TPBVP of the robust family; ``C(t_1)`` is its Eq. 7 budget under ``mode``."""

    config: RobustSolverConfig | None = None
    mode: str = "chance"

    def __post_init__(self) -> None:
        from scpformer.problems.robust_rendezvous.scenario import check_mode

        check_mode(self.mode)

    def guess(self, instance: RobustInstance) -> WarmStartResult:
        from scpformer.problems.robust_rendezvous.instance import RobustInstance
        from scpformer.problems.robust_rendezvous.problem import solve_tpbvp
        from scpformer.problems.robust_rendezvous.safety import trajectory_violations

        check_instance(instance, RobustInstance, "robust-rendezvous")
        start = time.perf_counter()
        solution = solve_tpbvp(instance, self.config)
        ctg = math.nan
        if solution.trajectory is not None:
            z = solution.trajectory
            ctg = float(trajectory_violations(instance, z.x, z.u, self.mode)[0])
        return _result("tpbvp", solution, ctg, start)


@dataclass(frozen=True)
class AnalyticWarmStart:
    """An analytic guess of the 6-DoF problem with ``n_nodes`` nodes: ``profile`` is
    ``"straight_line"`` (Szmuk & Acikmese) or ``"cubic_profile"`` (the solver's default), the
    names of :data:`scpformer.problems.pdg6dof.guess.ANALYTIC_GUESSES`."""

    n_nodes: int = 50
    profile: str = "straight_line"

    def __post_init__(self) -> None:
        from scpformer.problems.pdg6dof.guess import ANALYTIC_GUESSES

        if self.profile not in ANALYTIC_GUESSES:
            raise ValueError(
                f"profile must be one of {', '.join(ANALYTIC_GUESSES)}, got {self.profile!r}"
            )

    def guess(self, instance: Any) -> WarmStartResult:
        from scpformer.problems.pdg6dof.guess import ANALYTIC_GUESSES
        from scpformer.problems.pdg6dof.instance import PDGInstance

        check_instance(instance, PDGInstance, "pdg6dof")
        start = time.perf_counter()
        z = ANALYTIC_GUESSES[self.profile](instance, self.n_nodes)
        record = WarmStartRecord(
            source=self.profile,
            time_s=time.perf_counter() - start,
            cost=-float(z.x[-1, 13]),  # C(z) = -m_N (T-SCvx paper, Eq. 2)
            constraint_to_go=math.nan,
        )
        return WarmStartResult(z, record)
