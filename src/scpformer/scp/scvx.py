"""SCvx (Mao, Szmuk & Acikmese 2016; Algorithm 1 of the T-SCvx paper) for any problem family.

The algorithm object is stateless: parameters live in :class:`SCvxParameters`, the iterate and
trust radius in local variables of :func:`solve_scvx`, and everything that happened in the
returned history. A problem family plugs in through :class:`ConvexifiedProblem`.

Per iteration (Alg. 1): solve the subproblem about ``z_bar`` with radius ``eta`` (step 1);
``Delta J = J(z_bar) - J(z*)`` (Eq. 12) and ``Delta L = J(z_bar) - L(z*)`` (Eq. 13);
``rho = Delta J / Delta L`` (Eq. 14); reject and shrink if ``rho < rho_0``, else accept and
update ``eta`` by Eq. 15, clipped to ``[eta_lb, eta_ub]``.

Stopping test (``stopping = "stationary"``, the default): an accepted step whose predicted
decrease ``Delta L`` is below ``eps_opt max(1, |J|)`` while the trust radius is at least
``eta_stationary`` -- the convexified problem, given room to move, finds no descent, so the
iterate is a first-order stationary point of Eq. 16 up to that tolerance. A step made short by
a small radius (or by a proximal weight) proves nothing and does not stop the loop; a run that
never meets the test ends at ``iter_max`` as ``MAX_ITERATIONS`` and returns its last accepted
(lowest ``J``) iterate. The test certifies the iterate the subproblem is built about, so it is
read off the first solve of every iteration: when it holds about a feasible ``z_bar`` the loop
ends there, returning the candidate if the ratio test accepts it and ``z_bar`` otherwise,
without the second-order correction the candidate's defects would call for (measured on 12
nominal instances, numpy seed 0, and 12 of ``generate pdg6dof``'s, seed 99: one solve fewer
in most runs, cold and T-SCvx alike). ``stopping = "table1"`` is Table 1's test read as in
SCPToolbox.jl:
``|z* - z_bar|_inf <= eps_abs`` or ``|Delta J| <= eps_rel |J(z_bar)|``. Either way the nonlinear
penalty must be below ``feas_tol``, and, because a loop can meet the test with virtual control
stuck on an unreachable state, the virtual control and buffers of the subproblem
(``virtual_tol``) and the nonlinear defects (``defect_tol``) must be negligible; the problem's
nonlinear verification then decides ``Status.CONVERGED``. ``defect_tol = 2e-5`` because
per-interval defects add up along the horizon: 1e-4 over 49 intervals becomes ~5e-3 of
terminal position error in the single-shooting verification.

Stall test (``stall_window``, not in the paper): SCvx converges to stationary points of the
penalized cost, and from a start in whose neighbourhood the instance is infeasible that point
keeps virtual control (Mao et al. 2016, Thm. 3); the loop then creeps with tiny steps until
``iter_max``. A run whose accepted iterates keep a penalty above ``stall_penalty`` that fell by
less than ``stall_decrease`` (relative) over the last ``stall_window`` accepted iterations stops
as ``Status.STALLED``. Measured on 10 instances of ``generate pdg6dof``'s distribution that
end at ``iter_max`` (most of them out of propellant: the final mass at ``m_dry``), the penalty
is flat to two digits from iteration 15-25 on; on 12 instances that converge slowly (75-94
solves) it falls by 5-15% per 10 accepted iterations all the way. ``stall_window = 0`` turns
the test off. The 6-DoF family runs its default start's first run with a looser
``stall_decrease`` and restarts it with a longer final time
(:func:`scpformer.problems.pdg6dof.problem.solve_with_restart`).

Second-order correction (``second_order_correction``, not in the paper): when the defects of a
candidate push its ratio below ``rho_1`` the problem family corrects the candidate
(``solve_correction``, :func:`_wants_correction`): the 6-DoF family first tries a least-change
correction without a conic solve (:mod:`scpformer.problems.pdg6dof.correction`), else solves
the subproblem once more aiming at the nonlinear flow at the candidate. ``iter_max`` counts
every record of the history: conic solves and corrections.

Polish (``polish``, not in the paper): near a 6-DoF optimum the cost is flat along the thrust
of bang-bang arcs, so the subproblem moves the thrust of a few nodes by a sizable part of its
trust-region scale at every iteration while the cost changes by 1e-4. Each such step leaves
O(step^2) defects; the ratio test accepts it, and the penalty of the accepted iterates then
falls by a factor of only about 2 per iteration, while the stopping test waits for negligible
defects. A problem family that provides ``polish(candidate, evaluation)`` has every accepted
candidate of that tail -- its penalty at most ``polish_penalty``, its defects not negligible,
its virtual control negligible -- moved onto the nonlinear flow without a conic solve (the
6-DoF family: chord steps of its least-change correction), and the polished iterate replaces
the candidate when its ``J`` is lower. It adds no record to the history: the accepted step's
record then holds the polished iterate's cost, penalty, J and tight flags, and ``polished``
(its L, ratio and step norm stay those of the conic solve). Above the tail the
correction is large and mostly breaks a convex row that was not tight (thrust or gimbal; 82 of
97 attempts on the bench's 20 nominal instances, seed 0, at no threshold), so it is not tried
there: with ``polish_penalty = 1e-2``, 14 of 16 attempts succeed, and the conic solver's share
of the run stays at 71.5% (66.9% without the threshold). Measured in the README ("Polishing
accepted steps").

Defaults that differ from Table 1, measured on the 6-DoF problem (README, "A soft trust
region"): ``lambda_ = 2`` instead of 500, and ``iter_max = 100`` instead of 20 (a safeguard: a
converged 6-DoF run needs a median of 9 conic solves, p95 11, on the bench's nominal instances
of seed 0; harder instances of Table 2's ranges need more). The L1 penalty of Eq.
16 is exact once lambda exceeds the largest multiplier of the linearized dynamics; with the
cost ``-m_N`` the final mass row's multiplier is 1 (measured at a converged nominal solution:
the largest |y| is 1.00003), so 2 keeps a factor of two of margin and the virtual control still
vanishes at convergence. A larger weight charges the O(step^2) defects of every step far above
what they cost the Lagrangian, so the ratio test rejects good steps and the cost creeps: on the
bench's 20 nominal instances (seed 0, the same code run twice) lambda = 10 needed a median of
51.5 solves (p95 73) and stopped a median of 0.18% (max 0.46%) of the propellant above the
reference optimum, lambda = 2 31 solves (p95 40) and 0.12% (max 0.26%); at 500 the cost creeps
for hundreds of iterations. Algorithm 1 with Table 1 is ``lambda_=500, iter_max=20,
second_order_correction=False, polish=False, stopping="table1"`` with a hard trust region.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from scpformer.scp.conic import check_solver
from scpformer.scp.solution import (
    IterationRecord,
    Solution,
    Status,
    Trajectory,
    Verification,
    finished_solution,
)
from scpformer.validation import check_in_range, check_int, check_positive

STOPPING_TESTS = ("stationary", "table1")


@dataclass(frozen=True, kw_only=True)
class SCvxParameters:
    """SCvx parameters; defaults are Table 1 of the T-SCvx paper."""

    iter_max: int = 100  # maximum number of subproblem solves (Table 1: 20, see module doc)
    lambda_: float = 2.0  # penalty weight lambda (Table 1: 500, see the module docstring)
    rho_0: float = 0.0  # rejection threshold
    rho_1: float = 0.1  # shrink threshold
    rho_2: float = 0.7  # growth threshold
    beta_sh: float = 2.0  # shrink factor (alpha of Alg. 1)
    beta_gr: float = 2.0  # growth factor (beta of Alg. 1)
    eta_init: float = 2.0  # initial trust radius (eta_full,init)
    eta_lb: float = 1e-3  # minimum trust radius
    eta_ub: float = 10.0  # maximum trust radius
    eps_abs: float = 0.1  # absolute step tolerance (stopping = "table1")
    eps_rel: float = 1e-3  # relative penalized-cost tolerance (stopping = "table1")
    feas_tol: float = 0.5  # nonlinear penalty allowed at the stopping test
    virtual_tol: float = 1e-6  # max |nu|, max buffer for "negligible" (not in the paper)
    defect_tol: float = 2e-5  # max |x_{k+1} - F(x_k, u)| (not in the paper, see below)
    stopping: str = "stationary"  # "stationary" (Delta L test) or "table1" (eps_abs/eps_rel)
    eps_opt: float = 1e-4  # Delta L <= eps_opt max(1, |J|) at a stationary point (not in paper)
    eta_stationary: float = 1.0  # least trust radius at which Delta L certifies stationarity
    second_order_correction: bool = True  # re-solve with shifted defects when rho < rho_1
    polish: bool = True  # move accepted steps onto the nonlinear flow (module docstring)
    polish_penalty: float = 1e-2  # largest penalty of an accepted step that is polished
    stall_window: int = 15  # accepted iterations of the stall test (0: off; not in the paper)
    stall_decrease: float = 0.02  # least relative fall of the penalty over that window
    stall_penalty: float = 1e-3  # penalty below which the loop is never called stalled
    solver: str = "clarabel"  # conic solver: clarabel, ecos or qoco

    def __post_init__(self) -> None:
        check_int("iter_max", self.iter_max, least=1)
        check_int("stall_window", self.stall_window, least=0)
        check_in_range("stall_decrease", self.stall_decrease, 0.0, 1.0)
        check_positive("stall_penalty", self.stall_penalty)
        check_positive("polish_penalty", self.polish_penalty)
        for name in ("lambda_", "eta_init", "eta_lb", "eta_ub", "eps_abs", "eps_rel", "feas_tol"):
            check_positive(name, getattr(self, name))
        for name in ("virtual_tol", "defect_tol", "eps_opt", "eta_stationary"):
            check_positive(name, getattr(self, name))
        if self.stopping not in STOPPING_TESTS:
            raise ValueError(
                f"stopping must be one of {', '.join(STOPPING_TESTS)}, got {self.stopping!r}"
            )
        check_in_range("rho_0", self.rho_0, -1.0, 1.0)
        if not self.rho_0 <= self.rho_1 < self.rho_2 <= 1.0:
            raise ValueError(
                f"need rho_0 <= rho_1 < rho_2 <= 1, got {self.rho_0}, {self.rho_1}, {self.rho_2}"
            )
        for name in ("beta_sh", "beta_gr"):
            if check_positive(name, getattr(self, name)) < 1.0:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        if not self.eta_lb <= self.eta_init <= self.eta_ub:
            raise ValueError(
                f"need eta_lb <= eta_init <= eta_ub, got {self.eta_lb}, {self.eta_init}, "
                f"{self.eta_ub}"
            )
        check_solver(self.solver)


@dataclass(frozen=True)
class Evaluation:
    """Nonlinear quantities of a trajectory, and its linearization for the next subproblem."""

    cost: float  # C(z)
    penalty: float  # P(z): sum of |defects|_1 and nonconvex violations
    max_defect: float  # max |defect|
    tight_flags: np.ndarray  # (name, node) flags
    linearization: object  # opaque to SCvx; handed back to ``solve_subproblem``
    time: float  # seconds spent evaluating


@dataclass(frozen=True)
class Candidate:
    """The subproblem optimum ``z*`` with its linearized cost L and virtual-control sizes."""

    trajectory: Trajectory | None
    linear_cost: float
    virtual_norm: float  # |nu|_1 + sum buffers
    virtual_max: float  # max(|nu|_inf, max buffer)
    status: str
    solver_time: float
    ok: bool


class ConvexifiedProblem(Protocol):
    """What a problem family provides to SCvx."""

    def evaluate(self, z: Trajectory) -> Evaluation:
        """Nonlinear cost, penalty, defects, tight flags, and the linearization about ``z``."""

    def solve_subproblem(
        self, z: Trajectory, evaluation: Evaluation, eta: float, lambda_: float, solver: str
    ) -> Candidate:
        """Solve the convex subproblem about ``z`` with trust radius ``eta``."""

    def verify(self, z: Trajectory) -> Verification:
        """Propagate ``z``'s controls through the nonlinear model."""

    def node_times(self, z: Trajectory) -> np.ndarray:
        """Node times of ``z``."""

    def step_norm(self, z_new: Trajectory, z_old: Trajectory) -> float:
        """``|z_new - z_old|_inf`` in the scaled units of the trust region."""

    def solve_correction(
        self,
        z: Trajectory,
        evaluation: Evaluation,
        candidate: Candidate,
        candidate_evaluation: Evaluation,
        eta: float,
        lambda_: float,
        solver: str,
    ) -> Candidate:
        """Re-solve the subproblem about ``z`` aiming at the nonlinear flow at ``candidate``."""


