"""The linear model of the rendezvous (ART paper, Eqs. 9-10), vectorized over the horizon,
and the boundary data of Problems 1-3 (Eqs. 12-13) in ROE form.

The robust family builds on it (:mod:`scpformer.problems.robust_rendezvous`): the builder
reads only ``times()``, ``target.oe`` and ``scenario.j2`` of an instance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from scpformer.dynamics.orbits import propagate_kepler, propagate_mean_j2
from scpformer.dynamics.roe import control_input_matrix, psi_matrix, stm_j2, stm_kepler
from scpformer.problems.rendezvous.instance import RendezvousInstance


@dataclass(frozen=True)
class LinearModel:
    """Discrete linear ROE model of one instance, every node at once."""

    t: np.ndarray  # (N+1,) node times [s]
    oe: np.ndarray  # (N+1, 6) mean target elements (a, e, i, raan, argp, M) at the nodes
    Phi: np.ndarray  # (N, 6, 6) STM Phi(dt, t_k)
    B: np.ndarray  # (N, 6, 3) control input matrix B(t_k) [s]
    Psi: np.ndarray  # (N+1, 6, 6) ROE [m] -> RTN [m, m/s]

    def rollout(self, x0: np.ndarray, dv: np.ndarray) -> np.ndarray:
        """States ``x_k`` (N+1, 6) [m] from ``x_0`` under the impulses ``dv`` (N, 3) (Eq. 10)."""
        kicks = np.einsum("kij,kj->ki", self.B, dv)
        x = np.empty((self.t.size, 6))
        x[0] = x0
        for k in range(self.t.size - 1):  # a recursion: inherently sequential
            x[k + 1] = self.Phi[k] @ (x[k] + kicks[k])
        return x

    def rtn(self, x: np.ndarray) -> np.ndarray:
        """Relative RTN states ``Psi(t_k) x_k`` (N+1, 6) [m, m/s] (Eq. 9)."""
        return np.einsum("kij,kj->ki", self.Psi, x)

    def residual(self, x: np.ndarray, dv: np.ndarray) -> float:
        """``max |x_{k+1} - Phi_k (x_k + B_k dv_k)|`` [m], how well ``(x, dv)`` obeys Eq. 10."""
        pred = np.einsum("kij,kj->ki", self.Phi, x[:-1] + np.einsum("kij,kj->ki", self.B, dv))
        return float(np.abs(x[1:] - pred).max())


def linear_model(instance: RendezvousInstance | Any) -> LinearModel:
    """Build the STMs, input matrices and ``Psi`` at all nodes (vectorized, ~2 ms at N = 100).

    Reads only ``instance.times()``, ``instance.target.oe`` and ``instance.scenario.j2``: the
    robust family's instances are built with it too.
    """
    t = instance.times()
    dt = t[1] - t[0]
    oe0 = instance.target.oe.to_array()
    if instance.scenario.j2:
        oe = propagate_mean_j2(oe0, t)
        Phi = stm_j2(oe[:-1], dt)
    else:
        oe = propagate_kepler(oe0, t)
        Phi = stm_kepler(oe[:-1], dt)
    return LinearModel(t=t, oe=oe, Phi=Phi, B=control_input_matrix(oe[:-1]), Psi=psi_matrix(oe))


@dataclass(frozen=True)
class BoundaryData:
    """Boundary conditions and cone rows of Problems 1-3 in ROE form."""

    x_init: np.ndarray  # (6,) x_0 [m]
    x_dock: np.ndarray  # (6,) Psi_N^{-1} (dr_dp, 0) [m]
    x_wp: np.ndarray  # (6,) Psi_{N_wp}^{-1} (dr_wp, 0) [m]; nan once the waypoint is passed
    cone_A: np.ndarray  # (n_cone, 3, 6) D Psi_k, k = cone_start..N-1 (Eq. 13)
    cone_c: np.ndarray  # (n_cone, 6) n^T D Psi_k / cos gamma
    cone_b: np.ndarray  # (3,) -apex
    cone_d: float  # -n^T apex / cos gamma


def boundary_data(instance: RendezvousInstance, model: LinearModel) -> BoundaryData:
    """Eqs. 12-13 with ``Psi x = y`` solved for ``x`` (``Psi`` is invertible)."""
    sc = instance.scenario
    kw, n = sc.n_waypoint, sc.n_nodes
    axis, apex = np.asarray(sc.approach_axis), sc.cone_vertex_m
    cos_g = math.cos(math.radians(sc.cone_half_angle_deg))
    A = model.Psi[sc.cone_start : n, :3, :]
    if sc.waypoint_passed:
        x_wp = np.full(6, np.nan)
    else:
        x_wp = np.linalg.solve(model.Psi[kw], np.r_[sc.waypoint_m, 0.0, 0.0, 0.0])
    return BoundaryData(
        x_init=instance.roe0,
        x_dock=np.linalg.solve(model.Psi[n], np.r_[sc.dock_port_m, 0.0, 0.0, 0.0]),
        x_wp=x_wp,
        cone_A=A,
        cone_c=np.einsum("r,krj->kj", axis, A) / cos_g,
        cone_b=-apex,
        cone_d=float(-axis @ apex / cos_g),
    )
