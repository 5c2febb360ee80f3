"""The yaw and body-roll symmetries of the 6-DoF problem and the canonical frame built on them."""

import math

import numpy as np
import pytest

from scpformer.data.pdg6dof_family import instance_from_theta, theta_vector
from scpformer.dynamics import quaternion as quat
from scpformer.problems.pdg6dof import constraints as con
from scpformer.problems.pdg6dof import symmetry as sym
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.problem import (
    PDGSolverConfig,
    solve,
    solve_reference,
    verify_trajectory,
)
from scpformer.problems.pdg6dof.sampling import PDGSampleRanges, sample_instances
from scpformer.scp.solution import Status, Trajectory


def _sampled_thetas(n: int = 64, seed: int = 3) -> np.ndarray:
    instances = sample_instances(np.random.default_rng(seed), n, PDGSampleRanges.nominal())
    return np.array([theta_vector(i) for i in instances])


def test_canonical_theta_has_no_north_no_twist_and_a_nonnegative_scalar_part():
    theta = _sampled_thetas()
    canonical = sym.theta_to_canonical(theta, sym.canonical_frame(theta))
    np.testing.assert_allclose(canonical[:, 4], 0.0, atol=1e-12)  # r0 North
    np.testing.assert_allclose(canonical[:, 9], 0.0, atol=1e-12)  # q0 x (twist about body x)
    assert np.all(canonical[:, 8] >= 0.0)
    np.testing.assert_allclose(np.linalg.norm(canonical[:, 8:12], axis=1), 1.0, atol=1e-12)
    # invariants of both symmetries: altitude, horizontal distance, speed, tilt, |omega|, m0
    np.testing.assert_allclose(canonical[:, 2], theta[:, 2])
    np.testing.assert_allclose(canonical[:, 3], np.linalg.norm(theta[:, 3:5], axis=1))
    np.testing.assert_allclose(
        np.linalg.norm(canonical[:, 5:8], axis=1), np.linalg.norm(theta[:, 5:8], axis=1)
    )
    np.testing.assert_allclose(quat.tilt_angle(canonical[:, 8:12]), quat.tilt_angle(theta[:, 8:12]))
    np.testing.assert_allclose(
        np.linalg.norm(canonical[:, 12:15], axis=1), np.linalg.norm(theta[:, 12:15], axis=1)
    )
    np.testing.assert_array_equal(canonical[:, [0, 1, 15]], theta[:, [0, 1, 15]])


def test_yawed_rolled_and_sign_flipped_copies_share_one_canonical_theta():
    theta = _sampled_thetas(16)
    rng = np.random.default_rng(0)
    yaw = sym.yaw_quaternion(rng.uniform(-180.0, 180.0, len(theta)))
    roll = quat.from_axis_angle([1.0, 0.0, 0.0], rng.uniform(-math.pi, math.pi, len(theta)))
    moved = sym.roll_theta(sym.yaw_theta(theta, yaw), roll)
    moved[::2, 8:12] *= -1.0  # the same attitude
    canonical = sym.theta_to_canonical(theta, sym.canonical_frame(theta))
    np.testing.assert_allclose(
        sym.theta_to_canonical(moved, sym.canonical_frame(moved)), canonical, atol=1e-9
    )


def test_solution_to_and_from_the_canonical_frame_round_trips():
    theta = _sampled_thetas(8)
    rng = np.random.default_rng(1)
    x, u = rng.normal(size=(8, 5, 14)), rng.normal(size=(8, 5, 3))
    frame = sym.canonical_frame(theta)
    back = sym.solution_from_canonical(*sym.solution_to_canonical(x, u, frame), frame)
    np.testing.assert_allclose(back[0], x, atol=1e-12)
    np.testing.assert_allclose(back[1], u, atol=1e-12)


def test_the_frame_maps_are_the_yaw_then_the_roll_and_orthogonal():
    theta = _sampled_thetas(8)
    rng = np.random.default_rng(2)
    x, u = rng.normal(size=(8, 5, 14)), rng.normal(size=(8, 5, 3))
    frame = sym.canonical_frame(theta)
    x_c, u_c = sym.solution_to_canonical(x, u, frame)
    expected = sym.roll_states(sym.yaw_states(x, frame.q_yaw[:, None]), frame.q_roll[:, None])
    np.testing.assert_allclose(x_c, expected, atol=1e-12)
    np.testing.assert_allclose(u_c, sym.roll_body_vectors(u, frame.q_roll[:, None]), atol=1e-12)
    for m in (frame.state_map, frame.body_map):
        np.testing.assert_allclose(m @ np.swapaxes(m, -1, -2), np.broadcast_to(np.eye(len(m[0])),
                                   m.shape), atol=1e-12)  # fmt: skip


@pytest.fixture(scope="module")
def tilted():
    """A nominal instance tilted 20 deg with a roll and rates (neither symmetric nor upright)."""
    q0 = quat.multiply(
        quat.from_axis_angle([0.0, 0.6, 0.8], math.radians(20.0)),
        quat.from_axis_angle([1.0, 0.0, 0.0], 1.1),
    )
    instance = PDGInstance(q0=tuple(q0), omega0_deg=(0.0, 5.0, -3.0))
    return instance, solve(instance)


def test_a_solution_seen_in_the_canonical_frame_solves_the_canonical_instance(tilted):
    instance, solution = tilted
    assert solution.status is Status.CONVERGED, solution.message
    theta = theta_vector(instance)[None]
    frame = sym.canonical_frame(theta)
    canonical = instance_from_theta(sym.theta_to_canonical(theta, frame)[0], instance.constants)
    x, u = sym.solution_to_canonical(
        solution.trajectory.x[None], solution.trajectory.u[None], frame
    )
    moved = Trajectory(x=x[0], u=u[0], p=solution.trajectory.p)
    check = verify_trajectory(canonical, moved, PDGSolverConfig())
    assert check.passed, check.message
    np.testing.assert_allclose(
        con.constraint_values(canonical, moved.x, moved.u),
        con.constraint_values(instance, solution.trajectory.x, solution.trajectory.u),
        atol=1e-9,
    )


@pytest.mark.slow
def test_solving_the_body_rolled_instance_gives_the_rolled_solution(tilted):
    # Independent of the mapping above: SCvx solves the rolled instance from its own guess.
    # The default solves stop within the stationarity tolerance, where the cost is flat in the
    # final time (0.05 U_T of t_f costs about 3e-4 U_M), so they agree in cost; the optimum
    # itself, each run refined to full convergence, is the rolled one to 1e-2.
    instance, solution = tilted
    q_roll = quat.from_axis_angle([1.0, 0.0, 0.0], 2.0)
    rolled = instance_from_theta(sym.roll_theta(theta_vector(instance), q_roll), instance.constants)
    other = solve(rolled)
    assert other.status is Status.CONVERGED, other.message
    propellant = instance.m0 + solution.cost
    assert other.cost == pytest.approx(solution.cost, abs=2e-3 * propellant)
    reference = solve_reference(instance, PDGSolverConfig(), solution).trajectory
    rolled_reference = solve_reference(rolled, PDGSolverConfig(), other).trajectory
    assert rolled_reference.p[0] == pytest.approx(reference.p[0], abs=1e-2)
    expected = sym.roll_states(reference.x, q_roll)
    np.testing.assert_allclose(rolled_reference.x, expected, atol=1e-2)
