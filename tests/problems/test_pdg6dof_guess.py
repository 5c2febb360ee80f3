import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from scpformer.dynamics import quaternion as quat
from scpformer.problems.pdg6dof.guess import (
    cubic_acceleration,
    cubic_final_time,
    cubic_profile_guess,
    shortest_arc_from_x,
    straight_line_guess,
)
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.problem import PDGProblem, PDGSolverConfig
from scpformer.problems.pdg6dof.sampling import PDGSampleRanges, sample_instances
from scpformer.scp.solution import Trajectory


def test_cubic_profile_meets_both_boundary_conditions():
    inst = PDGInstance(r0=(5.0, 2.0, -1.0), v0=(-1.0, 0.5, 0.3))
    tf, s = 6.0, np.linspace(0.0, 1.0, 4001)
    acc = cubic_acceleration(inst, np.array([tf]), s)[0]
    v = inst.v0 + cumulative_trapezoid(acc, s * tf, axis=0, initial=0.0)
    r = inst.r0 + cumulative_trapezoid(v, s * tf, axis=0, initial=0.0)
    np.testing.assert_allclose(v[-1], inst.constants.v_f, atol=1e-9)
    np.testing.assert_allclose(r[-1], inst.constants.r_f, atol=1e-6)


def test_final_time_guess_is_within_bounds_and_near_the_optimum():
    tf = cubic_final_time(PDGInstance())
    assert 4.5 < tf < 5.5  # SCvx converges to t_f of about 5.0 on this instance


def test_straight_line_guess_starts_at_x0_and_ends_at_the_target():
    inst = PDGInstance()
    x, u, tf = straight_line_guess(inst, 30)
    np.testing.assert_allclose(x[0], inst.x0)
    np.testing.assert_allclose(x[-1, 0:6], np.r_[inst.constants.r_f, inst.constants.v_f])
    np.testing.assert_allclose(np.linalg.norm(x[:, 6:10], axis=1), 1.0, atol=1e-12)
    assert u.shape == (30, 3) and tf == pytest.approx(cubic_final_time(inst))


def test_cubic_profile_guess_starts_at_x0_and_meets_the_translational_targets():
    inst = PDGInstance()
    x, u, tf = cubic_profile_guess(inst, 50)
    np.testing.assert_allclose(x[0], inst.x0)
    np.testing.assert_allclose(
        x[-1, 0:6], np.r_[inst.constants.r_f, inst.constants.v_f], atol=1e-12
    )
    np.testing.assert_allclose(x[-1, 10:13], 0.0)
    np.testing.assert_allclose(np.linalg.norm(x[:, 6:10], axis=1), 1.0, atol=1e-12)
    c = inst.constants
    assert np.all((u[:, 0] >= c.T_min - 1e-12) & (u[:, 0] <= c.T_max + 1e-12))
    assert np.all(np.diff(x[:, 13]) < 0.0) and x[-1, 13] >= c.m_dry
    assert tf == pytest.approx(cubic_final_time(inst))


def test_cubic_profile_thrust_points_along_the_profile_acceleration():
    inst = PDGInstance()
    x, u, tf = cubic_profile_guess(inst, 50)
    specific = cubic_acceleration(inst, np.array([tf]), np.linspace(0, 1, 50))[0]
    specific = specific - inst.constants.g_I
    thrust_inertial = quat.rotate(x[1:, 6:10], u[1:])  # node 0 keeps the given attitude
    cosines = np.sum(thrust_inertial * specific[1:], axis=1) / (
        np.linalg.norm(thrust_inertial, axis=1) * np.linalg.norm(specific[1:], axis=1)
    )
    np.testing.assert_allclose(cosines, 1.0, atol=1e-12)


@pytest.mark.parametrize("direction", [(0.3, -2.0, 0.5), (1.0, 0, 0), (-1.0, 0, 0), (0, 0, 0)])
def test_shortest_arc_turns_the_body_x_axis_onto_the_direction(direction):
    d = np.array(direction, dtype=float)
    q = shortest_arc_from_x(d)
    assert np.linalg.norm(q) == pytest.approx(1.0)
    target = d / np.linalg.norm(d) if np.any(d) else np.array([1.0, 0, 0])
    np.testing.assert_allclose(quat.rotate(q, [1.0, 0, 0]), target, atol=1e-12)


def test_cubic_profile_nearly_obeys_the_translational_and_mass_dynamics():
    """The point of the cubic profile: its position, velocity and mass nodes nearly follow the
    nonlinear FOH flow of Eq. 4, where the straight line's do not. (Its body rates do not: a
    thrust along the body axis exerts no torque, so the flow keeps omega constant.)"""
    rows = [0, 1, 2, 3, 4, 5, 13]
    for inst in sample_instances(np.random.default_rng(0), 3, PDGSampleRanges.nominal()):
        problem = PDGProblem(inst, PDGSolverConfig())
        defects = {}
        for name, guess in (("cubic", cubic_profile_guess), ("line", straight_line_guess)):
            x, u, tf = guess(inst, 50)
            z = Trajectory(x=x, u=u, p=np.array([tf]))
            defects[name] = np.abs(problem.evaluate(z).linearization.defects(x)[:, rows]).sum()
        assert defects["cubic"] < 0.2 * defects["line"], defects
