import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from scpformer.problems.pdg6dof.guess import (
    cubic_acceleration,
    cubic_final_time,
    straight_line_guess,
)
from scpformer.problems.pdg6dof.instance import PDGInstance


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