def update_trust_radius(eta: float, rho: float, params: SCvxParameters) -> tuple[float, bool]:
    """Trust radius after a step with ratio ``rho`` and whether the step is accepted (Eq. 15)."""
    if rho < params.rho_0:
        return max(eta / params.beta_sh, params.eta_lb), False
    if rho < params.rho_1:
        eta = eta / params.beta_sh
    elif rho >= params.rho_2:
        eta = eta * params.beta_gr
    return float(np.clip(eta, params.eta_lb, params.eta_ub)), True


RadiusUpdate = Callable[[float, float, SCvxParameters], tuple[float, bool]]


def solve_scvx(
    problem: ConvexifiedProblem,
    guess: Trajectory,
    params: SCvxParameters | None = None,
    eta_init: float | None = None,
    radius_update: RadiusUpdate | None = None,
    prior_penalties: Sequence[float] = (),
) -> Solution:
    """Run SCvx from ``guess``; ``eta_init`` overrides ``params.eta_init`` (e.g. T-SCvx's 0.01).

    ``params.iter_max`` counts subproblem solves, second-order corrections included; every
    solve is one record of the history. ``radius_update(eta, rho, params) -> (eta, accepted)``
    replaces Eq. 15 (:func:`update_trust_radius`), e.g. by T-SCvx's Eq. 22.
    ``prior_penalties`` are the accepted penalties of a run that ``guess`` continues: the stall
    test sees them before this run's own.
    """
    radius_update = radius_update or update_trust_radius
    params = params or SCvxParameters()
    start = time.perf_counter()
    eta = params.eta_init if eta_init is None else eta_init
    z_bar, ev_bar = guess, problem.evaluate(guess)
    clock = {"discretization": ev_bar.time, "solver": 0.0}
    J_bar = ev_bar.cost + params.lambda_ * ev_bar.penalty
    history: list[IterationRecord] = []
    status, message = Status.MAX_ITERATIONS, ""
    penalties = list(prior_penalties)  # of the accepted iterates, for the stall test
    bar_negligible = False  # z_bar feasible enough to be returned as converged
    while len(history) < params.iter_max:
        t_iter = time.perf_counter()
        cand = problem.solve_subproblem(z_bar, ev_bar, eta, params.lambda_, params.solver)
        step = _evaluated(problem, cand, params, clock)
        if step is None:
            status, message = Status.SOLVER_FAILED, f"iteration {len(history) + 1}: {cand.status}"
            break
        ev, J = step
        if bar_negligible and _certifies_stationary(params, J_bar, cand.linear_cost, eta):
            accepted = J_bar - J >= params.rho_0 * (J_bar - cand.linear_cost)
            final = accepted and _negligible(params, cand, ev) and ev.penalty <= params.feas_tol
            history.append(
                _record(len(history) + 1, final, cand, ev, J, J_bar, z_bar, eta, problem, t_iter)
            )
            if final:
                z_bar, ev_bar = cand.trajectory, ev
            status = Status.CONVERGED
            break
        if _wants_correction(params, ev, J_bar, J, cand, len(history)):
            history.append(
                _record(len(history) + 1, False, cand, ev, J, J_bar, z_bar, eta, problem, t_iter)
            )
            t_iter = time.perf_counter()
            corrected = problem.solve_correction(
                z_bar, ev_bar, cand, ev, eta, params.lambda_, params.solver
            )
            step = _evaluated(problem, corrected, params, clock)
            if step is not None and step[1] < J:  # keep the prediction L of the first solve
                cand = dataclasses.replace(corrected, linear_cost=cand.linear_cost)
                ev, J = step
            else:  # the first candidate stands; this record still times the second solve
                cand = dataclasses.replace(cand, solver_time=corrected.solver_time)
        delta_J, delta_L = J_bar - J, J_bar - cand.linear_cost
        rho = _ratio(delta_J, delta_L)
        eta_used = eta
        if math.isnan(rho) or abs(delta_L) <= 1e-12 * max(1.0, abs(J_bar)):
            accepted = True  # the subproblem predicts no change: z_bar is stationary
        else:
            eta, accepted = radius_update(eta, rho, params)
        history.append(
            _record(
                len(history) + 1, accepted, cand, ev, J, J_bar, z_bar, eta_used, problem, t_iter
            )
        )
        if not accepted:
            continue
        stop = meets_stopping_test(params, history[-1], delta_J, delta_L, J_bar, eta_used)
        polished = _polished(problem, params, cand, ev, J, clock)
        if polished[0] is not cand:
            cand, ev, J = polished
            history[-1] = dataclasses.replace(
                history[-1],
                cost=ev.cost,
                penalty=ev.penalty,
                J=J,
                tight_flags=ev.tight_flags,
                polished=True,
            )
        z_bar, ev_bar, J_bar = cand.trajectory, ev, J
        bar_negligible = _negligible(params, cand, ev) and ev.penalty <= params.feas_tol
        if stop and bar_negligible:
            status = Status.CONVERGED
            break
        penalties.append(ev.penalty)
        if stalled(params, penalties):
            status, message = Status.STALLED, _stall_message(params, penalties, len(history))
            break
    return _finish(problem, z_bar, ev_bar, status, message, history, start, clock)


