"""Initial guesses of the 6-DoF problem.

Straight line (Szmuk & Acikmese 2018, Sec. IV): states are interpolated linearly between the
initial and the final boundary conditions (mass from ``m0`` towards ``m_dry``; the attitude
slerped to upright, keeping the initial roll), the thrust hovers, ``T = -m g`` along the body x
axis, and the final time is the one that minimizes the fuel of the cubic position profile
joining (r0, v0) to (r_f, v_f) flown at mass ``m0`` within ``T_max`` (:func:`cubic_final_time`).

Cubic profile (the default of :func:`~scpformer.problems.pdg6dof.problem.solve`; not in the
papers): the vehicle flies that same cubic, so position, velocity, thrust and mass agree with
the translational dynamics instead of only the end points. Measured on the bench's nominal
instances it halves the solves SCvx spends before its iterates become feasible (README, "The
initial guess").
"""

from __future__ import annotations

import numpy as np

from scpformer.dynamics import quaternion as quat
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.scp.solution import Trajectory
from scpformer.validation import check_positive


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


def cubic_coefficients(instance: PDGInstance, tf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(a2, a3)`` (G, 3) of the cubic ``r(t) = r0 + v0 t + a2 t^2 + a3 t^3`` per final time.

    The end conditions r(tf) = r_f, v(tf) = v_f give ``a2 = (3 D - tf E) / tf^2`` and
    ``a3 = (tf E - 2 D) / tf^3`` where ``D = r_f - r0 - v0 tf`` and ``E = v_f - v0``.
    """
    c = instance.constants
    r0, v0 = np.asarray(instance.r0), np.asarray(instance.v0)
    tf = np.asarray(tf, dtype=float)[:, None]  # (G, 1)
    D = np.asarray(c.r_f) - r0 - v0 * tf  # (G, 3)
    E = np.asarray(c.v_f) - v0  # (3,)
    return (3.0 * D - tf * E) / tf**2, (tf * E - 2.0 * D) / tf**3


def cubic_acceleration(instance: PDGInstance, tf: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Acceleration of the cubic of :func:`cubic_coefficients` for every final time ``tf``
    (G,) at the fractions ``s`` (M,) of it: (G, M, 3)."""
    a2, a3 = cubic_coefficients(instance, tf)
    t = np.asarray(tf, dtype=float)[:, None] * np.asarray(s, dtype=float)[None, :]  # (G, M)
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


def cubic_profile_guess(
    instance: PDGInstance, n_nodes: int, tf: float | None = None
) -> tuple[np.ndarray, np.ndarray, float]:
    """Initial guess ``(x (N, 14), u (N, 3), t_f)`` flying the cubic of final time ``tf``
    (default :func:`cubic_final_time`).

    Position and velocity follow the cubic; the thrust is ``m (a - g)`` (clipped to
    ``[T_min, T_max]``) along the body x axis, with the body turned the shortest way from
    upright (keeping the initial roll) to that direction; the mass burns ``alpha |T| + beta``
    along it (trapezoidal exponent per interval, floored at ``m_dry``); the body rates are the
    finite-difference rates of that attitude (starting from ``q_0``), ``omega = 2 (q* (x)
    dq/dt)_v``. Node 0 is ``x_0`` and the final rates are zero, as the boundary conditions
    require; the final attitude is left to SCvx.
    """
    c = instance.constants
    tf = cubic_final_time(instance) if tf is None else check_positive("tf", tf)
    s = np.linspace(0.0, 1.0, n_nodes)
    t = tf * s[:, None]
    a2, a3 = (a[0] for a in cubic_coefficients(instance, np.array([tf])))
    r = instance.r0 + instance.v0 * t + a2 * t**2 + a3 * t**3
    v = instance.v0 + 2.0 * a2 * t + 3.0 * a3 * t**2
    specific = 2.0 * a2 + 6.0 * a3 * t - c.g_I  # thrust / mass
    magnitude = np.linalg.norm(specific, axis=1)
    m = profile_mass(instance, magnitude, tf / (n_nodes - 1))
    q = quat.multiply(shortest_arc_from_x(specific), upright_attitude(instance.x0[6:10]))
    q[0] = instance.x0[6:10]
    q_dot = np.gradient(q, t[:, 0], axis=0)
    omega = 2.0 * quat.multiply(quat.conjugate(q), q_dot)[:, 1:]
    omega[-1] = 0.0
    x = np.concatenate([r, v, q, omega, m[:, None]], axis=1)
    x[0] = instance.x0
    u = np.zeros((n_nodes, 3))
    u[:, 0] = np.clip(m * magnitude, c.T_min, c.T_max)
    return x, u, tf


def cubic_profile_trajectory(
    instance: PDGInstance, n_nodes: int, tf: float | None = None
) -> Trajectory:
    """:func:`cubic_profile_guess` as a trajectory ``z = (x, u, p = (t_f,))``."""
    x, u, tf = cubic_profile_guess(instance, n_nodes, tf)
    return Trajectory(x=x, u=u, p=np.array([tf]))


def profile_mass(instance: PDGInstance, specific_thrust: np.ndarray, dt: float) -> np.ndarray:
    """Mass at the nodes when the thrust is ``m |a - g|``: ``dm/dt = -alpha m |a - g| - beta``
    (Eq. 4a) stepped with the trapezoidal exponent per interval, floored at ``m_dry``."""
    c = instance.constants
    m = np.empty(specific_thrust.size)
    m[0] = instance.m0
    burn = np.exp(-c.alpha_mdot * dt * 0.5 * (specific_thrust[:-1] + specific_thrust[1:]))
    for k in range(m.size - 1):
        m[k + 1] = m[k] * burn[k] - c.beta_mdot * dt
    return np.maximum(m, c.m_dry)


def shortest_arc_from_x(direction: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) turning the body x axis onto ``direction`` (..., 3) by the
    shortest arc: ``normalize(1 + e1 . d, e1 x d)`` for the unit vector ``d``; the identity for
    a zero direction and a half turn about e2 for ``d = -e1``, where the formula is 0 / 0."""
    e1 = np.array([1.0, 0.0, 0.0])
    norm = np.linalg.norm(direction, axis=-1, keepdims=True)
    d = np.where(norm > 0.0, direction / np.where(norm > 0.0, norm, 1.0), e1)
    q = np.concatenate([1.0 + d[..., :1], np.cross(e1, d)], axis=-1)
    size = np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(size > 1e-9, q / np.where(size > 1e-9, size, 1.0), [0.0, 0.0, 1.0, 0.0])


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


ANALYTIC_GUESSES = {  # name -> trajectory builder; the first is the solver's default
    "cubic_profile": cubic_profile_trajectory,
    "straight_line": straight_line_trajectory,
}
