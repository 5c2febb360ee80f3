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

import math
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from scpformer.dynamics import quaternion as quat
from scpformer.jit import compiled

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

    @cached_property
    def scalars(self) -> tuple[float, ...]:
        """The constants :func:`dynamics_scalar` reads, as Python floats: the diagonal of
        ``J_B``, ``r_T_B``, ``r_cp_B``, ``g_I``, then ``-0.5 rho S_A C_A``, ``alpha_mdot`` and
        ``beta_mdot`` (computed once per model; a float of a numpy array costs a call)."""
        return (
            *np.diag(self.J_B).tolist(),
            *self.r_T_B.tolist(),
            *self.r_cp_B.tolist(),
            *self.g_I.tolist(),
            -0.5 * float(self.rho_SA_CA),
            float(self.alpha_mdot),
            float(self.beta_mdot),
        )


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
    return _rates(model, x, u, _body_terms(model, x, u))


def jacobians(model: RigidBodyModel, x: Array, u: Array) -> tuple[Array, Array]:
    """Exact Jacobians ``A = df/dx`` (..., 14, 14) and ``B = df/du`` (..., 14, 3) of Eq. 4."""
    return _jacobians(model, x, u, _body_terms(model, x, u))


def linearize(model: RigidBodyModel, x: Array, u: Array) -> tuple[Array, Array, Array]:
    """``(f, A, B)``: :func:`dynamics` and :func:`jacobians` in one call, the same numbers.

    The two share the direction cosines, the body-frame velocity, the aerodynamic force and
    the total force in the inertial frame (:class:`_BodyTerms`); the FOH discretization
    evaluates both at every RK4 stage, and computing those once saves about a fifth of the
    pair's time.
    """
    terms = _body_terms(model, x, u)
    return (_rates(model, x, u, terms), *_jacobians(model, x, u, terms))


class _BodyTerms(NamedTuple):
    """What Eq. 4 and its Jacobians share (all with the leading batch axes)."""

    C: Array  # C_{I<-B}(q) (..., 3, 3)
    Ct: Array  # its transpose, d v_B / d v_I
    v_B: Array  # body-frame velocity C^T v_I (..., 3)
    aero: Array  # aerodynamic force A_B (..., 3)
    force: Array  # T_B + A_B (..., 3)
    force_I: Array  # C (T_B + A_B), the total force in the inertial frame (..., 3)


def _body_terms(model: RigidBodyModel, x: Array, u: Array) -> _BodyTerms:
    C = quat.dcm(x[..., Q])
    Ct = np.swapaxes(C, -1, -2)
    v_B = np.einsum("...ij,...j->...i", Ct, x[..., V])
    aero = aero_force(model, v_B)
    force = u + aero
    return _BodyTerms(C, Ct, v_B, aero, force, np.einsum("...ij,...j->...i", C, force))


def _rates(model: RigidBodyModel, x: Array, u: Array, terms: _BodyTerms) -> Array:
    """Eq. 4 from the shared body terms."""
    q, w, m = x[..., Q], x[..., W], x[..., M]
    torque = quat.cross(model.r_T_B, u) + quat.cross(model.r_cp_B, terms.aero)
    torque = torque - quat.cross(w, w @ model.J_B.T)
    xdot = np.empty(np.broadcast_shapes(x.shape, (*u.shape[:-1], N_STATE)))
    xdot[..., R] = x[..., V]
    xdot[..., V] = terms.force_I / m[..., None] + model.g_I
    xdot[..., Q] = 0.5 * quat.multiply(q, np.concatenate([np.zeros_like(m)[..., None], w], -1))
    xdot[..., W] = torque @ model.J_B_inv.T
    xdot[..., M] = -model.alpha_mdot * np.linalg.norm(u, axis=-1) - model.beta_mdot
    return xdot


