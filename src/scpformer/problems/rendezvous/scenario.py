"""Constants of the rendezvous family: ART paper Table 1 (target orbit, OCP, SCP columns).

Notation (ART paper, Section 4)
-------------------------------
* Target (ISS) orbit: classical elements ``(a, e, i, Omega, omega, M(t_1))``, taken as the
  MEAN elements of the J2 model (the state transition matrix of Koenig et al. 2017 propagates
  mean relative orbital elements); :mod:`.problem` builds an osculating initial state
  consistent with them for the nonlinear verification.
* Keep-out zone (KOZ): ellipsoid ``|E_koz dr|_2 >= 1`` with principal semi-axes
  ``r_koz = (h_iss + 15, l_iss + 20, w_iss + 15)`` m along R, T, N.
* Docking port ``dr_dp = (0, l_iss, 0)``, approach axis ``n_ac = (0, 1, 0)``, half-angle
  ``gamma_ac = 30 deg``; the waypoint ``dr_wp = dr_dp + 30 n_ac`` is held with zero relative
  velocity at node ``N_wp = N - 10``.
* SCP: at most ``K = 20`` iterations, trust radius from ``zeta_1 = 200 m`` shrinking
  exponentially towards ``zeta_K = 1 m`` (Eq. 18), cost tolerance ``J_tol = 1e-6 m/s`` (Eq. 19).

Node indexing. Times are ``t_0 .. t_N`` (N intervals, N + 1 nodes, 0-based). The impulse
``dv_k`` is applied at ``t_k`` for ``k = 0 .. N-1`` and the docking conditions hold at ``t_N``.
``n_waypoint = N - waypoint_offset`` is the 0-based index of the waypoint node, so the waypoint
precedes docking by ``waypoint_offset`` intervals (as in the ART reference code; the paper's
1-based ``t_{N_wp}`` with ``N_wp = N - 10`` would be index ``N - 11``). The keep-out constraint
applies at nodes ``0 .. n_waypoint`` and the approach cone at nodes ``n_waypoint .. N-1``.

A remaining-horizon problem of closed-loop guidance may start at or after the waypoint node
(``waypoint_offset >= N``, ``n_waypoint <= 0``, :attr:`RendezvousScenario.waypoint_passed`):
it has no waypoint condition and no keep-out constraint, and the cone applies at nodes
``1 .. N-1`` (node 0's position is given: a row there could only make the problem infeasible,
when a navigation estimate lies just outside the cone). ``n_waypoint = 1`` is refused (one
impulse cannot reach the waypoint's six conditions), as is a passed waypoint with fewer than
two impulses.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np

from scpformer.dynamics.orbits import R_EARTH, OrbitalElements
from scpformer.scp.conic import check_solver
from scpformer.validation import (
    check_bool,
    check_finite,
    check_in_range,
    check_int,
    check_positive,
    known_fields,
)

STOP_TESTS = ("step", "radius")
UNIT_AXIS_TOL = 1e-6
MIN_SIN_INCLINATION = 1e-6
#: Longest OCP horizon (and free-drift arc) accepted [target orbits]: 200 orbits, about 13 days
#: in the ISS orbit. The ART paper samples horizons of 1 to 3 orbits (Table 1) and the robust
#: ART paper uses 1.29 orbits plus a 1-orbit drift; 200 leaves a wide margin for studies of
#: long horizons while refusing absurd values (1e6 orbits), whose replay and time grids would
#: run for minutes or exhaust memory instead of failing.
MAX_HORIZON_ORBITS = 200.0


def check_orbits(name: str, value: Any) -> float:
    """``value`` as a float after checking ``0 < value <= MAX_HORIZON_ORBITS`` (a duration in
    target orbits); ``ValueError`` naming ``name`` and the bound otherwise."""
    orbits = check_positive(name, value)
    if orbits > MAX_HORIZON_ORBITS:
        raise ValueError(
            f"{name} must be at most {MAX_HORIZON_ORBITS:g} orbits (MAX_HORIZON_ORBITS), "
            f"got {orbits:g}"
        )
    return orbits


def _vector(name: str, value: Any, size: int) -> tuple[float, ...]:
    return tuple(float(v) for v in check_finite(name, value, shape=(size,)))


MAX_NODES = 1000  # largest number of impulses N accepted (memory and time, not physics)
#: Fewest impulses of a problem whose waypoint is passed: docking fixes the 6 ROE at t_N, which
#: a single 3-D impulse cannot reach from a given state in general.
MIN_PASSED_NODES = 2


@dataclass(frozen=True, kw_only=True)
class TargetOrbit:
    """Mean orbital elements of the target (ISS) at ``t_0``, Table 1 of the ART paper."""

    a_m: float = R_EARTH + 416e3  # semi-major axis a [m], R_E + 416 km
    e: float = 5.58e-4  # eccentricity e [-]
    i_deg: float = 51.64  # inclination i [deg]
    raan_deg: float = 301.04  # right ascension of the ascending node Omega [deg]
    argp_deg: float = 26.18  # argument of periapsis omega [deg]
    M_deg: float = 68.23  # mean anomaly M(t_1) [deg]

    def __post_init__(self) -> None:
        for f in fields(self):
            value = float(check_finite(f"target.{f.name}", getattr(self, f.name), shape=()))
            object.__setattr__(self, f.name, value)
        if self.a_m < R_EARTH:
            raise ValueError(
                f"target.a_m: semi-major axis {self.a_m:.6g} m is below the Earth radius "
                f"{R_EARTH:.6g} m"
            )
        if not 0.0 <= self.e < 1.0:
            raise ValueError(f"target.e: eccentricity must satisfy 0 <= e < 1, got {self.e}")
        if self.a_m * (1.0 - self.e) < R_EARTH:
            raise ValueError(
                f"target.e: periapsis radius {self.a_m * (1 - self.e):.6g} m is below the Earth "
                "radius"
            )
        check_in_range("target.i_deg", self.i_deg, 0.0, 180.0)
        if abs(math.sin(math.radians(self.i_deg))) < MIN_SIN_INCLINATION:
            raise ValueError(
                "target.i_deg: quasi-nonsingular ROE are singular for an equatorial orbit"
            )

    @property
    def oe(self) -> OrbitalElements:
        """The elements as :class:`~scpformer.dynamics.orbits.OrbitalElements` (radians)."""
        return OrbitalElements.from_degrees(
            self.a_m, self.e, self.i_deg, self.raan_deg, self.argp_deg, self.M_deg
        )

    @property
    def period_s(self) -> float:
        """Keplerian orbital period ``2 pi sqrt(a^3 / mu)`` [s] (Table 1: 1.548 h)."""
        return self.oe.period

    def to_dict(self) -> dict[str, float]:
        """Plain values, the keys of the ``target_oe`` record of the .npz file."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Any) -> TargetOrbit:
        """Build from plain values; unknown keys raise ``ValueError`` naming them."""
        if isinstance(data, cls):
            return data
        return cls(**known_fields(cls, data, "target"))


