"""Vehicle and scenario constants of the 6-DoF Mars powered descent problem (Table 1).

All values are nondimensional: length U_L, time U_T, mass U_M, with |g| = 1. Table 1 of the
T-SCvx paper gives them; Szmuk & Acikmese (2018) define the model they belong to. Details the
paper leaves out, and the choices made here:

* ``alpha_mdot = 1 / (I_sp g0)`` with ``g0 = |g_I| = 1`` (nondimensional), and the back-pressure
  loss ``beta_mdot = alpha_mdot P_amb A_noz`` (Szmuk, Reynolds & Acikmese 2020, Eq. 4a).
* The aerodynamic force is ``A_B = -0.5 (rho S_A C_A) |v_B| v_B`` with the lumped coefficient
  ``rho S_A C_A = 0.2`` of Table 1 (``rho = 0.020`` is the density alone, kept for reference).
* The body x axis is the thrust axis (``r_T_B = -0.01 e1`` puts the engine below the centre of
  mass), so the gimbal constraint 6b reads ``cos(delta_max) |T_B| <= e1 . T_B``; the paper's
  ``e3`` there is the axis of a different body-frame convention.
* ``V_alpha = 2.0`` belongs to the speed-triggered angle-of-attack constraint of Szmuk et al.
  2020, which Eqs. 5-6 do not include; it is stored but unused.
* The final time is bounded to ``[tf_min, tf_max] = [0.5, 20] U_T`` (Eq. 3a leaves t_f,max open).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from scpformer.dynamics.powered_descent import RigidBodyModel
from scpformer.validation import check_finite, check_positive


@dataclass(frozen=True, kw_only=True)
class VehicleConstants:
    """Model constants of Table 1 (T-SCvx paper), nondimensional."""

    g_I: tuple[float, float, float] = (-1.0, 0.0, 0.0)  # gravity [U_L/U_T^2]
    J_B_diag: tuple[float, float, float] = (0.001, 0.01, 0.01)  # 0.01 diag(0.1,1,1) [U_M U_L^2]
    r_T_B: tuple[float, float, float] = (-0.01, 0.0, 0.0)  # engine gimbal point, body [U_L]
    r_cp_B: tuple[float, float, float] = (0.0, 0.0, 0.0)  # centre of pressure, body [U_L]
    rho: float = 0.020  # atmospheric density [U_M/U_L^3] (reference only)
    rho_SA_CA: float = 0.2  # lumped drag coefficient rho S_A C_A [U_M/U_L]
    P_amb: float = 0.1  # ambient pressure [U_M/U_T^2/U_L]
    A_noz: float = 0.5  # nozzle exit area [U_L^2]
    I_sp: float = 30.0  # specific impulse [U_T]
    omega_max_deg: float = 90.0  # maximum angular rate, Eq. 5d [deg/U_T]
    delta_max_deg: float = 20.0  # maximum gimbal angle, Eq. 6b [deg]
    T_min: float = 0.3  # minimum thrust, Eq. 6a [U_M U_L/U_T^2]
    T_max: float = 5.0  # maximum thrust, Eq. 6a [U_M U_L/U_T^2]
    V_alpha: float = 2.0  # angle-of-attack trigger speed (unused, see module doc) [U_L/U_T]
    m_dry: float = 2.0  # dry mass, Eq. 5a [U_M]
    r_f: tuple[float, float, float] = (0.0, 0.0, 0.0)  # final position, Eq. 3f [U_L]
    v_f: tuple[float, float, float] = (-0.1, 0.0, 0.0)  # final velocity, Eq. 3g [U_L/U_T]
    tf_min: float = 0.5  # lower bound on the final time [U_T]
    tf_max: float = 20.0  # upper bound on the final time, Eq. 3a [U_T]

    def __post_init__(self) -> None:
        for name in ("g_I", "J_B_diag", "r_T_B", "r_cp_B", "r_f", "v_f"):
            value = check_finite(name, getattr(self, name), shape=(3,))
            object.__setattr__(self, name, tuple(float(v) for v in value))
        for name in ("rho_SA_CA", "P_amb", "A_noz"):
            check_finite(name, getattr(self, name), nonnegative=True)
        for name in ("I_sp", "omega_max_deg", "T_min", "T_max", "m_dry", "tf_min"):
            check_positive(name, getattr(self, name))
        check_finite("rho", self.rho, nonnegative=True)
        check_finite("V_alpha", self.V_alpha)
        if min(self.J_B_diag) <= 0.0:
            raise ValueError(f"J_B_diag must be positive, got {self.J_B_diag}")
        if not 0.0 < self.delta_max_deg < 90.0:
            raise ValueError(f"delta_max_deg must lie in (0, 90), got {self.delta_max_deg}")
        if self.T_max <= self.T_min:
            raise ValueError(f"T_max ({self.T_max}) must exceed T_min ({self.T_min})")
        if self.tf_max <= self.tf_min:
            raise ValueError(f"tf_max ({self.tf_max}) must exceed tf_min ({self.tf_min})")
        if np.linalg.norm(self.g_I) == 0.0:
            raise ValueError("g_I must be nonzero")

    @property
    def alpha_mdot(self) -> float:
        """Fuel consumption per unit thrust ``1 / (I_sp g0)``, ``g0 = |g_I|`` [U_T/U_L]."""
        return 1.0 / (self.I_sp * float(np.linalg.norm(self.g_I)))

    @property
    def beta_mdot(self) -> float:
        """Back-pressure mass flow ``alpha_mdot P_amb A_noz`` [U_M/U_T]."""
        return self.alpha_mdot * self.P_amb * self.A_noz

    @property
    def J_B(self) -> np.ndarray:
        """Inertia matrix (3, 3)."""
        return np.diag(self.J_B_diag)

    def model(self) -> RigidBodyModel:
        """The plain-array model used by :mod:`scpformer.dynamics.powered_descent`."""
        return RigidBodyModel(
            g_I=np.array(self.g_I),
            J_B=self.J_B,
            J_B_inv=np.linalg.inv(self.J_B),
            r_T_B=np.array(self.r_T_B),
            r_cp_B=np.array(self.r_cp_B),
            alpha_mdot=self.alpha_mdot,
            beta_mdot=self.beta_mdot,
            rho_SA_CA=self.rho_SA_CA,
        )

    def to_dict(self) -> dict[str, Any]:
        """All constants, derived ones included, as JSON-ready plain values."""
        out = asdict(self)
        out.update(
            J_B=self.J_B.tolist(),
            alpha_mdot=self.alpha_mdot,
            beta_mdot=self.beta_mdot,
        )
        return out


DEFAULT_CONSTANTS = VehicleConstants()

DEG = math.pi / 180.0
