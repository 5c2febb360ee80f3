"""Problem instance of the robust rendezvous and its seeded sampler (robust Table 1).

theta = (x_0,rtn, waypoint): the initial relative state of the servicer in the target's RTN
frame [m, m/s] and which of the four pre-docking states ends the transfer. The target orbit,
the scenario constants and the uncertainty models (Table 2) default to the paper's tables.

Boundary states in ROE. Table 1 gives both boundary states in RTN; the paper converts them to
ROE before solving. Here ``x = Psi(t)^{-1} x_rtn`` (the first-order map of Eq. 9 of the ART
paper, :func:`scpformer.dynamics.roe.psi_matrix`), so that the model's own position
``D Psi x`` of the boundary nodes is exactly the RTN value of the table; the passive-safety
constraints are written with the same ``Psi``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.dynamics.roe import psi_matrix
from scpformer.dynamics.uncertainty import (
    GatesModel,
    NavigationModel,
    ProcessNoise,
    UncertaintyModel,
)
from scpformer.problems.rendezvous.instance import MAX_ROE_FRACTION
from scpformer.problems.rendezvous.scenario import TargetOrbit
from scpformer.problems.robust_rendezvous.scenario import (
    WAYPOINTS,
    RobustScenario,
    check_waypoint,
    robust_target,
)
from scpformer.validation import check_finite, check_int, check_interval, known_fields, read_json

#: Nominal initial RTN state of Table 1: (-4 km, -17.5 km, 0) and (0, 6.849 m/s, 0).
X0_RTN_TABLE1 = (-4000.0, -17500.0, 0.0, 0.0, 6.849, 0.0)


def _uncertainty_from_dict(data: Any) -> UncertaintyModel:
    if isinstance(data, UncertaintyModel):
        return data
    kwargs = known_fields(UncertaintyModel, data, "uncertainty")
    parts = {"navigation": NavigationModel, "actuation": GatesModel, "process_noise": ProcessNoise}
    for key, cls in parts.items():
        if key in kwargs:
            kwargs[key] = cls(**known_fields(cls, kwargs[key], f"uncertainty.{key}"))
    return UncertaintyModel(**kwargs)


def _uncertainty_to_dict(model: UncertaintyModel) -> dict[str, Any]:
    """The model as JSON; ``fix_every`` only when it is not Eq. 14's 1 (files and cache keys
    of the paper's model stay what they were)."""
    nav, act = model.navigation, model.actuation
    fixes = {} if model.fix_every == 1 else {"fix_every": model.fix_every}
    return fixes | {
        "navigation": {"s1": list(nav.s1), "s2": list(nav.s2), "rho1": nav.rho1,
                       "rho2": nav.rho2},
        "actuation": {k: getattr(act, k) for k in ("sigma_s", "sigma_p", "sigma_r", "sigma_a")},
        "process_noise": {"Q_roe": [list(r) for r in model.process_noise.Q_roe]},
        "delta": model.delta,
    }  # fmt: skip


