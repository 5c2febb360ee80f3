"""Stage 1 of the robust rendezvous: the convex two-point boundary value problem ("CVX" of
the robust ART paper), the rendezvous family's compiled Problem 1 on this family's dynamics,
and the boundary states in scaled mean ROE."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from scpformer.dynamics.mean_elements import rtn_to_mean_roe
from scpformer.problems.rendezvous.linear_model import LinearModel, linear_model
from scpformer.problems.rendezvous.scp import BOUND_SETTINGS
from scpformer.problems.rendezvous.subproblems import compiled_subproblem
from scpformer.problems.robust_rendezvous.instance import RobustInstance
from scpformer.problems.robust_rendezvous.plan_dynamics import (
    linearize_dynamics,
    target_mean_osc_map,
)
from scpformer.problems.robust_rendezvous.scenario import RobustSolverConfig
from scpformer.scp.conic import ConicSettings
from scpformer.scp.solution import Solution, Status, Timing, Trajectory


@dataclass(frozen=True)
class Boundary:
    """Boundary states of the instance in scaled mean ROE [m]."""

    x_init: np.ndarray  # (6,) Psi(t_0)^-1 x_0,rtn
    x_final: np.ndarray  # (6,) Psi(t_N)^-1 x_f,rtn


def boundary(instance: RobustInstance, model: LinearModel, dynamics: str = "stm") -> Boundary:
    """``x = Psi^{-1} x_rtn`` at both ends (see :mod:`.instance`).

    With the nonlinear dynamics the waypoint is reached in the truth model's OSCULATING
    relative state: ``x_final`` is the mean ROE of the deputy whose osculating RTN state is
    ``x_f`` (:func:`scpformer.dynamics.mean_elements.rtn_to_mean_roe`; it differs from
    ``Psi^{-1} x_f`` by the J2 short-period relative motion, metres at the waypoints' ROE of
    kilometres). The initial state stays the instance's mean ``roe0``, from which the replay
    builds its consistent osculating start.
    """
    x_final = np.linalg.solve(model.Psi[-1], instance.xf_rtn)
    if dynamics != "stm":
        mo = target_mean_osc_map(instance).take(slice(-1, None))
        x_final = model.oe[-1, 0] * rtn_to_mean_roe(mo, instance.xf_rtn[None, :])[0]
    return Boundary(
        x_init=np.linalg.solve(model.Psi[0], np.asarray(instance.x0_rtn)), x_final=x_final
    )


# ======================================================================================
# stage 1: convex TPBVP (the rendezvous family's compiled Problem 1)
# ======================================================================================
TPBVP_DEFECT_M = 1e-4  # nonlinear TPBVP: stop relinearizing below this dynamics defect [m]
TPBVP_MAX_SOLVES = 4  # nonlinear TPBVP: at most this many convex solves


def solve_tpbvp(
    instance: RobustInstance,
    config: RobustSolverConfig | None = None,
    settings: ConicSettings | None = None,
) -> Solution:
    """The convex TPBVP ("CVX" of the paper): lower bound of the cost, no safety constraint.

    With the STM (``config.dynamics = "stm"``) one convex solve. With the nonlinear mean
    dynamics the TPBVP is re-solved about its own solution, the dynamics linearized as
    ``x_{k+1} = Phi_k x_k + Gamma_k u_k + f_k`` (:func:`linearize_dynamics`); the affine terms
    are absorbed by ``x = z + c``, ``c_{k+1} = Phi_k c_k + f_k``, ``c_0 = 0``, so the compiled
    Problem 1 solves for ``z`` with the final state shifted by ``c_N``. Until the defect is
    below ``TPBVP_DEFECT_M`` (two or three solves): the warm start of SCvx* then obeys the plan's
    dynamics (an STM warm start costs SCvx* several iterations to repair its defects).
    ``settings``: conic solver settings other than the defaults (:func:`tpbvp_lower_bound`).
    """
    config = config or RobustSolverConfig()
    start = time.perf_counter()
    model = linear_model(instance)
    bnd = boundary(instance, model, config.dynamics)
    n, solver = instance.n_nodes, config.scvx.solver
    sub = compiled_subproblem("tpbvp", n, max(1, n - 2), solver)
    Phi, Gamma, c = model.Phi, model.Phi @ model.B, np.zeros((n + 1, 6))
    t_setup, t_solver, solves = time.perf_counter() - start, 0.0, 0
    while True:
        sub.set_dynamics(Phi, Gamma, bnd.x_init, bnd.x_final - c[-1])
        sol = sub.solve(solver, settings)
        t_solver, solves = t_solver + sol.solver_time, solves + 1
        if not sol.ok or config.dynamics == "stm" or solves >= TPBVP_MAX_SOLVES:
            break
        x = sol.x + c
        lin = linearize_dynamics(instance, model, x, sol.u, config.dynamics)
        if solves > 1 and float(np.abs(lin.defect).max()) < TPBVP_DEFECT_M:
            break
        Phi, Gamma = lin.Phi, lin.Gamma
        for k in range(n):  # the affine part of the linearized dynamics, a recursion
            c[k + 1] = Phi[k] @ c[k] + lin.f[k]
    if sol.ok:
        x = sol.x + c
        status, traj = Status.CONVERGED, Trajectory(x=x, u=sol.u, p=np.zeros(0))
    else:
        infeasible = sol.status.startswith("infeasible")
        status = Status.INFEASIBLE_INSTANCE if infeasible else Status.SOLVER_FAILED
        traj = None
    timing = Timing(time.perf_counter() - start, t_setup, t_solver, 0.0)
    return Solution(
        status=status,
        trajectory=traj,
        t=model.t,
        cost=sol.cost,
        iterations=solves,
        timing=timing,
        message=f"convex TPBVP: {sol.status}",
        extras={"stage": "tpbvp", "dynamics": config.dynamics},
    )


def tpbvp_lower_bound(
    instance: RobustInstance, config: RobustSolverConfig | None = None
) -> Solution:
    """:func:`solve_tpbvp` to the tight tolerances of
    :data:`scpformer.problems.rendezvous.scp.BOUND_SETTINGS`: ``J_CVX`` as a bound.

    With Clarabel's defaults the TPBVP's cost came out up to 2.5e-4 (relative, median 1.9e-5)
    above this solve's on 20 draws of the sampler (seed 9090), more than the gaps to
    ``J_CVX`` the robust studies measure on many instances.
    """
    return solve_tpbvp(instance, config, BOUND_SETTINGS)
