"""6-DoF rigid-body powered descent dynamics (Eq. 4 of the T-SCvx paper) and exact Jacobians.

Notation
--------
x = (r_I, v_I, q_{B<-I}, omega_B, m)   state (14,), the order of Eq. 24 of the T-SCvx paper
u = T_B                                thrust in the body frame (3,); body x is the thrust axis
e1 = Up (opposite to g), e2 = East, e3 = North (inertial frame at the landing site)

Dynamics (Eq. 4), all nondimensional (U_L, U_T, U_M):

    m_dot     = -alpha_mdot |T_B| - beta_mdot                               (4a)
    r_dot     = v_I                                                         (4b)
    v_dot     = C_{I<-B}(q) (T_B + A_B) / m + g_I                           (4c)
    q_dot     = 0.5 Omega(omega_B) q                                        (4d)
    omega_dot = J^-1 (r_T x T_B + r_cp x A_B - omega_B x J omega_B)         (4e)

with the aerodynamic force of Szmuk & Acikmese (2018),
``A_B = -0.5 (rho S_A C_A) |v_B| v_B`` and ``v_B = C(q)^T v_I``. ``rho S_A C_A`` is the
single lumped coefficient of Table 1. Every function is vectorized over a leading batch axis,
so a whole horizon (or all integration intervals) is evaluated in one call.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from scpformer.dynamics import quaternion as quat

Array = NDArray[np.float64]

N_STATE = 14
N_CONTROL = 3
R, V, Q, W, M = slice(0, 3), slice(3, 6), slice(6, 10), slice(10, 13), 13


@dataclass(frozen=True)
class RigidBodyModel:
    """Numeric vehicle model used in the inner loops (plain arrays, no validation).

    Build it with :meth:`scpformer.problems.pdg6dof.VehicleConstants.model`.
    """

    g_I: Array  # gravitational acceleration, inertial (3,) [U_L/U_T^2]
    J_B: Array  # inertia matrix (3, 3) [U_M U_L^2]
    J_B_inv: Array  # its inverse (3, 3)
    r_T_B: Array  # thrust application point, body (3,) [U_L]
    r_cp_B: Array  # centre of pressure, body (3,) [U_L]
    alpha_mdot: float  # fuel consumption per unit thrust, 1/(I_sp g0) [U_T/U_L]
    beta_mdot: float  # mass flow lost to back pressure, alpha P_amb A_noz [U_M/U_T]
    rho_SA_CA: float  # lumped aerodynamic coefficient rho S_A C_A [U_M/U_L]


def aero_force(model: RigidBodyModel, v_B: Array) -> Array:
    """Aerodynamic force ``A_B = -0.5 rho S_A C_A |v_B| v_B`` (..., 3)."""
    speed = np.linalg.norm(v_B, axis=-1, keepdims=True)
    return -0.5 * model.rho_SA_CA * speed * v_B


def aero_force_jacobian(model: RigidBodyModel, v_B: Array) -> Array:
    """``dA_B/dv_B = -0.5 rho S_A C_A (|v| I + v v^T / |v|)`` (..., 3, 3), zero at rest."""
    speed = np.linalg.norm(v_B, axis=-1)[..., None, None]
    outer = v_B[..., :, None] * v_B[..., None, :]
    safe = np.where(speed > 0.0, speed, 1.0)
    return -0.5 * model.rho_SA_CA * (speed * np.eye(3) + np.where(speed > 0.0, outer / safe, 0.0))


def dynamics(model: RigidBodyModel, x: Array, u: Array) -> Array:
    """Time derivative ``f(x, u)`` of Eq. 4, shapes (..., 14), (..., 3) -> (..., 14)."""
    q, w, m = x[..., Q], x[..., W], x[..., M]
    v_B = quat.rotate_inverse(q, x[..., V])
    aero = aero_force(model, v_B)
    torque = np.cross(model.r_T_B, u) + np.cross(model.r_cp_B, aero)
    torque = torque - np.cross(w, w @ model.J_B.T)
    xdot = np.empty(np.broadcast_shapes(x.shape, (*u.shape[:-1], N_STATE)))
    xdot[..., R] = x[..., V]
    xdot[..., V] = quat.rotate(q, u + aero) / m[..., None] + model.g_I
    xdot[..., Q] = 0.5 * np.einsum("...ij,...j->...i", quat.omega_matrix(w), q)
    xdot[..., W] = torque @ model.J_B_inv.T
    xdot[..., M] = -model.alpha_mdot * np.linalg.norm(u, axis=-1) - model.beta_mdot
    return xdot


def jacobians(model: RigidBodyModel, x: Array, u: Array) -> tuple[Array, Array]:
    """Exact Jacobians ``A = df/dx`` (..., 14, 14) and ``B = df/du`` (..., 14, 3) of Eq. 4."""
    q, w, m = x[..., Q], x[..., W], x[..., M]
    batch = np.broadcast_shapes(x.shape[:-1], u.shape[:-1])
    A = np.zeros((*batch, N_STATE, N_STATE))
    B = np.zeros((*batch, N_STATE, N_CONTROL))
    v_B = quat.rotate_inverse(q, x[..., V])
    aero = aero_force(model, v_B)
    dA_dvB = aero_force_jacobian(model, v_B)
    dvB_dv = np.swapaxes(quat.dcm(q), -1, -2)
    dvB_dq = quat.rotate_inverse_jacobian(q, x[..., V])
    C = quat.dcm(q)
    inv_m = (1.0 / m)[..., None, None]

    A[..., R, V] = np.eye(3)
    A[..., V, V] = inv_m * C @ dA_dvB @ dvB_dv
    A[..., V, Q] = inv_m * (quat.rotate_jacobian(q, u + aero) + C @ dA_dvB @ dvB_dq)
    A[..., V, M] = -quat.rotate(q, u + aero) / m[..., None] ** 2
    A[..., Q, Q] = 0.5 * quat.omega_matrix(w)
    A[..., Q, W] = 0.5 * quat.xi_matrix(q)
    r_cp_cross_dA = quat.skew(model.r_cp_B) @ dA_dvB
    J_inv = model.J_B_inv
    A[..., W, V] = J_inv @ r_cp_cross_dA @ dvB_dv
    A[..., W, Q] = J_inv @ r_cp_cross_dA @ dvB_dq
    gyro = quat.skew(w) @ model.J_B - quat.skew(w @ model.J_B.T)
    A[..., W, W] = -J_inv @ gyro

    B[..., V, :] = inv_m * C
    B[..., W, :] = J_inv @ quat.skew(model.r_T_B)
    thrust = np.linalg.norm(u, axis=-1, keepdims=True)
    B[..., M, :] = -model.alpha_mdot * np.where(
        thrust > 0.0, u / np.where(thrust > 0, thrust, 1), 0
    )
    return A, B