@dataclass(frozen=True, kw_only=True)
class RobustInstance:
    """One robust rendezvous instance; validated at construction (fails fast naming the field)."""

    x0_rtn: tuple[float, ...] = X0_RTN_TABLE1  # x_0,rtn: initial relative RTN state [m, m/s]
    waypoint: str = "+T"  # pre-docking state x_f: +T, -T, +R or -R (750 m on V-bar or R-bar)
    target: TargetOrbit = field(default_factory=robust_target)
    scenario: RobustScenario = field(default_factory=RobustScenario)
    uncertainty: UncertaintyModel = field(default_factory=UncertaintyModel)

    def __post_init__(self) -> None:
        for name, cls in (
            ("target", TargetOrbit),
            ("scenario", RobustScenario),
            ("uncertainty", UncertaintyModel),
        ):
            if not isinstance(getattr(self, name), cls):
                got = type(getattr(self, name)).__name__
                raise ValueError(f"{name} must be a {cls.__name__}, got {got}")
        x0 = check_finite("x0_rtn", self.x0_rtn, shape=(6,))
        limit = MAX_ROE_FRACTION * self.target.a_m  # the same close-proximity bound
        if np.max(np.abs(x0[:3])) > limit:
            raise ValueError(
                f"x0_rtn: position {np.max(np.abs(x0[:3])):.3g} m exceeds {limit:.3g} m "
                f"({MAX_ROE_FRACTION:g} a): the linear ROE model holds for close proximity only"
            )
        object.__setattr__(self, "x0_rtn", tuple(float(v) for v in x0))
        object.__setattr__(self, "waypoint", check_waypoint(self.waypoint))
        inside = np.linalg.norm(x0[:3] / np.asarray(self.scenario.ae_semi_axes_m))
        if self.scenario.n_ae_to_koz > 0 and inside <= 1.0:
            raise ValueError(
                f"x0_rtn: the initial position {tuple(x0[:3])} m lies inside the approach "
                f"ellipsoid (|E dr| = {inside:.3f} <= 1)"
            )

    # -- derived numeric quantities (the attribute names of the rendezvous family) ---------
    @property
    def n_nodes(self) -> int:
        """N, the number of impulses (``N + 1`` nodes)."""
        return self.scenario.n_nodes

    @property
    def horizon_s(self) -> float:
        """Horizon ``t_N - t_0`` [s]."""
        return self.scenario.horizon_orbits * self.target.period_s

    @property
    def t_safety_s(self) -> float:
        """``T_safety`` [s]."""
        return self.scenario.t_safety_orbits * self.target.period_s

    def times(self) -> np.ndarray:
        """Node times ``t_0 .. t_N`` [s] from ``t_0 = 0``, (N + 1,)."""
        return np.linspace(0.0, self.horizon_s, self.n_nodes + 1)

    @property
    def roe0(self) -> np.ndarray:
        """Initial scaled mean ROE ``Psi(t_0)^{-1} x_0,rtn`` [m], (6,)."""
        return np.linalg.solve(psi_matrix(self.target.oe), np.asarray(self.x0_rtn))

    @property
    def xf_rtn(self) -> np.ndarray:
        """Pre-docking RTN state ``x_f`` [m, m/s], (6,)."""
        return self.scenario.waypoint_rtn(self.waypoint)

    # -- serialization -------------------------------------------------------------------
    @classmethod
    def from_dict(cls, data: Any) -> RobustInstance:
        """Build from plain values; unknown keys (also nested) raise ``ValueError``."""
        kwargs = known_fields(cls, data, "instance")
        if "x0_rtn" in kwargs and isinstance(kwargs["x0_rtn"], list):
            kwargs["x0_rtn"] = tuple(kwargs["x0_rtn"])
        if "target" in kwargs:
            kwargs["target"] = TargetOrbit.from_dict(kwargs["target"])
        if "scenario" in kwargs:
            kwargs["scenario"] = RobustScenario.from_dict(kwargs["scenario"])
        if "uncertainty" in kwargs:
            kwargs["uncertainty"] = _uncertainty_from_dict(kwargs["uncertainty"])
        return cls(**kwargs)

    @classmethod
    def from_json(cls, path: str | Path) -> RobustInstance:
        """Read an instance from a JSON file (keys as in :meth:`from_dict`)."""
        return cls.from_dict(read_json(path, "instance"))

    def to_dict(self) -> dict[str, Any]:
        """Plain-value dictionary that :meth:`from_dict` reads back."""
        return {
            "x0_rtn": list(self.x0_rtn),
            "waypoint": self.waypoint,
            "target": self.target.to_dict(),
            "scenario": self.scenario.to_dict(),
            "uncertainty": _uncertainty_to_dict(self.uncertainty),
        }


@dataclass(frozen=True, kw_only=True)
class RobustSampleRanges:
    """Uniform randomization of Table 1 (last column) about the nominal ``x_0,rtn``.

    Table 1 prints ``delta r_{r,0} + [-3, 3]`` km for the along-track entry; the radial symbol
    is a typo for ``delta r_{t,0}``. The other components stay at their nominal values. The
    waypoint is drawn uniformly among ``waypoints``.
    """

    dr_r_m: tuple[float, float] = (-1400.0, 1400.0)  # delta r_r offset from nominal [m]
    dr_t_m: tuple[float, float] = (-3000.0, 3000.0)  # delta r_t offset from nominal [m]
    dv_t_m_s: tuple[float, float] = (-1.0, 1.0)  # delta v_t offset from nominal [m/s]
    waypoints: tuple[str, ...] = WAYPOINTS  # pre-docking states drawn uniformly: +T, -T, +R, -R

    def __post_init__(self) -> None:
        for name in ("dr_r_m", "dr_t_m", "dv_t_m_s"):
            object.__setattr__(self, name, check_interval(f"ranges.{name}", getattr(self, name)))
        if not self.waypoints:
            raise ValueError("ranges.waypoints must not be empty")
        waypoints = tuple(check_waypoint(w, "ranges.waypoints") for w in self.waypoints)
        object.__setattr__(self, "waypoints", waypoints)


def sample_instances(
    rng: np.random.Generator | int,
    n: int,
    ranges: RobustSampleRanges | None = None,
    *,
    nominal_x0_rtn: tuple[float, ...] = X0_RTN_TABLE1,
    scenario: RobustScenario | None = None,
    target: TargetOrbit | None = None,
    uncertainty: UncertaintyModel | None = None,
) -> list[RobustInstance]:
    """Draw ``n`` instances uniformly over ``ranges`` (default: Table 1) from ``rng`` or a seed."""
    n = check_int("n", n, least=0)
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    ranges = ranges or RobustSampleRanges()
    common = {
        "scenario": scenario or RobustScenario(),
        "target": target or robust_target(),
        "uncertainty": uncertainty or UncertaintyModel(),
    }
    out = []
    for _ in range(n):
        x0 = np.asarray(nominal_x0_rtn, dtype=float).copy()
        x0[0] += rng.uniform(*ranges.dr_r_m)
        x0[1] += rng.uniform(*ranges.dr_t_m)
        x0[4] += rng.uniform(*ranges.dv_t_m_s)
        waypoint = ranges.waypoints[int(rng.integers(len(ranges.waypoints)))]
        out.append(RobustInstance(x0_rtn=tuple(x0), waypoint=waypoint, **common))
    return out