def _polished(
    problem: ConvexifiedProblem,
    params: SCvxParameters,
    cand: Candidate,
    ev: Evaluation,
    J: float,
    clock: dict[str, float],
) -> tuple[Candidate, Evaluation, float]:
    """The accepted ``cand`` moved onto the nonlinear flow by ``problem.polish``, when the
    family provides it, the candidate's defects are not negligible while its virtual control
    is, and the polished iterate has the lower ``J`` (module docstring, "Polish")."""
    polish = getattr(problem, "polish", None)
    if polish is None or not params.polish or _negligible(params, cand, ev):
        return cand, ev, J
    if cand.virtual_max > params.virtual_tol or ev.penalty > params.polish_penalty:
        return cand, ev, J  # not dynamically feasible yet, or not yet in the tail
    polished = polish(cand, ev)
    step = None if polished is None else _evaluated(problem, polished, params, clock)
    if step is None or not step[1] < J:
        return cand, ev, J
    return polished, step[0], step[1]


def _negligible(params: SCvxParameters, cand: Candidate, ev: Evaluation) -> bool:
    """Virtual control, buffers and nonlinear defects of an iterate are negligible."""
    return cand.virtual_max <= params.virtual_tol and ev.max_defect <= params.defect_tol


def _certifies_stationary(
    params: SCvxParameters, J_bar: float, linear_cost: float, eta: float
) -> bool:
    """The first solve about ``z_bar`` finds no descent: ``z_bar`` is stationary.

    The ``"stationary"`` test of :func:`meets_stopping_test` is a property of the subproblem
    about ``z_bar``, not of its candidate: when the subproblem, with a radius of at least
    ``eta_stationary``, predicts a decrease ``Delta L`` below ``eps_opt max(1, |J|)``, ``z_bar``
    is a stationary point whether or not the candidate's nonlinear defects pass the ratio test.
    """
    if params.stopping != "stationary" or eta < params.eta_stationary:
        return False
    return J_bar - linear_cost <= params.eps_opt * max(1.0, abs(J_bar))


