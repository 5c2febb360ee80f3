"""The tracking law of the closed-loop landing (``scpformer.guidance.pdg6dof_tracking``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scpformer.dynamics import powered_descent_kernels as pdk
from scpformer.guidance import pdg6dof_mpc as mpc
from scpformer.guidance.pdg6dof_tracking import (
    TrackingWeights,
    project_thrust,
    tracking_gains,
)
from scpformer.pdg6dof import PDGInstance, PDGSolverConfig
from scpformer.scp.discretization import foh_discretize

INSTANCE = PDGInstance()
C = INSTANCE.constants
TAN = math.tan(math.radians(C.delta_max_deg))


def _feasible(u: np.ndarray, tol: float = 1e-9) -> bool:
    norm = float(np.linalg.norm(u))
    return (C.T_min - tol <= norm <= C.T_max + tol
            and float(np.linalg.norm(u[1:])) <= TAN * u[0] + tol)  # fmt: skip


def _cone_points(rng: np.random.Generator, n: int) -> np.ndarray:
    """Random points of the gimbal cone inside the magnitude bounds."""
    mag = rng.uniform(C.T_min, C.T_max, n)
    angle = rng.uniform(0.0, math.radians(C.delta_max_deg), n)
    phi = rng.uniform(0.0, 2 * math.pi, n)
    return mag[:, None] * np.stack([np.cos(angle), np.sin(angle) * np.cos(phi),
                                    np.sin(angle) * np.sin(phi)], axis=1)  # fmt: skip


def test_a_feasible_thrust_is_left_alone_and_any_thrust_is_made_feasible():
    rng = np.random.default_rng(0)
    for u in _cone_points(rng, 200):
        np.testing.assert_allclose(project_thrust(u, INSTANCE), u, rtol=1e-8)
    for u in rng.normal(0.0, 4.0, (500, 3)):
        p = project_thrust(u, INSTANCE)
        assert _feasible(p), (u, p)
        np.testing.assert_allclose(project_thrust(p, INSTANCE), p, rtol=1e-8)


def test_outside_the_gimbal_cone_it_is_the_nearest_feasible_thrust():
    """Where the cone projection lands inside the magnitude bounds it is the Euclidean
    projection onto the whole (smaller) set: no sampled feasible point is closer."""
    rng = np.random.default_rng(1)
    feasible = _cone_points(rng, 20000)
    checked = 0
    for u in rng.normal([3.0, 0.0, 0.0], 1.5, (400, 3)):
        if np.linalg.norm(u[1:]) <= TAN * u[0]:
            continue
        p = project_thrust(u, INSTANCE)
        if not C.T_min + 1e-6 < np.linalg.norm(p) < C.T_max - 1e-6:
            continue
        checked += 1
        assert np.linalg.norm(u - p) <= np.linalg.norm(feasible - u, axis=1).min() + 1e-9
    assert checked > 50


@pytest.fixture(scope="module")
def plan():
    return mpc.open_loop_plan(INSTANCE).trajectory


def _closed_loop_cost(plan, gains, weights, dx0):
    """The LQR cost of the linear deviation dynamics under ``gains`` from ``dx0``."""
    model = pdk.packed_constants(C.model())
    disc = foh_discretize(lambda x, u: pdk.linearize(model, x, u), plan.x, plan.u,
                          float(plan.p[0]), PDGSolverConfig().n_sub)  # fmt: skip
    q = np.diag(weights.state_weight())
    r = np.eye(3) / weights.thrust**2
    dx, cost = dx0, 0.0
    for k in range(disc.A.shape[0]):
        du = -gains[k] @ dx
        cost += dx @ q @ dx + du @ r @ du
        dx = disc.A[k] @ dx + (disc.Bm[k] + disc.Bp[k]) @ du
    return cost + weights.terminal**2 * dx @ q @ dx, dx


def test_the_gains_are_optimal_for_the_linear_deviations_and_shrink_them(plan):
    """The Riccati gains minimize the quadratic cost of the linearized deviations (no
    perturbed gain does better), and bring a deviation's weighted size down by the
    touchdown far below where the uncorrected linear flight takes it."""
    weights = TrackingWeights()
    gains = tracking_gains(INSTANCE, plan, weights, PDGSolverConfig().n_sub)
    assert gains.shape == (plan.x.shape[0] - 1, 3, 14) and np.isfinite(gains).all()
    rng = np.random.default_rng(2)
    dx0 = np.zeros(14)
    dx0[0:6] = rng.normal(0.0, 0.05, 6)
    best, dx_end = _closed_loop_cost(plan, gains, weights, dx0)
    for _ in range(5):
        worse, _ = _closed_loop_cost(plan, gains + rng.normal(0.0, 0.05, gains.shape) * np.abs(
            gains).max(), weights, dx0)  # fmt: skip
        assert worse >= best
    _, dx_open = _closed_loop_cost(plan, np.zeros_like(gains), weights, dx0)
    q = weights.state_weight()
    assert dx_end @ (q * dx_end) < 0.05 * (dx_open @ (q * dx_open))


def test_bad_weights_are_refused_naming_the_field():
    with pytest.raises(ValueError, match=r"tracking\.thrust"):
        TrackingWeights(thrust=0.0)
    with pytest.raises(ValueError, match=r"tracking\.position"):
        TrackingWeights(position=float("nan"))