@dataclass(frozen=True, kw_only=True)
class RendezvousScenario:
    """OCP constants of the ISS rendezvous (Table 1, OCP column) and the horizon domain.

    ``horizon_range_orbits`` may not reach beyond :data:`MAX_HORIZON_ORBITS` (200 orbits).
    """

    n_nodes: int = 100  # N, number of impulses (N + 1 nodes t_0..t_N)
    w_iss_m: float = 108.0  # ISS width w_iss [m]
    l_iss_m: float = 74.0  # ISS length l_iss [m]
    h_iss_m: float = 45.0  # ISS height h_iss [m]
    koz_margins_m: tuple[float, float, float] = (15.0, 20.0, 15.0)  # r_koz - (h, l, w) [m]
    dock_port_m: tuple[float, float, float] = (0.0, 74.0, 0.0)  # docking port dr_dp, RTN [m]
    approach_axis: tuple[float, float, float] = (0.0, 1.0, 0.0)  # approach axis n_ac (unit)
    cone_half_angle_deg: float = 30.0  # approach cone half-angle gamma_ac [deg]
    cone_vertex_setback_m: float = 5.0  # cone vertex at dr_dp - setback * n_ac [m], see note
    waypoint_distance_m: float = 30.0  # dr_wp = dr_dp + distance * n_ac [m]
    waypoint_offset: int = 10  # N - N_wp, intervals from the waypoint to docking
    horizon_range_orbits: tuple[float, float] = (1.0, 3.0)  # admissible OCP horizon [orbits]
    j2: bool = True  # J2 state transition matrix (Koenig 2017); False: Keplerian

    # Note on cone_vertex_setback_m. With the vertex at the docking port itself (Eq. 13 read
    # literally) the last coast arc t_{N-1} -> t_N cannot lie in the cone: an impulse changes
    # velocity only, so the position at t_{N-1} is the backward coast of the docked state,
    # which on the eccentric, J2-perturbed orbit sits ~0.6 mm off the V-bar at ~80 deg from
    # the axis; Problem 2 is then infeasible (measured with Clarabel and ECOS on the nominal
    # instance). We therefore keep the vertex 5 m behind the port. The ART paper's public
    # code (art-aeroconf24) does not: it puts the vertex at the port itself. On 20 instances
    # from that code's own sampler, moving its vertex to ours lowers its costs by a median of
    # 2.8%, almost all of the cost difference between the two programs. The later
    # transformermpc-ral24 code sets the vertex 5 m back, as we do
    # (benchmarks/rendezvous_vs_public_art.py checks that its scenario matches ours).

    def __post_init__(self) -> None:
        # at most MAX_NODES (memory and time: the compiled SCP holds dense (N+1) x 6 blocks per
        # node; the paper uses 100), so that a typo fails here, not in the OOM killer
        n_nodes = check_int("scenario.n_nodes", self.n_nodes, most=MAX_NODES)
        object.__setattr__(self, "n_nodes", n_nodes)
        offset = check_int("scenario.waypoint_offset", self.waypoint_offset)
        object.__setattr__(self, "waypoint_offset", offset)
        if self.waypoint_offset < 2:
            raise ValueError(f"scenario.waypoint_offset must be >= 2, got {self.waypoint_offset}")
        if self.n_nodes < MIN_PASSED_NODES or self.n_nodes == self.waypoint_offset + 1:
            raise ValueError(
                f"scenario.n_nodes must be >= waypoint_offset + 2 = {self.waypoint_offset + 2} "
                f"(the waypoint at node 2 or later) or between {MIN_PASSED_NODES} and "
                f"waypoint_offset = {self.waypoint_offset} (the waypoint passed), "
                f"got {self.n_nodes}"
            )
        for name in ("w_iss_m", "l_iss_m", "h_iss_m", "waypoint_distance_m"):
            object.__setattr__(self, name, check_positive(f"scenario.{name}", getattr(self, name)))
        setback = float(check_finite("scenario.cone_vertex_setback_m", self.cone_vertex_setback_m))
        if setback < 0.0:
            raise ValueError(f"scenario.cone_vertex_setback_m must be >= 0, got {setback}")
        object.__setattr__(self, "cone_vertex_setback_m", setback)
        margins = check_finite("scenario.koz_margins_m", self.koz_margins_m, shape=(3,))
        if np.any(margins < 0.0):
            raise ValueError(f"scenario.koz_margins_m must be >= 0, got {tuple(margins)}")
        object.__setattr__(self, "koz_margins_m", tuple(float(m) for m in margins))
        object.__setattr__(
            self, "dock_port_m", _vector("scenario.dock_port_m", self.dock_port_m, 3)
        )
        axis = _vector("scenario.approach_axis", self.approach_axis, 3)
        if abs(np.linalg.norm(axis) - 1.0) > UNIT_AXIS_TOL:
            raise ValueError(
                f"scenario.approach_axis must be a unit vector, got norm {np.linalg.norm(axis):.6g}"
            )
        object.__setattr__(self, "approach_axis", axis)
        gamma = check_in_range("scenario.cone_half_angle_deg", self.cone_half_angle_deg, 0.0, 90.0)
        if not 0.0 < gamma < 90.0:
            raise ValueError(f"scenario.cone_half_angle_deg must lie in (0, 90), got {gamma}")
        object.__setattr__(self, "cone_half_angle_deg", gamma)
        lo, hi = _vector("scenario.horizon_range_orbits", self.horizon_range_orbits, 2)
        if not 0.0 < lo <= hi:
            raise ValueError(
                f"scenario.horizon_range_orbits must satisfy 0 < low <= high, got ({lo}, {hi})"
            )
        check_orbits("scenario.horizon_range_orbits", hi)
        object.__setattr__(self, "horizon_range_orbits", (lo, hi))
        object.__setattr__(self, "j2", check_bool("scenario.j2", self.j2))
        if self.koz_metric(self.waypoint_m) < 1.0:
            raise ValueError(
                "scenario.waypoint_distance_m: the waypoint "
                f"{tuple(round(v, 3) for v in self.waypoint_m)} m lies inside the keep-out zone"
            )

    # -- derived quantities --------------------------------------------------------------
    @property
    def koz_semi_axes_m(self) -> tuple[float, float, float]:
        """Principal semi-axes ``(r_r, r_t, r_n) = (h + 15, l + 20, w + 15)`` [m] (Table 1)."""
        mr, mt, mn = self.koz_margins_m
        return (self.h_iss_m + mr, self.l_iss_m + mt, self.w_iss_m + mn)

    @property
    def E_koz(self) -> np.ndarray:
        """Position block ``Diag(1/r_r, 1/r_t, 1/r_n)`` of ``E_koz`` (Eq. 14), (3, 3) [1/m]."""
        return np.diag(1.0 / np.asarray(self.koz_semi_axes_m))

    @property
    def n_waypoint(self) -> int:
        """0-based node index of the waypoint, ``N - waypoint_offset`` (see module docstring)."""
        return self.n_nodes - self.waypoint_offset

    @property
    def waypoint_passed(self) -> bool:
        """Whether the waypoint lies at or before node 0 (``waypoint_offset >= n_nodes``).

        Such a scenario poses the remaining horizon of the final approach (closed-loop
        re-planning at or after the waypoint node, :mod:`scpformer.guidance.rendezvous_mpc`):
        no waypoint condition, the approach cone (Eq. 13) at every node the plan moves,
        ``1 .. N-1`` (:attr:`cone_start`), and no keep-out constraint (every node after the
        waypoint lies in the approach corridor, inside the keep-out ellipsoid, which no longer
        applies there).
        """
        return self.n_waypoint <= 0

    @property
    def n_keep_out(self) -> int:
        """Number of keep-out nodes ``0 .. n_waypoint`` (0 once the waypoint is passed)."""
        return 0 if self.waypoint_passed else self.n_waypoint + 1

    @property
    def cone_start(self) -> int:
        """First node of the approach cone: ``n_waypoint``, or 1 once the waypoint is passed.

        Once passed, node 0 is the current state (a navigation estimate), which no impulse
        moves: like the keep-out check of an initial state, a cone row there could only make
        the problem infeasible (measured: estimates 0.3 m outside the cone near the port).
        """
        return 1 if self.waypoint_passed else self.n_waypoint

    @property
    def waypoint_m(self) -> np.ndarray:
        """Waypoint ``dr_wp = dr_dp + d_wp n_ac`` [m], (3,)."""
        return np.asarray(self.dock_port_m) + self.waypoint_distance_m * np.asarray(
            self.approach_axis
        )

    @property
    def cone_vertex_m(self) -> np.ndarray:
        """Apex of the approach cone ``dr_dp - setback n_ac`` [m], (3,)."""
        return np.asarray(self.dock_port_m) - self.cone_vertex_setback_m * np.asarray(
            self.approach_axis
        )

    def koz_metric(self, r_rtn: Any) -> np.ndarray:
        """``|E_koz dr|_2`` (>= 1 outside the keep-out zone) for positions ``(..., 3)`` [m]."""
        return np.linalg.norm(np.asarray(r_rtn, dtype=float)[..., :3] @ self.E_koz, axis=-1)

    def to_dict(self) -> dict[str, Any]:
        """Plain values that :meth:`from_dict` reads back."""
        out = asdict(self)
        for key, value in out.items():
            if isinstance(value, tuple):
                out[key] = list(value)
        return out

    @classmethod
    def from_dict(cls, data: Any) -> RendezvousScenario:
        """Build from plain values; unknown keys raise ``ValueError`` naming them."""
        if isinstance(data, cls):
            return data
        kwargs = known_fields(cls, data, "scenario")
        for key, value in kwargs.items():
            if isinstance(value, list):
                kwargs[key] = tuple(value)
        return cls(**kwargs)