def _jacobians(model: RigidBodyModel, x: Array, u: Array, terms: _BodyTerms) -> tuple[Array, Array]:
    """``A`` and ``B`` of :func:`jacobians` from the shared body terms."""
    q, w, m = x[..., Q], x[..., W], x[..., M]
    C, Ct, v_B = terms.C, terms.Ct, terms.v_B
    batch = np.broadcast_shapes(x.shape[:-1], u.shape[:-1])
    A = np.zeros((*batch, N_STATE, N_STATE))
    B = np.zeros((*batch, N_STATE, N_CONTROL))
    inv_m = (1.0 / m)[..., None, None]
    A[..., R, V] = np.eye(3)
    A[..., V, Q] = inv_m * quat.rotate_jacobian(q, terms.force)
    A[..., V, M] = -terms.force_I / m[..., None] ** 2
    A[..., Q, Q] = 0.5 * quat.omega_matrix(w)
    A[..., Q, W] = 0.5 * quat.xi_matrix(q)
    J_inv = model.J_B_inv
    gyro = quat.skew(w) @ model.J_B - quat.skew(w @ model.J_B.T)
    A[..., W, W] = -J_inv @ gyro
    if model.rho_SA_CA != 0.0:  # the aerodynamic terms, skipped in vacuum
        dA_dvB = aero_force_jacobian(model, v_B)
        dvB_dq = quat.rotate_inverse_jacobian(q, x[..., V])
        C_dA = C @ dA_dvB
        A[..., V, V] = inv_m * C_dA @ Ct
        A[..., V, Q] += inv_m * C_dA @ dvB_dq
        if np.any(model.r_cp_B):  # aerodynamic torque
            r_cp_cross_dA = J_inv @ quat.skew(model.r_cp_B) @ dA_dvB
            A[..., W, V] = r_cp_cross_dA @ Ct
            A[..., W, Q] = r_cp_cross_dA @ dvB_dq

    B[..., V, :] = inv_m * C
    B[..., W, :] = J_inv @ quat.skew(model.r_T_B)
    thrust = np.linalg.norm(u, axis=-1, keepdims=True)
    B[..., M, :] = -model.alpha_mdot * np.where(
        thrust > 0.0, u / np.where(thrust > 0, thrust, 1), 0
    )
    return A, B


def dynamics_scalar(model: RigidBodyModel, x: Array, u: Array) -> Array:
    """Eq. 4 for one state, in plain floats: the right-hand side of the truth propagation.

    Numerically the same as :func:`dynamics` (a test holds them together) but compiled
    (:func:`scalar_rates`): 1.6 us for a single state against 61 us for :func:`dynamics`,
    whose time there is numpy's per-call overhead. Written independently of the vectorized
    form and of the discretization's kernels (:mod:`scpformer.dynamics.powered_descent_kernels`),
    it also cross-checks them. Assumes a diagonal (principal-axis) inertia matrix, as every scenario
    of the papers has.
    """
    return scalar_rates(
        np.asarray(model.scalars), np.asarray(x, dtype=float), np.asarray(u, dtype=float)
    )


@compiled
def scalar_rates(constants: Array, x: Array, u: Array) -> Array:
    """:func:`dynamics_scalar` on the constants of :attr:`RigidBodyModel.scalars` (15,)."""
    vx, vy, vz, q0, q1, q2, q3, wx, wy, wz, m = x[3:]
    tx, ty, tz = u
    # C(q) as the polynomial I + 2 q0 [qv x] + 2 [qv x]^2 (see quaternion.dcm)
    c00, c11, c22 = (
        1 - 2 * (q2 * q2 + q3 * q3),
        1 - 2 * (q1 * q1 + q3 * q3),
        1 - 2 * (q1 * q1 + q2 * q2),
    )
    c01, c10 = 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q2 + q0 * q3)
    c02, c20 = 2 * (q1 * q3 + q0 * q2), 2 * (q1 * q3 - q0 * q2)
    c12, c21 = 2 * (q2 * q3 - q0 * q1), 2 * (q2 * q3 + q0 * q1)
    vbx = c00 * vx + c10 * vy + c20 * vz  # v_B = C^T v_I
    vby = c01 * vx + c11 * vy + c21 * vz
    vbz = c02 * vx + c12 * vy + c22 * vz
    jx, jy, jz, px, py, pz, cx, cy, cz, gx, gy, gz, drag, alpha, beta = constants
    k = drag * math.sqrt(vbx * vbx + vby * vby + vbz * vbz)
    ax, ay, az = k * vbx, k * vby, k * vbz
    fx, fy, fz = tx + ax, ty + ay, tz + az
    inv_m = 1.0 / m
    mx = py * tz - pz * ty + cy * az - cz * ay - (wy * jz * wz - wz * jy * wy)
    my = pz * tx - px * tz + cz * ax - cx * az - (wz * jx * wx - wx * jz * wz)
    mz = px * ty - py * tx + cx * ay - cy * ax - (wx * jy * wy - wy * jx * wx)
    out = np.empty(14)
    out[0], out[1], out[2] = vx, vy, vz
    out[3] = (c00 * fx + c01 * fy + c02 * fz) * inv_m + gx
    out[4] = (c10 * fx + c11 * fy + c12 * fz) * inv_m + gy
    out[5] = (c20 * fx + c21 * fy + c22 * fz) * inv_m + gz
    out[6] = 0.5 * (-q1 * wx - q2 * wy - q3 * wz)
    out[7] = 0.5 * (q0 * wx + q2 * wz - q3 * wy)
    out[8] = 0.5 * (q0 * wy + q3 * wx - q1 * wz)
    out[9] = 0.5 * (q0 * wz + q1 * wy - q2 * wx)
    out[10], out[11], out[12] = mx / jx, my / jy, mz / jz
    out[13] = -alpha * math.sqrt(tx * tx + ty * ty + tz * tz) - beta
    return out