def stalled(params: SCvxParameters, penalties: list[float]) -> bool:
    """The stall test of the module docstring on the accepted iterates' penalties."""
    window = params.stall_window
    if window == 0 or len(penalties) <= window or penalties[-1] <= params.stall_penalty:
        return False
    return penalties[-1] > (1.0 - params.stall_decrease) * penalties[-1 - window]


def _stall_message(params: SCvxParameters, penalties: list[float], solves: int) -> str:
    before, now = penalties[-1 - params.stall_window], penalties[-1]
    return (
        f"stalled after {solves} iterations: the penalty fell from {before:.3g} to {now:.3g} "
        f"in the last {params.stall_window} accepted iterations (an infeasible stationary "
        "point; the instance is likely infeasible near this start)"
    )


def _ratio(delta_J: float, delta_L: float) -> float:
    """``rho = Delta J / Delta L`` (Eq. 14); nan when the subproblem predicts no change."""
    return delta_J / delta_L if delta_L != 0.0 else math.nan


def _evaluated(
    problem: ConvexifiedProblem, cand: Candidate, params: SCvxParameters, clock: dict[str, float]
) -> tuple[Evaluation, float] | None:
    """Nonlinear evaluation and penalized cost ``J`` (Eq. 16) of a candidate; None if failed.

    A candidate far from the iterate can make the nonlinear flow overflow; its ``J`` is then
    ``inf``, so that the ratio test rejects it (a nan ``J`` would make the ratio nan, which
    reads as "the subproblem predicts no change" and accepts the step).
    """
    clock["solver"] += cand.solver_time
    if not cand.ok or cand.trajectory is None:
        return None
    ev = problem.evaluate(cand.trajectory)
    clock["discretization"] += ev.time
    J = ev.cost + params.lambda_ * ev.penalty
    return ev, J if math.isfinite(J) else math.inf


