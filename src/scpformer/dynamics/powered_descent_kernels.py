"""Compiled (numba) kernels of Eq. 4 and its Jacobians for a batch of states: the hot path.

The FOH discretization of the 6-DoF problem evaluates the dynamics and their Jacobians at
every RK4 stage of every interval (``4 n_sub`` calls of (N - 1) points per SCvx evaluation),
and the numpy form of :mod:`scpformer.dynamics.powered_descent` spends almost all of its
time there in the per-call overhead of some hundred small array operations on (49, 3, 3)
blocks. These kernels compute the same quantities point by point in compiled loops: one call
of :func:`linearize` on 49 points takes about 35 us against about 280 us for
:func:`scpformer.dynamics.powered_descent.linearize` (medians of 200 calls; README,
"Compiled dynamics, and Clarabel without cvxpy in the loop").

The formulas are those of :mod:`scpformer.dynamics.powered_descent` (Eq. 4 of the T-SCvx
paper, the polynomial direction-cosine matrix ``C(q) = I + 2 q0 [qv x] + 2 [qv x]^2`` and its
exact Jacobians of :mod:`scpformer.dynamics.quaternion`), written out per point. The numpy
module stays the readable reference: tests hold the two together to 1e-12 and check both
against finite differences. The vehicle constants come in as one flat vector,
:func:`packed_constants`.

Compiled on first use and cached on disk (:data:`scpformer.jit.compiled`), so only the
first process on a machine pays the compilation (about 7 s for these kernels).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from scpformer.dynamics.powered_descent import N_CONTROL, N_STATE, RigidBodyModel
from scpformer.jit import compiled

Array = NDArray[np.float64]

# Offsets of the fields of packed_constants.
_G, _J, _JINV, _RT, _RCP, _ALPHA, _BETA, _DRAG = 0, 3, 12, 21, 24, 27, 28, 29
N_PACKED = 30


def packed_constants(model: RigidBodyModel) -> Array:
    """``(g_I, J_B, J_B^-1, r_T_B, r_cp_B, alpha_mdot, beta_mdot, -0.5 rho S_A C_A)`` flat
    (30,), the matrices row-major: what the kernels read."""
    return np.concatenate(
        [
            model.g_I,
            np.ravel(model.J_B),
            np.ravel(model.J_B_inv),
            model.r_T_B,
            model.r_cp_B,
            [model.alpha_mdot, model.beta_mdot, -0.5 * model.rho_SA_CA],
        ]
    ).astype(np.float64)


def dynamics(constants: Array, x: Array, u: Array) -> Array:
    """``f(x, u)`` of Eq. 4 for states (K, 14) and thrusts (K, 3) -> (K, 14)."""
    x, u = _batch(x, u)
    return _dynamics(constants, x, u)


def linearize(constants: Array, x: Array, u: Array) -> tuple[Array, Array, Array]:
    """``(f, A, B)``: Eq. 4 and its exact Jacobians (K, 14), (K, 14, 14), (K, 14, 3)."""
    x, u = _batch(x, u)
    return _linearize(constants, x, u)


def _batch(x: Array, u: Array) -> tuple[Array, Array]:
    """``x`` (K, 14) and ``u`` (K, 3) as C-contiguous float arrays (the kernels' layout)."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    u = np.ascontiguousarray(u, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != N_STATE or u.shape != (x.shape[0], N_CONTROL):
        raise ValueError(f"expected x (K, 14) and u (K, 3), got {x.shape} and {u.shape}")
    return x, u


@compiled
def _dcm(q0: float, q1: float, q2: float, q3: float, C: Array) -> None:
    """``C(q) = I + 2 q0 [qv x] + 2 [qv x]^2`` into ``C`` (3, 3)."""
    C[0, 0] = 1.0 - 2.0 * (q2 * q2 + q3 * q3)
    C[1, 1] = 1.0 - 2.0 * (q1 * q1 + q3 * q3)
    C[2, 2] = 1.0 - 2.0 * (q1 * q1 + q2 * q2)
    C[0, 1] = 2.0 * (q1 * q2 - q0 * q3)
    C[1, 0] = 2.0 * (q1 * q2 + q0 * q3)
    C[0, 2] = 2.0 * (q1 * q3 + q0 * q2)
    C[2, 0] = 2.0 * (q1 * q3 - q0 * q2)
    C[1, 2] = 2.0 * (q2 * q3 - q0 * q1)
    C[2, 1] = 2.0 * (q2 * q3 + q0 * q1)


@compiled
def _rotate_jacobian(
    q0: float, q1: float, q2: float, q3: float, w: Array, scale: float, out: Array
) -> None:
    """``out += scale d(C(q) w)/dq`` (3, 4) (:func:`scpformer.dynamics.quaternion.rotate_jacobian`).

    ``d/dq0 = 2 qv x w``; ``d/dqv = -2 q0 [w x] + 2 ((qv . w) I + qv w^T - 2 w qv^T)``.
    """
    qv = (q1, q2, q3)
    out[0, 0] += scale * 2.0 * (q2 * w[2] - q3 * w[1])
    out[1, 0] += scale * 2.0 * (q3 * w[0] - q1 * w[2])
    out[2, 0] += scale * 2.0 * (q1 * w[1] - q2 * w[0])
    dot = q1 * w[0] + q2 * w[1] + q3 * w[2]
    for i in range(3):
        for j in range(3):
            value = qv[i] * w[j] - 2.0 * w[i] * qv[j]
            if i == j:
                value += dot
            out[i, j + 1] += scale * (2.0 * value - 2.0 * q0 * _skew(w, i, j))


@compiled
def _skew(w: Array, i: int, j: int) -> float:
    """Entry ``(i, j)`` of ``[w x]``."""
    if i == j:
        return 0.0
    if i == 0:
        return -w[2] if j == 1 else w[1]
    if i == 1:
        return w[2] if j == 0 else -w[0]
    return -w[1] if j == 0 else w[0]


@compiled
def _point(p: Array, x: Array, u: Array, f: Array, C: Array, v_B: Array, aero: Array) -> None:
    """Eq. 4 at one point into ``f`` (14,), leaving ``C``, ``v_B`` and ``A_B`` for the
    Jacobians."""
    q0, q1, q2, q3 = x[6], x[7], x[8], x[9]
    _dcm(q0, q1, q2, q3, C)
    for i in range(3):
        v_B[i] = C[0, i] * x[3] + C[1, i] * x[4] + C[2, i] * x[5]
    speed = np.sqrt(v_B[0] ** 2 + v_B[1] ** 2 + v_B[2] ** 2)
    for i in range(3):
        aero[i] = p[_DRAG] * speed * v_B[i]
    fx, fy, fz = u[0] + aero[0], u[1] + aero[1], u[2] + aero[2]
    m = x[13]
    for i in range(3):
        f[i] = x[3 + i]
        f[3 + i] = (C[i, 0] * fx + C[i, 1] * fy + C[i, 2] * fz) / m + p[_G + i]
    w = x[10:13]
    f[6] = 0.5 * (-q1 * w[0] - q2 * w[1] - q3 * w[2])
    f[7] = 0.5 * (q0 * w[0] + q2 * w[2] - q3 * w[1])
    f[8] = 0.5 * (q0 * w[1] + q3 * w[0] - q1 * w[2])
    f[9] = 0.5 * (q0 * w[2] + q1 * w[1] - q2 * w[0])
    Jw0 = p[_J] * w[0] + p[_J + 1] * w[1] + p[_J + 2] * w[2]
    Jw1 = p[_J + 3] * w[0] + p[_J + 4] * w[1] + p[_J + 5] * w[2]
    Jw2 = p[_J + 6] * w[0] + p[_J + 7] * w[1] + p[_J + 8] * w[2]
    rT, rcp = p[_RT : _RT + 3], p[_RCP : _RCP + 3]
    # torque = r_T x T + r_cp x A_B - w x J w
    t0 = rT[1] * u[2] - rT[2] * u[1] + rcp[1] * aero[2] - rcp[2] * aero[1]
    t1 = rT[2] * u[0] - rT[0] * u[2] + rcp[2] * aero[0] - rcp[0] * aero[2]
    t2 = rT[0] * u[1] - rT[1] * u[0] + rcp[0] * aero[1] - rcp[1] * aero[0]
    t0 -= w[1] * Jw2 - w[2] * Jw1
    t1 -= w[2] * Jw0 - w[0] * Jw2
    t2 -= w[0] * Jw1 - w[1] * Jw0
    for i in range(3):
        f[10 + i] = p[_JINV + 3 * i] * t0 + p[_JINV + 3 * i + 1] * t1 + p[_JINV + 3 * i + 2] * t2
    f[13] = -p[_ALPHA] * np.sqrt(u[0] ** 2 + u[1] ** 2 + u[2] ** 2) - p[_BETA]


@compiled
def _dynamics(p: Array, x: Array, u: Array) -> Array:
    f = np.empty((x.shape[0], N_STATE))
    C, v_B, aero = np.empty((3, 3)), np.empty(3), np.empty(3)
    for k in range(x.shape[0]):
        _point(p, x[k], u[k], f[k], C, v_B, aero)
    return f


@compiled
def _linearize(p: Array, x: Array, u: Array) -> tuple[Array, Array, Array]:
    K = x.shape[0]
    f = np.empty((K, N_STATE))
    A = np.zeros((K, N_STATE, N_STATE))
    B = np.zeros((K, N_STATE, N_CONTROL))
    C, v_B, aero = np.empty((3, 3)), np.empty(3), np.empty(3)
    work = np.empty((4, 3, 4))  # scratch of the Jacobians, reused at every point
    J = p[_J : _J + 9].reshape(3, 3)
    Jinv = p[_JINV : _JINV + 9].reshape(3, 3)
    constant_B = np.zeros((3, 3))  # J^-1 [r_T x], the same at every point
    _mm_into(Jinv, _skew_matrix(p[_RT : _RT + 3]), constant_B, 1.0)
    aero_torque = np.zeros((3, 3))  # J^-1 [r_cp x]
    _mm_into(Jinv, _skew_matrix(p[_RCP : _RCP + 3]), aero_torque, 1.0)
    for k in range(K):
        _point(p, x[k], u[k], f[k], C, v_B, aero)
        _point_jacobians(p, x[k], u[k], C, v_B, aero, J, Jinv, A[k], B[k], work)
        _aero_jacobians(x[k], C, v_B, 1.0 / x[k, 13], p[_DRAG], aero_torque, A[k], work)
        B[k, 10:13, :] = constant_B
    return f, A, B


@compiled
def _point_jacobians(
    p: Array,
    x: Array,
    u: Array,
    C: Array,
    v_B: Array,
    aero: Array,
    J: Array,
    Jinv: Array,
    A: Array,
    B: Array,
    work: Array,
) -> None:
    """``df/dx`` (14, 14) and ``df/du`` (14, 3) at one point into zeroed ``A`` and ``B``
    (:func:`scpformer.dynamics.powered_descent.jacobians`, term by term), without the
    aerodynamic terms (:func:`_aero_jacobians`) and the constant ``J^-1 [r_T x]``."""
    q0, q1, q2, q3 = x[6], x[7], x[8], x[9]
    w, m = x[10:13], x[13]
    inv_m = 1.0 / m
    force = work[0, 0, :3]
    for i in range(3):
        force[i] = u[i] + aero[i]
        A[i, 3 + i] = 1.0
    for i in range(3):  # dv/dm = -C (T + A_B) / m^2
        A[3 + i, 13] = -(C[i, 0] * force[0] + C[i, 1] * force[1] + C[i, 2] * force[2]) * inv_m**2
    _rotate_jacobian(q0, q1, q2, q3, force, inv_m, A[3:6, 6:10])
    for i in range(3):  # 0.5 Omega(w) and 0.5 Xi(q)
        A[6, 7 + i] = -0.5 * w[i]
        A[7 + i, 6] = 0.5 * w[i]
        A[6, 10 + i] = -0.5 * x[7 + i]
        for j in range(3):
            A[7 + i, 7 + j] = -0.5 * _skew(w, i, j)
            A[7 + i, 10 + j] = 0.5 * (_skew(x[7:10], i, j) + (q0 if i == j else 0.0))
    Jw = work[0, 1, :3]
    for i in range(3):
        Jw[i] = J[i, 0] * w[0] + J[i, 1] * w[1] + J[i, 2] * w[2]
    gyro = work[1, :, :3]  # [w x] J - [(J w) x]
    for i in range(3):
        for j in range(3):
            gyro[i, j] = (
                _skew(w, i, 0) * J[0, j] + _skew(w, i, 1) * J[1, j] + _skew(w, i, 2) * J[2, j]
            ) - _skew(Jw, i, j)
    _mm_into(Jinv, gyro, A[10:13, 10:13], -1.0)
    for i in range(3):
        for j in range(3):
            B[3 + i, j] = inv_m * C[i, j]
    thrust = np.sqrt(u[0] ** 2 + u[1] ** 2 + u[2] ** 2)
    if thrust > 0.0:
        for j in range(3):
            B[13, j] = -p[_ALPHA] * u[j] / thrust


@compiled
def _aero_jacobians(
    x: Array,
    C: Array,
    v_B: Array,
    inv_m: float,
    drag: float,
    aero_torque: Array,
    A: Array,
    work: Array,
) -> None:
    """The aerodynamic terms of ``A``: ``dA_B/dv_B = drag (|v| I + v v^T / |v|)`` through
    ``v_B = C^T v_I`` into the velocity rows, and through ``J^-1 [r_cp x] A_B``
    (``aero_torque = J^-1 [r_cp x]``) into the rate rows."""
    speed = np.sqrt(v_B[0] ** 2 + v_B[1] ** 2 + v_B[2] ** 2)
    if drag == 0.0 or speed == 0.0:
        return
    dA = work[1, :, :3]
    for i in range(3):
        for j in range(3):
            dA[i, j] = drag * ((speed if i == j else 0.0) + v_B[i] * v_B[j] / speed)
    dvB_dq = work[2]  # d(C^T v)/dq: the chain rule through the conjugate
    dvB_dq[:] = 0.0
    _rotate_jacobian(x[6], -x[7], -x[8], -x[9], x[3:6], 1.0, dvB_dq)
    for j in range(1, 4):
        for i in range(3):
            dvB_dq[i, j] = -dvB_dq[i, j]
    C_dA = work[3, :, :3]
    C_dA[:] = 0.0
    _mm_into(C, dA, C_dA, 1.0)
    _mm_into(C_dA, C.T, A[3:6, 3:6], inv_m)
    _mm_into(C_dA, dvB_dq, A[3:6, 6:10], inv_m)
    torque_dA = work[0, :, :3]
    torque_dA[:] = 0.0
    _mm_into(aero_torque, dA, torque_dA, 1.0)
    _mm_into(torque_dA, C.T, A[10:13, 3:6], 1.0)
    _mm_into(torque_dA, dvB_dq, A[10:13, 6:10], 1.0)


@compiled
def _skew_matrix(w: Array) -> Array:
    """``[w x]`` (3, 3)."""
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            out[i, j] = _skew(w, i, j)
    return out


@compiled
def _mm_into(a: Array, b: Array, out: Array, scale: float) -> None:
    """``out += scale a @ b`` for small matrices, in plain loops (a BLAS call costs more at
    this size)."""
    for i in range(a.shape[0]):
        for j in range(b.shape[1]):
            total = 0.0
            for k in range(a.shape[1]):
                total += a[i, k] * b[k, j]
            out[i, j] += scale * total
