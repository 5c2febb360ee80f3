"""Closed-loop guidance of the ISS rendezvous: shrinking-horizon model predictive control.

The open-loop plan of the ART paper (Problem 3, Section 4) is solved once from the nominal
instance. The loop then flies it through the truth model and re-plans on board:

1. every ``replan_every`` impulses (node ``k = K, 2K, ...``; the first ``K`` impulses are the
   open-loop plan's, solved from the known initial state) the navigation filter gives an
   estimate of the servicer's MEAN scaled ROE: the true state (osculating, two-body + J2)
   averaged to mean elements exactly as the verification defines them
   (:func:`scpformer.dynamics.mean_elements.osculating_to_mean_qns`), plus a navigation error
   ``~ N(0, X_nav(rho))`` of the robust ART paper (Eqs. 10-11, Table 2;
   :class:`~scpformer.dynamics.uncertainty.NavigationModel`);
2. the remaining problem is Problem 3 from that estimate over the nodes ``k .. N`` (a shrinking
   horizon to the fixed final time ``t_N``, the same time step, waypoint hold at ``N_wp``,
   approach cone and docking port), posed as a :class:`RendezvousInstance` of ``N - k``
   impulses whose target elements are the target's mean elements at ``t_k``
   (:func:`remaining_instance`), and solved by the family's public ``solve`` with the
   chosen warm start; the plan is checked like any solution (its nonlinear replay,
   :mod:`scpformer.problems.rendezvous.verification`). From the waypoint node on
   (``k >= N_wp``) the remaining problem is the final approach: the waypoint is passed, the
   approach cone holds from node ``k + 1`` on (the estimate at ``k`` is given and may lie
   just outside it) and the keep-out zone no longer applies
   (:attr:`~scpformer.problems.rendezvous.scenario.RendezvousScenario.waypoint_passed`);
3. the plan's next ``K`` impulses are applied through the truth model (two-body + J2 of
   :func:`scpformer.dynamics.truth.propagate_relative`, as the verification and the robust
   family's truth replay do), each with a Gates execution error (Eqs. 12-13,
   :class:`~scpformer.dynamics.uncertainty.GatesModel`) and with the process noise ``Q``
   added to the state at every node (Table 2, mapped to RTN by ``Psi(t_k)``, Eq. 9, as the
   robust family's Monte Carlo check does).

A re-plan that fails (no trajectory, or a trajectory whose verification fails) is recorded,
and the last accepted plan keeps being flown. Re-plans continue through the final approach,
up to ``N - 2`` (:func:`replan_nodes`: two impulses still reach the docking conditions); the
node ``N_wp - 1`` poses no problem (one impulse cannot reach the waypoint hold) and is
replaced by ``N_wp - 2``.

Warm starts of a re-plan (:data:`WARMSTARTS`): ``cold`` is the family's default start (the
convex Problem 2 solved from the estimate); ``previous`` the last accepted plan shifted in
time to node ``k`` (the classical MPC warm start), given to ``solve`` as a
:class:`~scpformer.scp.warmstart.GivenWarmStart`; ``art`` the ART model started mid-horizon,
its context the flown prefix (Celestini et al., RA-L 2024; :mod:`.rendezvous_art`); ``best``
ART's guess or the shifted previous plan, the one the post hoc check (robust ART paper, Eq. 8)
prefers. Each re-plan records the start the SCP began from (:attr:`ReplanRecord.used`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from os import PathLike
from typing import Any, ClassVar

import numpy as np

from scpformer.dynamics.mean_elements import osculating_to_mean_qns, qns_difference
from scpformer.dynamics.orbits import (
    eci_to_oe,
    j2_secular_rates,
    oe_to_eci,
    qns_to_oe,
    rtn_to_eci,
)
from scpformer.dynamics.roe import oe_to_roe, psi_matrix, qns_offset_to_roe
from scpformer.dynamics.truth import propagate_relative
from scpformer.dynamics.uncertainty import GatesModel, NavigationModel, ProcessNoise, burn_frame
from scpformer.guidance.records import (
    check_budget,
    flyable_plan,
    replan_statistics,
    replan_tables,
    within_budget,
)
from scpformer.guidance.rendezvous_art import (
    LEARNED,
    FlownLog,
    art_provider,
    solve_learned,
    uses_art,
)
from scpformer.problems.rendezvous.constraints import cone_slack, keep_out_slack
from scpformer.problems.rendezvous.linear_model import linear_model
from scpformer.problems.rendezvous.scenario import MIN_PASSED_NODES, TargetOrbit
from scpformer.problems.rendezvous.verification import osculating_initial_state
from scpformer.rendezvous import (
    RendezvousInstance,
    RendezvousSolverConfig,
    VerificationTolerances,
    solve,
)
from scpformer.scp.solution import Solution, Status, Trajectory
from scpformer.scp.warmstart import GivenWarmStart
from scpformer.validation import check_bool, check_int, check_positive
from scpformer.warmstart.art import FlownHistory

#: Warm starts of a re-plan that the loop implements.
WARMSTARTS = ("cold", "previous", "art", "best")
#: Warm starts a user may ask for that the loop does not implement, and why (none today).
UNSUPPORTED: dict[str, str] = {}
#: Accuracy of the mean elements of a navigation fix: samples per orbit of the averaging and
#: RK4 steps per sample (those of :func:`osculating_to_mean_qns`, ~2 mm in the ROE).
MEAN_SAMPLES, MEAN_SUBSTEPS = 48, 12
#: Burns of the default plan after its last re-plan node (K = 10: node 90 = N_wp): at the
#: waypoint node N_wp and the final one at N - 1 (measured: nodes 90 and 99 of its 7 burns).
TAIL_BURNS = 2


def check_warmstart(
    name: Any,
    warmstarts: tuple[str, ...] = WARMSTARTS,
    unsupported: dict[str, str] = UNSUPPORTED,
) -> str:
    """``name`` when it is a warm start of ``warmstarts`` (default :data:`WARMSTARTS`);
    ``ValueError`` otherwise (naming why one of ``unsupported`` is missing)."""
    if name in unsupported:
        raise ValueError(f"warmstart {name!r} is not available: {unsupported[name]}")
    if name not in warmstarts:
        raise ValueError(f"warmstart must be one of {', '.join(warmstarts)}, got {name!r}")
    return str(name)


# ======================================================================================
# configuration
# ======================================================================================
@dataclass(frozen=True, kw_only=True)
class ErrorModels:
    """The errors the closed loop flies with (robust ART paper, Section 4, Table 2).

    A ``None`` model means no error of that kind; :meth:`none` turns every error off (the loop
    then reproduces the open-loop plan up to the model error it corrects).

    Attributes
    ----------
    navigation
        Error of each navigation fix in scaled mean ROE, ``N(0, X_nav(rho))`` with
        ``X_nav = rho^2 diag(s(rho))^2`` (Eqs. 10-11; ~0.3 m along-track at the 74-104 m
        ranges of the final approach with Table 2's ``s_2``).
    actuation
        Gates execution error of every impulse (Eqs. 12-13; 0.3 mm/s fixed per axis).
    process_noise
        ``N(0, Q_roe)`` added to the true state at every node (Table 2: 1 mm per element).
    """

    navigation: NavigationModel | None = field(default_factory=NavigationModel)
    actuation: GatesModel | None = field(default_factory=GatesModel)
    process_noise: ProcessNoise | None = field(default_factory=ProcessNoise)

    def __post_init__(self) -> None:
        for name, cls in (
            ("navigation", NavigationModel),
            ("actuation", GatesModel),
            ("process_noise", ProcessNoise),
        ):
            value = getattr(self, name)
            if value is not None and not isinstance(value, cls):
                raise ValueError(f"errors.{name} must be a {cls.__name__} or None, "
                                 f"got {type(value).__name__}")  # fmt: skip

    @classmethod
    def none(cls) -> ErrorModels:
        """No navigation, actuation or process error."""
        return cls(navigation=None, actuation=None, process_noise=None)


def navigation_position_sigma(nav: NavigationModel, rho: float) -> float:
    """1-sigma RTN position error [m] of a navigation fix at range ``rho`` [m] (Eqs. 9-11).

    The per-element ROE sigmas ``rho s(rho)`` mapped to position by the near-circular
    ``Psi`` (D'Amico 2010): ``dr_R = a da - a dex cos u - a dey sin u``, ``dr_T = a dlambda +
    2 (a dex sin u - a dey cos u)``, ``dr_N = a dix sin u - a diy cos u``, averaged over the
    argument of latitude ``u``; returns ``sqrt(var_R + var_T + var_N)``.
    """
    sig = rho * np.asarray(nav.scale(rho), dtype=float)
    var_r = sig[0] ** 2 + 0.5 * (sig[2] ** 2 + sig[3] ** 2)
    var_t = sig[1] ** 2 + 2.0 * (sig[2] ** 2 + sig[3] ** 2)
    var_n = 0.5 * (sig[4] ** 2 + sig[5] ** 2)
    return float(math.sqrt(var_r + var_t + var_n))


def terminal_tolerance(
    plan_position_m: float, plan_velocity_m_s: float, rho: float, errors: ErrorModels,
    period_s: float, tail_burns: int,
) -> tuple[float, float]:  # fmt: skip
    """Terminal miss [m] and velocity [m/s] a closed loop may leave, from its error sources.

    ``plan_*``: the plan's own model error (a nominal replay's verification thresholds);
    ``rho`` [m]: the range of the last navigation fix, whose 3-sigma RTN position error
    ``3 sigma(rho)`` (:func:`navigation_position_sigma`) and velocity counterpart
    ``3 n sigma(rho)`` (``n = 2 pi / period_s``) reach ``t_N``; ``tail_burns``: burns flown
    after the last re-plan, each leaving the 3-sigma of Eq. 12's fixed terms,
    ``sqrt(sigma_r^2 + 2 sigma_a^2)``, as a velocity error. Returns
    ``(sqrt(p^2 + (3 sigma)^2), sqrt(v^2 + tail (3 sigma_act)^2 + (3 n sigma)^2))``.
    """
    sigma_pos = navigation_position_sigma(errors.navigation, rho) if errors.navigation else 0.0
    act = errors.actuation
    sigma_act = math.sqrt(act.sigma_r**2 + 2.0 * act.sigma_a**2) if act else 0.0
    n_mean = 2.0 * math.pi / period_s
    position = math.hypot(plan_position_m, 3.0 * sigma_pos)
    velocity = math.sqrt(
        plan_velocity_m_s**2 + tail_burns * (3.0 * sigma_act) ** 2
        + (3.0 * n_mean * sigma_pos) ** 2
    )  # fmt: skip
    return position, velocity


@dataclass(frozen=True, kw_only=True)
class DockingTolerance:
    """Success thresholds of a flown rendezvous (not in the papers; derived in :meth:`derive`).

    Attributes
    ----------
    position_m
        Largest miss ``|r(t_N) - dr_dp|`` of the true final state [m].
    velocity_m_s
        Largest ``|v(t_N)|`` of the true final state [m/s].
    keep_out
        Largest ``1 - |E_koz dr|`` along the true flown trajectory up to the waypoint (dense)
        [-]; the verification's threshold of a nominal replay
        (``VerificationTolerances.keep_out``, 0.02: 1.2-2.6 m at the semi-axes 60-123 m).
    cone_m
        Largest approach-cone violation ``|d| cos gamma - n.d`` from the waypoint on (dense)
        [m]; the verification's ``cone_m`` (0.5 m).
    """

    position_m: float = 2.63  # derive() of the default instance and errors, rounded [m]
    velocity_m_s: float = 3.55e-3  # same [m/s]
    keep_out: float = 0.02
    cone_m: float = 0.5

    def __post_init__(self) -> None:
        for name in ("position_m", "velocity_m_s", "keep_out", "cone_m"):
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"tolerance.{name} must be a positive number, got {value}")
            object.__setattr__(self, name, value)

    @classmethod
    def derive(
        cls,
        instance: RendezvousInstance,
        errors: ErrorModels | None = None,
        verification: VerificationTolerances | None = None,
        tail_burns: int = TAIL_BURNS,
    ) -> DockingTolerance:
        """The tolerance of a closed-loop docking, from the approach geometry and the errors.

        With ``K = 10`` the last re-plan is at the waypoint node ``N_wp`` (:func:`replan_nodes`),
        at the waypoint ``dr_wp`` (104 m from the target, Table 1); the last
        ``waypoint_offset`` intervals (the final approach in the cone) are flown on that plan.
        Every term below is one source's error at ``t_N``:

        * the plan's own model error: the verification's ``terminal_position_m`` (2 m) and
          ``terminal_velocity_m_s`` (2 mm/s) of a nominal replay (measured maxima 0.68 m and
          0.46 mm/s on 100 plans);
        * the last navigation fix, taken at about the waypoint's range ``rho = |dr_wp|``:
          3-sigma RTN position error (Eqs. 10-11, Table 2 ``s_2``: 0.57 m 1-sigma at 104 m,
          :func:`navigation_position_sigma`) and its velocity counterpart ``n x`` that, at the
          target's mean motion ``n``;
        * the execution errors of the burns after the last re-plan (``tail_burns``: 2, the
          default plan's burns at the waypoint node and at ``N - 1``), each persisting to
          ``t_N`` as a velocity error: 3-sigma of Eq. 12's fixed terms,
          ``sqrt(sigma_r^2 + 2 sigma_a^2)`` = 0.52 mm/s 1-sigma in 3-D.

        Position: ``sqrt(2^2 + (3 x 0.57)^2) = 2.63 m``, capped by the radius of the approach
        cone's cross-section at the docking port, ``setback tan(gamma_ac) = 5 tan 30 deg =
        2.89 m`` (Table 1 geometry: a larger lateral miss leaves the cone the approach is
        constrained to). Velocity: ``sqrt(2^2 + 2 (3 x 0.52)^2 + (3 n 0.57)^2)`` = 3.55 mm/s
        (``3 n 0.57 m`` = 1.93 mm/s).
        Path constraints: the verification's keep-out and cone thresholds.
        """
        errors = errors or ErrorModels()
        tol = verification or VerificationTolerances()
        check_int("tail_burns", tail_burns, least=0)
        sc = instance.scenario
        position, velocity = terminal_tolerance(
            tol.terminal_position_m, tol.terminal_velocity_m_s,
            float(np.linalg.norm(sc.waypoint_m)), errors, instance.target.period_s, tail_burns,
        )  # fmt: skip
        cone_radius = sc.cone_vertex_setback_m * math.tan(math.radians(sc.cone_half_angle_deg))
        if cone_radius > 0.0:
            position = min(position, max(cone_radius, tol.terminal_position_m))
        return cls(position_m=position, velocity_m_s=velocity, keep_out=tol.keep_out,
                   cone_m=tol.cone_m)  # fmt: skip


@dataclass(frozen=True, kw_only=True)
class LoopConfig:
    """The settings the closed loops of both rendezvous families share; each family's
    ``MPCConfig`` extends it with its ``solver`` (a :attr:`solver_type`) and its own settings,
    and names its warm starts (:attr:`warmstarts`, :attr:`unsupported`).

    Attributes
    ----------
    replan_every
        ``K``, impulses flown between re-plans (>= 1); re-plans happen at nodes
        ``K, 2K, ...`` up to ``N - 2`` (the family's ``replan_nodes``). Default 10: 9
        re-plans over N = 100 impulses.
    warmstart
        Warm start of every re-plan, one of the family's ``WARMSTARTS``.
    compare
        Other warm starts solved on the same re-plan instances for comparison only (their
        plans are not flown): per re-plan cost, iterations and wall time of each. The flown
        start is dropped from it.
    errors
        Navigation, actuation and process errors (default: robust ART paper Table 2).
    tolerance
        Success thresholds; ``None`` derives them from the instance and the errors.
    samples_per_interval
        Truth outputs per interval for the dense constraint check of the flown trajectory
        (default 10).
    burn_threshold_m_s
        Impulses of at least this norm are burns and executed with a Gates error; smaller
        ones are applied as planned (default 1e-6 m/s). A plan's impulses are either burns
        (mm/s to cm/s) or conic round-off (the default rendezvous plan: 7 burns of 5-63 mm/s,
        93 impulses below 3e-9 m/s); no thruster fires for the latter, and Eq. 12's fixed
        terms (0.3 mm/s) would otherwise add a burn error at every node.
    model
        The ART model of the learned starts (``art``, ``best``): a training run folder or
        checkpoint, or None (``default``) for the family's shipped model; only with one of
        those starts.
    time_budget_s
        Wall seconds a re-plan may take (warm start, solve and verification); a later one is
        not flown and recorded as late (:func:`~scpformer.guidance.records.within_budget`).
        None (default): no budget. The re-planning period (710 s by default) is far above
        any re-plan measured here, so the budget is for studying slower computers.

    Raises
    ------
    ValueError
        Naming the field that is out of range or of the wrong type.
    """

    warmstarts: ClassVar[tuple[str, ...]] = WARMSTARTS
    unsupported: ClassVar[dict[str, str]] = UNSUPPORTED
    solver_type: ClassVar[type] = RendezvousSolverConfig

    replan_every: int = 10
    warmstart: str = "cold"
    compare: tuple[str, ...] = ()
    errors: ErrorModels = field(default_factory=ErrorModels)
    tolerance: DockingTolerance | None = None
    samples_per_interval: int = 10
    burn_threshold_m_s: float = 1e-6
    model: str | None = None
    time_budget_s: float | None = None

    def __post_init__(self) -> None:
        check_int("replan_every", self.replan_every, least=1)
        object.__setattr__(self, "time_budget_s", check_budget(self.time_budget_s))
        for name in (self.warmstart, *self.compare):
            check_warmstart(name, self.warmstarts, self.unsupported)
        compare = tuple(n for n in self.compare if n != self.warmstart)
        object.__setattr__(self, "compare", compare)
        solver = getattr(self, "solver", None)
        if not isinstance(solver, self.solver_type):
            raise ValueError(f"solver must be a {self.solver_type.__name__}, got "
                             f"{type(solver).__name__}")  # fmt: skip
        if not isinstance(self.errors, ErrorModels):
            raise ValueError(f"errors must be an ErrorModels, got {type(self.errors).__name__}")
        if self.tolerance is not None and not isinstance(self.tolerance, DockingTolerance):
            raise ValueError(f"tolerance must be a DockingTolerance or None, got "
                             f"{type(self.tolerance).__name__}")  # fmt: skip
        check_int("samples_per_interval", self.samples_per_interval, least=1)
        check_positive("burn_threshold_m_s", self.burn_threshold_m_s)
        self._check_model()

    def _check_model(self) -> None:
        if self.model is None:
            return
        if not isinstance(self.model, str | PathLike):
            raise ValueError(f"model must be a path or None, got {type(self.model).__name__}")
        if not uses_art(self):
            raise ValueError("model: used with the warm starts art and best only")
        object.__setattr__(self, "model", str(self.model))


@dataclass(frozen=True, kw_only=True)
class MPCConfig(LoopConfig):
    """How the closed loop of the rendezvous re-plans and what it flies through: the settings
    of :class:`LoopConfig` and the two below. With the default ``replan_every`` = 10 (the
    waypoint offset of Table 1) the re-plans are at nodes 10, 20, ..., 90, the last at the
    waypoint node, re-planning the final approach; the default ``samples_per_interval``
    checks the flown trajectory every ~11 s on the default 2-orbit, 100-impulse instance.

    Attributes
    ----------
    solver
        The family's SCP and verification constants (default: ART paper Table 1).
    accept_max_iterations
        Accept a re-plan that reached the iteration limit when its verification passes
        (default True): every SCP iterate of this family satisfies Problem 3 in the model
        (the keep-out cut is conservative, Eqs. 15-16) and the best one is returned.
    """

    solver: RendezvousSolverConfig = field(default_factory=RendezvousSolverConfig)
    accept_max_iterations: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        check_bool("accept_max_iterations", self.accept_max_iterations)


# ======================================================================================
# results
# ======================================================================================
@dataclass(frozen=True)
class ReplanRecord:
    """One re-plan (or one comparison solve of the same re-plan instance)."""

    node: int  # node k it starts from
    warmstart: str
    accepted: bool  # a verified trajectory: flown from here on (for the flown warm start)
    status: str  # Solution.status, or "invalid_instance" when the estimate poses none
    cost: float  # sum |dv| of the plan [m/s] (nan without one)
    iterations: int
    wall_s: float  # wall time of the solve, warm start and verification included [s]
    message: str
    used: str = ""  # the start the SCP began from, as its solve records it (cold: convex)
    late: bool = False  # over the time budget: not accepted (records.within_budget)


@dataclass(frozen=True)
class Flight:
    """What :func:`fly_truth` flew, shared by the rendezvous families' closed loops.

    ``t`` (M,) and ``rtn`` (M, 6): the true relative state [m, m/s] every
    ``1 / samples_per_interval`` of an interval, node ``k`` at index ``k * m`` (pre-impulse),
    the final state last. ``dv_planned`` and ``dv_applied`` (N, 3) [m/s]: commanded and
    executed impulses (RTN of the servicer). ``replans`` and ``comparisons``: the flown and
    the comparison re-plans. ``estimates`` (R, 6) [m]: the navigation estimates of the
    re-plans (mean scaled ROE), ``truth_roe`` (R, 6) the true mean ROE. ``chief_oe``
    (N + 1, 6): the target's osculating elements at the nodes (the chief of the truth, for
    checks from the flown states).
    """

    t: np.ndarray
    rtn: np.ndarray
    dv_planned: np.ndarray
    dv_applied: np.ndarray
    replans: list[ReplanRecord]
    comparisons: list[ReplanRecord]
    estimates: np.ndarray
    truth_roe: np.ndarray
    samples_per_interval: int
    chief_oe: np.ndarray

    def flight_fields(self) -> dict[str, Any]:
        """The fields of this flight by name (to build a result that extends it)."""
        return {f.name: getattr(self, f.name) for f in fields(Flight)}


@dataclass(frozen=True, kw_only=True)
class ClosedLoopResult(Flight):
    """A flown rendezvous: its :class:`Flight` with the ``instance``, the loop's ``config``,
    the success ``tolerance`` and the ``open_loop`` plan it started from."""

    instance: RendezvousInstance
    config: MPCConfig
    tolerance: DockingTolerance
    open_loop: Solution

    @property
    def n_nodes(self) -> int:
        return self.dv_planned.shape[0]

    @property
    def terminal_position_error(self) -> float:
        """``|r(t_N) - dr_dp|`` of the true final state [m]."""
        dock = np.asarray(self.instance.scenario.dock_port_m)
        return float(np.linalg.norm(self.rtn[-1, :3] - dock))

    @property
    def terminal_velocity_error(self) -> float:
        """``|v(t_N)|`` of the true final state [m/s]."""
        return float(np.linalg.norm(self.rtn[-1, 3:]))

    @property
    def fuel(self) -> float:
        """Executed delta-v ``sum |dv_applied|`` [m/s]."""
        return float(np.linalg.norm(self.dv_applied, axis=1).sum())

    @property
    def open_loop_fuel(self) -> float:
        """Cost of the open-loop plan ``sum |dv|`` [m/s]."""
        return float(self.open_loop.cost)

    def path_violations(self) -> dict[str, Any]:
        """Dense keep-out (nodes 0 .. N_wp) and cone (N_wp .. N) check of the flown states.

        The windows are the verification's. Returns the worst keep-out ``1 - |E_koz dr|``
        [-], the worst cone violation [m] (both clipped at 0) and ``count``: samples beyond
        the tolerance.
        """
        sc, m = self.instance.scenario, self.samples_per_interval
        kw, n = sc.n_waypoint, sc.n_nodes
        koz = -keep_out_slack(self.rtn[: kw * m + 1], sc)
        cone = -cone_slack(self.rtn[kw * m : n * m], sc)
        count = int((koz > self.tolerance.keep_out).sum() + (cone > self.tolerance.cone_m).sum())
        return {
            "keep_out": float(max(0.0, koz.max())),
            "cone_m": float(max(0.0, cone.max())) if cone.size else 0.0,
            "count": count,
        }

    @property
    def success(self) -> bool:
        """Terminal tolerance met and no constraint violated along the flown trajectory."""
        tol = self.tolerance
        return (
            self.terminal_position_error <= tol.position_m
            and self.terminal_velocity_error <= tol.velocity_m_s
            and self.path_violations()["count"] == 0
        )

    @property
    def replan_period_s(self) -> float:
        """Time between re-plans ``K dt`` [s]."""
        t_nodes = self.t[:: self.samples_per_interval]
        return float(self.config.replan_every * (t_nodes[1] - t_nodes[0]))

    def summary(self) -> dict[str, Any]:
        """The row of ``runs.csv`` (without the run number)."""
        violations = self.path_violations()
        return {
            "warmstart": self.config.warmstart,
            "success": self.success,
            "terminal_position_error": self.terminal_position_error,
            "terminal_velocity_error": self.terminal_velocity_error,
            "fuel": self.fuel,
            "open_loop_fuel": self.open_loop_fuel,
            **replan_statistics(self.replans),
            "replan_period_s": self.replan_period_s,
            "violations": violations["count"],
            "keep_out_violation": violations["keep_out"],
            "cone_violation_m": violations["cone_m"],
        }

    def arrays(self) -> dict[str, np.ndarray]:
        """Arrays of ``run-NNNN.npz``: flown states, impulses, re-plans and comparisons."""

        out = {
            "t": self.t, "rtn": self.rtn, "dv_planned": self.dv_planned,
            "dv_applied": self.dv_applied, "estimates": self.estimates,
            "truth_roe": self.truth_roe, "open_loop_x": self.open_loop.trajectory.x,
            "open_loop_u": self.open_loop.trajectory.u, "open_loop_t": self.open_loop.t,
            "open_loop_rtn": linear_model(self.instance).rtn(self.open_loop.trajectory.x),
            "samples_per_interval": np.array(self.samples_per_interval),
        }  # fmt: skip
        return out | replan_tables(self.replans, self.comparisons, ReplanRecord)


# ======================================================================================
# the pieces of the loop
# ======================================================================================
def mean_state(
    x_chief: np.ndarray, x_deputy: np.ndarray, j2: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Mean classical elements of the target (6,) and mean scaled ROE [m] (6,) of the servicer
    from their osculating ECI states (6,) each.

    With J2 both are averaged over their own draconitic period
    (:func:`~scpformer.dynamics.mean_elements.osculating_to_mean_qns`), the definition of the
    mean elements that the verification's consistent initial state inverts; without J2 mean
    and osculating coincide.
    """
    x = np.stack([x_chief, x_deputy])
    oe = eci_to_oe(x[:, :3], x[:, 3:])
    if not j2:
        return oe[0], oe_to_roe(oe[0], oe[1]) * oe[0, 0]
    rates = j2_secular_rates(oe)
    periods = 2.0 * math.pi / (rates[1] + rates[2])
    m = osculating_to_mean_qns(x, periods, MEAN_SAMPLES, MEAN_SUBSTEPS)
    roe = qns_offset_to_roe(m[0], qns_difference(m[1], m[0])) * m[0, 0]
    return qns_to_oe(m[0]), roe


def remaining_instance(
    instance: RendezvousInstance, k: int, roe_m: np.ndarray, target_oe: np.ndarray
) -> RendezvousInstance:
    """Problem 3 from node ``k``: ``N - k`` impulses of the same time step to ``t_N``.

    ``roe_m`` (6,) is the initial mean scaled ROE [m] and ``target_oe`` (6,) the target's mean
    classical elements (radians) at ``t_k``. The waypoint stays ``waypoint_offset`` intervals
    before docking, i.e. at the same node ``N_wp``; from ``N_wp`` on (``k >= N_wp``) it is
    passed: the remaining problem is the final approach, in the cone, without the waypoint and
    the keep-out zone (``RendezvousScenario.waypoint_passed``). The scenario's horizon range
    is widened to the remaining horizon.

    Raises
    ------
    ValueError
        When the remaining problem cannot be posed (``k = N_wp - 1``: one impulse to the
        waypoint hold; fewer than 2 intervals left), or the instance is invalid (e.g. the
        estimated initial position lies inside the keep-out zone before the waypoint).
    """
    sc = instance.scenario
    n_rem = sc.n_nodes - k
    if not poses_problem(sc.n_nodes, sc.waypoint_offset, k):
        raise ValueError(
            f"node {k}: {n_rem} intervals remain, the problem needs waypoint_offset + 2 = "
            f"{sc.waypoint_offset + 2} or more (the waypoint ahead), or {MIN_PASSED_NODES} to "
            f"waypoint_offset = {sc.waypoint_offset} (the waypoint passed)"
        )
    deg = np.degrees(target_oe[2:])
    target = TargetOrbit(a_m=float(target_oe[0]), e=float(target_oe[1]), i_deg=float(deg[0]),
                         raan_deg=float(deg[1]), argp_deg=float(deg[2]),
                         M_deg=float(deg[3]))  # fmt: skip
    dt = instance.horizon_s / sc.n_nodes
    horizon = n_rem * dt / target.period_s
    lo, hi = sc.horizon_range_orbits
    scenario = replace(sc, n_nodes=n_rem, horizon_range_orbits=(min(lo, horizon), max(hi, horizon)))
    return RendezvousInstance(roe0_m=tuple(float(v) for v in roe_m), horizon_orbits=horizon,
                              target=target, scenario=scenario)  # fmt: skip


def poses_problem(n_nodes: int, waypoint_offset: int, k: int) -> bool:
    """Whether node ``0 < k < N`` poses a remaining problem: at least two intervals to the
    waypoint (``k <= N_wp - 2``), or the waypoint passed (``k >= N_wp``) with at least
    :data:`MIN_PASSED_NODES` intervals left (``RendezvousScenario``)."""
    n_rem = n_nodes - k
    return 0 < k and (n_rem >= waypoint_offset + 2 or MIN_PASSED_NODES <= n_rem <= waypoint_offset)


def replan_nodes(n_nodes: int, waypoint_offset: int, replan_every: int) -> list[int]:
    """Nodes of the re-plans: ``K, 2K, ...`` up to ``N - MIN_PASSED_NODES`` (= N - 2), through
    the final approach after the waypoint node ``N_wp = N - waypoint_offset``.

    The node ``N_wp - 1`` poses no problem (:func:`poses_problem`: one impulse cannot reach
    the waypoint hold); a re-plan due there happens at ``N_wp - 2`` instead. Node 0 flies the
    open-loop plan, solved from the instance's own (true, known) initial state.
    ``K > N - 2`` gives no re-plan: the open-loop plan is flown.
    """
    nodes: list[int] = []
    for k in range(replan_every, n_nodes - MIN_PASSED_NODES + 1, replan_every):
        if not poses_problem(n_nodes, waypoint_offset, k):
            k -= 1
        if poses_problem(n_nodes, waypoint_offset, k) and k not in nodes:
            nodes.append(k)
    return nodes


def shifted_plan(plan: Solution, shift: int) -> GivenWarmStart:
    """The plan's states and impulses from its node ``shift`` on: the warm start ``previous``."""
    x, u = plan.trajectory.x[shift:], plan.trajectory.u[shift:]
    return GivenWarmStart(Trajectory(x=np.array(x), u=np.array(u), p=np.zeros(0)), "previous")


def _accepted(sol: Solution, accept_max_iterations: bool) -> bool:
    if sol.trajectory is None or sol.verification is None or not sol.verification.passed:
        return False
    ok = (Status.CONVERGED, Status.MAX_ITERATIONS) if accept_max_iterations else (
        Status.CONVERGED,)  # fmt: skip
    return sol.status in ok


def replan_once(
    sub: Any, error: str, k: int, name: str, solve_with: Callable[[str], Solution],
    accepted: Callable[[Solution], bool], budget_s: float | None = None,
) -> tuple[ReplanRecord, Solution | None]:  # fmt: skip
    """One re-plan (or comparison solve) of the remaining problem ``sub`` from node ``k`` with
    warm start ``name``: ``solve_with(name)`` timed (warm start, solve and verification) and
    recorded, not accepted when over ``budget_s`` (:func:`within_budget`); ``sub`` None
    records the ``error`` that kept the node from posing a problem."""
    if sub is None:
        return ReplanRecord(k, name, False, "invalid_instance", math.nan, 0, 0.0, error), None
    start = time.perf_counter()
    sol = solve_with(name)
    wall = time.perf_counter() - start
    used = str((sol.extras.get("warmstart") or {}).get("used", ""))
    record = ReplanRecord(k, name, accepted(sol), sol.status.value, float(sol.cost),
                          sol.iterations, wall, sol.message, used)  # fmt: skip
    return within_budget(record, budget_s), sol


def replan_compared(
    sub: Any, error: str, k: int, flown: str, compare: tuple[str, ...],
    solve_with: Callable[[str], Solution], accepted: Callable[[Solution], bool],
    budget_s: float | None = None,
) -> tuple[ReplanRecord, list[ReplanRecord], Solution | None]:  # fmt: skip
    """The flown re-plan (:func:`replan_once` with ``flown``), then the comparison solves of
    the same problem with each warm start of ``compare`` (recorded, never flown), all under
    the time budget ``budget_s``."""
    record, sol = replan_once(sub, error, k, flown, solve_with, accepted, budget_s)
    others = [replan_once(sub, error, k, name, solve_with, accepted, budget_s)[0]
              for name in compare]  # fmt: skip
    return record, others, sol


def _solver(
    sub: RendezvousInstance | None, previous: Solution, shift: int, cfg: MPCConfig,
    history: FlownHistory | None = None,
) -> Callable[[str], Solution]:  # fmt: skip
    """``solve_with(name)`` of a re-plan: the family's solve from the warm start ``name``
    (``art``, ``best``: with the flown ``history``, :func:`.rendezvous_art.solve_learned`)."""

    def solve_with(name: str) -> Solution:
        if name in LEARNED:
            return solve_learned(name, sub, history, shifted_plan(previous, shift), cfg.solver,
                                 cfg.model)  # fmt: skip
        warm = shifted_plan(previous, shift) if name == "previous" else None
        return solve(sub, cfg.solver, warmstart=warm)

    return solve_with


def open_loop_plan(instance: RendezvousInstance, config: MPCConfig | None = None) -> Solution:
    """The open-loop plan: Problem 3 of the nominal instance from the family's default start.

    Raises
    ------
    ValueError
        When it fails (no verified trajectory): there is nothing to fly.
    """
    cfg = config or MPCConfig()
    return flyable_plan(
        solve(instance, cfg.solver), lambda sol: _accepted(sol, cfg.accept_max_iterations)
    )


def fly(
    instance: RendezvousInstance,
    config: MPCConfig | None = None,
    *,
    seed: int = 0,
    open_loop: Solution | None = None,
) -> ClosedLoopResult:
    """Fly ``instance`` in closed loop (see the module docstring).

    Parameters
    ----------
    instance
        The rendezvous; its nominal initial state is the truth's (consistent osculating
        state, :func:`osculating_initial_state`).
    config
        Re-planning period, warm start, errors, tolerance.
    seed
        Seed of the error draws. The draws are standard normal numbers drawn up front per
        node (navigation 6, actuation 3, process 6), so two warm starts flown with the same
        seed see the same errors (common random numbers).
    open_loop
        The open-loop plan (:func:`open_loop_plan`), solved when not given.
    """
    cfg = config or MPCConfig()
    check_int("seed", seed, least=0)
    if not isinstance(instance, RendezvousInstance):
        raise ValueError(f"instance must be a RendezvousInstance, got {type(instance).__name__}")
    open_loop = open_loop or open_loop_plan(instance, cfg)
    sc = instance.scenario
    log = FlownLog(instance, open_loop) if uses_art(cfg) else None
    if log:  # the model is loaded before the re-plans are timed
        art_provider(cfg.model, cfg.solver)

    def replan(
        k: int, estimate: np.ndarray, target_oe: np.ndarray, plan: Solution, shift: int
    ) -> tuple[ReplanRecord, list[ReplanRecord], Solution | None]:
        try:
            sub, error = remaining_instance(instance, k, estimate, target_oe), ""
        except ValueError as err:
            sub, error = None, str(err)
        history = log.history(k, estimate, plan, shift) if log else None
        return replan_compared(sub, error, k, cfg.warmstart, cfg.compare,
                               _solver(sub, plan, shift, cfg, history),
                               lambda sol: _accepted(sol, cfg.accept_max_iterations),
                               cfg.time_budget_s)  # fmt: skip

    schedule = replan_nodes(sc.n_nodes, sc.waypoint_offset, cfg.replan_every)
    flight = fly_truth(instance, open_loop, schedule, replan, cfg.errors, seed=seed,
                       samples_per_interval=cfg.samples_per_interval,
                       burn_threshold_m_s=cfg.burn_threshold_m_s)  # fmt: skip
    tolerance = cfg.tolerance or DockingTolerance.derive(
        instance, cfg.errors, cfg.solver.verification
    )
    return ClosedLoopResult(instance=instance, config=cfg, tolerance=tolerance,
                            open_loop=open_loop, **flight.flight_fields())  # fmt: skip


#: ``replan(k, estimate, target_oe, plan, shift) -> (flown record, comparison records,
#: solution or None)`` of a family: pose the remaining problem from the estimate and solve it.
Replanner = Callable[
    [int, np.ndarray, np.ndarray, Solution, int],
    tuple[ReplanRecord, list[ReplanRecord], Solution | None],
]


def fly_truth(
    instance: Any,
    open_loop: Solution,
    schedule: list[int],
    replan: Replanner,
    errors: ErrorModels,
    *,
    seed: int,
    samples_per_interval: int,
    burn_threshold_m_s: float,
) -> Flight:
    """The truth flight of a shrinking-horizon loop, shared by the rendezvous families.

    ``instance`` is a rendezvous or robust rendezvous instance (``times``, ``target``,
    ``roe0`` and ``scenario.j2`` are read). From the consistent osculating initial state,
    at every node ``k``: the process noise is added (Table 2, mapped to RTN by ``Psi(t_k)``);
    at a node of ``schedule`` the navigation fix (mean elements of the truth plus
    ``N(0, X_nav(rho))``) is handed to ``replan`` and its accepted plan replaces the flown one;
    the flown plan's impulse ``k`` is executed with a Gates error (burns of at least
    ``burn_threshold_m_s``) and the truth propagated to ``t_{k+1}`` (two-body + J2),
    ``samples_per_interval`` outputs per interval. The draws are standard normal numbers
    drawn up front per node (navigation 6, actuation 3, process 6) from ``seed``.
    """
    sc, m = instance.scenario, samples_per_interval
    n = instance.n_nodes
    t_nodes = instance.times()
    model = linear_model(instance)  # mean target elements and Psi at the nodes (process noise)
    rng = np.random.default_rng(seed)
    z_nav, z_act, z_proc = (rng.standard_normal((n, d)) for d in (6, 3, 6))
    chol_q = np.linalg.cholesky(errors.process_noise.matrix) if errors.process_noise else None

    oe_c, rtn = osculating_initial_state(instance)
    plan, plan_start = open_loop, 0
    t_out, rtn_out, chief_oe = [], [], [np.asarray(oe_c, dtype=float)]
    dv_planned, dv_applied = np.zeros((n, 3)), np.zeros((n, 3))
    replans: list[ReplanRecord] = []
    comparisons: list[ReplanRecord] = []
    estimates, truths = [], []
    for k in range(n):
        if chol_q is not None:  # process noise at every node (Table 2), first order via Psi
            rtn = rtn + model.Psi[k] @ (chol_q @ z_proc[k])
        if k in schedule:
            r_c, v_c = _chief_eci(oe_c)
            r_d, v_d = rtn_to_eci(r_c, v_c, rtn)
            target_oe, roe = mean_state(np.r_[r_c, v_c], np.r_[r_d, v_d], sc.j2)
            estimate = roe.copy()
            if errors.navigation is not None:
                rho = float(np.linalg.norm((psi_matrix(target_oe) @ roe)[:3]))
                estimate = roe + rho * errors.navigation.scale(rho) * z_nav[k]
            truths.append(roe)
            estimates.append(estimate)
            record, others, sol = replan(k, estimate, target_oe, plan, k - plan_start)
            replans.append(record)
            comparisons.extend(others)
            if record.accepted and sol is not None:
                plan, plan_start = sol, k
        dv = np.asarray(plan.trajectory.u[k - plan_start], dtype=float)
        dv_planned[k] = dv
        dv_exec = dv.copy()
        if errors.actuation is not None and np.linalg.norm(dv) >= burn_threshold_m_s:
            dv_exec = dv + burn_frame(dv) @ (_gates_sd(errors.actuation, dv) * z_act[k])
        dv_applied[k] = dv_exec
        dt = t_nodes[k + 1] - t_nodes[k]
        times = t_nodes[k] + dt * np.arange(m + 1) / m
        res = propagate_relative(oe_c, rtn, [t_nodes[k]], dv_exec[None], t_out=times, j2=sc.j2)
        t_out.append(times[:-1])
        rtn_out.append(res.rtn[:-1])
        rtn = np.array(res.rtn[-1])
        oe_c = eci_to_oe(res.x_chief[-1, :3], res.x_chief[-1, 3:])
        chief_oe.append(np.asarray(oe_c, dtype=float))
    t_out.append(t_nodes[-1:])
    rtn_out.append(rtn[None])
    return Flight(
        t=np.concatenate(t_out), rtn=np.concatenate(rtn_out), dv_planned=dv_planned,
        dv_applied=dv_applied, replans=replans, comparisons=comparisons,
        estimates=np.array(estimates).reshape(-1, 6), truth_roe=np.array(truths).reshape(-1, 6),
        samples_per_interval=m, chief_oe=np.array(chief_oe),
    )  # fmt: skip


def _chief_eci(oe_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r, v = oe_to_eci(oe_c)
    return np.asarray(r), np.asarray(v)


def _gates_sd(model: GatesModel, dv: np.ndarray) -> np.ndarray:
    """Burn-frame standard deviations (magnitude, two pointing) of Eq. 12 [m/s], (3,)."""
    dv2 = float(dv @ dv)
    par = math.sqrt(model.sigma_r**2 + dv2 * model.sigma_s**2)
    perp = math.sqrt(model.sigma_a**2 + dv2 * model.sigma_p**2)
    return np.array([par, perp, perp])
