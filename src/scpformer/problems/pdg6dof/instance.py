"""Problem instance theta of the 6-DoF powered descent family, and its sampler.

theta = (gamma_gs, theta_max, r0, v0, q0, omega0, m0): the parameters the T-SCvx paper varies
(Section IV.A, Table 2). The final state is fixed by :class:`VehicleConstants`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.dynamics import quaternion as quat
from scpformer.problems.pdg6dof.constants import VehicleConstants
from scpformer.validation import check_finite, check_in_range, known_fields, read_json

# a wet-to-dry mass ratio beyond any single-stage lander (Table 1: m0 = 3, m_dry = 2)
MAX_MASS_RATIO = 20.0
UNIT_QUATERNION_TOL = 1e-6
#: Largest |r0|, |v0|, |omega0_deg| accepted (nondimensional units). Table 2 spans |r0| < 20;
#: far beyond it the scaled subproblem loses all precision and ends as a solver failure.
MAX_INITIAL_STATE_NORM = 1e4


@dataclass(frozen=True, kw_only=True)
class PDGInstance:
    """One 6-DoF powered descent instance; validated at construction.

    Units are those of Table 1 (nondimensional); inertial axes are e1 = Up, e2 = East,
    e3 = North, and ``q0`` is the scalar-first quaternion q_{B<-I}.
    """

    r0: tuple[float, float, float] = (4.0, 4.0, 0.0)  # initial position, Eq. 3c [U_L]
    v0: tuple[float, float, float] = (-1.0, -1.0, 0.0)  # initial velocity, Eq. 3d [U_L/U_T]
    q0: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)  # initial attitude q_{B<-I}
    omega0_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)  # initial rate, Eq. 3e [deg/U_T]
    m0: float = 3.0  # initial (wet) mass, Eq. 3b [U_M]
    gamma_gs_deg: float = 20.0  # glideslope angle, Eq. 5b [deg]
    theta_max_deg: float = 90.0  # maximum tilt angle, Eq. 5c [deg]; >= 180 means unconstrained
    constants: VehicleConstants = field(default_factory=VehicleConstants)

    def __post_init__(self) -> None:
        for name, size in (("r0", 3), ("v0", 3), ("q0", 4), ("omega0_deg", 3)):
            value = check_finite(name, getattr(self, name), shape=(size,))
            with np.errstate(over="ignore"):  # entries near 1e308: the norm is inf, not a warning
                norm = float(np.linalg.norm(value))
            if name != "q0" and norm > MAX_INITIAL_STATE_NORM:
                raise ValueError(
                    f"{name}: norm {norm:.3g} exceeds {MAX_INITIAL_STATE_NORM:g}"
                    " (nondimensional units of Table 1; Table 2 spans |r0| < 20)"
                )
            object.__setattr__(self, name, tuple(float(v) for v in value))
        norm = float(np.linalg.norm(self.q0))
        if abs(norm - 1.0) > UNIT_QUATERNION_TOL:
            raise ValueError(f"q0 must be a unit quaternion, got norm {norm:.6g}")
        m0 = float(check_finite("m0", self.m0, shape=()))
        if m0 <= self.constants.m_dry:
            raise ValueError(f"m0 ({m0}) must exceed the dry mass m_dry ({self.constants.m_dry})")
        if m0 > MAX_MASS_RATIO * self.constants.m_dry:
            raise ValueError(
                f"m0 ({m0:.3g}) exceeds {MAX_MASS_RATIO:g} times the dry mass m_dry "
                f"({self.constants.m_dry}); Table 1's lander carries m0 = 1.5 m_dry"
            )
        object.__setattr__(self, "m0", m0)
        gamma = check_in_range("gamma_gs_deg", self.gamma_gs_deg, 0.0, 90.0)
        if gamma >= 90.0:
            raise ValueError(f"gamma_gs_deg must be below 90, got {gamma}")
        object.__setattr__(self, "gamma_gs_deg", gamma)
        theta = check_in_range("theta_max_deg", self.theta_max_deg, 0.0, 360.0)
        if theta <= 0.0:
            raise ValueError(f"theta_max_deg must be positive, got {theta}")
        object.__setattr__(self, "theta_max_deg", theta)

    # -- derived numeric quantities ------------------------------------------------------
    @property
    def x0(self) -> np.ndarray:
        """Initial state (14,) in the order (r, v, q, omega [rad/U_T], m) of Eq. 24."""
        omega = np.deg2rad(self.omega0_deg)
        return np.concatenate([self.r0, self.v0, self.q0, omega, [self.m0]])

    @property
    def tan_gamma_gs(self) -> float:
        """``tan(gamma_gs)`` of Eq. 5b."""
        return math.tan(math.radians(self.gamma_gs_deg))

    @property
    def tilt_bound(self) -> float:
        """``sin(theta_max / 2)``: Eq. 5c as ``|H_theta q| <= bound``; 1 (vacuous) past 180 deg."""
        return math.sin(math.radians(min(self.theta_max_deg, 180.0)) / 2.0)

    # -- construction and serialization --------------------------------------------------
    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PDGInstance:
        """Build from plain values; unknown keys raise ``ValueError`` naming them.

        ``data["constants"]``, if present, is a dict of :class:`VehicleConstants` overrides.
        """
        kwargs = known_fields(cls, data, "instance")
        if "constants" in kwargs:
            kwargs["constants"] = constants_from_dict(kwargs["constants"])
        return cls(**kwargs)

    @classmethod
    def from_json(cls, path: str | Path) -> PDGInstance:
        """Read an instance from a JSON file (keys as in :meth:`from_dict`)."""
        return cls.from_dict(read_json(path))

    def to_dict(self) -> dict[str, Any]:
        """Plain-value dictionary that :meth:`from_dict` reads back."""
        out = asdict(self)
        out["constants"] = asdict(self.constants)
        return out

    def with_initial_state(self, x: np.ndarray) -> PDGInstance:
        """The same descent from the state ``x`` (14,) (the order of :attr:`x0`, rate in
        rad/U_T, quaternion normalized): the remaining problem from a point of a flight, with
        this instance's constraints, vehicle and terminal conditions. ``ValueError`` when
        ``x`` poses no instance (e.g. a mass at the dry mass)."""
        x = np.asarray(x, dtype=float)
        if x.shape != (14,) or not np.all(np.isfinite(x)):
            raise ValueError(f"x must be a finite state of shape (14,), got shape {x.shape}")
        return replace(self, r0=tuple(x[0:3]), v0=tuple(x[3:6]),
                       q0=tuple(quat.normalize(x[6:10])), omega0_deg=tuple(np.degrees(x[10:13])),
                       m0=float(x[13]))  # fmt: skip

    def rotated_about_up(self, angle_rad: float) -> PDGInstance:
        """The same instance seen in an inertial frame rotated by ``angle_rad`` about Up (e1).

        Positions and velocities rotate, the attitude becomes ``q_R (x) q0``, body rates are
        unchanged. Gravity, the landing target and every constraint are symmetric about Up, so
        the rotated solution solves the rotated instance (the T-SCvx augmentation, Sec. III.E.2).
        """
        q_rot = quat.from_axis_angle([1.0, 0.0, 0.0], angle_rad)
        return replace(
            self,
            r0=tuple(quat.rotate(q_rot, self.r0)),
            v0=tuple(quat.rotate(q_rot, self.v0)),
            q0=tuple(quat.normalize(quat.multiply(q_rot, self.q0))),
        )


def constants_from_dict(data: dict[str, Any]) -> VehicleConstants:
    """:class:`VehicleConstants` from a dict of overrides; unknown keys raise ``ValueError``."""
    if isinstance(data, VehicleConstants):
        return data
    if not isinstance(data, dict):
        raise ValueError(f"constants must be a JSON object, got {type(data).__name__}")
    known = {f.name for f in fields(VehicleConstants)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ValueError(f"unknown constants field(s): {', '.join(unknown)}")
    return VehicleConstants(**data)
