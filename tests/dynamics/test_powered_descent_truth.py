"""The compiled DOP853 of the 6-DoF truth propagation against scipy's and exact solutions."""

import math

import numpy as np
import pytest
from scipy.integrate import DOP853

from scpformer.dynamics import powered_descent as pd
from scpformer.dynamics import powered_descent_truth as truth
from scpformer.problems.pdg6dof.constants import VehicleConstants


def truth_params(constants, u_k, slope):
    return np.concatenate([constants, u_k, slope])


def test_free_fall_matches_the_exact_solution_at_every_sample():
    """No thrust, no drag, no rotation: r = r0 + v0 t + g t^2 / 2 and m = m0 - beta t."""
    constants = np.asarray(VehicleConstants(rho_SA_CA=0.0).model().scalars)
    x0 = np.concatenate(
        [[3.0, 0.5, -0.2], [-1.0, 0.3, 0.1], [1.0, 0.0, 0.0, 0.0], [0.0] * 3, [2.0]]
    )
    times = np.linspace(0.0, 2.0, 41)[1:]
    out = np.empty((times.size, 14))
    params = truth_params(constants, np.zeros(3), np.zeros(3))
    step = truth.integrate(params, x0, times, 0.0, 1e-10, 1e-12, out)
    assert step > 0.0
    g, beta = constants[9:12], constants[14]
    t = times[:, None]
    np.testing.assert_allclose(out[:, 0:3], x0[0:3] + x0[3:6] * t + 0.5 * g * t**2, atol=1e-10)
    np.testing.assert_allclose(out[:, 3:6], x0[3:6] + g * t, atol=1e-10)
    np.testing.assert_allclose(out[:, 13], x0[13] - beta * times, atol=1e-10)
    np.testing.assert_allclose(out[:, 6:10], np.tile(x0[6:10], (times.size, 1)), atol=0.0)


def test_a_state_that_blows_up_reports_a_too_small_step():
    """Thrust that burns the vehicle's last mass in 0.1 time units: v' ~ T / m diverges."""
    constants = np.asarray(VehicleConstants().model().scalars)
    x0 = np.concatenate([[3.0, 0.0, 0.0], [0.0] * 3, [1.0, 0.0, 0.0, 0.0], [0.0] * 3, [0.1]])
    thrust = np.array([1.0 / constants[13], 0.0, 0.0])  # m' = -alpha |T| - beta ~ -1
    out = np.empty((1, 14))
    params = truth_params(constants, thrust, np.zeros(3))
    step = truth.integrate(params, x0, np.array([0.5]), 0.0, 1e-10, 1e-12, out)
    assert step == truth.TOO_SMALL_STEP


@pytest.mark.parametrize("first_step", [0.0, 0.05])
def test_truth_propagation_follows_scipy_dop853_step_for_step(first_step):
    """The same method, step control and dense output as scipy's DOP853 on the 6-DoF truth
    model: the states agree to round-off and the proposed next step is the same."""
    constants = np.asarray(VehicleConstants(r_cp_B=(0.05, 0.02, -0.03)).model().scalars)
    rng = np.random.default_rng(3)
    x0 = np.concatenate([[2.0, 0.3, -0.2], [-0.5, 0.1, 0.2], [1.0, 0.02, -0.03, 0.01],
                         [0.01, 0.02, -0.01], [2.0]])  # fmt: skip
    u_k, slope = np.array([4.0, 0.2, -0.1]), rng.normal(size=3)
    params = truth_params(constants, u_k, slope)
    times = np.linspace(0.0, 1.0, 6)[1:] * 0.7
    out = np.empty((times.size, 14))
    step = truth.integrate(params, x0, times, first_step, 1e-10, 1e-12, out)

    def rhs(t, x):
        return pd.scalar_rates(constants, x, u_k + t * slope)

    reference = DOP853(rhs, 0.0, x0, times[-1], rtol=1e-10, atol=1e-12,
                       first_step=first_step or None)  # fmt: skip
    expected, j = np.empty_like(out), 0
    while reference.status == "running":
        reference.step()
        while j < times.size - 1 and times[j] <= reference.t:
            expected[j] = reference.dense_output()(times[j])
            j += 1
    expected[-1] = reference.y
    np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-13)
    assert step == pytest.approx(reference.h_abs, rel=1e-6)  # error norms: round-off
    assert math.isfinite(step)


@pytest.mark.parametrize("where", ["state", "thrust", "slope"])
def test_a_non_finite_input_ends_the_integration_with_a_too_small_step(where):
    """nan makes every error estimate nan; the step must shrink to the floor and stop (a
    nan-blind comparison would loop forever)."""
    constants = np.asarray(VehicleConstants().model().scalars)
    x0 = np.concatenate([[3.0, 0.0, 0.0], [0.0] * 3, [1.0, 0.0, 0.0, 0.0], [0.0] * 3, [2.0]])
    thrust, slope = np.array([3.0, 0.0, 0.0]), np.zeros(3)
    {"state": x0, "thrust": thrust, "slope": slope}[where][1] = np.nan
    out = np.empty((2, 14))
    params = truth_params(constants, thrust, slope)
    step = truth.integrate(params, x0, np.array([0.25, 0.5]), 0.0, 1e-10, 1e-12, out)
    assert step == truth.TOO_SMALL_STEP


def test_propagation_names_the_interval_where_the_state_stops_being_finite():
    from scpformer.problems.pdg6dof.guess import straight_line_trajectory
    from scpformer.problems.pdg6dof.problem import propagate
    from scpformer.problems.pdg6dof.sampling import sample_instances

    instance = sample_instances(np.random.default_rng(0), 1)[0]
    z = straight_line_trajectory(instance, 10)
    z.u[4] = np.nan
    with pytest.raises(RuntimeError, match="nonlinear propagation failed on interval 3"):
        propagate(instance, z)
