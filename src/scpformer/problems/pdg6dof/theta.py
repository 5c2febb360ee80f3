"""The parameters theta of a 6-DoF instance as a vector (16,), in the order of
:data:`THETA_NAMES`, and back: what the T-SCvx networks and the datasets see of an instance.

Glideslope and tilt bounds [deg], r0 (3) [U_L], v0 (3) [U_L/U_T], q0 (4, scalar first),
omega0 (3) [deg/U_T], m0 [U_M].
"""

from __future__ import annotations

import numpy as np

from scpformer.problems.pdg6dof.constants import VehicleConstants
from scpformer.problems.pdg6dof.instance import PDGInstance

THETA_NAMES: tuple[str, ...] = (
    "gamma_gs_deg",
    "theta_max_deg",
    "r0_up",
    "r0_east",
    "r0_north",
    "v0_up",
    "v0_east",
    "v0_north",
    "q0_w",
    "q0_x",
    "q0_y",
    "q0_z",
    "omega0_x_deg",
    "omega0_y_deg",
    "omega0_z_deg",
    "m0",
)


def theta_vector(instance: PDGInstance) -> np.ndarray:
    """theta (16,) of ``instance`` in the order of :data:`THETA_NAMES`."""
    return np.array(
        [
            instance.gamma_gs_deg,
            instance.theta_max_deg,
            *instance.r0,
            *instance.v0,
            *instance.q0,
            *instance.omega0_deg,
            instance.m0,
        ]
    )


def instance_from_theta(theta: np.ndarray, constants: VehicleConstants) -> PDGInstance:
    """Inverse of :func:`theta_vector` (validated by :class:`PDGInstance`)."""
    theta = np.asarray(theta, dtype=float)
    return PDGInstance(
        gamma_gs_deg=float(theta[0]),
        theta_max_deg=float(theta[1]),
        r0=tuple(theta[2:5]),
        v0=tuple(theta[5:8]),
        q0=tuple(theta[8:12]),
        omega0_deg=tuple(theta[12:15]),
        m0=float(theta[15]),
        constants=constants,
    )
