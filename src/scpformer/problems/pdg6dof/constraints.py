"""Inequality constraints 5a-5d and 6a-6b, evaluated on whole trajectories, with stable row names.

Every row is written ``g(x_k, u_k) <= 0`` and indexed by ``(name, node)``. The flag vector of
tight constraints is ordered name-major, ``[(name, k) for name in CONSTRAINT_NAMES for k in
range(N)]``, and means the same thing everywhere (solver history, datasets, T-SCvx models).

=============  ==========================================  ==========  ========
name           g(x, u)                                     equation    convex
=============  ==========================================  ==========  ========
mass           m_dry - m                                   5a          yes
glideslope     tan(gamma_gs) |H_gamma r| - e1.r            5b          yes
tilt           |H_theta q| - sin(theta_max / 2)            5c          yes
omega          |omega| - omega_max                         5d          yes
thrust_min     T_min - |T|                                 6a (lower)  no
thrust_max     |T| - T_max                                 6a (upper)  yes
gimbal         cos(delta_max) |T| - e1.T                   6b          yes
=============  ==========================================  ==========  ========

Eq. 5c, ``cos(theta_max) <= 1 - 2 |H_theta q|^2``, is written in the equivalent second-order
cone form ``|H_theta q| <= sin(theta_max / 2)`` (Szmuk & Acikmese 2018).
"""

from __future__ import annotations

import math

import numpy as np

from scpformer.problems.pdg6dof.instance import PDGInstance

CONSTRAINT_NAMES: tuple[str, ...] = (
    "mass",
    "glideslope",
    "tilt",
    "omega",
    "thrust_min",
    "thrust_max",
    "gimbal",
)
NONCONVEX_NAMES: frozenset[str] = frozenset({"thrust_min"})
# rows of constraint_values that are convex (imposed exactly by every subproblem)
CONVEX_ROWS: tuple[int, ...] = tuple(
    i for i, name in enumerate(CONSTRAINT_NAMES) if name not in NONCONVEX_NAMES
)
STATE_CONSTRAINTS: frozenset[str] = frozenset({"mass", "glideslope", "tilt", "omega"})


def constraint_index(n_nodes: int) -> list[tuple[str, int]]:
    """The stable (name, node) label of every inequality row, in flag-vector order."""
    return [(name, k) for name in CONSTRAINT_NAMES for k in range(n_nodes)]


def constraint_values(instance: PDGInstance, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """All inequality rows ``g <= 0`` at the given points, shape (len(CONSTRAINT_NAMES), N).

    ``x`` is (N, 14) and ``u`` is (N, 3); any number of points may be passed (nodes or a dense
    sampling of a propagated trajectory).
    """
    c = instance.constants
    thrust = np.linalg.norm(u, axis=-1)
    return np.stack(
        [
            c.m_dry - x[:, 13],
            instance.tan_gamma_gs * np.linalg.norm(x[:, 1:3], axis=-1) - x[:, 0],
            np.linalg.norm(x[:, 8:10], axis=-1) - instance.tilt_bound,
            np.linalg.norm(x[:, 10:13], axis=-1) - math.radians(c.omega_max_deg),
            c.T_min - thrust,
            thrust - c.T_max,
            math.cos(math.radians(c.delta_max_deg)) * thrust - u[:, 0],
        ]
    )


def tight_flags(values: np.ndarray, tol: float) -> np.ndarray:
    """Tight-constraint flags ``g >= -tol`` flattened name-major (see module docstring)."""
    return (values >= -tol).reshape(-1)


def initial_state_violations(instance: PDGInstance, tol: float = 1e-9) -> list[str]:
    """Names of the state constraints the fixed initial state already violates.

    Such an instance is infeasible before any optimization (e.g. Table 2 samples rates up to
    123 deg/U_T against omega_max = 90 deg/U_T); the solver reports it as a status.
    """
    values = constraint_values(instance, instance.x0[None, :], np.array([[1.0, 0.0, 0.0]]))
    return [
        name
        for name, value in zip(CONSTRAINT_NAMES, values[:, 0], strict=True)
        if name in STATE_CONSTRAINTS and value > tol
    ]