@dataclass(frozen=True, kw_only=True)
class SCPParameters:
    """The SCP of Section 4 (Table 1, SCP column) and how its subproblems are solved.

    ``stop_test`` selects the reading of Eq. 19. Read literally (``"radius"``) the test
    ``zeta_k <= zeta_K`` can never hold before ``k = K``, since Eq. 18 gives
    ``zeta_k = zeta_1 (zeta_K / zeta_1)^((k-1)/K) > zeta_K`` for ``k <= K``; the SCP then always
    runs ``K`` iterations. ``"step"`` (default) uses the realized step
    ``max_i |de_k(t_i) - de_bar_k(t_i)|_2 <= zeta_K`` instead, as the ART reference code does,
    which stops as soon as the iterates and the cost have settled.
    """

    K: int = 20  # K, maximum number of SCP iterations
    zeta_1: float = 200.0  # zeta_1, initial (maximum) trust region radius [m]
    zeta_K: float = 1.0  # zeta_K, final (minimum) trust region radius [m]
    J_tol: float = 1e-6  # J_tol, tolerance on the cost decrease [m/s]
    stop_test: str = "step"  # reading of Eq. 19: "step" (realized step) or "radius" (literal)
    solver: str = "clarabel"  # conic solver: clarabel, ecos or qoco

    def __post_init__(self) -> None:
        object.__setattr__(self, "K", check_int("scp.K", self.K, least=1))
        zeta_1 = check_positive("scp.zeta_1", self.zeta_1)
        zeta_K = check_positive("scp.zeta_K", self.zeta_K)
        if zeta_K > zeta_1:
            raise ValueError(f"scp.zeta_K ({zeta_K}) must not exceed scp.zeta_1 ({zeta_1})")
        object.__setattr__(self, "zeta_1", zeta_1)
        object.__setattr__(self, "zeta_K", zeta_K)
        object.__setattr__(self, "J_tol", check_positive("scp.J_tol", self.J_tol))
        if self.stop_test not in STOP_TESTS:
            raise ValueError(f"scp.stop_test must be one of {STOP_TESTS}, got {self.stop_test!r}")
        check_solver(self.solver, "scp.solver")

    @property
    def beta(self) -> float:
        """Shrink factor ``(zeta_K / zeta_1)^(1/K)`` of Eq. 18."""
        return (self.zeta_K / self.zeta_1) ** (1.0 / self.K)


