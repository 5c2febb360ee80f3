"""Remaining-horizon rendezvous problems whose waypoint is passed (the final approach of
closed-loop re-planning): no waypoint row, the approach cone from the current node on, no
keep-out zone; and the default problem, whose structure they leave unchanged."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from scpformer.problems.rendezvous.constraints import (
    cone_slack,
    constraint_index,
    constraint_to_go,
    tight_flags,
)
from scpformer.problems.rendezvous.instance import RendezvousInstance
from scpformer.problems.rendezvous.linear_model import boundary_data, linear_model
from scpformer.problems.rendezvous.scenario import RendezvousScenario, TargetOrbit
from scpformer.problems.rendezvous.subproblems import RendezvousSubproblem, compiled_subproblem
from scpformer.rendezvous import solve
from scpformer.scp.solution import Status

DEFAULT = RendezvousInstance()
#: The SCP's cost tolerance (Eq. 19, Table 1), and the relative agreement of two solves of
#: one convex problem from different references.
J_TOL = 1e-6


@pytest.fixture(scope="module")
def plan():
    """Problem 3 of the default instance: the plan whose tail the remaining problems re-pose."""
    return solve(DEFAULT)


def remaining(plan, k: int) -> RendezvousInstance:
    """Problem 3 from the plan's own state at node ``k`` to ``t_N`` (same time step)."""
    model = linear_model(DEFAULT)
    oe = model.oe[k]
    deg = np.degrees(oe[2:])
    target = TargetOrbit(a_m=float(oe[0]), e=float(oe[1]), i_deg=float(deg[0]),
                         raan_deg=float(deg[1]), argp_deg=float(deg[2]),
                         M_deg=float(deg[3]))  # fmt: skip
    n_rem = DEFAULT.n_nodes - k
    horizon = (model.t[-1] - model.t[k]) / target.period_s
    scenario = dataclasses.replace(DEFAULT.scenario, n_nodes=n_rem, horizon_range_orbits=(0.01, 3))
    return RendezvousInstance(roe0_m=tuple(plan.trajectory.x[k]), horizon_orbits=horizon,
                              target=target, scenario=scenario)  # fmt: skip


def test_the_default_problem_keeps_its_waypoint_keep_out_and_cone_rows():
    sc = DEFAULT.scenario
    assert not sc.waypoint_passed and (sc.n_keep_out, sc.cone_start) == (91, 90)
    kw, n = sc.n_waypoint, sc.n_nodes  # the rows as they were written before passed waypoints
    expected = [("keep_out", k) for k in range(kw + 1)] + [
        ("approach_cone", k) for k in range(kw, n)
    ]
    assert constraint_index(sc) == expected
    sub = compiled_subproblem("scp", n, kw)
    assert not sub.passed and sub.koz_a.shape == (kw + 1, 6) and sub.cone_A.shape == (n - kw, 18)
    assert len(sub.problem.constraints) == 7  # dynamics, x_0, x_N, waypoint, cone, cut, trust
    assert not np.isnan(boundary_data(DEFAULT, linear_model(DEFAULT)).x_wp).any()


@pytest.mark.parametrize("k", [90, 95, 98])
def test_a_remaining_problem_after_the_waypoint_is_solved_and_verified(plan, k):
    """From the waypoint node (90) on the plan's own tail is optimal for the remaining
    problem: the re-posed problem finds its cost, and its replay passes the checks."""
    instance = remaining(plan, k)
    sc = instance.scenario
    assert sc.waypoint_passed and (sc.n_keep_out, sc.cone_start) == (0, 1)
    sol = solve(instance)
    assert sol.status is Status.CONVERGED and sol.verification.passed, sol.message
    tail = float(np.linalg.norm(plan.trajectory.u[k:], axis=1).sum())
    assert sol.cost == pytest.approx(tail, rel=1e-5, abs=J_TOL)
    assert sol.iterations <= 2  # no keep-out zone: Problem 2 again, solved by its first cut
    rtn = linear_model(instance).rtn(sol.trajectory.x)
    assert cone_slack(rtn[1 : sc.n_nodes], sc).min() >= -1e-6  # the cone after node k
    assert np.linalg.norm(rtn[-1] - np.r_[sc.dock_port_m, 0, 0, 0]) < 1e-6
    assert constraint_index(sc) == [("approach_cone", j) for j in range(1, sc.n_nodes)]
    assert tight_flags(rtn, sc, 1e-5).shape == (sc.n_nodes - 1,)
    assert not constraint_to_go(rtn, sc).any()  # no keep-out node counts
    checked = sol.verification.node_violations
    assert checked["waypoint_position_m"] == 0.0 and checked["keep_out"] == 0.0


def test_the_shifted_plan_warm_starts_a_remaining_problem_after_the_waypoint(plan):
    instance = remaining(plan, 92)
    sol = solve(instance, warmstart=plan.trajectory.x[92:])
    assert sol.status is Status.CONVERGED and sol.verification.passed, sol.message
    assert sol.cost == pytest.approx(solve(instance).cost, rel=1e-5, abs=J_TOL)


def test_inside_the_keep_out_zone_only_a_passed_waypoint_poses_a_problem(plan):
    """Every node after the waypoint lies inside the keep-out ellipsoid (the approach corridor
    crosses it); the instance checks the initial position only while the waypoint is ahead."""
    instance = remaining(plan, 95)
    assert instance.scenario.koz_metric(instance.rtn0_linear[:3]) < 1.0
    ahead = dataclasses.replace(instance.scenario, waypoint_offset=2)
    with pytest.raises(ValueError, match="inside the keep-out zone"):
        dataclasses.replace(instance, scenario=ahead)


@pytest.mark.parametrize(
    ("n_nodes", "offset"),
    [(11, 10), (1, 10), (3, 2)],  # one impulse to the waypoint; one impulse to dock
)
def test_problems_one_impulse_cannot_pose_are_refused(n_nodes, offset):
    with pytest.raises(ValueError, match=r"scenario\.n_nodes must be >="):
        RendezvousScenario(n_nodes=n_nodes, waypoint_offset=offset)


def test_every_passed_waypoint_shares_one_compiled_structure():
    assert compiled_subproblem("convex", 7, -3) is compiled_subproblem("convex", 7, 0)
    with pytest.raises(ValueError, match="n_waypoint must lie in"):
        RendezvousSubproblem("scp", 1, 0)


def test_an_estimate_just_outside_the_cone_still_poses_a_feasible_final_approach(plan):
    """The current state is given: no cone row holds it (navigation errors put estimates
    ~0.3 m outside the cone near the port, measured in closed loop); the plan re-enters the
    cone from the next node on."""
    instance = remaining(plan, 95)
    sc = instance.scenario
    model = linear_model(instance)
    rtn0 = instance.rtn0_linear
    lateral = np.array([1.0, 0.0, 0.0])  # R, across the approach axis (T)
    d = rtn0[:3] - sc.cone_vertex_m
    radius = np.tan(np.radians(sc.cone_half_angle_deg)) * d[1]
    shifted = rtn0.copy()
    shifted[:3] += lateral * (radius - d[0] + 0.3)  # 0.3 m outside the cone
    assert cone_slack(shifted, sc) < 0.0
    outside = dataclasses.replace(instance, roe0_m=tuple(np.linalg.solve(model.Psi[0], shifted)))
    sol = solve(outside)
    assert sol.status is Status.CONVERGED and sol.verification.passed, sol.message
    rtn = linear_model(outside).rtn(sol.trajectory.x)
    assert cone_slack(rtn[1 : sc.n_nodes], sc).min() >= -1e-6