def _wants_correction(
    params: SCvxParameters,
    ev: Evaluation,
    J_bar: float,
    J: float,
    cand: Candidate,
    solves: int,
) -> bool:
    """Try a second-order correction when the defects of the candidate spoil its ratio.

    A step of length d leaves nonlinear defects O(d^2) that the L1 penalty charges at
    ``lambda`` while the linear model predicts none, so near a solution good steps get
    ``rho < rho_1`` and the trust region shrinks (the Maratos effect). The correction re-solves
    the subproblem with the linearized dynamics shifted by the candidate's defects; it is kept
    when its ``J`` is lower, and the ratio then compares its ``Delta J`` with the first
    solve's ``Delta L`` (Nocedal & Wright, Sec. 15.5).
    """
    if not params.second_order_correction or solves + 2 > params.iter_max or ev.penalty <= 0.0:
        return False
    if cand.virtual_max > params.virtual_tol:
        return False  # the subproblem itself is not dynamically feasible yet: nothing to correct
    delta_L = J_bar - cand.linear_cost
    return delta_L > 0.0 and (J_bar - J) < params.rho_1 * delta_L


def meets_stopping_test(
    params: SCvxParameters,
    record: IterationRecord,
    delta_J: float,
    delta_L: float,
    J_bar: float,
    eta_used: float,
) -> bool:
    """Whether the accepted step ends the loop (feasibility is checked by the caller).

    ``"stationary"``: the predicted decrease of the penalized cost, ``Delta L`` (Eq. 13), is
    below ``eps_opt max(1, |J|)`` with a trust radius of at least ``eta_stationary``: the
    convexified problem about the iterate, given room to move, finds no descent, which makes
    the iterate a first-order stationary point of Eq. 16 up to that tolerance. A small step or
    cost change under a small radius proves nothing and does not stop the loop.
    ``"table1"``: Table 1's ``eps_abs`` on the step or ``eps_rel`` on ``|Delta J|``.
    """
    if params.stopping == "table1":
        return record.step_norm <= params.eps_abs or abs(delta_J) <= params.eps_rel * abs(J_bar)
    return _certifies_stationary(params, J_bar, J_bar - delta_L, eta_used)


