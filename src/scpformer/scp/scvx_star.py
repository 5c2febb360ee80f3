"""SCvx* (Oguri 2023): successive convexification made feasible by an augmented Lagrangian.

K. Oguri, "Successive Convexification with Feasibility Guarantee via Augmented Lagrangian for
Non-Convex Optimal Control Problems", IEEE CDC 2023 (robust ART paper, ref. [20]). The robust
ART paper solves its subproblem (Eq. 17) with it, with the parameters of its Table 1.

Notation
--------
Problem: ``min f0(z)  s.t.  g(z) = 0,  h(z) <= 0,  z in Z`` (``Z`` convex, kept exact).

* Penalty, ``P(y, s) = lambda^T y + mu^T s + w/2 (|y|^2 + |s|^2)`` (:func:`penalty`), with
  multipliers ``lambda`` (of ``g``), ``mu >= 0`` (of ``h``) and weight ``w > 0``.
* Penalized nonlinear cost ``J(z) = f0(z) + P(g(z), h+(z))``, ``h+ = max(0, h)``.
* Convex subproblem about the reference ``z_bar`` (robust paper Eq. 17 is an instance)::

      min  f0(z) + P(xi, zeta)
      s.t. g_bar + G (z - z_bar) = xi,  h_bar + H (z - z_bar) <= zeta,  zeta >= 0,
           |z - z_bar|_inf <= r  (in the problem's scaled units),  z in Z

  with virtual buffers ``xi``, ``zeta``; its optimum ``z*`` has ``L = f0(z*) + P(xi*, zeta*)``.
* ``Delta J = J(z_bar) - J(z*)``, ``Delta L = J(z_bar) - L``, ``rho = Delta J / Delta L``,
  ``chi = |(g(z*), h+(z*))|_2`` (the feasibility measure).

Algorithm 1 of Oguri (2023), one iteration (:meth:`SCvxStar.step`):

1. solve the subproblem with the current ``lambda, mu, w, r``; a failed conic solve stops the
   run with ``Status.SOLVER_FAILED`` and the solver's reason;
2. stop (``Status.CONVERGED``, subject to the problem's verification) when
   ``|Delta J| <= eps_opt`` and ``chi <= eps_feas``; ``z*`` is returned;
3. accept ``z*`` as the new reference when ``rho >= rho_0``; then, if ``|Delta J| < delta``
   (the subproblem-level stationarity test), update the multipliers with the constraint
   values of ``z*``, ``lambda <- lambda + w g``, ``mu <- max(0, mu + w h)``, the weight
   ``w <- min(beta w, w_max)`` and the stationarity tolerance ``delta <- |Delta J|`` the first
   time (``delta`` starts at infinity), ``delta <- gamma delta`` afterwards;
4. trust region: ``r <- max(r / alpha_1, r_min)`` if ``rho < rho_1``,
   ``r <- min(alpha_2 r, r_max)`` if ``rho >= rho_2``, unchanged otherwise.

Rejected steps (``shrink_from_step``, not in Oguri 2023): a rejected ``z*`` that lies strictly
inside the trust region is the subproblem's optimum for every radius above its step length,
so halving ``r`` from far above that length re-solves the same subproblem, finds the same
step and rejects it again. A rejected step therefore shrinks the radius from
``min(r, |z* - z_bar|_inf)``, the contraction on the step length that practical trust-region
codes use (Conn, Gould & Toint, *Trust-Region Methods*, 2000). Measured with passive safety
started from the TPBVP, ``iter_max = 20``, on instances of ``generate robust-rendezvous``
(seed 0), Oguri's rule -> this one, converged runs:

* instances 100-129 (an unselected range): 25 -> 28 of 30 deterministic, 21 -> 24 chance;
  mean solves of the converged runs 8.8 -> 8.3 and 6.4 -> 7.3 (more hard runs now finish);
* the 15 whose PS-CVX runs ended at 20 solves in the earlier robust-warmstart study, and
  instances 1-5: 10 -> 15 of 20 deterministic, 8 -> 10 chance. One of them had re-solved the
  same rejected step five times, at radii 5000 down to 312 m.

None of those runs converged under Oguri's rule and failed under this one. The
``robust-warmstart`` study run twice on its 60 test instances (six warm starts and modes, 360
SCvx* runs, same models): 33 runs converge only under this rule and 4 only under Oguri's;
PS-CVX-C ends at the cap on 20% against 25%. On the two-variable problem
of the tests the path changes and is sometimes longer (15 -> 29 solves from ``r^(0) = 0.5``,
equal from 1 and 2). ``shrink_from_step = False`` is Oguri's rule exactly.

When ``Delta L`` is zero to roundoff (or negative, which only happens when the reference
violates the convex constraints ``Z``, e.g. a raw initial guess), the subproblem predicts
no decrease from ``z_bar``; ``rho`` is then taken as 1 (accept, like :mod:`scpformer.scp.scvx`).

The algorithm object is stateless: parameters in :class:`SCvxStarParameters`, the iterate,
multipliers, weight, radius and ``delta`` in :class:`SCvxStarState`, and each iteration in an
:class:`~scpformer.scp.solution.IterationRecord` plus a :class:`SCvxStarRecord`. A problem
family plugs in through :class:`AugmentedLagrangianProblem` and builds its subproblem once
as a parametric (DPP) cvxpy problem, using :class:`PenaltyTerm` for ``P(xi, zeta)``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Protocol

import cvxpy as cp
import numpy as np

from scpformer.scp.conic import assign, check_solver
from scpformer.scp.solution import (
    IterationRecord,
    Solution,
    Status,
    Trajectory,
    Verification,
    finished_solution,
)
from scpformer.validation import check_bool, check_finite, check_int, check_positive

__all__ = [
    "AugmentedLagrangianProblem",
    "NonlinearEvaluation",
    "PenaltyTerm",
    "SCvxStar",
    "SCvxStarParameters",
    "SCvxStarRecord",
    "SCvxStarResult",
    "SCvxStarState",
    "StepResult",
    "SubproblemResult",
    "feasibility",
    "next_delta",
    "penalty",
    "update_multipliers",
    "update_trust_radius",
]

TIGHT_TOL = 1e-6  # h(z) >= -TIGHT_TOL flags a row as tight when the problem gives no flags
_DEGENERATE_DELTA_L = 1e-12  # |Delta L| below this times max(1, |J_bar|) predicts no change


# ----------------------------------------------------------------------------------------
# parameters
# ----------------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class SCvxStarParameters:
    """SCvx* parameters; defaults are Table 1 of the robust ART paper (and Oguri 2023)."""

    eps_opt: float = 1e-3  # epsilon_opt: tolerance on |Delta J| at the stopping test
    eps_feas: float = 1e-3  # epsilon_feas: tolerance on chi = |(g, h+)|_2
    alpha_1: float = 2.0  # alpha_1: trust radius shrink factor, r <- r / alpha_1
    alpha_2: float = 3.0  # alpha_2: trust radius growth factor, r <- alpha_2 r
    beta: float = 2.0  # beta: penalty weight growth factor, w <- beta w
    gamma: float = 0.9  # gamma: decay of the stationarity tolerance, delta <- gamma delta
    r_min: float = 1e-6  # r_min: smallest trust radius
    r_max: float = 5e3  # r_max: largest trust radius
    r_init: float = 100.0  # r^(0): initial trust radius (scaled units of the problem)
    w_init: float = 10.0  # w^(0): initial penalty weight
    w_max: float = 1e8  # w_max: weight cap (not in Table 1; Oguri requires one)
    rho_0: float = 0.0  # rho_0: acceptance threshold (not in Table 1; Oguri's values)
    rho_1: float = 0.25  # rho_1: shrink below this ratio
    rho_2: float = 0.7  # rho_2: grow at or above this ratio
    iter_max: int = 20  # maximum number of subproblem solves
    expand_on_infeasible: bool = True  # grow r by alpha_2 on an infeasible subproblem (not paper)
    shrink_from_step: bool = True  # a rejected step shrinks r from its length (not paper)
    solver: str = "clarabel"  # conic solver, one of scpformer.scp.conic.SOLVERS

    def __post_init__(self) -> None:
        check_int("iter_max", self.iter_max, least=1)
        for name in ("eps_opt", "eps_feas", "r_min", "r_max", "r_init", "w_init", "w_max"):
            check_positive(name, getattr(self, name))
        for name in ("alpha_1", "alpha_2", "beta"):
            if check_positive(name, getattr(self, name)) <= 1.0:
                raise ValueError(f"{name} must exceed 1, got {getattr(self, name)}")
        if not 0.0 < check_positive("gamma", self.gamma) < 1.0:
            raise ValueError(f"gamma must lie in (0, 1), got {self.gamma}")
        rhos = [float(check_finite(n, getattr(self, n), shape=())) for n in ("rho_0", "rho_1")]
        if not 0.0 <= rhos[0] < rhos[1] < float(check_finite("rho_2", self.rho_2, shape=())) < 1:
            raise ValueError(
                f"need 0 <= rho_0 < rho_1 < rho_2 < 1, got {self.rho_0}, {self.rho_1}, {self.rho_2}"
            )
        if not self.r_min <= self.r_init <= self.r_max:
            raise ValueError(
                f"need r_min <= r_init <= r_max, got {self.r_min}, {self.r_init}, {self.r_max}"
            )
        if self.w_init > self.w_max:
            raise ValueError(f"w_init must not exceed w_max, got {self.w_init} > {self.w_max}")
        check_bool("expand_on_infeasible", self.expand_on_infeasible)
        check_bool("shrink_from_step", self.shrink_from_step)
        check_solver(self.solver)


# ----------------------------------------------------------------------------------------
# pure update rules
# ----------------------------------------------------------------------------------------
def penalty(y: np.ndarray, s: np.ndarray, lambda_: np.ndarray, mu: np.ndarray, w: float) -> float:
    """Augmented-Lagrangian penalty ``P(y, s) = lambda^T y + mu^T s + w/2 (|y|^2 + |s|^2)``.

    ``J(z) = f0(z) + P(g(z), h+(z))`` and ``L = f0(z*) + P(xi, zeta)`` (Oguri 2023).
    """
    return float(lambda_ @ y + mu @ s + 0.5 * w * (y @ y + s @ s))


def feasibility(g: np.ndarray, h: np.ndarray) -> float:
    """``chi = |(g, max(0, h))|_2``, the constraint violation tested against ``eps_feas``."""
    return float(np.linalg.norm(np.concatenate([g, np.maximum(h, 0.0)])))


def update_trust_radius(
    r: float, rho: float, params: SCvxStarParameters, step_norm: float = math.inf
) -> tuple[float, bool]:
    """Trust radius after a step with ratio ``rho``, and whether the step is accepted.

    A rejected step of length ``step_norm`` (``|z* - z_bar|_inf``, the trust region's units)
    shrinks from ``min(r, step_norm)`` when ``params.shrink_from_step`` (module docstring).
    """
    accepted = rho >= params.rho_0
    if not accepted and params.shrink_from_step:
        r = min(r, step_norm)  # a NaN step length keeps r
    if rho < params.rho_1:
        r = max(r / params.alpha_1, params.r_min)
    elif rho >= params.rho_2:
        r = min(r * params.alpha_2, params.r_max)
    return r, accepted


def update_multipliers(
    lambda_: np.ndarray, mu: np.ndarray, w: float, g: np.ndarray, h: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Method-of-multipliers update: ``lambda + w g`` and ``max(0, mu + w h)``."""
    return lambda_ + w * g, np.maximum(mu + w * h, 0.0)


def next_delta(delta: float, delta_J: float, gamma: float) -> float:
    """Stationarity tolerance after a multiplier update: ``|Delta J|``, then ``gamma delta``."""
    return abs(delta_J) if math.isinf(delta) else gamma * delta


# ----------------------------------------------------------------------------------------
# interface with a problem family
# ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class NonlinearEvaluation:
    """Cost and nonlinear constraints at a point, and the data to linearize about it."""

    cost: float  # f0(z)
    g: np.ndarray  # (n_g,) equality constraints, satisfied when 0
    h: np.ndarray  # (n_h,) inequality constraints, satisfied when <= 0
    linearization: object = None  # opaque to SCvx*, handed back to ``solve_subproblem``
    tight_flags: np.ndarray | None = None  # (name, node) flags; default h >= -TIGHT_TOL
    time: float = 0.0  # seconds spent evaluating and linearizing

    @property
    def h_plus(self) -> np.ndarray:
        """``max(0, h)``."""
        return np.maximum(self.h, 0.0)

    @property
    def chi(self) -> float:
        """Constraint violation ``|(g, h+)|_2``."""
        return feasibility(self.g, self.h)

    def flags(self) -> np.ndarray:
        """Tight-constraint flags: the problem's, else ``h >= -TIGHT_TOL``."""
        return self.tight_flags if self.tight_flags is not None else self.h >= -TIGHT_TOL


@dataclass(frozen=True)
class SubproblemResult:
    """The convex subproblem's optimum ``z*`` and its virtual buffers."""

    ok: bool  # the conic solver returned an (inaccurate) optimum
    status: str  # the solver's status string
    z: Trajectory | None  # z*
    cost: float  # f0 of z* as modeled in the subproblem (the convex cost)
    xi: np.ndarray | None  # (n_g,) virtual buffers of the linearized g
    zeta: np.ndarray | None  # (n_h,) >= 0 virtual buffers of the linearized h
    step_norm: float  # |z* - z_bar|_inf in the scaled units of the trust region
    solver_time: float  # seconds spent in the conic solve
    message: str = ""


class AugmentedLagrangianProblem(Protocol):
    """What a problem family provides to SCvx*."""

    def evaluate(self, z: Trajectory) -> NonlinearEvaluation:
        """``f0(z)``, ``g(z)``, ``h(z)`` and the linearization data about ``z``."""

    def solve_subproblem(
        self,
        z: Trajectory,
        evaluation: NonlinearEvaluation,
        *,
        lambda_: np.ndarray,
        mu: np.ndarray,
        w: float,
        r: float,
        solver: str,
    ) -> SubproblemResult:
        """Solve the subproblem about ``z`` (write parameters, re-solve the compiled problem)."""

    def verify(self, z: Trajectory) -> Verification:
        """Check ``z`` against the nonlinear model."""

    def node_times(self, z: Trajectory) -> np.ndarray | None:
        """Node times of ``z`` (``None`` for a problem without time)."""


class PenaltyTerm:
    """``P(xi, zeta)`` of the subproblem over cvxpy Parameters: built once, DPP-compliant.

    Holds the buffers ``xi`` (free) and ``zeta`` (nonnegative), the parameters ``lambda_``,
    ``mu`` (nonnegative), ``w`` and the trust radius ``r``; a problem family adds
    ``g_lin(z) == xi``, ``h_lin(z) <= zeta`` and ``|z - z_bar|_inf <= r`` to its own
    constraints and ``expression`` to its objective, then calls :meth:`assign` before each
    re-solve. Sizes may be zero (no ``g`` or no ``h``).
    """

    def __init__(self, n_g: int, n_h: int) -> None:
        if n_g < 0 or n_h < 0:
            raise ValueError(f"n_g and n_h must be nonnegative, got {n_g}, {n_h}")
        self.n_g, self.n_h = n_g, n_h
        self.w = cp.Parameter(nonneg=True, name="w")
        self.r = cp.Parameter(nonneg=True, name="r")
        self.lambda_ = cp.Parameter(n_g, name="lambda") if n_g else None
        self.mu = cp.Parameter(n_h, nonneg=True, name="mu") if n_h else None
        self.xi = cp.Variable(n_g, name="xi") if n_g else None
        self.zeta = cp.Variable(n_h, nonneg=True, name="zeta") if n_h else None
        terms: list[cp.Expression] = [cp.Constant(0.0)]
        for mult, buf in ((self.lambda_, self.xi), (self.mu, self.zeta)):
            if buf is not None:
                terms += [mult @ buf, 0.5 * self.w * cp.sum_squares(buf)]
        self.expression: cp.Expression = cp.sum(cp.hstack(terms))

    def assign(self, *, lambda_: np.ndarray, mu: np.ndarray, w: float, r: float) -> None:
        """Write the multipliers, weight and trust radius into the parameters."""
        assign(self.w, w)
        assign(self.r, r)
        if self.lambda_ is not None:
            assign(self.lambda_, lambda_)
        if self.mu is not None:
            assign(self.mu, mu)

    def buffers(self) -> tuple[np.ndarray, np.ndarray]:
        """Values of ``xi`` and ``zeta`` after a solve (empty arrays when absent)."""
        xi = np.zeros(0) if self.xi is None else np.asarray(self.xi.value, dtype=float)
        zeta = np.zeros(0) if self.zeta is None else np.asarray(self.zeta.value, dtype=float)
        return xi, np.maximum(zeta, 0.0)


# ----------------------------------------------------------------------------------------
# state, records, results
# ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SCvxStarState:
    """Everything SCvx* carries from one iteration to the next."""

    z: Trajectory  # reference z_bar
    evaluation: NonlinearEvaluation  # f0, g, h at z_bar
    lambda_: np.ndarray  # (n_g,) multipliers of g
    mu: np.ndarray  # (n_h,) multipliers of h, >= 0
    w: float  # penalty weight
    r: float  # trust radius
    delta: float  # stationarity tolerance for the multiplier update (inf at the start)
    iteration: int = 0  # subproblems solved so far


@dataclass(frozen=True)
class SCvxStarRecord:
    """SCvx*-specific quantities of one iteration (next to its ``IterationRecord``)."""

    iteration: int
    delta_J: float  # J(z_bar) - J(z*)
    delta_L: float  # J(z_bar) - L
    chi: float  # |(g(z*), h+(z*))|_2
    w: float  # weight used in this subproblem
    delta: float  # stationarity tolerance in force during this iteration
    multipliers_updated: bool  # lambda, mu, w, delta were updated after this iteration


@dataclass(frozen=True)
class StepResult:
    """Outcome of one iteration: the next state, its records, and a final status if any."""

    state: SCvxStarState
    record: IterationRecord | None  # None when the conic solve failed
    star: SCvxStarRecord | None
    status: Status | None = None  # None: keep iterating
    message: str = ""


@dataclass(frozen=True)
class SCvxStarResult:
    """A solve: the project's :class:`Solution`, SCvx* records and the final state."""

    solution: Solution
    records: tuple[SCvxStarRecord, ...]  # aligned with ``solution.history``
    state: SCvxStarState  # final multipliers, weight, radius


# ----------------------------------------------------------------------------------------
# the algorithm
# ----------------------------------------------------------------------------------------
class SCvxStar:
    """SCvx* of Oguri (2023); stateless, see the module docstring."""

    def __init__(self, params: SCvxStarParameters | None = None) -> None:
        self.params = params or SCvxStarParameters()

    def init(self, problem: AugmentedLagrangianProblem, guess: Trajectory) -> SCvxStarState:
        """Initial state at ``guess``: zero multipliers, ``w^(0)``, ``r^(0)``, ``delta = inf``."""
        ev = problem.evaluate(guess)
        return SCvxStarState(
            z=guess,
            evaluation=ev,
            lambda_=np.zeros_like(np.asarray(ev.g, dtype=float)),
            mu=np.zeros_like(np.asarray(ev.h, dtype=float)),
            w=self.params.w_init,
            r=self.params.r_init,
            delta=math.inf,
        )

    def step(self, problem: AugmentedLagrangianProblem, state: SCvxStarState) -> StepResult:
        """One iteration of Algorithm 1 (see the module docstring)."""
        p, t0, k = self.params, time.perf_counter(), state.iteration + 1
        sub = problem.solve_subproblem(
            state.z,
            state.evaluation,
            lambda_=state.lambda_,
            mu=state.mu,
            w=state.w,
            r=state.r,
            solver=p.solver,
        )
        if sub.status == "infeasible" and p.expand_on_infeasible and state.r < p.r_max:
            return self._expanded(state, sub, k, t0)
        if not sub.ok or sub.z is None:
            reason = f"iteration {k}: conic solver status {sub.status!r} {sub.message}".strip()
            return StepResult(replace(state, iteration=k), None, None, Status.SOLVER_FAILED, reason)
        ev = problem.evaluate(sub.z)
        J_bar, J, L = self._costs(state, ev, sub)
        delta_J, delta_L = J_bar - J, J_bar - L
        degenerate = delta_L <= _DEGENERATE_DELTA_L * max(1.0, abs(J_bar))
        rho = 1.0 if degenerate else delta_J / delta_L
        converged = abs(delta_J) <= p.eps_opt and ev.chi <= p.eps_feas
        r_next, accepted = update_trust_radius(state.r, rho, p, sub.step_norm)
        nxt = replace(state, iteration=k, r=r_next)
        updated = accepted and not converged and abs(delta_J) < state.delta
        if accepted or converged:
            nxt = replace(nxt, z=sub.z, evaluation=ev)
        if updated:
            nxt = self._update_multipliers(nxt, ev, delta_J)
        record = IterationRecord(
            iteration=k,
            accepted=accepted or converged,
            cost=ev.cost,
            penalty=J - ev.cost,
            J=J,
            L=L,
            rho=rho,
            trust_radius=state.r,
            virtual_control_norm=_l1(sub.xi) + _l1(sub.zeta),
            step_norm=sub.step_norm,
            tight_flags=ev.flags(),
            time_discretization=ev.time,
            time_solver=sub.solver_time,
            time_total=time.perf_counter() - t0,
            solver_status=sub.status,
        )
        star = SCvxStarRecord(k, delta_J, delta_L, ev.chi, state.w, state.delta, updated)
        return StepResult(nxt, record, star, Status.CONVERGED if converged else None)

    def solve(self, problem: AugmentedLagrangianProblem, guess: Trajectory) -> SCvxStarResult:
        """Run SCvx* from ``guess`` for at most ``iter_max`` subproblems."""
        start = time.perf_counter()
        state = self.init(problem, guess)
        init_time = state.evaluation.time
        history: list[IterationRecord] = []
        records: list[SCvxStarRecord] = []
        status, message = Status.MAX_ITERATIONS, ""
        for _ in range(self.params.iter_max):
            out = self.step(problem, state)
            state = out.state
            if out.record is not None and out.star is not None:
                history.append(out.record)
                records.append(out.star)
            if out.status is not None:
                status, message = out.status, out.message
                break
        solution = _finish(problem, state, status, message, history, start, init_time)
        return SCvxStarResult(solution=solution, records=tuple(records), state=state)

    def _expanded(
        self, state: SCvxStarState, sub: SubproblemResult, k: int, t0: float
    ) -> StepResult:
        """A rejected iteration that grows the trust radius by ``alpha_2`` (up to ``r_max``).

        Not in Oguri's algorithm: an infeasible subproblem (a reference that misses a fixed
        boundary state by more than the radius lets the last impulses reach) says the radius
        is too small, not that the problem is infeasible.
        """
        nan = math.nan
        record = IterationRecord(
            iteration=k, accepted=False, cost=nan, penalty=nan, J=nan, L=nan, rho=nan,
            trust_radius=state.r, virtual_control_norm=nan, step_norm=nan,
            tight_flags=state.evaluation.flags(), time_discretization=0.0,
            time_solver=sub.solver_time, time_total=time.perf_counter() - t0,
            solver_status=sub.status,
        )  # fmt: skip
        star = SCvxStarRecord(k, nan, nan, state.evaluation.chi, state.w, state.delta, False)
        r_next = min(self.params.alpha_2 * state.r, self.params.r_max)
        return StepResult(replace(state, iteration=k, r=r_next), record, star, None)

    @staticmethod
    def _costs(
        state: SCvxStarState, ev: NonlinearEvaluation, sub: SubproblemResult
    ) -> tuple[float, float, float]:
        """``J(z_bar)``, ``J(z*)`` and ``L`` with the multipliers and weight of ``state``."""
        lam, mu, w, ev_bar = state.lambda_, state.mu, state.w, state.evaluation
        J_bar = ev_bar.cost + penalty(ev_bar.g, ev_bar.h_plus, lam, mu, w)
        J = ev.cost + penalty(ev.g, ev.h_plus, lam, mu, w)
        xi = np.zeros_like(lam) if sub.xi is None else sub.xi
        zeta = np.zeros_like(mu) if sub.zeta is None else sub.zeta
        return J_bar, J, sub.cost + penalty(xi, zeta, lam, mu, w)

    def _update_multipliers(
        self, state: SCvxStarState, ev: NonlinearEvaluation, delta_J: float
    ) -> SCvxStarState:
        """Multipliers, weight and ``delta`` after an accepted, stationary step."""
        lam, mu = update_multipliers(state.lambda_, state.mu, state.w, ev.g, ev.h)
        return replace(
            state,
            lambda_=lam,
            mu=mu,
            w=min(self.params.beta * state.w, self.params.w_max),
            delta=next_delta(state.delta, delta_J, self.params.gamma),
        )


def _l1(v: np.ndarray | None) -> float:
    return 0.0 if v is None else float(np.sum(np.abs(v)))


def _finish(
    problem: AugmentedLagrangianProblem,
    state: SCvxStarState,
    status: Status,
    message: str,
    history: list[IterationRecord],
    start: float,
    init_time: float,
) -> Solution:
    return finished_solution(
        problem,
        state.z,
        state.evaluation.cost,
        status,
        message,
        history,
        start=start,
        discretization=init_time + sum(h.time_discretization for h in history),
        solver=sum(h.time_solver for h in history),
        merit=f"chi {state.evaluation.chi:.3g}",
    )
