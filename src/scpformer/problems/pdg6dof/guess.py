"""Straight-line initial guess of the 6-DoF problem (Szmuk & Acikmese 2018, Sec. IV).

States are interpolated linearly between the initial and the final boundary conditions (mass
from ``m0`` towards ``m_dry``; the attitude slerped to upright, keeping the initial roll), the
thrust hovers, ``T = -m g`` along the body x axis, and the final time is the descent time at
the mean of the initial and final vertical speeds, clipped to the final-time bounds.
"""

from __future__ import annotations

import numpy as np

from scpformer.dynamics import quaternion as quat
from scpformer.problems.pdg6dof.instance import PDGInstance


def upright_attitude(q0: np.ndarray) -> np.ndarray:
    """The upright attitude (q2 = q3 = 0) that keeps the roll angle of ``q0`` about e1."""
    roll = np.array([q0[0], q0[1], 0.0, 0.0])
    norm = np.linalg.norm(roll)
    return roll / norm if norm > 1e-9 else quat.IDENTITY.copy()


def straight_line_guess(
    instance: PDGInstance, n_nodes: int
) -> tuple[np.ndarray, np.ndarray, float]:
    """Initial guess ``(x (N, 14), u (N, 3), t_f)``."""
    c = instance.constants
    s = np.linspace(0.0, 1.0, n_nodes)[:, None]
    x0 = instance.x0
    xf = x0.copy()
    xf[0:3], xf[3:6] = c.r_f, c.v_f
    xf[6:10] = upright_attitude(x0[6:10])
    xf[10:13] = 0.0
    xf[13] = c.m_dry
    x = (1.0 - s) * x0 + s * xf
    x[:, 6:10] = slerp(x0[6:10], xf[6:10], s[:, 0])
    mean_mass = 0.5 * (instance.m0 + c.m_dry)
    u = np.tile([-mean_mass * c.g_I[0], 0.0, 0.0], (n_nodes, 1))
    u[:, 0] = np.clip(u[:, 0], c.T_min, c.T_max)
    descent_speed = 0.5 * (abs(instance.v0[0]) + abs(c.v_f[0]))
    tf = np.clip(2.0 * instance.r0[0] / max(descent_speed, 1e-3), c.tf_min, c.tf_max)
    tf = float(np.clip(tf, c.tf_min + 0.5 * (c.tf_max - c.tf_min) * 0, c.tf_max))
    return x, u, tf


def slerp(q_a: np.ndarray, q_b: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Spherical interpolation between unit quaternions at fractions ``s`` (M,) -> (M, 4)."""
    dot = float(np.dot(q_a, q_b))
    if dot < 0.0:
        q_b, dot = -q_b, -dot
    if dot > 0.9995:
        out = q_a + s[:, None] * (q_b - q_a)
        return out / np.linalg.norm(out, axis=1, keepdims=True)
    angle = np.arccos(dot)
    return (np.sin((1 - s) * angle)[:, None] * q_a + np.sin(s * angle)[:, None] * q_b) / np.sin(
        angle
    )
