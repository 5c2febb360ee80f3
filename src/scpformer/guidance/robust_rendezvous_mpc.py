"""Closed-loop guidance of the chance-constrained, passively safe rendezvous: shrinking-horizon
model predictive control of the robust ART paper's problem (Eq. 1, ``safety_mode="chance"``).

The open-loop plan is the family's three-stage solve of the nominal instance
(:func:`scpformer.robust_rendezvous.solve`). The loop flies it through the truth model and
re-plans on board, with the truth flight of the deterministic rendezvous loop
(:func:`scpformer.guidance.rendezvous_mpc.fly_truth`, one piece of code for both):

1. every ``replan_every`` impulses (nodes ``k = K, 2K, ...`` up to ``N - 2``,
   :func:`replan_nodes`) the navigation filter gives an estimate of the servicer's MEAN
   scaled ROE: the true osculating state averaged to mean elements, plus an error
   ``~ N(0, X_nav(rho))`` of Eqs. 10-11 (Table 2), exactly as the deterministic loop;
2. the remaining problem is posed from that estimate (:func:`remaining_instance`) and solved
   by the family's ``solve`` (verified like any solution: model residual, passive-safety
   rows with their margin, truth replay to the waypoint);
3. the plan's next ``K`` impulses are flown through two-body + J2 with the Gates execution
   error of each burn (Eqs. 12-13) and the process noise ``Q`` added at every node (Table 2).

A re-plan that fails (no converged, verified plan) is recorded and the last accepted plan
keeps being flown; only a CONVERGED plan is accepted (a passive-safety stage stopped at its
iteration cap returns an earlier stage's trajectory, which is not passively safe). A re-plan
records its wall time (the solve with its warm start and verification; the target maps of
the remaining problem are built before it, :func:`prepare`), its convex solves over all
stages (:func:`stage_solves`), whether it converged and was accepted, and its warm start.

The remaining problem from node ``k``
-------------------------------------
Eq. 1 over the nodes ``k .. N``: ``N - k`` impulses of the same time step to the fixed final
time ``t_N``, the same pre-docking state ``x_f`` (Table 1: the only waypoint of this problem
is its terminal state, never passed before ``t_N``; hence re-plans run to ``N - 2``, the
last problem with two impulses), from ``x(t_k) = x_hat_k``, the estimate:

    min sum_{i=k}^{N-1} |u_i|_2   s.t.   x_{i+1} = F(G(x_i, u_i)),  x_k = x_hat_k,  x_N = x_f,
    P(drift from y_i enters the ellipsoid E_i during T_safety) <= Delta,   i = k .. N-1,

with the chance constraint transcribed as in the open loop (Eqs. 14-16):
``1 + beta_i - a_i^T y_i <= 0``, ``beta_i = q(Delta) sqrt(a_i^T X_i a_i)`` and

    X_i = X_nav(x_i) + B_i U(u_i) B_i^T + Q                                      (Eq. 14)

Eq. 14 assumes a navigation fix at every node, so the covariance of node ``i`` is a function
of ``(x_i, u_i)`` alone: at the first node of the remaining problem ``X_k`` holds
``X_nav(x_hat_k)``, the covariance of the very estimate the problem starts from (the loop
draws its navigation error from the same ``X_nav``), and at the later nodes the covariance of
the fixes to come, propagated by ``Phi`` to the worst drift instant ``t*`` (Eq. 14, second
line; :mod:`scpformer.problems.robust_rendezvous.safety`). The passive-safety constraints
hold on every remaining node ``k .. N-1`` with the same ``T_safety`` and ``N_safety``, and each
node keeps its domain: the approach ellipsoid before the absolute node ``N_ae-to-koz``, the
keep-out zone from it on (``n_ae_to_koz - k`` in the remaining problem, 0 once passed).

It is posed as a :class:`~scpformer.robust_rendezvous.RobustInstance`: target = the target's
mean elements at ``t_k``, ``x0_rtn = Psi(t_k) x_hat_k`` (the instance's ``roe0 =
Psi^{-1} x0_rtn`` is then ``x_hat_k`` exactly), ``horizon = (N - k) dt``, the same waypoint,
uncertainty model and ``Delta``. An estimate inside the approach ellipsoid while the node is
still guarded by it poses no problem (the instance refuses it): the re-plan is recorded as
``invalid_instance`` and the flown plan kept.

Warm starts of a re-plan (:data:`WARMSTARTS`): ``cold`` is the family's default, the
three-stage procedure (TPBVP -> collision avoidance -> passive safety) from the estimate;
``previous`` the last accepted plan shifted in time to node ``k`` (its states from ``k`` on,
the first replaced by the estimate, and its impulses), given to ``method="passive_safety"``
(SCvx* on Eq. 17 straight from it, Table 1's 20 solves). The learned ART start is not
offered: see :data:`UNSUPPORTED`.

Success of a flown run (:class:`RobustClosedLoopResult`): the pre-docking state ``x_f`` is
reached within :func:`derive_tolerance`, the dense flown trajectory never enters the active
ellipsoid (the keep-out check; this problem has no approach cone: it ends at the pre-docking
hold, where the deterministic family's cone begins) and every flown node passes the family's
dense Monte Carlo test of passive safety (:func:`flown_passive_safety`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np

from scpformer.dynamics.orbits import oe_to_eci, rtn_dcm, rtn_to_eci
from scpformer.dynamics.roe import psi_matrix
from scpformer.guidance.rendezvous_mpc import (
    ClosedLoopResult,
    DockingTolerance,
    ErrorModels,
    ReplanRecord,
    fly_truth,
    replan_compared,
    shifted_plan,
    terminal_tolerance,
)
from scpformer.problems.rendezvous.linear_model import linear_model
from scpformer.problems.rendezvous.scenario import TargetOrbit
from scpformer.problems.robust_rendezvous.montecarlo import (
    MonteCarloConfig,
    MonteCarloResult,
    propagate_drift_truth,
)
from scpformer.problems.robust_rendezvous.plan_dynamics import (
    osculating_rtn_map,
    target_mean_osc_map,
)
from scpformer.problems.robust_rendezvous.safety import drift_offsets
from scpformer.robust_rendezvous import RobustInstance, RobustSolverConfig, solve
from scpformer.scp.solution import Solution, Status, Trajectory
from scpformer.scp.warmstart import GivenWarmStart
from scpformer.validation import check_int, check_positive

#: Warm starts of a re-plan that the loop implements.
WARMSTARTS = ("cold", "previous")
#: Warm starts a user may ask for that the loop does not implement, and why.
UNSUPPORTED = {
    "art": (
        "the shipped robust ART model cannot start mid-horizon: it generates from time step 0 "
        "of a 100-impulse problem from t_0 with a fresh context and a learned time-step "
        "embedding; a remaining problem of N - k impulses from node k would be out of "
        "distribution"
    ),
}
#: Smallest number of impulses of a remaining problem (the scenario's ``n_nodes >= 2``).
MIN_REMAINING = 2


def check_warmstart(name: Any) -> str:
    """``name`` when it is a warm start of :data:`WARMSTARTS`; ``ValueError`` otherwise
    (naming why an unimplemented one is missing)."""
    if name in UNSUPPORTED:
        raise ValueError(f"warmstart {name!r} is not available: {UNSUPPORTED[name]}")
    if name not in WARMSTARTS:
        raise ValueError(f"warmstart must be one of {', '.join(WARMSTARTS)}, got {name!r}")
    return str(name)


@dataclass(frozen=True, kw_only=True)
class MPCConfig:
    """How the closed loop of the robust rendezvous re-plans and what it flies through.

    Attributes
    ----------
    replan_every
        ``K`` (>= 1), impulses flown between re-plans; re-plans at ``K, 2K, ...`` up to
        ``N - 2`` (:func:`replan_nodes`). Default 10: 9 re-plans over the N = 100 impulses
        (every 710 s on the default 1.29-orbit horizon).
    warmstart
        Warm start of every re-plan, one of :data:`WARMSTARTS`.
    compare
        Other warm starts solved on the same re-plan problems for comparison only.
    solver
        The family's configuration; its ``safety_mode`` must be ``"chance"``.
    errors
        Navigation, actuation and process errors of the flight (default: Table 2, the same
        models as the instance's default ``uncertainty``, which the chance constraint
        designs for).
    tolerance
        Success thresholds; ``None`` derives them (:func:`derive_tolerance`).
    samples_per_interval
        Truth outputs per interval for the dense keep-out check (default 10: every 7 s).
    burn_threshold_m_s
        Impulses of at least this norm are burns, executed with a Gates error (the
        deterministic loop's convention; default 1e-6 m/s).
    safety_samples
        Draws per node of the Monte Carlo check of the flown trajectory's passive safety
        (:func:`flown_passive_safety`; default 50, whose binomial threshold at
        ``Delta = 1e-3`` and confidence 1e-4 is 2 draws: a node fails when 3 or more of its
        50 drifts enter the ellipsoid; ~10 s a run of 100 nodes on one core).
    safety_confidence
        One-sided confidence of that binomial test (``MonteCarloResult.passes``).
    """

    replan_every: int = 10
    warmstart: str = "cold"
    compare: tuple[str, ...] = ()
    solver: RobustSolverConfig = field(default_factory=RobustSolverConfig)
    errors: ErrorModels = field(default_factory=ErrorModels)
    tolerance: DockingTolerance | None = None
    samples_per_interval: int = 10
    burn_threshold_m_s: float = 1e-6
    safety_samples: int = 50
    safety_confidence: float = 1e-4

    def __post_init__(self) -> None:
        check_int("replan_every", self.replan_every, least=1)
        check_warmstart(self.warmstart)
        compare = tuple(self.compare)
        for name in compare:
            check_warmstart(name)
        object.__setattr__(self, "compare", tuple(n for n in compare if n != self.warmstart))
        if not isinstance(self.solver, RobustSolverConfig):
            raise ValueError(f"solver must be a RobustSolverConfig, got "
                             f"{type(self.solver).__name__}")  # fmt: skip
        if self.solver.safety_mode != "chance":
            raise ValueError(f"solver.safety_mode must be 'chance' (the chance-constrained "
                             f"rendezvous), got {self.solver.safety_mode!r}")  # fmt: skip
        if not isinstance(self.errors, ErrorModels):
            raise ValueError(f"errors must be an ErrorModels, got {type(self.errors).__name__}")
        if self.tolerance is not None and not isinstance(self.tolerance, DockingTolerance):
            raise ValueError(f"tolerance must be a DockingTolerance or None, got "
                             f"{type(self.tolerance).__name__}")  # fmt: skip
        check_int("samples_per_interval", self.samples_per_interval, least=1)
        check_positive("burn_threshold_m_s", self.burn_threshold_m_s)
        check_int("safety_samples", self.safety_samples, least=1)
        confidence = check_positive("safety_confidence", self.safety_confidence)
        if confidence >= 1.0:
            raise ValueError(f"safety_confidence must be below 1, got {confidence}")


# ======================================================================================
# the remaining problem
# ======================================================================================
def replan_nodes(n_nodes: int, replan_every: int) -> list[int]:
    """Nodes of the re-plans: ``K, 2K, ...`` up to ``N - 2`` (the last remaining problem with
    two impulses); node 0 flies the open-loop plan. ``K > N - 2`` gives no re-plan."""
    return list(range(replan_every, n_nodes - MIN_REMAINING + 1, replan_every))


def remaining_instance(
    instance: RobustInstance, k: int, roe_m: np.ndarray, target_oe: np.ndarray
) -> RobustInstance:
    """Eq. 1 from node ``k`` (module docstring): ``N - k`` impulses of the same step to ``t_N``.

    ``roe_m`` (6,) is the initial mean scaled ROE [m] (the estimate) and ``target_oe`` (6,)
    the target's mean classical elements (radians) at ``t_k``.

    Raises
    ------
    ValueError
        When fewer than 2 impulses remain, or the instance is invalid (e.g. the estimate lies
        inside the approach ellipsoid while the node is still guarded by it).
    """
    sc = instance.scenario
    n_rem = sc.n_nodes - k
    if k <= 0 or n_rem < MIN_REMAINING:
        raise ValueError(f"node {k}: the remaining problem needs 0 < k <= N - {MIN_REMAINING} "
                         f"= {sc.n_nodes - MIN_REMAINING}")  # fmt: skip
    deg = np.degrees(target_oe[2:])
    target = TargetOrbit(a_m=float(target_oe[0]), e=float(target_oe[1]), i_deg=float(deg[0]),
                         raan_deg=float(deg[1]), argp_deg=float(deg[2]),
                         M_deg=float(deg[3]))  # fmt: skip
    horizon = n_rem * (instance.horizon_s / sc.n_nodes) / target.period_s
    scenario = replace(sc, n_nodes=n_rem, horizon_orbits=horizon,
                       n_ae_to_koz=max(0, sc.n_ae_to_koz - k))  # fmt: skip
    x0 = psi_matrix(target.oe) @ np.asarray(roe_m, dtype=float)
    return RobustInstance(x0_rtn=tuple(float(v) for v in x0), waypoint=instance.waypoint,
                          target=target, scenario=scenario,
                          uncertainty=instance.uncertainty)  # fmt: skip


def previous_plan(plan: Solution, shift: int, x0: np.ndarray) -> GivenWarmStart:
    """The warm start ``previous``: the plan shifted to its node ``shift``
    (:func:`~scpformer.guidance.rendezvous_mpc.shifted_plan`) with its first state replaced
    by the estimate ``x0`` (6,), which the remaining problem fixes: the SCvx* trust region
    (100 m at the start) would otherwise have to bridge the navigation error at once."""
    warm = shifted_plan(plan, shift).value
    x = np.array(warm.x)
    x[0] = x0
    return GivenWarmStart(Trajectory(x=x, u=warm.u, p=np.zeros(0)), "previous")


def accepted(sol: Solution) -> bool:
    """A converged plan that passed its verification."""
    verified = sol.verification is not None and sol.verification.passed
    return sol.trajectory is not None and verified and sol.status == Status.CONVERGED


def open_loop_plan(instance: RobustInstance, config: MPCConfig | None = None) -> Solution:
    """The open-loop plan: the family's three-stage solve of the nominal instance.

    Raises
    ------
    ValueError
        When it fails (no converged, verified plan): there is nothing to fly.
    """
    cfg = config or MPCConfig()
    sol = solve(instance, cfg.solver)
    if not accepted(sol):
        raise ValueError(f"the open-loop plan failed ({sol.status.value}): {sol.message}")
    return sol


# ======================================================================================
# success
# ======================================================================================
def derive_tolerance(
    instance: RobustInstance,
    open_loop: Solution,
    errors: ErrorModels | None = None,
    replan_every: int = 10,
    config: RobustSolverConfig | None = None,
) -> DockingTolerance:
    """The terminal tolerance of a flown run, derived like
    :meth:`~scpformer.guidance.rendezvous_mpc.DockingTolerance.derive`
    (:func:`~scpformer.guidance.rendezvous_mpc.terminal_tolerance`) from:

    * the plan's own model error: the truth-replay thresholds of the family's verification
      (``RobustVerification``: 2 m, 2 mm/s);
    * the last navigation fix, at the last re-plan node of :func:`replan_nodes` (node 0 without
      re-plans), taken at the open-loop plan's range there (the estimate's error is what the
      last plan cannot see: 3-sigma of Eqs. 10-11 in position, ``3 n sigma`` in velocity);
    * the open-loop plan's burns from that node on (at least one), each leaving its 3-sigma
      Gates fixed-term error (Eq. 12) as a velocity error at ``t_N``.

    Default instance, ``K = 10``: the last fix at node 90, ~750 m from the target, below
    ``rho_2`` (``s_2`` of Table 2: 4.1 m 1-sigma); 2 burns after it; 12.5 m and 14.9 mm/s.
    The keep-out threshold is the deterministic family's (0.02 of the normalized distance,
    4 m at the 200 m keep-out zone, 20 m at the 1 km approach ellipsoid).
    """
    errors = errors or ErrorModels()
    verification = (config or RobustSolverConfig()).verification
    nodes = replan_nodes(instance.n_nodes, replan_every)
    last = nodes[-1] if nodes else 0
    x, u = open_loop.trajectory.x, open_loop.trajectory.u
    rho = float(np.linalg.norm(linear_model(instance).rtn(x)[last, :3]))
    burns = max(1, int((np.linalg.norm(u[last:], axis=1) >= 1e-6).sum()))
    position, velocity = terminal_tolerance(
        verification.terminal_position_m, verification.terminal_velocity_m_s, rho, errors,
        instance.target.period_s, burns,
    )  # fmt: skip
    return DockingTolerance(position_m=position, velocity_m_s=velocity)


def flown_passive_safety(
    instance: RobustInstance,
    chief_oe: np.ndarray,
    rtn: np.ndarray,
    dv_planned: np.ndarray,
    dv_applied: np.ndarray,
    n_samples: int = 50,
    seed: int = 0,
    monte_carlo: MonteCarloConfig | None = None,
) -> MonteCarloResult:
    """The family's dense Monte Carlo check of passive safety, about the FLOWN trajectory.

    The family's check (:func:`scpformer.problems.robust_rendezvous.monte_carlo`) draws, at
    every node, the navigation and process errors about the plan's nominal state and a Gates
    error about its impulse, loses control and counts entries into the node's active
    ellipsoid during ``T_safety`` on a dense grid (``dense_step_s``, two-body + J2). Here the
    nominal is the truth actually flown: ``chief_oe`` (N + 1, 6) the osculating target
    elements and ``rtn`` (N, 6) the true pre-impulse relative states at the nodes, with the
    commanded impulses ``dv_planned`` (N, 3). Draw 0 of every node is the flight itself (its
    executed impulse ``dv_applied``, no added error); draws ``1 .. n_samples - 1`` add
    ``N(0, X_nav + Q)`` (mapped to RTN by ``Psi(t_i)``) and ``dv_planned + N(0, U)``. Drift:
    :func:`~scpformer.problems.robust_rendezvous.montecarlo.propagate_drift_truth` (RK4 of
    at most ``rk4_step_s``) at every point of the dense grid. The result's ``passes(
    confidence, dense=True)`` is the family's binomial test at ``Delta``.
    """
    cfg = monte_carlo or MonteCarloConfig()
    start = time.perf_counter()
    unc, sc, n = instance.uncertainty, instance.scenario, instance.n_nodes
    model = linear_model(instance)
    rng = np.random.default_rng(seed)
    rho = np.linalg.norm(rtn[:, :3], axis=1)
    sigma = rho[:, None] * unc.navigation.scale(rho)
    e = rng.standard_normal((n, n_samples, 6)) * sigma[:, None, :]
    e += rng.standard_normal((n, n_samples, 6)) @ np.linalg.cholesky(unc.process_noise.matrix).T
    du = unc.actuation.sample(dv_planned, rng, n_samples)  # (M, N, 3)
    u_exec = dv_planned[:, None, :] + np.swapaxes(du, 0, 1)
    e[:, 0], u_exec[:, 0] = 0.0, dv_applied
    states = rtn[:, None, :] + np.einsum("kij,kmj->kmi", model.Psi[:n], e)
    r_c, v_c = oe_to_eci(chief_oe[:n])
    r_d, v_d = rtn_to_eci(r_c[:, None], v_c[:, None], states)
    v_d = v_d + np.einsum("kmji,kmj->kmi", rtn_dcm(r_d, v_d), u_exec)
    chief, deputy = np.concatenate([r_c, v_c], -1), np.concatenate([r_d, v_d], -1)
    design = drift_offsets(instance.t_safety_s, sc.n_safety)
    m = max(1, math.ceil((design[1] - design[0]) / cfg.dense_step_s)) if design.size > 1 else 1
    tau = np.linspace(0.0, design[-1], (design.size - 1) * m + 1)
    E = sc.ellipsoid_E()[:n]
    d_design, d_dense = np.empty((n, n_samples)), np.empty((n, n_samples))
    chunk = max(1, 2_000_000 // (n_samples * tau.size))
    for lo in range(0, n, chunk):
        sel = slice(lo, lo + chunk)
        drift = propagate_drift_truth(chief[sel], deputy[sel], tau, cfg.rk4_step_s, sc.j2)
        d = np.linalg.norm(np.einsum("krs,kmts->kmtr", E[sel], drift[..., :3]), axis=-1)
        d_design[sel], d_dense[sel] = d[:, :, ::m].min(axis=2), d.min(axis=2)
    return MonteCarloResult(
        nodes=np.arange(n), p_design=(d_design < 1.0).mean(axis=1),
        p_dense=(d_dense < 1.0).mean(axis=1), min_distance=d_dense, n_samples=n_samples,
        delta=unc.delta, propagator="truth", wall_s=time.perf_counter() - start,
    )  # fmt: skip


# ======================================================================================
# results
# ======================================================================================
@dataclass(frozen=True)
class RobustClosedLoopResult(ClosedLoopResult):
    """A flown robust rendezvous: :class:`~scpformer.guidance.rendezvous_mpc.ClosedLoopResult`
    with the target's osculating elements ``chief_oe`` (N + 1, 6) at the nodes, the terminal
    errors taken against the pre-docking state ``x_f`` and the path checks of this problem
    (keep-out of the active ellipsoid, passive safety of every flown node)."""

    chief_oe: np.ndarray

    @property
    def terminal_position_error(self) -> float:
        """``|r(t_N) - r_f|`` of the true final state [m]."""
        return float(np.linalg.norm(self.rtn[-1, :3] - self.instance.xf_rtn[:3]))

    @property
    def terminal_velocity_error(self) -> float:
        """``|v(t_N) - v_f|`` of the true final state [m/s]."""
        return float(np.linalg.norm(self.rtn[-1, 3:] - self.instance.xf_rtn[3:]))

    @cached_property
    def passive_safety(self) -> MonteCarloResult:
        """:func:`flown_passive_safety` of the flight (seed 0: the same standard normal
        draws for every run and warm start)."""
        m = self.samples_per_interval
        return flown_passive_safety(
            self.instance, self.chief_oe, self.rtn[: self.n_nodes * m : m], self.dv_planned,
            self.dv_applied, self.config.safety_samples,
        )  # fmt: skip

    def path_violations(self) -> dict[str, Any]:
        """Dense keep-out check of the flown states (the ellipsoid guarding each interval's
        node: approach ellipsoid before ``N_ae-to-koz``, keep-out zone after) and the passive
        safety test of every node.

        Returns ``keep_out`` (worst ``1 - |E dr|``, clipped at 0), ``cone_m`` (0: no cone in
        this problem), ``passive_safety_nodes`` (nodes whose draws entering the ellipsoid
        exceed the binomial threshold at ``Delta``), ``passive_safety_p_max`` (the largest
        empirical probability) and ``count``: keep-out samples beyond the tolerance plus the
        failing nodes.
        """
        sc, m = self.instance.scenario, self.samples_per_interval
        node = np.minimum(np.arange(self.rtn.shape[0]) // m, self.n_nodes - 1)
        E = sc.ellipsoid_E()[node]
        koz = 1.0 - np.linalg.norm(np.einsum("krs,ks->kr", E, self.rtn[:, :3]), axis=1)
        mc = self.passive_safety
        failing = int((mc.counts(dense=True) > mc.threshold(self.config.safety_confidence)).sum())
        return {
            "keep_out": float(max(0.0, koz.max())),
            "cone_m": 0.0,
            "passive_safety_nodes": failing,
            "passive_safety_p_max": float(mc.p_dense.max()),
            "count": int((koz > self.tolerance.keep_out).sum()) + failing,
        }

    def summary(self) -> dict[str, Any]:
        """The row of ``runs.csv`` (without the run number)."""
        violations = self.path_violations()
        return super().summary() | {
            key: violations[key] for key in ("passive_safety_nodes", "passive_safety_p_max")
        }

    def arrays(self) -> dict[str, np.ndarray]:
        """The deterministic loop's arrays, the chief's elements and the per-node passive
        safety (empirical probability on the dense grid, smallest distance of draw 0)."""
        mc = self.passive_safety
        return super().arrays() | {
            "chief_oe": self.chief_oe, "passive_safety_p": mc.p_dense,
            "passive_safety_flown_distance": mc.min_distance[:, 0],
        }  # fmt: skip


# ======================================================================================
# the loop
# ======================================================================================
def _solver(
    sub: RobustInstance | None, previous: Solution, shift: int, cfg: MPCConfig
) -> Callable[[str], Solution]:
    """``solve_with(name)`` of a re-plan: ``cold`` the three-stage solve, ``previous`` passive
    safety from the shifted plan (:func:`previous_plan`). The solution's ``iterations`` is the
    count of convex solves of every stage it ran (:func:`stage_solves`)."""

    def solve_with(name: str) -> Solution:
        if name == "previous":
            warm = previous_plan(previous, shift, sub.roe0)
            sol = solve(sub, cfg.solver, method="passive_safety", warmstart=warm)
        else:
            sol = solve(sub, cfg.solver)
        return replace(sol, iterations=stage_solves(sol))

    return solve_with


def stage_solves(sol: Solution) -> int:
    """Convex solves of every stage of a robust solve: TPBVP, collision avoidance and passive
    safety for ``cold`` (``Solution.iterations`` counts the last stage's only), passive safety
    alone for ``previous``; the numbers a re-plan's iterations compare."""
    stages = sol.extras.get("stage_iterations", {})
    return int(sum(stages.values())) if stages else int(sol.iterations)


def prepare(sub: RobustInstance) -> None:
    """Build the remaining problem's target maps before the timed solves: the mean/osculating
    map at its nodes and the mean-ROE -> osculating-RTN spline of its drift arcs
    (:mod:`scpformer.problems.robust_rendezvous.plan_dynamics`; ~1.3 s, cached for one target
    at a time). They depend on the target's orbit alone, not on the warm start: a flight
    computer has them before the re-plan, and left in the timing they would fall on whichever
    start solves the re-plan first."""
    target_mean_osc_map(sub)
    osculating_rtn_map(sub)


def fly(
    instance: RobustInstance,
    config: MPCConfig | None = None,
    *,
    seed: int = 0,
    open_loop: Solution | None = None,
) -> RobustClosedLoopResult:
    """Fly ``instance`` in closed loop (see the module docstring).

    ``seed`` seeds the error draws (common random numbers across warm starts, as in the
    deterministic loop); ``open_loop`` is the plan of :func:`open_loop_plan`, solved when not
    given.
    """
    cfg = config or MPCConfig()
    check_int("seed", seed, least=0)
    if not isinstance(instance, RobustInstance):
        raise ValueError(f"instance must be a RobustInstance, got {type(instance).__name__}")
    open_loop = open_loop or open_loop_plan(instance, cfg)

    def replan(
        k: int, estimate: np.ndarray, target_oe: np.ndarray, plan: Solution, shift: int
    ) -> tuple[ReplanRecord, list[ReplanRecord], Solution | None]:
        try:
            sub, error = remaining_instance(instance, k, estimate, target_oe), ""
            prepare(sub)
        except ValueError as err:
            sub, error = None, str(err)
        return replan_compared(sub, error, k, cfg.warmstart, cfg.compare,
                               _solver(sub, plan, shift, cfg), accepted)  # fmt: skip

    schedule = replan_nodes(instance.n_nodes, cfg.replan_every)
    flight = fly_truth(instance, open_loop, schedule, replan, cfg.errors, seed=seed,
                       samples_per_interval=cfg.samples_per_interval,
                       burn_threshold_m_s=cfg.burn_threshold_m_s)  # fmt: skip
    tolerance = cfg.tolerance or derive_tolerance(
        instance, open_loop, cfg.errors, cfg.replan_every, cfg.solver
    )
    return RobustClosedLoopResult(instance=instance, config=cfg, tolerance=tolerance,
                                  open_loop=open_loop, chief_oe=flight.chief_oe,
                                  **flight.result_fields())  # fmt: skip
