"""Results of an SCP solve: trajectory, status, per-iteration history, timings, verification."""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from enum import Enum
from typing import Any

import numpy as np


class Status(str, Enum):
    """Outcome of a solve. Only ``CONVERGED`` promises a trajectory that is feasible and verified.

    CONVERGED              stopping test met, virtual control and buffers negligible, and the
                           nonlinear propagation of the controls confirms the trajectory
    VERIFICATION_FAILED    the SCP loop converged but the nonlinear propagation disagrees
    MAX_ITERATIONS         the iteration limit was reached first (the paper counts it infeasible)
    INFEASIBLE_INSTANCE    the instance is infeasible before solving (reason in ``message``)
    SOLVER_FAILED          the conic solver failed on a subproblem (reason in ``message``)
    STALLED                the penalty stopped decreasing at an infeasible iterate: a stationary
                           point of the penalized cost (Eq. 16) that keeps virtual control, as
                           SCvx reaches when the instance is infeasible near its start (Mao et
                           al. 2016, Thm. 3); the best iterate is returned
    """

    CONVERGED = "converged"
    VERIFICATION_FAILED = "verification_failed"
    MAX_ITERATIONS = "max_iterations"
    INFEASIBLE_INSTANCE = "infeasible_instance"
    SOLVER_FAILED = "solver_failed"
    STALLED = "stalled"


@dataclass(frozen=True)
class Trajectory:
    """A discrete trajectory: states (N, n_x), controls (N, n_u), parameters (n_p,)."""

    x: np.ndarray
    u: np.ndarray
    p: np.ndarray


@dataclass(frozen=True)
class IterationRecord:
    """One SCP iteration (one conic solve), accepted or rejected."""

    iteration: int  # 1-based count of subproblem solves
    accepted: bool  # step accepted by the ratio test (Alg. 1 step 3)
    cost: float  # C(x, u) of the candidate (e.g. -m_N)
    penalty: float  # nonlinear penalty P of the candidate (defects + nonconvex violations)
    J: float  # penalized nonlinear cost of the candidate, Eq. 12 / 16
    L: float  # linearized penalized cost of the subproblem optimum, Eq. 13
    rho: float  # ratio Delta J / Delta L, Eq. 14 (nan when Delta L = 0)
    trust_radius: float  # eta used for this subproblem
    virtual_control_norm: float  # |nu|_1 + sum of virtual buffers of the subproblem solution
    step_norm: float  # |z* - z_bar|_inf in trust-region-scaled units
    tight_flags: np.ndarray  # bool flags of every (name, node) inequality row at the candidate
    time_discretization: float  # s spent linearizing/discretizing at the candidate
    time_solver: float  # s inside the conic solver
    time_total: float  # s for the whole iteration
    solver_status: str = ""
    polished: bool = False  # accepted, then polished: cost, penalty, J, flags are the polished

    def summary(self) -> dict[str, Any]:
        """The scalar fields (no flag vector), for tables and plots."""
        out = asdict(self)
        out.pop("tight_flags")
        return out


@dataclass(frozen=True)
class Verification:
    """Nonlinear propagation of the solution's controls with an adaptive integrator."""

    passed: bool
    terminal_error: dict[str, float]  # name -> |propagated final - required final|
    max_defect: float  # max over nodes of |propagated state - solution state|_inf
    node_violations: dict[str, float]  # constraint name -> max violation at the nodes (>= 0)
    path_violations: dict[str, float]  # constraint name -> max violation between nodes (>= 0)
    message: str = ""


def verified_status(
    status: Status, message: str, verification: Verification | None
) -> tuple[Status, str]:
    """``CONVERGED`` stands only if the nonlinear verification passed (DESIGN invariant).

    A converged SCP loop whose trajectory fails the independent check becomes
    ``VERIFICATION_FAILED`` with the verification's message; any other status is kept.
    """
    if status is Status.CONVERGED and verification is not None and not verification.passed:
        return Status.VERIFICATION_FAILED, verification.message or message
    return status, message


@dataclass(frozen=True)
class Timing:
    """Wall-time split of a solve, in seconds."""

    total: float
    discretization: float
    solver: float
    verification: float

    @property
    def other(self) -> float:
        """Everything we own besides discretization and the conic solver (excl. verification)."""
        return max(self.total - self.discretization - self.solver - self.verification, 0.0)


@dataclass(frozen=True)
class Solution:
    """A solve's result; it says the truth about itself (DESIGN.md, invariants)."""

    status: Status
    trajectory: Trajectory | None
    t: np.ndarray | None  # (N,) node times
    cost: float
    iterations: int
    history: list[IterationRecord] = field(default_factory=list)
    verification: Verification | None = None
    timing: Timing | None = None
    message: str = ""
    extras: dict[str, Any] = field(default_factory=dict)  # family-specific facts (e.g. stage)

    @property
    def converged(self) -> bool:
        """True only for a verified, feasible, converged trajectory."""
        return self.status is Status.CONVERGED

    def tight_flags(self) -> np.ndarray:
        """Flags of the last accepted iterate (all False when there is none)."""
        accepted = [rec for rec in self.history if rec.accepted]
        if not accepted:
            return np.zeros(0, dtype=bool)
        return accepted[-1].tight_flags


def finished_solution(
    problem: Any,
    z: Trajectory,
    cost: float,
    status: Status,
    message: str,
    history: list[IterationRecord],
    *,
    start: float,
    discretization: float,
    solver: float,
    merit: str,
) -> Solution:
    """The :class:`Solution` of an SCP loop that stopped at ``z`` with ``status``.

    ``z`` is verified by ``problem.verify`` (timed), :func:`verified_status` decides the
    status, and a run stopped at the iteration cap says so with ``merit`` (its last penalty or
    constraint violation, e.g. ``"penalty 0.1"``). ``start`` is the loop's
    ``time.perf_counter()`` at its start; ``discretization`` and ``solver`` its seconds in
    each.
    """
    t_verify = time.perf_counter()
    verification = problem.verify(z)
    t_verify = time.perf_counter() - t_verify
    status, message = verified_status(status, message, verification)
    if status is Status.MAX_ITERATIONS:
        message = f"no convergence in {len(history)} iterations ({merit})"
    timing = Timing(
        total=time.perf_counter() - start,
        discretization=discretization,
        solver=solver,
        verification=t_verify,
    )
    return Solution(
        status=status,
        trajectory=z,
        t=problem.node_times(z),
        cost=cost,
        iterations=len(history),
        history=history,
        verification=verification,
        timing=timing,
        message=message,
    )
