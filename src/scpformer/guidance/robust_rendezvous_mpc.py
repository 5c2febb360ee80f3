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

Eq. 14 assumes a navigation fix at every node: the covariance of node ``i`` is then a
function of ``(x_i, u_i)`` alone, and at the first node of the remaining problem ``X_k`` holds
``X_nav(x_hat_k)``, the covariance of the very estimate the problem starts from (the loop
draws its navigation error from the same ``X_nav``). This loop takes a fix only at its
re-plans and flies the plan open loop in between, so by default (``MPCConfig.covariance =
"loop"``) every plan designs for that: fixes at the nodes ``k, k + K, ...`` and, between
them, the covariance of the last fix carried by the dynamics, plus the Gates and process
errors of every node since (``UncertaintyModel.fix_every = K``,
:func:`scpformer.dynamics.uncertainty.covariance_history`). ``covariance="eq14"`` designs
for a fix at every node; flown so, the drift entries fall late in the re-planning intervals,
where the flown dispersion exceeds Eq. 14's (measured: the closed-loop guide). Either way the
covariance is propagated by ``Phi`` to the worst drift instant ``t*`` (Eq. 14, second line;
:mod:`scpformer.problems.robust_rendezvous.safety`). The passive-safety constraints
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
(SCvx* on Eq. 17 straight from it, Table 1's 20 solves); ``art`` is PS-ART-C from node
``k``: the robust ART model (``MPCConfig.model``, default the shipped one) generates the
remaining ``N - k`` impulses with the flown prefix as its context and ``R(t_k) = -J`` of the
remaining TPBVP (:mod:`.rendezvous_art`, the deterministic loop's mid-horizon start), the
post hoc check of Eq. 8 keeps its guess or falls back to the TPBVP, and SCvx* on passive
safety starts from the result (the record's ``used``: ``art`` or ``tpbvp``); ``best`` puts
ART's guess (as ``art`` makes it) and the shifted plan of ``previous`` through the same Eq. 8
check, against the ``R(t_k) = -J`` and ``C(t_k) = 0`` ART was conditioned on, and SCvx* on
passive safety starts from the one it prefers (:func:`best_guess`; ``used``: ``art``,
``previous`` or, when the check accepts neither, ``tpbvp``, the fallback of ``art``).

Success of a flown run (:class:`RobustClosedLoopResult`): the pre-docking state ``x_f`` is
reached within :func:`derive_tolerance`, and no constraint is violated along the true flown
trajectory: the dense flown states never enter the active ellipsoid (the keep-out check; this
problem has no approach cone: it ends at the pre-docking hold, where the deterministic
family's cone begins), the free drift after every executed burn stays out of it
(:func:`flown_drift_distance`: the realized loss of control, in two-body + J2 on the dense grid
of the family's Monte Carlo) and every flown plan passes the family's dense Monte Carlo
verification of passive safety at the nodes it was flown (:func:`plans_passive_safety`:
the chance constraint of what was flown, checked in the truth model).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any, ClassVar

import numpy as np

from scpformer.dynamics.orbits import oe_to_eci, rtn_dcm, rtn_to_eci
from scpformer.dynamics.roe import psi_matrix
from scpformer.guidance.records import flyable_plan
from scpformer.guidance.rendezvous_art import FlownLog, art_provider, uses_art
from scpformer.guidance.rendezvous_mpc import (
    ClosedLoopResult,
    DockingTolerance,
    ErrorModels,
    LoopConfig,
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
    monte_carlo,
    propagate_drift_truth,
)
from scpformer.problems.robust_rendezvous.plan_dynamics import (
    osculating_rtn_map,
    target_mean_osc_map,
)
from scpformer.problems.robust_rendezvous.safety import drift_offsets, trajectory_violations
from scpformer.robust_rendezvous import RobustInstance, RobustSolverConfig, solve
from scpformer.scp.solution import Solution, Status, Trajectory
from scpformer.scp.warmstart import GivenWarmStart, WarmStartResult, timed, trajectory_cost
from scpformer.validation import check_int, check_positive
from scpformer.warmstart.art import AcceptanceCheck, FlownHistory, preferred_guess

#: Warm starts of a re-plan that the loop implements.
WARMSTARTS = ("cold", "previous", "art", "best")
#: The family of the robust ART model (:func:`~.rendezvous_art.art_provider`).
FAMILY = "robust-rendezvous"
#: Warm starts a user may ask for that the loop does not implement, and why.
UNSUPPORTED: dict[str, str] = {}
#: Covariances a plan's chance constraints may design for (:class:`MPCConfig`).
COVARIANCES = ("eq14", "loop")
#: Smallest number of impulses of a remaining problem (the scenario's ``n_nodes >= 2``).
MIN_REMAINING = 2


@dataclass(frozen=True, kw_only=True)
class MPCConfig(LoopConfig):
    """How the closed loop of the robust rendezvous re-plans and what it flies through: the
    settings of :class:`~scpformer.guidance.rendezvous_mpc.LoopConfig` (its warm starts are
    :data:`WARMSTARTS`; the default ``replan_every`` = 10 re-plans every 710 s on the default
    1.29-orbit horizon, the default ``samples_per_interval`` checks the keep-out every 7 s;
    the default ``errors`` are the models of the instance's default ``uncertainty``, which
    the chance constraint designs for) and those below.

    Attributes
    ----------
    solver
        The family's configuration; its ``safety_mode`` must be ``"chance"``.
    safety_samples
        Draws per node of the family's Monte Carlo verification of the flown plans at the
        nodes they were flown (:func:`plans_passive_safety`; default 200, whose binomial
        threshold at ``Delta = 1e-3`` and confidence 1e-4 is 3 draws: a node fails when 4 or
        more of its 200 drifts enter the ellipsoid; ~8 s a run of 100 nodes on one core).
    safety_confidence
        One-sided confidence of that binomial test (``MonteCarloResult.passes``).
    mission_risk
        The chance ``epsilon`` the loop designs for that ANY guarded node of the flight sees
        its drift enter its ellipsoid, or ``None`` (default) for the instance's own per-node
        ``Delta`` (Table 2: 1e-3). When set, every node's chance constraint, in the open-loop
        plan and in every re-plan, uses ``Delta = epsilon / N`` over the ``N`` guarded nodes:
        the uniform risk allocation of Boole's inequality, ``P(any entry) <= sum_i Delta_i =
        epsilon`` (Ono & Williams, "Iterative risk allocation", AAAI 2008, start from it).
        The paper's ``Delta = 1e-3`` per node allows up to ``1 - (1 - 1e-3)^100 = 9.5%`` per
        100-node flight; a mission that must fail at most 1 run in 100 needs ``epsilon =
        0.01``, i.e. ``Delta = 1e-4``. The Monte Carlo verification tests that ``Delta``.
    covariance
        The covariance ``X_i`` every node's chance constraint designs for
        (:data:`COVARIANCES`): ``"loop"`` (default) the loop's own navigation, a fix at each
        re-plan only (``UncertaintyModel.fix_every = replan_every``): between the fixes the
        plan is flown open loop and the covariance grows from the last fix by the dynamics,
        the Gates errors and the process noise
        (:func:`scpformer.dynamics.uncertainty.covariance_history`), and the family's Monte
        Carlo verification of every plan draws its errors the same way; ``"eq14"`` the
        paper's Eq. 14, a navigation fix before every maneuver, which the loop does not have:
        flown with it, drift entries cluster late in the re-planning intervals (the guide's
        robust section).
    """

    warmstarts: ClassVar[tuple[str, ...]] = WARMSTARTS
    unsupported: ClassVar[dict[str, str]] = UNSUPPORTED
    solver_type: ClassVar[type] = RobustSolverConfig

    solver: RobustSolverConfig = field(default_factory=RobustSolverConfig)
    safety_samples: int = 200
    safety_confidence: float = 1e-4
    mission_risk: float | None = None
    covariance: str = "loop"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.covariance not in COVARIANCES:
            raise ValueError(f"covariance must be one of {', '.join(COVARIANCES)}, "
                             f"got {self.covariance!r}")  # fmt: skip
        if self.solver.safety_mode != "chance":
            raise ValueError(f"solver.safety_mode must be 'chance' (the chance-constrained "
                             f"rendezvous), got {self.solver.safety_mode!r}")  # fmt: skip
        check_int("safety_samples", self.safety_samples, least=1)
        confidence = check_positive("safety_confidence", self.safety_confidence)
        if confidence >= 1.0:
            raise ValueError(f"safety_confidence must be below 1, got {confidence}")
        if self.mission_risk is not None:
            risk = check_positive("mission_risk", self.mission_risk)
            if risk >= 1.0:
                raise ValueError(f"mission_risk must be below 1, got {risk}")


def designed_instance(instance: RobustInstance, config: MPCConfig) -> RobustInstance:
    """``instance`` with the uncertainty the loop designs for (:class:`MPCConfig`): the
    per-node risk, its own ``Delta`` or ``config.mission_risk / N`` over its ``N`` guarded
    nodes, and the navigation fixes, before every maneuver (Eq. 14) or at the re-plans."""
    changes: dict[str, Any] = {}
    if config.mission_risk is not None:
        changes["delta"] = config.mission_risk / instance.n_nodes
    if config.covariance == "loop":
        changes["fix_every"] = config.replan_every
    if not changes:
        return instance
    return replace(instance, uncertainty=replace(instance.uncertainty, **changes))


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
    """The open-loop plan: the family's three-stage solve of the nominal instance, at the
    per-node risk the loop designs for (:func:`designed_instance`).

    Raises
    ------
    ValueError
        When it fails (no converged, verified plan): there is nothing to fly.
    """
    cfg = config or MPCConfig()
    return flyable_plan(solve(designed_instance(instance, cfg), cfg.solver), accepted)


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
    ``rho_2`` (``s_2`` of Table 2: 4.1 m 1-sigma); the plan has no burn after it (its last
    burns are at nodes 76-77), so one is counted (a re-plan's correction); 12.5 m and
    14.3 mm/s.
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


def flown_drift_distance(
    instance: RobustInstance,
    chief_oe: np.ndarray,
    rtn: np.ndarray,
    dv_applied: np.ndarray,
    monte_carlo_config: MonteCarloConfig | None = None,
) -> np.ndarray:
    """Smallest normalized distance ``|E_i dr|`` (N,) of the free drift that would follow a
    loss of control right after each flown burn: from the true pre-impulse state ``rtn``
    (N, 6) and target ``chief_oe`` (N + 1, 6) at node ``i``, the executed impulse
    ``dv_applied`` (N, 3), over ``T_safety`` in two-body + J2 on the dense grid of the
    family's Monte Carlo (``dense_step_s``, RK4 of at most ``rk4_step_s``,
    :func:`~scpformer.problems.robust_rendezvous.montecarlo.propagate_drift_truth`), against
    the node's ellipsoid (AE before ``N_ae-to-koz``, KOZ after). Below 1: the flown state was
    not passively safe."""
    cfg = monte_carlo_config or MonteCarloConfig()
    sc, n = instance.scenario, instance.n_nodes
    r_c, v_c = oe_to_eci(chief_oe[:n])
    r_d, v_d = rtn_to_eci(r_c, v_c, rtn)
    v_d = v_d + np.einsum("kji,kj->ki", rtn_dcm(r_d, v_d), dv_applied)
    chief, deputy = np.concatenate([r_c, v_c], -1), np.concatenate([r_d, v_d], -1)
    design = drift_offsets(instance.t_safety_s, sc.n_safety)
    steps = max(1, math.ceil((design[1] - design[0]) / cfg.dense_step_s)) if design.size > 1 else 1
    tau = np.linspace(0.0, design[-1], (design.size - 1) * steps + 1)
    drift = propagate_drift_truth(chief, deputy[:, None], tau, cfg.rk4_step_s, sc.j2)[:, 0]
    E = sc.ellipsoid_E()[:n]
    return np.linalg.norm(np.einsum("krs,kts->ktr", E, drift[..., :3]), axis=-1).min(axis=1)


@dataclass(frozen=True)
class FlownPlan:
    """A plan the loop flew: from node ``start`` (of the flight) it was the flown plan for
    ``nodes`` impulses; ``instance`` is the problem it solves (the remaining problem from its
    estimate; the nominal instance for the open-loop plan)."""

    start: int
    nodes: int
    instance: RobustInstance
    plan: Solution


def plans_passive_safety(
    flown: list[FlownPlan], n_samples: int, confidence: float
) -> tuple[np.ndarray, np.ndarray]:
    """The family's dense Monte Carlo verification of passive safety
    (:func:`scpformer.problems.robust_rendezvous.monte_carlo`, two-body + J2 drift on the dense
    grid) of every flown plan at the nodes it was flown: navigation and process errors about
    the plan's nominal state (its truth replay from its own initial state, the estimate),
    Gates errors about its impulses, loss of control, entries into the node's ellipsoid
    during ``T_safety``. Returns per node of the flight the empirical violation probability
    (N,) and whether the node fails the family's binomial test at ``Delta`` (N,) bool
    (``MonteCarloResult.counts`` above ``threshold(confidence)``). Seed 0 for every plan."""
    p, failing = [], []
    for seg in flown:
        x, u = seg.plan.trajectory.x, seg.plan.trajectory.u
        mc = monte_carlo(seg.instance, x, u, MonteCarloConfig(n_samples=n_samples),
                         nodes=np.arange(seg.nodes),
                         dynamics=seg.plan.extras.get("dynamics", "nonlinear"))  # fmt: skip
        p.append(mc.p_dense)
        failing.append(mc.counts(dense=True) > mc.threshold(confidence))
    return np.concatenate(p), np.concatenate(failing)


# ======================================================================================
# results
# ======================================================================================
@dataclass(frozen=True, kw_only=True)
class RobustClosedLoopResult(ClosedLoopResult):
    """A flown robust rendezvous: :class:`~scpformer.guidance.rendezvous_mpc.ClosedLoopResult`
    with the plans flown (``flown``, in order), the terminal errors taken against the
    pre-docking state ``x_f`` and the path checks of this problem (keep-out of the active
    ellipsoid, passive safety of the flown states and of the flown plans, from the target's
    osculating elements ``chief_oe`` at the nodes)."""

    flown: list[FlownPlan]

    @property
    def terminal_position_error(self) -> float:
        """``|r(t_N) - r_f|`` of the true final state [m]."""
        return float(np.linalg.norm(self.rtn[-1, :3] - self.instance.xf_rtn[:3]))

    @property
    def terminal_velocity_error(self) -> float:
        """``|v(t_N) - v_f|`` of the true final state [m/s]."""
        return float(np.linalg.norm(self.rtn[-1, 3:] - self.instance.xf_rtn[3:]))

    @cached_property
    def drift_distance(self) -> np.ndarray:
        """:func:`flown_drift_distance` of the flight, (N,)."""
        m = self.samples_per_interval
        rtn = self.rtn[: self.n_nodes * m : m]
        return flown_drift_distance(self.instance, self.chief_oe, rtn, self.dv_applied)

    @cached_property
    def plan_safety(self) -> tuple[np.ndarray, np.ndarray]:
        """:func:`plans_passive_safety` of the flown plans: (N,) probabilities, (N,) fails."""
        return plans_passive_safety(self.flown, self.config.safety_samples,
                                    self.config.safety_confidence)  # fmt: skip

    def path_violations(self) -> dict[str, Any]:
        """The path checks of the flight.

        * ``keep_out``: worst ``1 - |E dr|`` (clipped at 0) of the dense flown states against
          the ellipsoid guarding each interval's node (AE before ``N_ae-to-koz``, KOZ after);
          samples beyond ``tolerance.keep_out`` count;
        * ``drift_entries``: flown nodes whose free drift after the executed burn enters the
          node's ellipsoid (:func:`flown_drift_distance` below 1; the realized loss of control);
        * ``passive_safety_nodes``: flown nodes failing the family's Monte Carlo test of the
          plan flown there (:func:`plans_passive_safety`), ``passive_safety_p_max`` the largest
          empirical probability;
        * ``cone_m``: 0 (this problem has no approach cone); ``count``: the sum of the three
          counts.
        """
        sc, m = self.instance.scenario, self.samples_per_interval
        node = np.minimum(np.arange(self.rtn.shape[0]) // m, self.n_nodes - 1)
        E = sc.ellipsoid_E()[node]
        koz = 1.0 - np.linalg.norm(np.einsum("krs,ks->kr", E, self.rtn[:, :3]), axis=1)
        p, failing = self.plan_safety
        entries = int((self.drift_distance < 1.0).sum())
        count = int((koz > self.tolerance.keep_out).sum()) + entries + int(failing.sum())
        return {
            "keep_out": float(max(0.0, koz.max())),
            "cone_m": 0.0,
            "drift_entries": entries,
            "passive_safety_nodes": int(failing.sum()),
            "passive_safety_p_max": float(p.max()),
            "count": count,
        }

    def summary(self) -> dict[str, Any]:
        """The row of ``runs.csv`` (without the run number)."""
        violations = self.path_violations()
        keys = ("drift_entries", "passive_safety_nodes", "passive_safety_p_max")
        return super().summary() | {key: violations[key] for key in keys}

    def arrays(self) -> dict[str, np.ndarray]:
        """The deterministic loop's arrays, the chief's elements, the flown drift distances and
        the flown plans' violation probabilities per node."""
        return super().arrays() | {
            "chief_oe": self.chief_oe, "drift_distance": self.drift_distance,
            "passive_safety_p": self.plan_safety[0],
            "flown_plan_start": np.array([seg.start for seg in self.flown]),
        }  # fmt: skip


# ======================================================================================
# the warm start best
# ======================================================================================
def previous_candidate(
    sub: RobustInstance, warm: GivenWarmStart, mode: str, dynamics: str = "nonlinear"
) -> WarmStartResult:
    """The shifted plan of ``previous`` (:func:`previous_plan`) as a candidate of the post hoc
    check: its guess with the record's ``cost`` = ``sum |u|`` [m/s] and ``constraint_to_go`` =
    ``C(t_k)``, the Eq. 7 budget of its states and impulses in the remaining problem ``sub``
    (passive safety ``mode``, plan model ``dynamics``; the measure ART's own guess is given,
    ``RobustArtFamily.trajectory_ctg``); ``time_s`` is the time this took."""
    start = time.perf_counter()
    prev = warm.guess(sub)
    x, u = prev.trajectory.x, prev.trajectory.u
    ctg = float(trajectory_violations(sub, x, u, mode, dynamics=dynamics)[0])
    record = replace(prev.record, cost=trajectory_cost(prev.trajectory), constraint_to_go=ctg)
    return replace(prev, record=timed(record, start))


def best_guess(
    art: WarmStartResult, previous: WarmStartResult, check: AcceptanceCheck
) -> WarmStartResult:
    """The guess of the warm start ``best``: of ART's guess and the shifted plan, the one the
    post hoc check prefers (robust ART paper, Eq. 8).

    Both are put through Eq. 8, ``E_R = (R - R_des) / R_des`` and ``E_C = C - C_des``, against
    the desired ``R_des = R(t_k) = -J`` (the remaining TPBVP) and ``C_des = C(t_k)`` ART was
    conditioned on (``art.record.details``: ``rtg0``, ``ctg0``; ART's own guess by its
    ``art_cost`` and ``art_constraint_to_go``, whatever its decision); the preferred one
    (:func:`~scpformer.warmstart.art.preferred_guess`: accepted first, then the smaller
    ``E_C``, then the smaller ``|E_R|``, ART on a tie) is returned when the check accepts it.

    When the check accepts neither, the paper's logic holds (Sec. 5: a guess that fails the
    check is replaced by the CVX fallback): ``art``'s own result is returned, the remaining
    TPBVP (its ``used`` is ``tpbvp``); an unaccepted shifted plan is never preferred to it.
    When ART has no guess (the TPBVP failed: no ``R(t_k)`` to condition on, nothing to fall
    back to) the shifted plan is returned unchecked.

    Parameters
    ----------
    art
        ``ArtWarmStart.guess`` of the remaining problem (the start ``art``).
    previous
        :func:`previous_candidate` of the same problem.
    check
        The Eq. 8 acceptance region (the ART provider's).

    Returns
    -------
    WarmStartResult
        The chosen guess; its record names it (``used``: ``art``, ``previous`` or ``tpbvp``),
        ``time_s`` covers ART's guess (TPBVP and generation) and the checks, ``details`` adds
        ``best`` (the start chosen), ``accepted`` (each candidate's decision) and the shifted
        plan's ``previous_E_R`` and ``previous_E_C``; ``solution`` is ART's TPBVP, a stage of
        the re-plan's solve whichever guess starts it.
    """
    start = time.perf_counter()
    details = art.record.details
    if "rtg0" not in details:  # ART generated nothing
        reason = f"best: previous (ART has no guess: {art.record.reason})"
        record = replace(previous.record, reason=reason, time_s=art.record.time_s,
                         details={**details, "best": "previous"})  # fmt: skip
        return replace(previous, record=record)
    chosen, decisions = preferred_guess(
        check, rtg_desired=details["rtg0"], ctg_desired=details["ctg0"],
        candidates={"art": (details["art_cost"], details["art_constraint_to_go"]),
                    "previous": (previous.record.cost, previous.record.constraint_to_go)},
    )  # fmt: skip
    reason = "best: " + "; ".join(f"{n} ({d.reason})" for n, d in decisions.items())
    result = previous if chosen == "previous" and decisions[chosen].accepted else art
    used = "previous" if result is previous else art.record.used
    extra = {"best": used, "accepted": {n: d.accepted for n, d in decisions.items()},
             "previous_E_R": decisions["previous"].E_R,
             "previous_E_C": decisions["previous"].E_C}  # fmt: skip
    elapsed = art.record.time_s + previous.record.time_s + time.perf_counter() - start
    record = replace(result.record, reason=reason, time_s=elapsed, details={**details, **extra})
    return WarmStartResult(result.trajectory, record, art.solution)


# ======================================================================================
# the loop
# ======================================================================================
def _solver(
    sub: RobustInstance | None, previous: Solution, shift: int, cfg: MPCConfig,
    history: FlownHistory | None = None,
) -> Callable[[str], Solution]:  # fmt: skip
    """``solve_with(name)`` of a re-plan: ``cold`` the three-stage solve, the others passive
    safety from the warm start of :func:`_warmstart`. The solution's ``iterations`` is the
    count of convex solves of every stage it ran (:func:`stage_solves`)."""

    def solve_with(name: str) -> Solution:
        if name == "cold":
            sol = solve(sub, cfg.solver)
        else:
            warm = _warmstart(name, sub, previous, shift, cfg, history)
            sol = solve(sub, cfg.solver, method="passive_safety", warmstart=warm)
        return replace(sol, iterations=stage_solves(sol))

    return solve_with


def _warmstart(
    name: str, sub: RobustInstance, previous: Solution, shift: int, cfg: MPCConfig,
    history: FlownHistory | None,
) -> GivenWarmStart | WarmStartResult:  # fmt: skip
    """The passive-safety warm start ``name`` of a re-plan: ``previous`` the shifted plan
    (:func:`previous_plan`); ``art`` the robust ART model's guess started mid-horizon with the
    flown ``history`` as its context (PS-ART-C of the robust ART paper, its post hoc check of
    Eq. 8 with the TPBVP as the fallback, ``R(t_k) = -J`` of the remaining TPBVP;
    :mod:`.rendezvous_art`); ``best`` the one of the two Eq. 8 prefers (:func:`best_guess`).
    Everything here runs inside the re-plan's timing."""
    warm = previous_plan(previous, shift, sub.roe0)
    if name == "previous":
        return warm
    provider = art_provider(cfg.model, cfg.solver, FAMILY)
    art = provider.guess(sub, history)
    if name == "art":
        return art
    candidate = previous_candidate(sub, warm, cfg.solver.safety_mode, cfg.solver.dynamics)
    return best_guess(art, candidate, provider.acceptance or AcceptanceCheck())


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
    instance = designed_instance(instance, cfg)  # every re-plan keeps its Delta

    starts: list[tuple[int, RobustInstance, Solution]] = [(0, instance, open_loop)]
    log = FlownLog(instance, open_loop) if uses_art(cfg) else None
    if log:  # the model is loaded before the re-plans are timed
        art_provider(cfg.model, cfg.solver, FAMILY)

    def replan(
        k: int, estimate: np.ndarray, target_oe: np.ndarray, plan: Solution, shift: int
    ) -> tuple[ReplanRecord, list[ReplanRecord], Solution | None]:
        try:
            sub, error = remaining_instance(instance, k, estimate, target_oe), ""
            prepare(sub)
        except ValueError as err:
            sub, error = None, str(err)
        history = log.history(k, estimate, plan, shift) if log else None
        record, others, sol = replan_compared(sub, error, k, cfg.warmstart, cfg.compare,
                                              _solver(sub, plan, shift, cfg, history),
                                              accepted, cfg.time_budget_s)  # fmt: skip
        if record.accepted and sol is not None and sub is not None:  # flown from k on
            starts.append((k, sub, sol))
        return record, others, sol

    schedule = replan_nodes(instance.n_nodes, cfg.replan_every)
    flight = fly_truth(instance, open_loop, schedule, replan, cfg.errors, seed=seed,
                       samples_per_interval=cfg.samples_per_interval,
                       burn_threshold_m_s=cfg.burn_threshold_m_s)  # fmt: skip
    tolerance = cfg.tolerance or derive_tolerance(
        instance, open_loop, cfg.errors, cfg.replan_every, cfg.solver
    )
    ends = [k for k, _, _ in starts[1:]] + [instance.n_nodes]
    flown = [FlownPlan(start=k, nodes=end - k, instance=sub, plan=sol)
             for (k, sub, sol), end in zip(starts, ends, strict=True)]  # fmt: skip
    return RobustClosedLoopResult(instance=instance, config=cfg, tolerance=tolerance,
                                  open_loop=open_loop, flown=flown,
                                  **flight.flight_fields())  # fmt: skip
