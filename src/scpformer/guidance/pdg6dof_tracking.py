"""Feedback tracking of a landing plan between re-plans: a time-varying LQR on the plan's FOH
linearization.

A re-planned plan is flown open loop between re-plans by :mod:`scpformer.guidance.pdg6dof_mpc`
unless a tracking law closes the loop at the interval rate. Guidance of a real lander is built
that way: a low-rate trajectory optimizer and a high-rate controller that keeps the vehicle on
the trajectory (Acikmese & Ploen 2007 and Szmuk & Acikmese 2018 plan; the vehicle's attitude
and translation controllers track). Without it, the errors of the truth (thrust magnitude and
pointing, mass, inertia, aerodynamics) accumulate over each re-planning period, and over the
open-loop tail after the last re-plan, which is what makes the late re-plans fail.

The law is the finite-horizon discrete LQR of the plan's first-order-hold linearization (the
matrices SCvx itself solves with, :func:`scpformer.scp.discretization.foh_discretize`, Eq. 10
of the T-SCvx paper): with the deviation ``dx_k = x_hat_k - x_k`` of the navigation estimate
from the plan at node ``k``, a thrust correction ``du_k = -K_k dx_k`` held constant over the
interval (added to both node thrusts of its first-order hold), so that

    dx_{k+1} = A_k dx_k + (B^-_k + B^+_k) du_k,

and ``K_k`` from the Riccati recursion (Bertsekas, *Dynamic Programming and Optimal Control*,
Vol. I, Sec. 4.1)

    P_N = Q_f,   K_k = (R + B_k' P_{k+1} B_k)^-1 B_k' P_{k+1} A_k,
    P_k = Q + A_k' P_{k+1} (A_k - B_k K_k),

with Bryson's-rule weights (:class:`TrackingWeights`). The corrected thrust is projected onto
the convex part of the thrust set before it is commanded: the gimbal cone 6b (the Euclidean
projection onto a second-order cone) and the magnitude bounds 6a (a radial clip), so the
commanded thrust meets every control constraint exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scpformer.dynamics import powered_descent_kernels as pdk
from scpformer.pdg6dof import PDGInstance
from scpformer.scp.discretization import foh_discretize
from scpformer.scp.solution import Trajectory
from scpformer.validation import check_positive

#: Indices of the state (Eq. 24's order) weighted by the tracking law: position, velocity,
#: the vector part of the quaternion and the body rate. The mass is not tracked (it is what
#: the plan spends; a heavier or lighter vehicle is corrected through its motion) and neither
#: is the quaternion's scalar part (its deviation is second order in the attitude error).
POSITION, VELOCITY, ATTITUDE, RATE = slice(0, 3), slice(3, 6), slice(7, 10), slice(10, 13)
#: Margin kept inside the thrust set by the projection [U_M U_L/U_T^2, rad].
INSIDE = 1e-9


@dataclass(frozen=True, kw_only=True)
class TrackingWeights:
    """Weights of the tracking LQR by Bryson's rule: ``Q = diag(1 / d^2)`` for the deviation
    ``d`` one accepts in each state, ``R = I / d_T^2`` for the thrust correction ``d_T`` one
    accepts, nondimensional units of Table 1.

    Attributes
    ----------
    position
        Acceptable position deviation [U_L]: 0.02, a third of the touchdown position tolerance
        (:class:`scpformer.guidance.pdg6dof_mpc.LandingTolerance`, 0.064 with the default
        errors).
    velocity
        Acceptable velocity deviation [U_L/U_T]: 0.02, under half the velocity tolerance (0.047).
    attitude_deg
        Acceptable attitude deviation [deg]: 1 (the quaternion's vector part is weighted at
        ``sin(1 deg / 2)``).
    rate_deg
        Acceptable body rate deviation [deg/U_T]: 2, a third of the rate tolerance (5.6).
    thrust
        Acceptable thrust correction [U_M U_L/U_T^2]: 0.25, 5% of ``T_max`` (Table 1), well inside
        the margin between the plan's thrust and its bounds on most of a descent.
    terminal
        Factor of the terminal weight ``Q_f = terminal^2 Q``: 3, a touchdown deviation held to a
        third of the path's.
    """

    position: float = 0.02
    velocity: float = 0.02
    attitude_deg: float = 1.0
    rate_deg: float = 2.0
    thrust: float = 0.25
    terminal: float = 3.0

    def __post_init__(self) -> None:
        for name in ("position", "velocity", "attitude_deg", "rate_deg", "thrust", "terminal"):
            object.__setattr__(self, name, check_positive(f"tracking.{name}",
                                                          getattr(self, name)))  # fmt: skip

    def state_weight(self, n: int = 14) -> np.ndarray:
        """The diagonal of ``Q`` (n,)."""
        q = np.zeros(n)
        q[POSITION] = self.position**-2
        q[VELOCITY] = self.velocity**-2
        q[ATTITUDE] = math.sin(math.radians(self.attitude_deg) / 2.0) ** -2
        q[RATE] = math.radians(self.rate_deg) ** -2
        return q


def tracking_gains(
    instance: PDGInstance, plan: Trajectory, weights: TrackingWeights, n_sub: int
) -> np.ndarray:
    """The LQR gains ``K_k`` (N - 1, 3, 14) of the plan's intervals (module docstring).

    ``plan`` is a trajectory of ``N`` nodes over its final time ``plan.p[0]``; ``n_sub`` RK4
    steps per interval discretize it (the family's ``PDGSolverConfig.n_sub``).
    """
    model = pdk.packed_constants(instance.constants.model())
    disc = foh_discretize(lambda x, u: pdk.linearize(model, x, u), plan.x, plan.u,
                          float(plan.p[0]), n_sub)  # fmt: skip
    q = np.diag(weights.state_weight(plan.x.shape[1]))
    r = np.eye(plan.u.shape[1]) / weights.thrust**2
    p = weights.terminal**2 * q
    gains = np.empty((disc.A.shape[0], plan.u.shape[1], plan.x.shape[1]))
    for k in range(disc.A.shape[0] - 1, -1, -1):
        a, b = disc.A[k], disc.Bm[k] + disc.Bp[k]
        pb = p @ b
        gains[k] = np.linalg.solve(r + b.T @ pb, pb.T @ a)
        p = q + a.T @ p @ (a - b @ gains[k])
        p = 0.5 * (p + p.T)
    return gains


def project_thrust(u: np.ndarray, instance: PDGInstance) -> np.ndarray:
    """The body-frame thrust ``u`` (3,) moved into the convex thrust set: first onto the gimbal
    cone ``|u_yz| <= tan(delta_max) u_x`` (6b; the Euclidean projection onto a second-order
    cone), then radially into ``T_min <= |u| <= T_max`` (6a), ``INSIDE`` within each bound."""
    c = instance.constants
    a = math.tan(math.radians(c.delta_max_deg)) * (1.0 - INSIDE)
    u = np.array(u, dtype=float)
    t, s = u[0], float(np.linalg.norm(u[1:]))
    if s > a * t:
        if a * s <= -t:  # in the polar cone: the cone's edge on u's side, at T_min
            edge = np.r_[1.0, a * u[1:] / s] if s > 0.0 else np.array([1.0, 0.0, 0.0])
            u = c.T_min * edge / float(np.linalg.norm(edge))
        else:
            along = (t + a * s) / (1.0 + a * a)
            u = np.r_[along, along * a * u[1:] / s]
    norm = float(np.linalg.norm(u))
    clipped = min(max(norm, c.T_min + INSIDE), c.T_max - INSIDE)
    return u * (clipped / norm)
