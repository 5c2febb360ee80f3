"""Constants of the robust (chance-constrained, passively safe) rendezvous: robust ART Table 1.

Robust ART paper (``robust-art-chance-constrained.txt``), Section 4, Tables 1-2.

Notation and node convention
----------------------------
The family reuses the node convention of :mod:`scpformer.problems.rendezvous`: ``N`` impulses
``u_i = Delta v_i`` (RTN, m/s) at ``t_0 .. t_{N-1}`` and ``N + 1`` nodes ``t_0 .. t_N`` evenly
spread over the horizon (1.29 orbits); ``x_i`` is the scaled MEAN ROE before the impulse at
``t_i`` and ``x_{i+1} = Phi_i (x_i + B_i u_i)`` (Eq. 1). ``x_0`` and ``x_N`` are fixed (the
paper's ``x(t_1) = x_0``, ``x(t_N) = x_f`` with ``N_time = 100``).

Safety domains (Section 4): the approach ellipsoid (AE, semi-axes 1000 m) applies to the
passive-safety constraint of the nodes ``i < n_ae_to_koz`` and the keep-out zone (KOZ, 200 m)
to the nodes ``i >= n_ae_to_koz`` (0-based; the paper gives ``N_ae-to-koz = 55`` without an
index base). ``P = Diag(1/r_r^2, 1/r_t^2, 1/r_n^2)``; the code uses its square root
``E = Diag(1/r_r, 1/r_t, 1/r_n)`` so that ``|E dr|_2 >= 1`` is "outside".

Pre-docking waypoints (Table 1): ``x_f`` in RTN is ``+-750 m`` along V-bar (``+T``, ``-T``) or
R-bar (``+R``, ``-R``) with zero relative velocity.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from scpformer.dynamics.uncertainty import UncertaintyModel
from scpformer.problems.rendezvous.scenario import MAX_NODES, TargetOrbit, check_orbits
from scpformer.scp.scvx_star import SCvxStarParameters
from scpformer.validation import check_bool, check_finite, check_int, check_positive, known_fields

WAYPOINTS = ("+T", "-T", "+R", "-R")
MODES = ("deterministic", "chance")
DYNAMICS = ("nonlinear", "stm")
_WAYPOINT_AXIS = {"+T": (0.0, 1.0, 0.0), "-T": (0.0, -1.0, 0.0), "+R": (1.0, 0.0, 0.0),
                  "-R": (-1.0, 0.0, 0.0)}  # fmt: skip


def robust_target() -> TargetOrbit:
    """Target orbit of robust Table 1: ``a = 6738 km``, ``e = 5.58e-4``, ``i = 51.64 deg``,
    ``Omega = 301.04 deg``, ``omega = 26.18 deg``, ``M(t_1) = 68.23 deg`` (period 1.529 h).

    Taken as MEAN elements of the first-order J2 model, as in the rendezvous family.
    """
    return TargetOrbit(a_m=6738e3, e=5.58e-4, i_deg=51.64, raan_deg=301.04, argp_deg=26.18,
                       M_deg=68.23)  # fmt: skip


def check_waypoint(waypoint: Any, name: str = "waypoint") -> str:
    """Return ``waypoint`` if it names one of the four pre-docking states, else raise
    ``ValueError`` naming ``name``."""
    if waypoint not in WAYPOINTS:
        raise ValueError(f"{name} must be one of {', '.join(WAYPOINTS)}, got {waypoint!r}")
    return str(waypoint)


def check_mode(mode: Any) -> str:
    """Return ``mode`` if it is ``"deterministic"`` or ``"chance"``, else raise."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    return str(mode)


def _axes(name: str, value: Any) -> tuple[float, float, float]:
    axes = check_finite(name, value, shape=(3,))
    if np.any(axes <= 0.0):
        raise ValueError(f"{name} must be positive, got {tuple(axes)}")
    return tuple(float(v) for v in axes)


