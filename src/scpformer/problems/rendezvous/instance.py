"""Problem instance theta of the rendezvous family, and its seeded sampler (Table 1).

theta = (a dalpha(t_0), horizon): the initial MEAN relative orbital elements of the servicer
with respect to the target, scaled by the target semi-major axis (metres), and the horizon in
target orbits. The target orbit and the scenario constants default to Table 1.

ROE ordering (quasi-nonsingular, D'Amico 2010): ``(a da, a dlambda, a dex, a dey, a dix, a diy)``
with ``(dex, dey) = de (cos phi, sin phi)`` and ``(dix, diy) = di (cos theta, sin theta)``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.dynamics.roe import psi_matrix
from scpformer.problems.rendezvous.scenario import (
    RendezvousScenario,
    TargetOrbit,
    check_orbits,
)
from scpformer.validation import check_finite, check_interval, known_fields, read_json

#: Default initial relative orbit: a de = 80 m and a di = 140 m, both at 90 deg (e/i vector
#: separation, Table 1), 50 m ahead; its Problem 2 solution crosses the keep-out zone.
DEFAULT_ROE0_M = (0.0, 50.0, 0.0, 80.0, 0.0, 140.0)
MAX_SAMPLE_ATTEMPTS = 1000
#: Largest |a dalpha| / a accepted: the linear ROE model (and its replay) describe close
#: proximity only; Table 1 separations are ~1e-5 of a.
MAX_ROE_FRACTION = 1e-2


@dataclass(frozen=True, kw_only=True)
class RendezvousInstance:
    """One rendezvous instance; validated at construction (fails fast naming the field)."""

    roe0_m: tuple[float, ...] = DEFAULT_ROE0_M  # initial mean ROE a dalpha(t_0) [m]
    horizon_orbits: float = 2.0  # OCP horizon [target orbits], Table 1: [1, 3]
    target: TargetOrbit = field(default_factory=TargetOrbit)
    scenario: RendezvousScenario = field(default_factory=RendezvousScenario)

    def __post_init__(self) -> None:
        if not isinstance(self.target, TargetOrbit):
            raise ValueError(f"target must be a TargetOrbit, got {type(self.target).__name__}")
        if not isinstance(self.scenario, RendezvousScenario):
            raise ValueError(
                f"scenario must be a RendezvousScenario, got {type(self.scenario).__name__}"
            )
        roe0 = check_finite("roe0_m", self.roe0_m, shape=(6,))
        limit = MAX_ROE_FRACTION * self.target.a_m
        if np.max(np.abs(roe0)) > limit:
            raise ValueError(
                f"roe0_m: {np.max(np.abs(roe0)):.3g} m exceeds {limit:.3g} m "
                f"({MAX_ROE_FRACTION:g} a): the linear ROE model holds for close proximity only"
            )
        object.__setattr__(self, "roe0_m", tuple(float(v) for v in roe0))
        horizon = float(check_finite("horizon_orbits", self.horizon_orbits, shape=()))
        lo, hi = self.scenario.horizon_range_orbits
        if not lo <= horizon <= hi:
            raise ValueError(
                f"horizon_orbits must lie in [{lo}, {hi}] orbits (Table 1), got {horizon}"
            )
        object.__setattr__(self, "horizon_orbits", horizon)
        if self.scenario.waypoint_passed:  # the approach corridor: no keep-out zone any more
            return
        metric = float(self.scenario.koz_metric(self.rtn0_linear[:3]))
        if metric < 1.0:
            r = ", ".join(f"{v:.1f}" for v in self.rtn0_linear[:3])
            raise ValueError(
                f"roe0_m: the initial position ({r}) m RTN lies inside the keep-out zone "
                f"(|E_koz dr| = {metric:.3f} < 1)"
            )

    # -- derived numeric quantities ------------------------------------------------------
    @property
    def roe0(self) -> np.ndarray:
        """Initial scaled mean ROE ``a dalpha(t_0)`` [m], (6,)."""
        return np.asarray(self.roe0_m)

    @property
    def horizon_s(self) -> float:
        """Horizon ``t_N - t_0`` [s]."""
        return self.horizon_orbits * self.target.period_s

    @property
    def n_nodes(self) -> int:
        """N, the number of impulses (``N + 1`` nodes)."""
        return self.scenario.n_nodes

    def times(self) -> np.ndarray:
        """Node times ``t_0 .. t_N`` [s] from ``t_0 = 0``, (N + 1,)."""
        return np.linspace(0.0, self.horizon_s, self.n_nodes + 1)

    @property
    def rtn0_linear(self) -> np.ndarray:
        """Initial relative state ``Psi(t_0) a dalpha(t_0)`` [m, m/s] (Eq. 9), (6,)."""
        return psi_matrix(self.target.oe) @ self.roe0

    # -- construction and serialization --------------------------------------------------
    @classmethod
    def from_dict(cls, data: Any) -> RendezvousInstance:
        """Build from plain values; unknown keys (also nested) raise ``ValueError``.

        Keys: ``roe0_m`` (6 numbers), ``horizon_orbits``, and optionally ``target`` (keys of
        :class:`TargetOrbit`) and ``scenario`` (keys of :class:`RendezvousScenario`).
        """
        kwargs = known_fields(cls, data, "instance")
        if "target" in kwargs:
            kwargs["target"] = TargetOrbit.from_dict(kwargs["target"])
        if "scenario" in kwargs:
            kwargs["scenario"] = RendezvousScenario.from_dict(kwargs["scenario"])
        return cls(**kwargs)

    @classmethod
    def from_json(cls, path: str | Path) -> RendezvousInstance:
        """Read an instance from a JSON file (keys as in :meth:`from_dict`)."""
        return cls.from_dict(read_json(path))

    def to_dict(self) -> dict[str, Any]:
        """Plain-value dictionary that :meth:`from_dict` reads back."""
        return {
            "roe0_m": list(self.roe0_m),
            "horizon_orbits": self.horizon_orbits,
            "target": self.target.to_dict(),
            "scenario": self.scenario.to_dict(),
        }


@dataclass(frozen=True, kw_only=True)
class SampleRanges:
    """Uniform sampling domain of theta: Table 1, last column ("Dataset generation").

    The relative eccentricity and inclination vectors have magnitudes ``a de = r_r,koz + m_e``
    and ``a di = r_n,koz + m_i`` and nearly parallel phases ``phi, theta = 90 +- 5 deg``
    (e/i-vector separation, D'Amico 2010): the radial and normal oscillations are out of phase,
    so the relative orbit encircles the keep-out zone in the R-N plane (passive safety).
    Horizons lie in ``(0, MAX_HORIZON_ORBITS]`` (200 orbits).
    """

    horizon_orbits: tuple[float, float] = (1.0, 3.0)  # OCP horizon [orbits]
    da_m: tuple[float, float] = (-5.0, 5.0)  # a da [m]
    dlambda_m: tuple[float, float] = (-100.0, 100.0)  # a dlambda [m]
    de_margin_m: tuple[float, float] = (5.0, 30.0)  # a de - r_r,koz [m]
    di_margin_m: tuple[float, float] = (5.0, 30.0)  # a di - r_n,koz [m]
    phi_deg: tuple[float, float] = (85.0, 95.0)  # phase phi of the relative e vector [deg]
    theta_deg: tuple[float, float] = (85.0, 95.0)  # phase theta of the relative i vector [deg]

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            interval = check_interval(f"ranges.{f.name}", getattr(self, f.name))
            object.__setattr__(self, f.name, interval)
        if self.horizon_orbits[0] <= 0.0:
            raise ValueError(f"ranges.horizon_orbits must be positive, got {self.horizon_orbits}")
        check_orbits("ranges.horizon_orbits", self.horizon_orbits[1])


def sample_roe0(
    rng: np.random.Generator, scenario: RendezvousScenario, ranges: SampleRanges
) -> np.ndarray:
    """One passively safe initial relative orbit ``a dalpha(t_0)`` [m] drawn from ``ranges``."""
    r_r, _, r_n = scenario.koz_semi_axes_m
    da = rng.uniform(*ranges.da_m)
    dlam = rng.uniform(*ranges.dlambda_m)
    de = r_r + rng.uniform(*ranges.de_margin_m)
    di = r_n + rng.uniform(*ranges.di_margin_m)
    phi = math.radians(rng.uniform(*ranges.phi_deg))
    theta = math.radians(rng.uniform(*ranges.theta_deg))
    return np.array(
        [
            da,
            dlam,
            de * math.cos(phi),
            de * math.sin(phi),
            di * math.cos(theta),
            di * math.sin(theta),
        ]
    )


def sample_instances(
    rng: np.random.Generator,
    n: int,
    ranges: SampleRanges | None = None,
    scenario: RendezvousScenario | None = None,
    target: TargetOrbit | None = None,
) -> list[RendezvousInstance]:
    """Draw ``n`` instances uniformly over ``ranges`` (default: Table 1) from ``rng``.

    A draw whose initial position falls inside the keep-out zone (possible at the edges of the
    phase ranges, where the e and i vectors are up to 10 deg apart) is redrawn.
    """
    ranges = ranges or SampleRanges()
    scenario = scenario or RendezvousScenario()
    target = target or TargetOrbit()
    return [_sample_one(rng, ranges, scenario, target) for _ in range(n)]


def _sample_one(
    rng: np.random.Generator,
    ranges: SampleRanges,
    scenario: RendezvousScenario,
    target: TargetOrbit,
) -> RendezvousInstance:
    psi0 = psi_matrix(target.oe)
    for _ in range(MAX_SAMPLE_ATTEMPTS):
        horizon = rng.uniform(*ranges.horizon_orbits)
        roe0 = sample_roe0(rng, scenario, ranges)
        if scenario.koz_metric((psi0 @ roe0)[:3]) >= 1.0:
            return RendezvousInstance(
                roe0_m=tuple(roe0), horizon_orbits=horizon, target=target, scenario=scenario
            )
    raise ValueError("ranges: no initial relative orbit outside the keep-out zone was drawn")
