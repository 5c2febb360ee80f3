"""Closed-loop guidance of the 6-DoF Mars powered descent: re-planned free-final-time SCvx.

The open-loop plan is the family's optimum (Szmuk & Acikmese 2018; T-SCvx paper, Eqs. 2-6)
solved from the true initial state, which is known exactly at powered descent initiation. The
loop then flies the plan through the truth model and re-plans on board:

1. after every ``K`` intervals of the current plan (``replan_every``) the navigation filter
   gives an estimate of the true state: position, velocity, attitude and body rate with the
   errors of :class:`NavigationErrors`, and the mass the guidance believes (the true mass with
   the run's constant relative mass error, :attr:`ErrorModels.mass_fraction`);
2. the remaining problem is the family's free-final-time problem from that estimate: a
   :class:`~scpformer.pdg6dof.PDGInstance` with the estimate as ``r0, v0, q0, omega0, m0``
   and the instance's constraints, vehicle and terminal conditions (:func:`remaining_instance`),
   solved on the same ``N`` nodes over a new, free, remaining time by the family's public
   ``solve`` with the chosen warm start and checked by its verification;
3. the plan's first ``K`` intervals of first-order-hold thrust are applied through the truth
   model (Eq. 4 integrated by the compiled DOP853 of
   :mod:`scpformer.dynamics.powered_descent_truth`, the verification's integrator), with a
   Gates-style thrust magnitude and pointing error per interval, and a vehicle whose mass,
   inertia and aerodynamic coefficient differ from the planner's (:class:`ErrorModels`).

The horizon shrinks geometrically: each re-plan spreads ``N`` nodes over the remaining time
and flies ``K`` of its ``N - 1`` intervals. Re-planning stops when the remaining time of the
current plan is below ``min_remaining_time`` (default 1 U_T, twice the family's least final
time ``tf_min`` = 0.5 U_T, below which the remaining problem is not posed at all) or fewer
than ``K + 2`` of its nodes remain; the last plan is then flown to its end, where the
touchdown state is taken. A re-plan that fails (no trajectory, or one whose verification
fails, or an estimate that already violates a state constraint; an unconverged but verified
one is flown, :attr:`MPCConfig.accept_unconverged`) is recorded and
the last accepted plan keeps being flown; the next attempt comes ``K`` intervals later.

Warm starts of a re-plan (:data:`WARMSTARTS`): ``cold`` is SCvx from the family's default
start (the cubic profile); ``previous`` is SCvx from the last accepted plan shifted in time:
its nodes from the current one on, re-interpolated onto ``N`` nodes over its remaining time
(:func:`shifted_plan`, the free final time makes the node spacing change); ``tscvx`` is
T-SCvx (Algorithm 2) with the shipped mid-flight networks (``tscvx-midflight``) evaluated at
the current estimate as theta;
``best`` runs T-SCvx (Algorithm 2, the networks' predicted tight rows) from whichever guess
has the lower penalized cost ``J = C + lambda P`` (Eq. 16, the T-SCvx paper's acceptance
measure of a guess) on the re-plan problem: the networks' predicted solution or the shifted
plan (:func:`best_start`, :class:`PredictedRowsFrom`; the record's ``used`` says which
guess). The shifted plan is the better guess on nearly every re-plan; from it Algorithm 2
takes as many SCP iterations as SCvx, each on the smaller subproblem of the predicted tight
rows (measured on the 132 re-plans of runs 0-9 of seed 2026, where it was chosen: fewer /
same / more iterations than ``previous`` on 21 / 107 / 4, faster on 107 of 132, the same
cost on all 93 both accepted).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, fields, replace
from functools import lru_cache
from typing import Any, ClassVar

import numpy as np

from scpformer.dynamics import powered_descent_truth as truth
from scpformer.dynamics import quaternion as quat
from scpformer.files import require_model_path
from scpformer.guidance.pdg6dof_tracking import (
    TrackingWeights,
    project_thrust,
    tracking_gains,
)
from scpformer.guidance.records import (
    check_budget,
    flyable_plan,
    replan_statistics,
    replan_tables,
    within_budget,
)
from scpformer.pdg6dof import PDGInstance, PDGSolverConfig, sample_instances, solve
from scpformer.problems.pdg6dof import constraints as con
from scpformer.scp.solution import Solution, Status, Trajectory
from scpformer.scp.warmstart import GivenWarmStart
from scpformer.validation import check_bool, check_finite, check_int, check_positive

#: Warm starts of a re-plan that the loop implements.
WARMSTARTS = ("cold", "previous", "tscvx", "best")
#: Methods of ``solve`` per warm start (``best`` runs ``tscvx`` from either guess).
METHOD = {"cold": "scvx", "previous": "scvx", "tscvx": "tscvx", "best": "tscvx"}
#: Cost difference below which two re-plans tie [U_M]: SCvx's stationarity test, ``Delta L <=
#: eps_opt max(1, |J|)`` (eps_opt = 1e-4, |J| = m_f <= m0 = 3 U_M).
TIE_U_M = 3e-4
#: Seconds in one U_T for a Mars lander, where Table 1 fixes none. Two of its values tie the
#: units to physics: g = 1 U_L/U_T^2 is Mars's 3.711 m/s^2, and the exhaust velocity
#: I_sp g0 = 30 U_L/U_T is that of a 225 s engine (the Mars landing engines of MSL and Mars
#: 2020 are of this class), 2206.5 m/s. So U_L/U_T = 73.55 m/s, U_T = 73.55 / 3.711 = 19.8 s
#: and U_L = 1.46 km: the default descent starts 5.8 km up at 104 m/s and lasts 93 s.
#: Used to set a re-plan's wall time against the re-planning period.
TIME_UNIT_S = 19.8
#: Dense truth samples per interval of the constraint check: the verification's
#: ``PDGVerificationTolerances.samples_per_interval``.
SAMPLES_PER_INTERVAL = 5
#: Rows of the constraint check evaluated on the commanded thrust at the nodes.
CONTROL_ROWS = frozenset({"thrust_min", "thrust_max", "gimbal"})
DEG = math.pi / 180.0


def check_warmstart(name: Any) -> str:
    """``name`` when it is one of :data:`WARMSTARTS`; ``ValueError`` otherwise."""
    if name not in WARMSTARTS:
        raise ValueError(f"warmstart must be one of {', '.join(WARMSTARTS)}, got {name!r}")
    return str(name)


# ======================================================================================
# configuration
# ======================================================================================
@dataclass(frozen=True, kw_only=True)
class StateSigmas:
    """1-sigma sizes per axis of the four parts of the vehicle's state: ``position`` [U_L],
    ``velocity`` [U_L/U_T], ``attitude_deg`` (small rotation about each body axis) [deg] and
    ``rate_deg`` [deg/U_T]; each finite and nonnegative (``ValueError`` naming
    ``<label>.<field>``, the label a class attribute of the subclass)."""

    label: ClassVar[str] = "sigmas"
    position: float
    velocity: float
    attitude_deg: float
    rate_deg: float

    def __post_init__(self) -> None:
        for f in fields(StateSigmas):
            value = check_finite(f"{self.label}.{f.name}", getattr(self, f.name), shape=(),
                                 nonnegative=True)  # fmt: skip
            object.__setattr__(self, f.name, float(value))


@dataclass(frozen=True, kw_only=True)
class NavigationErrors(StateSigmas):
    """1-sigma error per axis of each navigation fix, nondimensional units of Table 1.

    Neither Szmuk & Acikmese (2018) nor the T-SCvx paper model navigation. The values are a
    careful engineer's choice at the scale of Table 1 (the default descent starts at
    ``|r0|`` = 5.7 U_L, ``|v0|`` = 1.4 U_L/U_T): position 0.01 U_L (0.2% of the initial range,
    the order of a terrain-relative navigation fix against the km-scale initiation point of
    a Mars lander), velocity 0.005 U_L/U_T (0.4% of the initial speed, a Doppler
    velocimeter's), attitude 0.1 deg per axis (a star tracker / IMU attitude solution is
    better; 0.1 deg is conservative) and body rate 0.1 deg/U_T per axis (gyro noise and bias,
    0.1% of omega_max = 90 deg/U_T).
    """

    label: ClassVar[str] = "navigation"
    position: float = 0.01  # [U_L]
    velocity: float = 0.005  # [U_L/U_T]
    attitude_deg: float = 0.1  # small rotation about each body axis [deg]
    rate_deg: float = 0.1  # [deg/U_T]


@dataclass(frozen=True, kw_only=True)
class InitialDispersion(StateSigmas):
    """1-sigma dispersion per axis of the true initial state about the instance's, per run.

    Position 0.1 U_L and velocity 0.05 U_L/U_T (1.8% and 3.5% of the default ``|r0|`` and
    ``|v0|``: the spread of the state at powered descent initiation after a parachute phase is
    a few percent of the range; kept small enough that every draw stays inside the glideslope
    cone and carries the propellant it needs), attitude 1 deg and rate 1 deg/U_T per axis (the
    default instance starts upright and at rest). Applied by :func:`dispersed_instance`.
    """

    label: ClassVar[str] = "dispersion"
    position: float = 0.1  # [U_L]
    velocity: float = 0.05  # [U_L/U_T]
    attitude_deg: float = 1.0  # [deg]
    rate_deg: float = 1.0  # [deg/U_T]


@dataclass(frozen=True, kw_only=True)
class ErrorModels:
    """The errors the closed loop flies with; every value is a 1-sigma size, ``0`` (or
    ``None``) turns that error off, :meth:`none` every one.

    Szmuk & Acikmese (2018) and the T-SCvx paper cite no error model; the sizes are chosen as
    follows.

    Attributes
    ----------
    thrust_magnitude
        Relative error of the thrust magnitude, drawn per interval and held over it (Gates
        2013's proportional magnitude term, ``sigma_s``, applied to a throttled engine): 1%,
        the thrust accuracy of a throttled bipropellant engine after calibration.
    pointing_deg
        Pointing error of the thrust vector per interval, a small rotation about the two axes
        normal to it (Gates' ``sigma_p``): 0.1 deg, a gimbal actuator's accuracy (1/200 of the
        20 deg gimbal range of Table 1).
    mass_fraction
        Relative error of the mass the guidance believes, constant over a run (the initial
        loading and the dead-reckoned consumption): 1%; the truth's mass is the instance's
        ``m0`` times ``1 + e``.
    inertia_fraction
        Relative error of each principal moment of inertia of the truth (drawn per axis, per
        run): 5%, the usual margin on a CAD inertia of a vehicle whose propellant sloshes
        and depletes.
    aero_fraction
        Relative error of the lumped aerodynamic coefficient ``rho S_A C_A`` of the truth (per
        run): 20%, the day-to-day spread of the Martian atmospheric density near the surface
        (the Mars-GRAM dispersions are 10-30% 1-sigma) with the drag coefficient's own.
    navigation
        Errors of each navigation fix (:class:`NavigationErrors`); ``None``: perfect knowledge.
    dispersion
        Initial-state dispersion per run (:class:`InitialDispersion`, applied by the campaign
        through :func:`dispersed_instance`); ``None``: the instance's state.
    """

    thrust_magnitude: float = 0.01
    pointing_deg: float = 0.1
    mass_fraction: float = 0.01
    inertia_fraction: float = 0.05
    aero_fraction: float = 0.2
    navigation: NavigationErrors | None = field(default_factory=NavigationErrors)
    dispersion: InitialDispersion | None = field(default_factory=InitialDispersion)

    def __post_init__(self) -> None:
        for name in ("thrust_magnitude", "pointing_deg", "mass_fraction", "inertia_fraction",
                     "aero_fraction"):  # fmt: skip
            value = float(check_finite(f"errors.{name}", getattr(self, name), shape=(),
                                       nonnegative=True))  # fmt: skip
            if name != "pointing_deg" and value >= 0.5:
                raise ValueError(f"errors.{name} must be below 0.5 (a relative 1-sigma), "
                                 f"got {value}")  # fmt: skip
            object.__setattr__(self, name, value)
        for name, cls in (("navigation", NavigationErrors), ("dispersion", InitialDispersion)):
            value = getattr(self, name)
            if value is not None and not isinstance(value, cls):
                raise ValueError(f"errors.{name} must be a {cls.__name__} or None, "
                                 f"got {type(value).__name__}")  # fmt: skip

    @classmethod
    def none(cls) -> ErrorModels:
        """No error of any kind: the loop replays its plans on the planner's own model."""
        return cls(thrust_magnitude=0.0, pointing_deg=0.0, mass_fraction=0.0,
                   inertia_fraction=0.0, aero_fraction=0.0, navigation=None,
                   dispersion=None)  # fmt: skip

    def any(self) -> bool:
        """Whether any error is on."""
        return bool(self.thrust_magnitude or self.pointing_deg or self.mass_fraction
                    or self.inertia_fraction or self.aero_fraction or self.navigation
                    or self.dispersion)  # fmt: skip


@dataclass(frozen=True, kw_only=True)
class LandingTolerance:
    """Success thresholds of a flown landing (not in the papers; derived in :meth:`derive`).

    Terminal errors are Euclidean norms at the end of the last plan (touchdown): position
    ``|r - r_f|`` [U_L], velocity ``|v - v_f|`` [U_L/U_T], tilt angle from Up [deg] and
    pitch/yaw rate ``|omega_y, omega_z|`` [deg/U_T] (the terminal conditions the verification
    checks, Eqs. 3f-3i). Path thresholds bound the dense constraint values ``g`` of
    :mod:`scpformer.problems.pdg6dof.constraints` along the true flown states (glideslope,
    tilt, rate, mass) and the commanded thrust (thrust bounds, gimbal).
    """

    position: float
    velocity: float
    tilt_deg: float
    rate_deg: float
    glideslope: float  # [U_L] on g = tan(gamma) |r_EN| - r_up
    tilt: float  # on g = |H q| - sin(theta_max / 2)
    omega: float  # [rad/U_T]
    control: float  # thrust bounds [U_M U_L/U_T^2] and gimbal (the verification's)

    def __post_init__(self) -> None:
        for name in ("position", "velocity", "tilt_deg", "rate_deg", "glideslope", "tilt",
                     "omega", "control"):  # fmt: skip
            object.__setattr__(self, name, check_positive(f"tolerance.{name}",
                                                          getattr(self, name)))  # fmt: skip

    @classmethod
    def derive(
        cls, errors: ErrorModels, config: MPCConfig, instance: PDGInstance | None = None,
        plan: Solution | None = None,
    ) -> LandingTolerance:  # fmt: skip
        """The thresholds of a closed-loop landing, from the terminal conditions and the errors.

        The last re-plan happens with between ``min_remaining_time`` ``T_m`` and
        ``T_m / (1 - K / (N - 1))`` left (the geometric shrinking of the horizon); the tail
        ``T = T_m / (1 - K / (N - 1))`` (1.11 U_T for K = 5, N = 50) is flown open loop on
        that plan (with ``K >= N - 2``, no re-plan: the whole plan, ``plan``'s final time).
        Each term is a 3-sigma error at touchdown, summed in quadrature:

        * the plan's own model error: the verification's ``terminal`` tolerance per
          component (5e-3), ``sqrt(3) x 5e-3`` in 3-D for position and velocity,
          ``2 asin(sqrt(2) x 5e-3)`` for the tilt and ``sqrt(2) x 5e-3 rad`` for the rate;
        * the last navigation fix: ``3 sqrt(3) sigma_r`` (position), ``3 sqrt(3) sigma_v``
          (velocity) and ``3 sqrt(3) sigma_v T`` (the velocity error carried over the tail into
          position), ``3 sqrt(2) sigma_att`` and ``3 sqrt(2) sigma_rate T`` (tilt: the attitude
          error and the rate error integrated over the tail), ``3 sqrt(2) sigma_rate`` (rate);
        * the vehicle and thrust errors over the tail, with the thrust acceleration near
          touchdown ``a = |g|`` (the descent ends hovering down at constant ``v_f``): the mass
          error as a bias ``3 sigma_m a`` (velocity ``x T``, position ``x T^2 / 2``), the
          magnitude error averaged over the tail's ``n`` intervals ``3 sigma_s a / sqrt(n)``, the
          pointing error ``3 sqrt(2) sigma_p a / sqrt(n)`` and the drag error at the final
          speed ``3 sigma_a rho S_A C_A |v_f|^2 / (2 m_dry)``;
        * the inertia error: the tail's attitude manoeuvre is commanded through torques sized
          for the planner's inertia, so the truth's rates are off by the relative inertia
          error: ``3 sigma_J`` times the largest pitch/yaw rate of ``plan`` (the open-loop
          plan) over its last ``T`` (rate) and times the angle it turns through there (tilt).
          The default descent ends with a 27 deg tilt manoeuvre back to upright at up to
          36 deg/U_T over its last 1.5 U_T: 3 x 5% of that is 5.5 deg/U_T and ~3 deg. Without
          ``plan`` the term is dropped.

        Path: the glideslope may be exceeded by ``(1 + tan gamma_gs)`` times the position
        tolerance (a trajectory shifted by ``dr`` changes ``g`` by at most that much), the tilt
        row by ``sin`` of half the tilt tolerance, the rate row by the rate tolerance; the
        commanded thrust by the verification's ``constraint`` tolerance (1e-3).
        """
        instance = instance or PDGInstance()
        c = instance.constants
        tol = config.solver.verification
        n_nodes, k = config.solver.n_nodes, config.replan_every
        if k < n_nodes - 2:
            tail = config.min_remaining_time / (1.0 - k / (n_nodes - 1))
        else:  # no re-plan: the whole plan is the tail
            tail = float(plan.trajectory.p[0]) if plan is not None else c.tf_max
        n_tail = max(n_nodes - 1, 1)
        nav = errors.navigation or NavigationErrors(position=0.0, velocity=0.0,
                                                    attitude_deg=0.0, rate_deg=0.0)  # fmt: skip
        a = float(np.linalg.norm(c.g_I))
        s3, s2 = math.sqrt(3.0), math.sqrt(2.0)
        drag = errors.aero_fraction * c.rho_SA_CA * float(np.dot(c.v_f, c.v_f)) / (2 * c.m_dry)
        accel_bias = errors.mass_fraction * a
        accel_noise = math.hypot(
            errors.thrust_magnitude * a, s2 * errors.pointing_deg * DEG * a
        ) / math.sqrt(n_tail)
        position = math.sqrt(
            (s3 * tol.terminal) ** 2 + (3 * s3 * nav.position) ** 2
            + (3 * s3 * nav.velocity * tail) ** 2
            + (3 * (accel_bias + accel_noise + drag) * tail**2 / 2) ** 2
        )  # fmt: skip
        velocity = math.sqrt(
            (s3 * tol.terminal) ** 2 + (3 * s3 * nav.velocity) ** 2
            + (3 * (accel_bias + accel_noise + drag) * tail) ** 2
        )  # fmt: skip
        peak_rate = turned = 0.0
        if plan is not None and plan.trajectory is not None:
            z = plan.trajectory
            t = np.linspace(0.0, float(z.p[0]), z.x.shape[0])
            rate_yz = np.linalg.norm(z.x[:, 11:13], axis=1)
            last = t >= t[-1] - tail
            peak_rate = float(rate_yz[last].max())
            turned = float(np.sum(0.5 * (rate_yz[1:] + rate_yz[:-1]) * np.diff(t) * last[1:]))
        tilt_model = 2.0 * math.asin(min(s2 * tol.terminal, 1.0))
        tilt = math.sqrt(
            tilt_model**2 + (3 * errors.inertia_fraction * turned) ** 2
            + (3 * s2 * nav.attitude_deg * DEG) ** 2 + (3 * s2 * nav.rate_deg * DEG * tail) ** 2
        )  # fmt: skip
        rate = math.sqrt(
            (s2 * tol.terminal) ** 2 + (3 * errors.inertia_fraction * peak_rate) ** 2
            + (3 * s2 * nav.rate_deg * DEG) ** 2
        )  # fmt: skip
        return cls(
            position=position, velocity=velocity, tilt_deg=math.degrees(tilt),
            rate_deg=math.degrees(rate),
            glideslope=tol.constraint + (1.0 + instance.tan_gamma_gs) * position,
            tilt=tol.constraint + math.sin(min(tilt, math.pi) / 2.0),
            omega=tol.constraint + rate,
            control=tol.constraint,
        )  # fmt: skip


@dataclass(frozen=True, kw_only=True)
class MPCConfig:
    """How the landing's closed loop re-plans and what it flies through.

    Attributes
    ----------
    replan_every
        ``K``, intervals of the current plan flown between re-plans (>= 1, < N - 2). Default
        5: a re-plan every tenth of the remaining descent (N = 50), 0.48 U_T at the start of
        the default descent (t_f = 4.7 U_T).
    min_remaining_time
        No re-plan when less time than this remains on the current plan [U_T] (default 1.0,
        twice the family's ``tf_min``); the last plan is flown to its end.
    warmstart
        Warm start of every re-plan, one of :data:`WARMSTARTS`.
    compare
        Other warm starts solved on the same re-plan instances for comparison only (not
        flown): per re-plan cost, iterations and wall time of each.
    solver
        The family's SCP and verification constants (default: Table 1).
    errors
        Navigation, thrust, vehicle and initial-state errors (:class:`ErrorModels`).
    tolerance
        Success thresholds; ``None`` derives them (:meth:`LandingTolerance.derive`).
    accept_unconverged
        Also fly a re-plan that stopped at the iteration limit or stalled when its
        verification passes (default True): the verified trajectory is flyable (its
        nonlinear replay meets the terminal conditions and the constraints at the nodes to
        the verification's tolerances), only not certified optimal; the alternative is the
        older plan, flown open loop from a state that has drifted further.
    tracking
        Weights of the feedback that keeps the vehicle on the plan between re-plans
        (:mod:`scpformer.guidance.pdg6dof_tracking`: a time-varying LQR on the plan's
        first-order-hold linearization, fed by a navigation fix every interval); ``None``
        flies the plan's thrust open loop between re-plans.
    thrust_margin, gimbal_margin_deg
        Control authority the plans leave to the tracking law (:func:`planning_instance`):
        every plan flown, the first one included, is solved with the thrust bounds 6a moved
        inwards by ``thrust_margin T_max`` (default 0.06: 0.3 U, five 1-sigma thrust errors
        plus the mass and drag corrections) and the gimbal bound 6b by ``gimbal_margin_deg``
        (default 2 deg, a tenth of the range). The fuel-optimal descent flies its last
        40% at ``T_max`` and ends at the gimbal stop, where no correction is possible. The
        open-loop reference (``open_loop_fuel``) keeps the full bounds, and so do the plans
        when ``tracking`` is None.
    model
        T-SCvx networks of the ``tscvx`` and ``best`` starts: a training run folder
        (``scpformer train tscvx``), or None / ``"default"`` for the shipped ones trained on
        the states a re-plan starts from (``tscvx-midflight`` of :mod:`scpformer.pretrained`:
        states at nodes 5-35 of optimal descents, with the planning margins as the dataset's
        bounds); the open-loop networks (``tscvx``) were trained on the sampler's initial
        states, outside the distribution of mid-flight states.
    time_budget_s
        Wall seconds a re-plan may take (warm start, solve, verification and the tracking
        gains of its plan); a later one is not flown and recorded as late
        (:func:`~scpformer.guidance.records.within_budget`). None (default): no budget. The
        re-planning period is in Table 1's nondimensional time, so what a budget in seconds
        means depends on the time unit U_T of the vehicle flown.
    replan_iter_max
        Conic solves a re-plan may take (``scvx.iter_max`` of the re-plans; None, the
        default: the solver's own, 100). A flight computer re-plans on a fixed budget: a
        re-plan that reaches the cap ends unconverged (flown when ``accept_unconverged`` and
        its verification passes, else the last accepted plan flies on) and a capped T-SCvx
        re-plan has no cold-SCvx fallback (the loop's fallback is the last plan). Unlike
        ``time_budget_s`` it does not depend on the machine. The first plan is solved
        uncapped, before the flight.
    """

    replan_every: int = 5
    min_remaining_time: float = 1.0
    warmstart: str = "cold"
    compare: tuple[str, ...] = ()
    solver: PDGSolverConfig = field(default_factory=PDGSolverConfig)
    errors: ErrorModels = field(default_factory=ErrorModels)
    tolerance: LandingTolerance | None = None
    accept_unconverged: bool = True
    tracking: TrackingWeights | None = field(default_factory=TrackingWeights)
    thrust_margin: float = 0.06
    gimbal_margin_deg: float = 2.0
    model: str | None = None
    time_budget_s: float | None = None
    replan_iter_max: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "time_budget_s", check_budget(self.time_budget_s))
        if self.replan_iter_max is not None:
            check_int("replan_iter_max", self.replan_iter_max, least=1)
        check_finite("thrust_margin", self.thrust_margin, shape=(), nonnegative=True)
        check_finite("gimbal_margin_deg", self.gimbal_margin_deg, shape=(), nonnegative=True)
        c = PDGInstance().constants
        if c.T_min + 2 * self.thrust_margin * c.T_max >= c.T_max:
            raise ValueError(f"thrust_margin {self.thrust_margin} leaves no thrust range "
                             f"(T_min {c.T_min}, T_max {c.T_max})")  # fmt: skip
        if self.gimbal_margin_deg >= c.delta_max_deg:
            raise ValueError(f"gimbal_margin_deg must be below delta_max = {c.delta_max_deg} "
                             f"deg, got {self.gimbal_margin_deg}")  # fmt: skip
        check_bool("accept_unconverged", self.accept_unconverged)
        if self.model is not None and not isinstance(self.model, str):
            raise ValueError(f"model must be a path string or None, got "
                             f"{type(self.model).__name__}")  # fmt: skip
        if self.model not in (None, "default"):
            require_model_path(self.model)  # a missing run fails here, not mid-flight
        if self.tracking is not None and not isinstance(self.tracking, TrackingWeights):
            raise ValueError(f"tracking must be a TrackingWeights or None, got "
                             f"{type(self.tracking).__name__}")  # fmt: skip
        if not isinstance(self.solver, PDGSolverConfig):
            raise ValueError(f"solver must be a PDGSolverConfig, got "
                             f"{type(self.solver).__name__}")  # fmt: skip
        check_int("replan_every", self.replan_every, least=1)
        check_positive("min_remaining_time", self.min_remaining_time)
        if self.min_remaining_time < PDGInstance().constants.tf_min:
            raise ValueError(f"min_remaining_time must be at least tf_min = "
                             f"{PDGInstance().constants.tf_min} U_T, got "
                             f"{self.min_remaining_time}")  # fmt: skip
        check_warmstart(self.warmstart)
        compare = tuple(self.compare)
        for name in compare:
            check_warmstart(name)
        object.__setattr__(self, "compare", tuple(n for n in compare if n != self.warmstart))
        if not isinstance(self.errors, ErrorModels):
            raise ValueError(f"errors must be an ErrorModels, got {type(self.errors).__name__}")
        if self.tolerance is not None and not isinstance(self.tolerance, LandingTolerance):
            raise ValueError(f"tolerance must be a LandingTolerance or None, got "
                             f"{type(self.tolerance).__name__}")  # fmt: skip

    @property
    def replan_solver(self) -> PDGSolverConfig:
        """The solver configuration of the re-plans: ``solver`` capped at
        ``replan_iter_max`` conic solves when set."""
        if self.replan_iter_max is None:
            return self.solver
        scvx = replace(self.solver.scvx, iter_max=self.replan_iter_max)
        return replace(self.solver, scvx=scvx)

    def tscvx_provider(self) -> Any:
        """The T-SCvx start of the re-plans (:func:`_tscvx_provider`): without the cold-SCvx
        fallback when the re-plans are capped (``replan_iter_max``)."""
        return _tscvx_provider(self.replan_solver, self.model, self.replan_iter_max is None)


# ======================================================================================
# results
# ======================================================================================
@dataclass(frozen=True)
class ReplanRecord:
    """One re-plan (or one comparison solve of the same re-plan instance)."""

    node: int  # interval count flown since the start of the descent
    time: float  # flight time of the re-plan [U_T]
    warmstart: str
    accepted: bool  # verified (and converged, see accept_unconverged): flown from here on
    status: str  # Solution.status
    cost: float  # -m_f of the plan [U_M] (nan without one)
    iterations: int
    wall_s: float  # wall time of the solve, warm start and verification included [s]
    period: float  # K times the node spacing of the plan being flown [U_T]
    fallback: str  # T-SCvx's fallback ("" when none or not T-SCvx)
    message: str
    used: str = ""  # the guess the solve ran from (best: previous or tscvx; else the name)
    late: bool = False  # over the time budget: not accepted (records.within_budget)


@dataclass(frozen=True)
class ClosedLoopResult:
    """A flown landing.

    ``t`` (M,) [U_T] and ``x`` (M, 14): the true state every ``1 / SAMPLES_PER_INTERVAL`` of
    an interval, the touchdown state last; ``u_cmd`` and ``u_exec`` (M, 3): commanded and
    executed body-frame thrust at those instants. ``estimates`` and ``truths`` (R, 14): the
    navigation estimates of the re-plans and the true states. ``truth_constants``: the
    vehicle the truth flew (mass at t0, inertia diagonal, ``rho S_A C_A``).
    """

    instance: PDGInstance
    config: MPCConfig
    tolerance: LandingTolerance
    open_loop: Solution
    t: np.ndarray
    x: np.ndarray
    u_cmd: np.ndarray
    u_exec: np.ndarray
    replans: list[ReplanRecord]
    comparisons: list[ReplanRecord]
    estimates: np.ndarray
    truths: np.ndarray
    truth_constants: dict[str, Any]

    @property
    def terminal_position_error(self) -> float:
        """``|r(t_f) - r_f|`` of the true touchdown state [U_L]."""
        return float(np.linalg.norm(self.x[-1, 0:3] - self.instance.constants.r_f))

    @property
    def terminal_velocity_error(self) -> float:
        """``|v(t_f) - v_f|`` [U_L/U_T]."""
        return float(np.linalg.norm(self.x[-1, 3:6] - self.instance.constants.v_f))

    @property
    def terminal_tilt_deg(self) -> float:
        """Tilt of the body x axis from Up at touchdown [deg]."""
        return float(np.degrees(quat.tilt_angle(self.x[-1, 6:10])))

    @property
    def terminal_rate_deg(self) -> float:
        """Pitch/yaw rate ``|omega_y, omega_z|`` at touchdown [deg/U_T]."""
        return float(np.degrees(np.linalg.norm(self.x[-1, 11:13])))

    @property
    def fuel(self) -> float:
        """Propellant used ``m(0) - m(t_f)`` of the truth [U_M]."""
        return float(self.x[0, 13] - self.x[-1, 13])

    @property
    def open_loop_fuel(self) -> float:
        """Propellant of the open-loop optimum from the same initial state [U_M]."""
        z = self.open_loop.trajectory
        return float(z.x[0, 13] - z.x[-1, 13])

    def path_violations(self) -> dict[str, Any]:
        """Worst dense constraint values along the flown trajectory (clipped at 0) and
        ``count``: samples beyond the tolerance, over every row.

        State rows (mass, glideslope, tilt, omega) on the true states at every dense sample;
        control rows (thrust bounds, gimbal) on the commanded thrust at the nodes, as the
        family's verification checks them: the executed thrust carries the actuator's error
        by definition (1% of T_max = 0.05 beyond a bound the command meets), and the
        first-order-hold chord between two node thrusts of magnitude T_min dips below T_min
        between the nodes (the nonconvex bound 6a is imposed at the nodes only).
        """
        values = con.constraint_values(self.instance, self.x, self.u_cmd)
        nodes = np.zeros(values.shape[1], dtype=bool)
        nodes[::SAMPLES_PER_INTERVAL] = True
        control = np.array([name in CONTROL_ROWS for name in con.CONSTRAINT_NAMES])
        values = np.where(control[:, None] & ~nodes[None, :], -np.inf, values)
        tol = self.tolerance
        limits = {"mass": tol.control, "glideslope": tol.glideslope, "tilt": tol.tilt,
                  "omega": tol.omega, "thrust_min": tol.control, "thrust_max": tol.control,
                  "gimbal": tol.control}  # fmt: skip
        out: dict[str, Any] = {}
        count = 0
        for name, row in zip(con.CONSTRAINT_NAMES, values, strict=True):
            out[name] = float(max(0.0, row.max()))
            count += int((row > limits[name]).sum())
        out["count"] = count
        return out

    @property
    def success(self) -> bool:
        """Touchdown within the tolerance and no constraint violated along the flight."""
        tol = self.tolerance
        return (
            self.terminal_position_error <= tol.position
            and self.terminal_velocity_error <= tol.velocity
            and self.terminal_tilt_deg <= tol.tilt_deg
            and self.terminal_rate_deg <= tol.rate_deg
            and self.path_violations()["count"] == 0
        )

    @property
    def replan_period(self) -> float:
        """Median time between re-plans ``K dt`` over the re-plans [U_T] (the first plan's
        when there is none)."""
        periods = [r.period for r in self.replans]
        if periods:
            return float(np.median(periods))
        z = self.open_loop.trajectory
        k = min(self.config.replan_every, z.x.shape[0] - 1)
        return float(k * z.p[0] / (z.x.shape[0] - 1))

    def summary(self) -> dict[str, Any]:
        """The row of ``runs.csv`` (without the run number)."""
        violations = self.path_violations()
        return {
            "warmstart": self.config.warmstart,
            "success": self.success,
            "terminal_position_error": self.terminal_position_error,
            "terminal_velocity_error": self.terminal_velocity_error,
            "terminal_tilt_deg": self.terminal_tilt_deg,
            "terminal_rate_deg": self.terminal_rate_deg,
            "fuel": self.fuel,
            "open_loop_fuel": self.open_loop_fuel,
            **replan_statistics(self.replans),
            "replan_period_s": self.replan_period,
            "tscvx_fallbacks": sum(bool(r.fallback) for r in self.replans),
            "violations": violations["count"],
            "flight_time": float(self.t[-1]),
        }

    def arrays(self) -> dict[str, np.ndarray]:
        """Arrays of ``run-NNNN.npz``: flown states and thrust, re-plans and comparisons."""

        z = self.open_loop.trajectory
        out = {
            "t": self.t, "x": self.x, "u_cmd": self.u_cmd, "u_exec": self.u_exec,
            "estimates": self.estimates, "truths": self.truths, "open_loop_x": z.x,
            "open_loop_u": z.u, "open_loop_t": np.asarray(self.open_loop.t),
        }  # fmt: skip
        return out | replan_tables(self.replans, self.comparisons, ReplanRecord)


# ======================================================================================
# the pieces of the loop
# ======================================================================================
def dispersed_instance(
    instance: PDGInstance, dispersion: InitialDispersion | None, rng: np.random.Generator
) -> PDGInstance:
    """``instance`` with its initial state dispersed by ``dispersion`` (per-axis normal
    draws; the attitude by a small body-axis rotation). ``None`` returns it unchanged."""
    if dispersion is None:
        return instance
    z = rng.standard_normal((4, 3))
    q0 = _rotated(np.asarray(instance.q0), z[2] * dispersion.attitude_deg * DEG)
    return replace(
        instance,
        r0=tuple(np.asarray(instance.r0) + dispersion.position * z[0]),
        v0=tuple(np.asarray(instance.v0) + dispersion.velocity * z[1]),
        q0=tuple(q0),
        omega0_deg=tuple(np.asarray(instance.omega0_deg) + dispersion.rate_deg * z[3]),
    )


def sampled_instance(rng: np.random.Generator) -> PDGInstance:
    """One instance of the family's nominal sampler (a sub-range of Table 2)."""
    return sample_instances(rng, 1)[0]


def remaining_instance(instance: PDGInstance, estimate: np.ndarray) -> PDGInstance:
    """The free-final-time problem from the estimated state ``estimate`` (14,) (the order of
    Eq. 24, rate in rad/U_T): the instance's constraints, vehicle and terminal conditions.

    Raises ``ValueError`` when the estimate poses no instance (e.g. a mass at the dry mass).
    """
    return instance.with_initial_state(estimate)


def planning_instance(instance: PDGInstance, cfg: MPCConfig) -> PDGInstance:
    """``instance`` with the thrust and gimbal bounds the plans use: ``T_min + m T_max <= |T|
    <= (1 - m) T_max`` and ``delta_max - d`` for the margins ``m, d`` of ``cfg``
    (:attr:`MPCConfig.thrust_margin`); the truth and the constraint check keep the
    instance's own bounds. The margins are the tracking law's: without tracking
    (``cfg.tracking`` None) the plans use the whole thrust set."""
    if cfg.tracking is None or not (cfg.thrust_margin or cfg.gimbal_margin_deg):
        return instance
    c = instance.constants
    margin = cfg.thrust_margin * c.T_max
    return replace(instance, constants=replace(
        c, T_min=c.T_min + margin, T_max=c.T_max - margin,
        delta_max_deg=c.delta_max_deg - cfg.gimbal_margin_deg))  # fmt: skip


def shifted_plan(plan: Solution, node: int, estimate: np.ndarray | None = None) -> GivenWarmStart:
    """The warm start ``previous``: the plan from its node ``node`` on, re-interpolated onto
    the plan's ``N`` nodes over its remaining time ``t_f - t_node`` (linear in time, as the
    first-order hold; quaternions renormalized), first state replaced by ``estimate``."""
    z = plan.trajectory
    n = z.x.shape[0]
    if not 0 <= node < n - 1:
        raise ValueError(f"node must lie in [0, {n - 2}], got {node}")
    dt = float(z.p[0]) / (n - 1)
    remaining = (n - 1 - node) * dt
    t_old = np.arange(n - node) * dt
    t_new = np.linspace(0.0, remaining, n)
    x = np.stack([np.interp(t_new, t_old, z.x[node:, i]) for i in range(z.x.shape[1])], axis=1)
    u = np.stack([np.interp(t_new, t_old, z.u[node:, i]) for i in range(z.u.shape[1])], axis=1)
    if estimate is not None:
        x[0] = estimate
    x[:, 6:10] /= np.linalg.norm(x[:, 6:10], axis=1, keepdims=True)
    return GivenWarmStart(Trajectory(x=x, u=u, p=np.array([remaining])), "previous")


def best_start(
    sub: PDGInstance, plan: Solution, node: int, estimate: np.ndarray, cfg: MPCConfig
) -> tuple[str, Any]:
    """The start of a ``best`` re-plan, a T-SCvx provider either way: ``("tscvx",
    provider)`` when the networks' predicted solution has a lower penalized cost
    ``J = C + lambda P`` (Eq. 16) on ``sub`` than the shifted previous plan, else
    ``("previous", PredictedRowsFrom(shifted plan, provider))``. A prediction the provider
    rejects (unusable, or ``J`` above its bound) loses."""
    from scpformer.warmstart.tscvx import penalized_cost

    config, provider = cfg.replan_solver, cfg.tscvx_provider()
    shifted = shifted_plan(plan, node, estimate)
    guess = provider.guess_for(sub, config)
    j_tscvx = guess.record.details.get("J_prediction", math.inf) if guess.record.accepted else (
        math.inf)  # fmt: skip
    j_shifted = penalized_cost(sub, config, shifted.guess(sub).trajectory)
    if j_tscvx < j_shifted:
        return "tscvx", provider
    return "previous", PredictedRowsFrom(shifted, provider)


@dataclass(frozen=True)
class PredictedRowsFrom:
    """T-SCvx's Algorithm 2 from another start's guess: the guess of ``start`` with the rows
    ``networks`` predict tight (``scpformer.problems.pdg6dof.tscvx.TscvxProvider``)."""

    start: GivenWarmStart
    networks: Any  # scpformer.warmstart.tscvx.TscvxWarmStart

    @property
    def params(self) -> Any:
        """The T-SCvx settings of the networks' provider."""
        return self.networks.params

    def guess(self, instance: PDGInstance) -> Any:
        """The start's guess."""
        return self.start.guess(instance)

    def guess_for(self, instance: PDGInstance, config: PDGSolverConfig) -> Any:
        """The start's guess (``config`` is the solve's; the guess is already on N nodes)."""
        return self.guess(instance)

    def tight(self, instance: PDGInstance) -> Any:
        """The networks' ``k -> flags`` of the rows predicted tight."""
        return self.networks.tight(instance)


def uses_tscvx(config: MPCConfig) -> bool:
    """Whether a loop's configuration flies or compares a start from the T-SCvx networks."""
    return bool({config.warmstart, *config.compare} & {"tscvx", "best"})


@lru_cache(maxsize=4)
def _tscvx_provider(
    config: PDGSolverConfig, model: str | None = None, cold_fallback: bool = True
) -> Any:
    """The T-SCvx networks of ``model`` (a training run folder; None or ``default``: the
    shipped mid-flight ones, ``tscvx-midflight``, checksum verified), loaded once per model
    and configuration;
    ``cold_fallback`` as in :class:`~scpformer.problems.pdg6dof.tscvx.TscvxParameters`."""
    from scpformer.pretrained import resolve_model
    from scpformer.problems.pdg6dof.tscvx import TscvxParameters
    from scpformer.warmstart.tscvx import TscvxWarmStart

    params = TscvxParameters(cold_fallback=cold_fallback)
    networks = resolve_model(model, "pdg6dof", guidance=True)
    return TscvxWarmStart.from_checkpoint(networks, config=config, params=params)


def _accepted(sol: Solution, unconverged: bool = False) -> bool:
    ok = (Status.CONVERGED, Status.MAX_ITERATIONS, Status.STALLED) if unconverged else (
        Status.CONVERGED,)  # fmt: skip
    return (
        sol.status in ok
        and sol.trajectory is not None
        and sol.verification is not None
        and sol.verification.passed
    )


def _replan(
    sub: PDGInstance | None, error: str, name: str, plan: Solution, node: int, k_flown: int,
    t_now: float, period: float, estimate: np.ndarray, cfg: MPCConfig,
) -> tuple[ReplanRecord, Solution | None]:  # fmt: skip
    if sub is None:
        record = ReplanRecord(k_flown, t_now, name, False, "invalid_instance", math.nan, 0, 0.0,
                              period, "", error)  # fmt: skip
        return record, None
    start = time.perf_counter()
    used = name
    if name == "best":
        used, warm = best_start(sub, plan, node, estimate, cfg)
    elif name == "previous":
        warm: Any = shifted_plan(plan, node, estimate)
    elif name == "tscvx":
        warm = cfg.tscvx_provider()
    else:
        warm = None
    method = METHOD[name]
    sol = solve(sub, cfg.replan_solver, method=method, warmstart=warm)
    wall = time.perf_counter() - start
    fallback = ""
    if method == "tscvx":
        fallback = str((sol.extras.get("tscvx") or {}).get("fallback") or "")
    cost = float(sol.cost) if sol.trajectory is not None else math.nan
    ok = _accepted(sol, cfg.accept_unconverged)
    record = ReplanRecord(k_flown, t_now, name, ok, sol.status.value, cost,
                          sol.iterations, wall, period, fallback, sol.message, used)  # fmt: skip
    return record, sol


def open_loop_plan(instance: PDGInstance, config: MPCConfig | None = None) -> Solution:
    """The open-loop optimum from the instance's (true, known) initial state: cold SCvx.

    Raises ``ValueError`` when it fails (no converged, verified trajectory to fly).
    """
    cfg = config or MPCConfig()
    return flyable_plan(solve(instance, cfg.solver), _accepted)


def navigation_fix(
    x: np.ndarray, mass_factor: float, nav: NavigationErrors | None, rng: np.random.Generator
) -> np.ndarray:
    """The navigation estimate (14,) of the true state ``x``: the mass the guidance believes
    (``m / mass_factor``) and, unless ``nav`` is None, position, velocity, attitude (a small
    body-axis rotation) and rate errors drawn from ``rng`` (12 normal draws)."""
    estimate = np.array(x, dtype=float)
    estimate[13] = x[13] / mass_factor
    if nav is not None:
        zn = rng.standard_normal(12)
        estimate[0:3] += nav.position * zn[0:3]
        estimate[3:6] += nav.velocity * zn[3:6]
        estimate[6:10] = _rotated(x[6:10], nav.attitude_deg * DEG * zn[6:9])
        estimate[10:13] += nav.rate_deg * DEG * zn[9:12]
    return estimate


def _deviation(estimate: np.ndarray, planned: np.ndarray) -> np.ndarray:
    """``estimate - planned`` with the estimate's quaternion taken in the plan's hemisphere
    (``q`` and ``-q`` are one attitude)."""
    dx = np.asarray(estimate, dtype=float) - planned
    if float(np.dot(estimate[6:10], planned[6:10])) < 0.0:
        dx[6:10] = -np.asarray(estimate[6:10]) - planned[6:10]
    return dx


def _gains(instance: PDGInstance, plan: Solution, cfg: MPCConfig) -> np.ndarray | None:
    """The tracking gains of ``plan`` (None without tracking)."""
    if cfg.tracking is None:
        return None
    return tracking_gains(instance, plan.trajectory, cfg.tracking, cfg.solver.n_sub)


def _rotated(q: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """``q (x) dq``: ``q`` rotated by the small body-axis rotation vector ``angles`` [rad]."""
    angle = float(np.linalg.norm(angles))
    if angle == 0.0:
        return np.array(q, dtype=float)
    return quat.normalize(quat.multiply(q, quat.from_axis_angle(angles, angle)))


def _thrust_error(u: np.ndarray, scale: float, angles: np.ndarray) -> np.ndarray:
    """``scale`` times ``u`` rotated by ``angles`` (2,) [rad] about two axes normal to it."""
    norm = float(np.linalg.norm(u))
    if norm == 0.0:
        return u * scale
    e = u / norm
    helper = np.array([0.0, 1.0, 0.0]) if abs(e[1]) < 0.9 else np.array([0.0, 0.0, 1.0])
    a = np.cross(e, helper)
    a /= np.linalg.norm(a)
    b = np.cross(e, a)
    rotvec = angles[0] * a + angles[1] * b
    angle = float(np.linalg.norm(rotvec))
    if angle > 0.0:
        u = quat.rotate(quat.from_axis_angle(rotvec, angle), u)
    return np.asarray(u) * scale


def fly(
    instance: PDGInstance,
    config: MPCConfig | None = None,
    *,
    seed: int = 0,
    open_loop: Solution | None = None,
) -> ClosedLoopResult:
    """Fly ``instance`` in closed loop (see the module docstring).

    Parameters
    ----------
    instance
        The descent; its initial state is the truth's (dispersion, if any, is applied by the
        caller: :func:`dispersed_instance`).
    config
        Re-planning period, warm start, errors, tolerance.
    seed
        Seed of the error draws: the vehicle errors from one stream, the navigation and the
        thrust errors each from their own, drawn in the order of use, so that two warm starts
        flown with the same seed see the same vehicle and the same error sequence.
    open_loop
        The open-loop plan (:func:`open_loop_plan`), solved when not given.
    """
    cfg = config or MPCConfig()
    check_int("seed", seed, least=0)
    if not isinstance(instance, PDGInstance):
        raise ValueError(f"instance must be a PDGInstance, got {type(instance).__name__}")
    open_loop = open_loop or open_loop_plan(instance, cfg)
    errors, c = cfg.errors, instance.constants
    rng_vehicle, rng_nav, rng_act, rng_track = (np.random.default_rng([seed, i])
                                                for i in range(4))  # fmt: skip
    z_vehicle = rng_vehicle.standard_normal(5)
    mass_factor = 1.0 + errors.mass_fraction * z_vehicle[0]
    truth_c = replace(
        c,
        J_B_diag=tuple(np.asarray(c.J_B_diag) * np.maximum(1.0 + errors.inertia_fraction
                                                           * z_vehicle[1:4], 0.5)),
        rho_SA_CA=float(c.rho_SA_CA * max(1.0 + errors.aero_fraction * z_vehicle[4], 0.0)),
    )  # fmt: skip
    scalars = np.asarray(truth_c.model().scalars)
    tol_v = cfg.solver.verification
    m = SAMPLES_PER_INTERVAL
    nav = errors.navigation

    planner = planning_instance(instance, cfg)
    first = open_loop if planner is instance else open_loop_plan(planner, cfg)
    if uses_tscvx(cfg):
        # the networks load and run once before the re-plans are timed (a flight computer's
        # start-up, as the rendezvous loops load ART's model)
        cfg.tscvx_provider().guess_for(planner, cfg.replan_solver)
    x = np.array(instance.x0)
    x[13] *= mass_factor
    plan, node, k_flown, t_now, since = first, 0, 0, 0.0, 0
    t_out, x_out, ucmd_out, uexec_out = [0.0], [x.copy()], [], []
    replans: list[ReplanRecord] = []
    comparisons: list[ReplanRecord] = []
    estimates, truths = [], []
    step = 0.0
    u1 = c1 = np.zeros(3)
    gains = _gains(instance, plan, cfg)
    while True:
        z = plan.trajectory
        n = z.x.shape[0]
        dt = float(z.p[0]) / (n - 1)
        remaining = (n - 1 - node) * dt
        if (since >= cfg.replan_every and remaining >= cfg.min_remaining_time
                and n - node >= cfg.replan_every + 2):  # fmt: skip
            since = 0
            estimate = navigation_fix(x, mass_factor, nav, rng_nav)
            truths.append(x.copy())
            estimates.append(estimate)
            try:
                sub, error = remaining_instance(planner, estimate), ""
            except ValueError as err:
                sub, error = None, str(err)
            period = cfg.replan_every * dt
            args = (sub, error)
            rest = (plan, node, k_flown, t_now, period, estimate, cfg)
            record, sol = _replan(*args, cfg.warmstart, *rest)
            if record.accepted and sol is not None:  # the new plan's gains: part of the re-plan
                start = time.perf_counter()
                new_gains = _gains(instance, sol, cfg)
                record = replace(record, wall_s=record.wall_s + time.perf_counter() - start)
            record = within_budget(record, cfg.time_budget_s)
            replans.append(record)
            for other in cfg.compare:
                comparisons.append(within_budget(_replan(*args, other, *rest)[0],
                                                 cfg.time_budget_s))  # fmt: skip
            if record.accepted and sol is not None:
                plan, node, gains = sol, 0, new_gains
                continue
        if node >= n - 1:
            break
        # one interval of the plan through the truth
        c0, c1 = np.asarray(z.u[node], dtype=float), np.asarray(z.u[node + 1], dtype=float)
        if gains is not None:
            du = -gains[node] @ _deviation(navigation_fix(x, mass_factor, nav, rng_track),
                                           z.x[node])  # fmt: skip
            c0, c1 = project_thrust(c0 + du, instance), project_thrust(c1 + du, instance)
        za = rng_act.standard_normal(3)
        scale = 1.0 + errors.thrust_magnitude * za[0]
        angles = errors.pointing_deg * DEG * za[1:3]
        u0 = _thrust_error(c0, scale, angles)
        u1 = _thrust_error(c1, scale, angles)
        params = np.concatenate([scalars, u0, (u1 - u0) / dt])
        sample = np.linspace(0.0, 1.0, m + 1)[1:]
        rows = np.empty((m, x.size))
        step = truth.integrate(params, x, sample * dt, step, tol_v.rtol, tol_v.atol, rows)
        if step == truth.TOO_SMALL_STEP:
            raise RuntimeError(f"truth propagation failed at t = {t_now:.3f} U_T")
        frac = np.r_[0.0, sample][:-1]
        ucmd_out.append(c0 + frac[:, None] * (c1 - c0))
        uexec_out.append(u0 + frac[:, None] * (u1 - u0))
        t_out.extend(t_now + sample * dt)
        x_out.extend(rows)
        x = rows[-1].copy()
        t_now += dt
        node += 1
        k_flown += 1
        since += 1
    ucmd_out.append((c1 if uexec_out else np.asarray(plan.trajectory.u[-1], dtype=float))[None])
    uexec_out.append((u1 if uexec_out else ucmd_out[-1][0])[None])
    tolerance = cfg.tolerance or LandingTolerance.derive(errors, cfg, instance, open_loop)
    return ClosedLoopResult(
        instance=instance, config=cfg, tolerance=tolerance, open_loop=open_loop,
        t=np.array(t_out), x=np.array(x_out), u_cmd=np.concatenate(ucmd_out),
        u_exec=np.concatenate(uexec_out), replans=replans, comparisons=comparisons,
        estimates=np.array(estimates).reshape(-1, 14), truths=np.array(truths).reshape(-1, 14),
        truth_constants={"m0": float(instance.m0 * mass_factor),
                         "J_B_diag": tuple(truth_c.J_B_diag), "rho_SA_CA": truth_c.rho_SA_CA},
    )  # fmt: skip