@dataclass(frozen=True, kw_only=True)
class RobustScenario:
    """OCP column of robust Table 1 (all but the target orbit and the boundary states).

    ``horizon_orbits`` and ``t_safety_orbits`` are each at most
    :data:`~scpformer.problems.rendezvous.scenario.MAX_HORIZON_ORBITS` (200 orbits).
    """

    n_nodes: int = 100  # N_time: number of impulses (N + 1 nodes)
    horizon_orbits: float = 1.29  # horizon [target orbits]
    t_safety_orbits: float = 1.0  # T_safety: free-drift duration after a contingency [orbits]
    n_safety: int = 20  # N_safety: samples of each free-drift arc (t_i .. t_i + T_safety)
    ae_semi_axes_m: tuple[float, float, float] = (1000.0, 1000.0, 1000.0)  # AE (r_r, r_t, r_n) [m]
    koz_semi_axes_m: tuple[float, float, float] = (200.0, 200.0, 200.0)  # KOZ (r_r, r_t, r_n) [m]
    n_ae_to_koz: int = 55  # N_ae-to-koz: first node (0-based) guarded by the KOZ instead of the AE
    waypoint_distance_m: float = 750.0  # |x_f| along R-bar or V-bar of the pre-docking state [m]
    j2: bool = True  # J2 state transition matrix (Koenig 2017); False: Keplerian

    def __post_init__(self) -> None:
        n_nodes = check_int("scenario.n_nodes", self.n_nodes, least=2, most=MAX_NODES)
        object.__setattr__(self, "n_nodes", n_nodes)  # MAX_NODES: memory and time, not physics
        object.__setattr__(self, "n_safety", check_int("scenario.n_safety", self.n_safety, least=1))
        switch = check_int("scenario.n_ae_to_koz", self.n_ae_to_koz, least=0)
        if switch > self.n_nodes:
            raise ValueError(f"scenario.n_ae_to_koz must be <= n_nodes, got {switch}")
        object.__setattr__(self, "n_ae_to_koz", switch)
        distance = check_positive("scenario.waypoint_distance_m", self.waypoint_distance_m)
        object.__setattr__(self, "waypoint_distance_m", distance)
        horizon = check_orbits("scenario.horizon_orbits", self.horizon_orbits)
        object.__setattr__(self, "horizon_orbits", horizon)
        # a free drift of no duration leaves no arc to sample (and no passive safety to impose)
        t_safe = check_orbits("scenario.t_safety_orbits", self.t_safety_orbits)
        object.__setattr__(self, "t_safety_orbits", t_safe)
        for name in ("ae_semi_axes_m", "koz_semi_axes_m"):
            object.__setattr__(self, name, _axes(f"scenario.{name}", getattr(self, name)))
        object.__setattr__(self, "j2", check_bool("scenario.j2", self.j2))
        # Section 4: the approach ellipsoid guards the far nodes and the keep-out zone inside
        # it the near ones; an AE inside the KOZ would relax the far nodes' safety below the
        # near ones', which no mission asks for
        if any(ae < koz for ae, koz in zip(self.ae_semi_axes_m, self.koz_semi_axes_m, strict=True)):
            raise ValueError(
                f"scenario.ae_semi_axes_m {self.ae_semi_axes_m} m must contain the keep-out "
                f"zone scenario.koz_semi_axes_m {self.koz_semi_axes_m} m (each semi-axis >=)"
            )
        if self.waypoint_distance_m <= max(self.koz_semi_axes_m):
            raise ValueError(
                f"scenario.waypoint_distance_m ({self.waypoint_distance_m} m) must exceed the "
                f"keep-out zone {self.koz_semi_axes_m} m"
            )

    def ellipsoid_E(self) -> np.ndarray:
        """``E_i = P_i^(1/2)`` of the domain guarding each node ``0 .. N``, (N+1, 3, 3) [1/m]."""
        inv = np.where(
            (np.arange(self.n_nodes + 1) < self.n_ae_to_koz)[:, None],
            1.0 / np.asarray(self.ae_semi_axes_m),
            1.0 / np.asarray(self.koz_semi_axes_m),
        )
        E = np.zeros((self.n_nodes + 1, 3, 3))
        E[:, [0, 1, 2], [0, 1, 2]] = inv
        return E

    def waypoint_rtn(self, waypoint: str) -> np.ndarray:
        """Pre-docking RTN state ``x_f`` [m, m/s] of ``waypoint`` (Table 1), (6,)."""
        axis = np.asarray(_WAYPOINT_AXIS[check_waypoint(waypoint)])
        return np.r_[self.waypoint_distance_m * axis, 0.0, 0.0, 0.0]

    def to_dict(self) -> dict[str, Any]:
        """Plain values that :meth:`from_dict` reads back."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, data: Any) -> RobustScenario:
        """Build from plain values; unknown keys raise ``ValueError`` naming them."""
        if isinstance(data, cls):
            return data
        data = known_fields(cls, data, "scenario")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in data.items()})


@dataclass(frozen=True, kw_only=True)
class RobustVerification:
    """Pass/fail thresholds of a robust solution (not in the paper).

    ``model_residual_m`` catches an inaccurate conic solution (the linear dynamics and the
    boundary conditions are exact constraints of every subproblem). By default
    (``truth_replay``) every verified plan is also replayed: its impulses go through the
    two-body + J2 propagator of osculating states from the consistent osculating initial state
    (:func:`~scpformer.problems.robust_rendezvous.problem.replay`), and the miss of the
    waypoint ``x_f`` at ``t_N`` must stay within ``terminal_position_m`` and
    ``terminal_velocity_m_s``, the thresholds of the deterministic rendezvous family's
    ``VerificationTolerances`` (2 m, 2 mm/s). Measured on 40 three-stage chance plans (seed 0,
    ``benchmarks/robust_truth_replay.py``): largest miss 0.96 m and 0.18 mm/s, none failing;
    a solve replays twice (stages 2 and 3; three times when stage 3 is retried), median
    0.04-0.07 s per replay and 0.11-0.13 s per solve on 2 shared cores (load 1.5 to 6), a few
    percent of the solve. The plans of ``dynamics = "stm"`` (the paper's first-order model) miss
    the waypoint by tens of metres at the kilometres of Table 1 and so fail this check; set
    ``truth_replay = False`` to compare such plans on the model alone.
    """

    model_residual_m: float = 1e-3  # max |x_{k+1} - Phi (x_k + B u_k)| and boundary misses [m]
    dynamics_defect_m: float = 0.02  # max nonlinear mean-dynamics defect of a plan [m]
    safety_tol: float = 1e-3  # h_i <= safety_tol counts as safe (normalized distance) [-]
    truth_replay: bool = True  # replay the impulses through the two-body + J2 propagator
    terminal_position_m: float = 2.0  # |r(t_N) - r_f| of the truth replay [m]
    terminal_velocity_m_s: float = 2e-3  # |v(t_N) - v_f| of the truth replay [m/s]

    def __post_init__(self) -> None:
        for name in (
            "model_residual_m",
            "dynamics_defect_m",
            "safety_tol",
            "terminal_position_m",
            "terminal_velocity_m_s",
        ):
            object.__setattr__(
                self, name, check_positive(f"verification.{name}", getattr(self, name))
            )
        object.__setattr__(
            self, "truth_replay", check_bool("verification.truth_replay", self.truth_replay)
        )


@dataclass(frozen=True, kw_only=True)
class RobustSolverConfig:
    """How the robust rendezvous is solved: SCvx* (robust Table 1) and verification.

    ``three_stage_iter_max`` (not in the paper) caps the passive-safety stage of the
    three-stage solve (:func:`~scpformer.problems.robust_rendezvous.api.solve`, what
    ``scpformer solve`` and ``generate`` run) instead of Table 1's 20, which
    ``scvx.iter_max`` keeps for every warm-started SCvx* run (PS-CVX and PS-ART, whose
    infeasibility rate at 20 solves is what the paper's Figs. 5-6 compare). Measured on the 44
    chance plans of seeds 10-20 (four waypoints each): 6 ended at 20 solves without
    converging; with 60 all 6 converged, in 21 to 36 solves. A stage-3 run that ends at the
    cap is not passively safe, so a user's plan should get the solves it needs.
    """

    safety_mode: str = "chance"  # passive safety: chance-constrained (Eq. 16) or deterministic
    tight_tol: float = 1e-4  # a safety row is tight when h_i >= -tight_tol [-]
    u_trust_scale: float = 1.0  # trust region on u is r * u_trust_scale [m/s] (paper: same r)
    n_linearized: int = 3  # K: worst drift samples per node linearized in Eq. 17 (paper: 1)
    margin_gradient: bool = True  # linearize the margin beta too (paper: held at the reference)
    dynamics: str = "nonlinear"  # plan model: mean-element flow (nonlinear) or the J2 STM (stm)
    three_stage_iter_max: int = 60  # SCvx* solves of stage 3 in the three-stage solve (paper: 20)
    scvx: SCvxStarParameters = field(default_factory=SCvxStarParameters)
    verification: RobustVerification = field(default_factory=RobustVerification)

    def __post_init__(self) -> None:
        object.__setattr__(self, "safety_mode", check_mode(self.safety_mode))
        object.__setattr__(self, "tight_tol", check_positive("tight_tol", self.tight_tol))
        object.__setattr__(
            self, "u_trust_scale", check_positive("u_trust_scale", self.u_trust_scale)
        )
        object.__setattr__(
            self, "n_linearized", check_int("n_linearized", self.n_linearized, least=1)
        )
        object.__setattr__(
            self,
            "three_stage_iter_max",
            check_int("three_stage_iter_max", self.three_stage_iter_max, least=1),
        )
        object.__setattr__(
            self, "margin_gradient", check_bool("margin_gradient", self.margin_gradient)
        )
        if self.dynamics not in DYNAMICS:
            raise ValueError(
                f"dynamics must be one of {', '.join(DYNAMICS)}, got {self.dynamics!r}"
            )


__all__ = [
    "DYNAMICS",
    "MODES",
    "WAYPOINTS",
    "RobustScenario",
    "RobustSolverConfig",
    "RobustVerification",
    "UncertaintyModel",
    "check_mode",
    "check_waypoint",
    "robust_target",
]
