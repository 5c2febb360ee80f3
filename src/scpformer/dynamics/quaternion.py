"""Quaternion and rotation helpers, vectorized over leading axes.

Notation
--------
q = (q0, q1, q2, q3)  Hamilton quaternion, scalar first.
q_{B<-I}              attitude quaternion of the papers: ``C_{I<-B}(q) w`` maps a body vector
                      into the inertial frame, and ``q_dot = 0.5 * Omega(omega_B) q``
                      (Szmuk & Acikmese 2018, Eq. 4d of the T-SCvx paper).
[w x]                 skew-symmetric cross-product matrix, ``[w x] v = w x v``.

All functions accept arrays of shape (..., 4) or (..., 3) and broadcast over the leading axes,
so a whole horizon of nodes is processed in one call. The direction-cosine matrix is the
polynomial ``C(q) = I + 2 q0 [qv x] + 2 [qv x]^2``; it equals the rotation matrix for unit
quaternions, and its Jacobians below are exact for that polynomial, which is what the
linearization of the (unnormalized) SCP iterates needs.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


def cross(a: ArrayLike, b: ArrayLike) -> Array:
    """Cross product over the last axis (..., 3); several times faster than ``np.cross``."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def skew(w: ArrayLike) -> Array:
    """Cross-product matrices ``[w x]`` of shape (..., 3, 3) from vectors (..., 3)."""
    w = np.asarray(w, dtype=float)
    out = np.zeros((*w.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -w[..., 2], w[..., 1]
    out[..., 1, 0], out[..., 1, 2] = w[..., 2], -w[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -w[..., 1], w[..., 0]
    return out


def multiply(p: ArrayLike, q: ArrayLike) -> Array:
    """Hamilton product ``p (x) q`` of quaternions (..., 4)."""
    p, q = np.asarray(p, dtype=float), np.asarray(q, dtype=float)
    p0, pv = p[..., :1], p[..., 1:]
    q0, qv = q[..., :1], q[..., 1:]
    scalar = p0 * q0 - np.sum(pv * qv, axis=-1, keepdims=True)
    vector = p0 * qv + q0 * pv + cross(pv, qv)
    return np.concatenate([scalar, vector], axis=-1)


def product_matrices(p: ArrayLike) -> tuple[Array, Array]:
    """``(L(p), R(p))`` (..., 4, 4) with ``p (x) q = L(p) q`` and ``q (x) p = R(p) q``."""
    p = np.asarray(p, dtype=float)
    scalar = p[..., 0, None, None] * np.eye(3)
    left = np.empty((*p.shape[:-1], 4, 4))
    left[..., 0, 0], left[..., 0, 1:], left[..., 1:, 0] = p[..., 0], -p[..., 1:], p[..., 1:]
    right = left.copy()
    left[..., 1:, 1:] = scalar + skew(p[..., 1:])
    right[..., 1:, 1:] = scalar - skew(p[..., 1:])
    return left, right


def conjugate(q: ArrayLike) -> Array:
    """Quaternion conjugate ``q*`` (..., 4)."""
    q = np.asarray(q, dtype=float)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def normalize(q: ArrayLike) -> Array:
    """Unit quaternion(s) ``q / |q|``; raises ``ValueError`` on a zero quaternion."""
    q = np.asarray(q, dtype=float)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm == 0.0):
        raise ValueError("cannot normalize a zero quaternion")
    return q / norm


def dcm(q: ArrayLike) -> Array:
    """Direction-cosine matrix ``C_{I<-B}(q)`` of shape (..., 3, 3)."""
    q = np.asarray(q, dtype=float)
    s = skew(q[..., 1:])
    return np.eye(3) + 2.0 * q[..., 0, None, None] * s + 2.0 * s @ s


def rotate(q: ArrayLike, w: ArrayLike) -> Array:
    """``C(q) w``: a body vector expressed in the inertial frame, shapes (..., 4), (..., 3)."""
    q, w = np.asarray(q, dtype=float), np.asarray(w, dtype=float)
    qv = q[..., 1:]
    qxw = cross(qv, w)
    return w + 2.0 * q[..., :1] * qxw + 2.0 * cross(qv, qxw)


def rotate_inverse(q: ArrayLike, w: ArrayLike) -> Array:
    """``C(q)^T w``: an inertial vector expressed in the body frame."""
    return rotate(conjugate(q), w)


def rotate_jacobian(q: ArrayLike, w: ArrayLike) -> Array:
    """``d(C(q) w)/dq`` of shape (..., 3, 4) for fixed ``w``.

    With ``C(q) w = w + 2 q0 (qv x w) + 2 qv x (qv x w)``:
    ``d/dq0 = 2 qv x w`` and
    ``d/dqv = -2 q0 [w x] + 2 ((qv.w) I + qv w^T - 2 w qv^T)``.
    """
    q, w = np.asarray(q, dtype=float), np.asarray(w, dtype=float)
    q0, qv = q[..., 0], q[..., 1:]
    jac = np.empty((*np.broadcast_shapes(q.shape[:-1], w.shape[:-1]), 3, 4))
    jac[..., 0] = 2.0 * cross(qv, w)
    qv_dot_w = np.sum(qv * w, axis=-1)[..., None, None]
    outer = qv[..., :, None] * w[..., None, :] - 2.0 * w[..., :, None] * qv[..., None, :]
    jac[..., 1:] = -2.0 * q0[..., None, None] * skew(w) + 2.0 * (qv_dot_w * np.eye(3) + outer)
    return jac


def rotate_inverse_jacobian(q: ArrayLike, w: ArrayLike) -> Array:
    """``d(C(q)^T w)/dq`` of shape (..., 3, 4): the chain rule through ``conjugate``."""
    return rotate_jacobian(conjugate(q), w) * np.array([1.0, -1.0, -1.0, -1.0])


def omega_matrix(w: ArrayLike) -> Array:
    """``Omega(w)`` (..., 4, 4) such that ``Omega(w) q = q (x) (0, w)`` (Szmuk & Acikmese 2018)."""
    w = np.asarray(w, dtype=float)
    out = np.zeros((*w.shape[:-1], 4, 4))
    out[..., 0, 1:] = -w
    out[..., 1:, 0] = w
    out[..., 1:, 1:] = -skew(w)
    return out


def xi_matrix(q: ArrayLike) -> Array:
    """``Xi(q)`` (..., 4, 3) such that ``q (x) (0, w) = Xi(q) w``, i.e. ``d(Omega(w) q)/dw``."""
    q = np.asarray(q, dtype=float)
    out = np.empty((*q.shape[:-1], 4, 3))
    out[..., 0, :] = -q[..., 1:]
    out[..., 1:, :] = q[..., 0, None, None] * np.eye(3) + skew(q[..., 1:])
    return out


def from_axis_angle(axis: ArrayLike, angle: ArrayLike) -> Array:
    """Unit quaternion of a rotation by ``angle`` (rad) about ``axis`` (normalized here)."""
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    half = 0.5 * np.asarray(angle, dtype=float)[..., None]
    return np.concatenate([np.cos(half), np.sin(half) * axis], axis=-1)


def tilt_angle(q: ArrayLike) -> Array:
    """Angle (rad) between the body x axis and the inertial x axis: ``arccos(1 - 2(q2^2+q3^2))``."""
    q = np.asarray(q, dtype=float)
    return np.arccos(np.clip(1.0 - 2.0 * (q[..., 2] ** 2 + q[..., 3] ** 2), -1.0, 1.0))