def _record(
    iteration: int,
    accepted: bool,
    cand: Candidate,
    ev: Evaluation,
    J: float,
    J_bar: float,
    z_bar: Trajectory,
    eta: float,
    problem: ConvexifiedProblem,
    t_iter: float,
) -> IterationRecord:
    return IterationRecord(
        iteration=iteration,
        accepted=accepted,
        cost=ev.cost,
        penalty=ev.penalty,
        J=J,
        L=cand.linear_cost,
        rho=_ratio(J_bar - J, J_bar - cand.linear_cost),
        trust_radius=eta,
        virtual_control_norm=cand.virtual_norm,
        step_norm=problem.step_norm(cand.trajectory, z_bar),
        tight_flags=ev.tight_flags,
        time_discretization=ev.time,
        time_solver=cand.solver_time,
        time_total=time.perf_counter() - t_iter,
        solver_status=cand.status,
    )


def _finish(
    problem: ConvexifiedProblem,
    z: Trajectory,
    ev: Evaluation,
    status: Status,
    message: str,
    history: list[IterationRecord],
    start: float,
    clock: dict[str, float],
) -> Solution:
    return finished_solution(
        problem,
        z,
        ev.cost,
        status,
        message,
        history,
        start=start,
        discretization=clock["discretization"],
        solver=clock["solver"],
        merit=f"penalty {ev.penalty:.3g}",
    )
