"""Straight-line initial guess of the 6-DoF problem (Szmuk & Acikmese 2018, Sec. IV).

States are interpolated linearly between the initial and the final boundary conditions (mass
from ``m0`` towards ``m_dry``; the attitude slerped to upright, keeping the initial roll), the
thrust hovers, ``T = -m g`` along the body x axis, and the final time is the one that minimizes
the fuel of the cubic position profile joining (r0, v0) to (r_f, v_f) flown at mass ``m0``
within ``T_max`` (:func:`cubic_final_time`).
"""

from __future__ import annotations

import numpy as np

from scpformer.dynamics import quaternion as quat
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.scp.solution import Trajectory


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
    tf = cubic_final_time(instance)
    return x, u, tf


def straight_line_trajectory(instance: PDGInstance, n_nodes: int) -> Trajectory:
    """:func:`straight_line_guess` as a trajectory ``z = (x, u, p = (t_f,))``."""
    x, u, tf = straight_line_guess(instance, n_nodes)
    return Trajectory(x=x, u=u, p=np.array([tf]))


def cubic_acceleration(instance: PDGInstance, tf: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Acceleration of the cubic r(t) joining (r0, v0) at 0 to (r_f, v_f) at ``tf``.

    With ``r(t) = r0 + v0 t + a2 t^2 + a3 t^3``, the end conditions give
    ``a2 = (3 D - tf E) / tf^2`` and ``a3 = (tf E - 2 D) / tf^3`` where ``D = r_f - r0 - v0 tf``
    and ``E = v_f - v0``. Evaluated for every final time ``tf`` (G,) at the fractions ``s``
    (M,) of it: (G, M, 3).
    """
    c = instance.constants
    r0, v0 = np.asarray(instance.r0), np.asarray(instance.v0)
    rf, vf = np.asarray(c.r_f), np.asarray(c.v_f)
    tf = np.asarray(tf, dtype=float)[:, None]  # (G, 1)
    D = rf - r0 - v0 * tf  # (G, 3)
    E = vf - v0  # (3,)
    a2 = (3.0 * D - tf * E) / tf**2
    a3 = (tf * E - 2.0 * D) / tf**3
    t = tf * np.asarray(s, dtype=float)[None, :]  # (G, M)
    return 2.0 * a2[:, None, :] + 6.0 * a3[:, None, :] * t[..., None]


def cubic_final_time(instance: PDGInstance, n_grid: int = 200, n_t: int = 51) -> float:
    """Final time minimizing the fuel ``int alpha m0 |a - g| + beta dt`` of the cubic profile.

    Grid search over ``[tf_min, tf_max]`` among the profiles whose thrust ``m0 |a - g|`` stays
    below ``T_max``; ``tf_max`` when none does. On the nominal instance it gives 4.81 (the
    converged t_f is 4.7-5.0), where a descent-time rule gave 14.6.
    """
    tf, fuel = cubic_profile_fuel(instance, n_grid, n_t)
    return float(tf[np.argmin(fuel)]) if np.isfinite(fuel).any() else float(tf[-1])


def cubic_profile_fuel(
    instance: PDGInstance, n_grid: int = 200, n_t: int = 51
) -> tuple[np.ndarray, np.ndarray]:
    """Final times on ``[tf_min, tf_max]`` (n_grid,) and the cubic profile's fuel at each.

    Fuel is ``tf int_0^1 alpha m0 |a - g| + beta ds``; ``inf`` where the thrust
    ``m0 |a - g|`` exceeds ``T_max``.
    """
    c = instance.constants
    tf = np.linspace(c.tf_min, c.tf_max, n_grid)
    s = np.linspace(0.0, 1.0, n_t)
    thrust = instance.m0 * np.linalg.norm(cubic_acceleration(instance, tf, s) - c.g_I, axis=-1)
    fuel = tf * np.trapezoid(c.alpha_mdot * thrust + c.beta_mdot, s, axis=1)
    fuel[thrust.max(axis=1) > c.T_max] = np.inf
    return tf, fuel


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