@dataclass(frozen=True, kw_only=True)
class VerificationTolerances:
    """Pass/fail thresholds of the nonlinear replay (not in the paper; see the note).

    The plan is computed with a first-order model of MEAN relative orbital elements and the
    replay propagates OSCULATING states of both spacecraft under two-body + J2 (DOP853). With
    an initial osculating state consistent with the mean one (``consistent_initial_state``),
    the remaining gap is the model's own error: the short-period J2 terms of the relative
    motion plus the first-order truncation of the STM and maps. Measured on 100 Problem 3
    solutions of sampled Table 1 instances (``scpformer bench rendezvous --n 100``): terminal
    miss median 0.28 m, max 0.68 m and max 0.46 mm/s; linear-vs-truth gap max 0.74 m;
    keep-out depth max 0.0027. The defaults leave a factor of about 3 over those maxima. With
    ``consistent_initial_state = False`` (mean elements used as osculating) the differential
    mean/osculating semi-major axis (~0.2 m) drifts into metres of along-track miss (4.9 m
    after 2 orbits on the default instance instead of 0.45 m).
    """

    terminal_position_m: float = 2.0  # |r(t_N) - dr_dp| of the replay [m]
    terminal_velocity_m_s: float = 2e-3  # |v(t_N)| of the replay [m/s]
    waypoint_position_m: float = 2.0  # |r(t_wp) - dr_wp| of the replay [m]
    waypoint_velocity_m_s: float = 2e-3  # |v(t_wp)| of the replay [m/s]
    keep_out: float = 0.02  # max of 1 - |E_koz r| at the keep-out nodes [-]
    cone_m: float = 0.5  # max of |d| cos(gamma) - n.d at the cone nodes, d = r - apex [m]
    model_residual_m: float = 1e-3  # max |x_{k+1} - Phi (x_k + B dv_k)| of the solution [m]
    samples_per_interval: int = 4  # replay outputs per interval (path violations)
    dv_zero_m_s: float = 1e-9  # impulses below this norm are replayed as zero [m/s]
    consistent_initial_state: bool = True  # osculating initial state whose mean is the model's

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.name in ("samples_per_interval", "consistent_initial_state"):
                continue
            object.__setattr__(
                self, f.name, check_positive(f"verification.{f.name}", getattr(self, f.name))
            )
        samples = check_int("verification.samples_per_interval", self.samples_per_interval, least=1)
        object.__setattr__(self, "samples_per_interval", samples)
        consistent = check_bool(
            "verification.consistent_initial_state", self.consistent_initial_state
        )
        object.__setattr__(self, "consistent_initial_state", consistent)


@dataclass(frozen=True, kw_only=True)
class RendezvousSolverConfig:
    """How to pose and solve the rendezvous problems: SCP constants and verification."""

    tight_tol: float = 1e-5  # a keep-out/cone row is tight when its slack is below this
    scp: SCPParameters = field(default_factory=SCPParameters)
    verification: VerificationTolerances = field(default_factory=VerificationTolerances)

    def __post_init__(self) -> None:
        object.__setattr__(self, "tight_tol", check_positive("tight_tol", self.tight_tol))
