import numpy as np
import pytest

from scpformer.dynamics import powered_descent as pd
from scpformer.dynamics import quaternion as quat
from scpformer.problems.pdg6dof.constants import VehicleConstants


def random_states(rng, n):
    x = np.zeros((n, 14))
    x[:, 0:3] = rng.uniform(-5, 5, (n, 3))
    x[:, 3:6] = rng.uniform(-2, 2, (n, 3))
    x[:, 6:10] = rng.normal(size=(n, 4))  # deliberately not unit
    x[:, 10:13] = rng.uniform(-1, 1, (n, 3))
    x[:, 13] = rng.uniform(2.0, 3.0, n)
    return x, rng.uniform(-3, 3, (n, 3))


@pytest.mark.parametrize(
    "r_cp, rho_SA_CA",
    [((0.0, 0.0, 0.0), 0.2), ((0.05, 0.02, -0.03), 0.2), ((0.05, 0.02, -0.03), 0.0)],
)
def test_jacobians_match_central_finite_differences(r_cp, rho_SA_CA):
    model = VehicleConstants(r_cp_B=r_cp, rho_SA_CA=rho_SA_CA, J_B_diag=(0.001, 0.01, 0.02)).model()
    x, u = random_states(np.random.default_rng(2), 6)
    A, B = pd.jacobians(model, x, u)
    h = 1e-6
    A_fd = np.stack(
        [
            (pd.dynamics(model, x + h * e, u) - pd.dynamics(model, x - h * e, u)) / (2 * h)
            for e in np.eye(14)
        ],
        axis=-1,
    )
    B_fd = np.stack(
        [
            (pd.dynamics(model, x, u + h * e) - pd.dynamics(model, x, u - h * e)) / (2 * h)
            for e in np.eye(3)
        ],
        axis=-1,
    )
    np.testing.assert_allclose(A, A_fd, atol=1e-7)
    np.testing.assert_allclose(B, B_fd, atol=1e-7)


def test_hover_upright_thrust_balances_gravity_without_rotation():
    model = VehicleConstants(rho_SA_CA=0.0).model()
    x = np.zeros(14)
    x[6], x[13] = 1.0, 2.5
    xdot = pd.dynamics(model, x, np.array([2.5, 0.0, 0.0]))
    np.testing.assert_allclose(xdot[3:6], 0.0, atol=1e-15)
    np.testing.assert_allclose(xdot[10:13], 0.0, atol=1e-15)
    assert xdot[13] == pytest.approx(-model.alpha_mdot * 2.5 - model.beta_mdot)


def test_roll_rate_is_constant_with_axisymmetric_inertia_and_no_aero_torque():
    """J_yy = J_zz and r_cp = 0: no torque about the thrust axis (why 3h-3i fix no roll)."""
    model = VehicleConstants().model()
    x, u = random_states(np.random.default_rng(3), 10)
    assert np.all(np.abs(pd.dynamics(model, x, u)[:, 10]) < 1e-14)


def test_attitude_kinematics_preserve_quaternion_norm():
    model = VehicleConstants().model()
    x, u = random_states(np.random.default_rng(4), 10)
    qdot = pd.dynamics(model, x, u)[:, 6:10]
    np.testing.assert_allclose(np.sum(qdot * x[:, 6:10], axis=1), 0.0, atol=1e-13)


def test_drag_opposes_inertial_velocity_for_unit_quaternion():
    model = VehicleConstants().model()
    rng = np.random.default_rng(5)
    q = quat.normalize(rng.normal(size=4))
    v = np.array([-1.0, 0.5, 0.2])
    drag_I = quat.rotate(q, pd.aero_force(model, quat.rotate_inverse(q, v)))
    np.testing.assert_allclose(drag_I, -0.5 * model.rho_SA_CA * np.linalg.norm(v) * v, atol=1e-14)


def test_scalar_truth_dynamics_agree_with_the_vectorized_model():
    model = VehicleConstants(r_cp_B=(0.05, 0.02, -0.03), J_B_diag=(0.001, 0.01, 0.02)).model()
    x, u = random_states(np.random.default_rng(6), 8)
    for xi, ui in zip(x, u, strict=True):
        np.testing.assert_allclose(
            pd.dynamics_scalar(model, xi, ui), pd.dynamics(model, xi, ui), atol=1e-12
        )


def test_linearize_returns_the_dynamics_and_jacobians_bit_for_bit():
    model = VehicleConstants(r_cp_B=(0.05, 0.02, -0.03), J_B_diag=(0.001, 0.01, 0.02)).model()
    x, u = random_states(np.random.default_rng(7), 9)
    f, A, B = pd.linearize(model, x, u)
    np.testing.assert_array_equal(f, pd.dynamics(model, x, u))
    for got, expected in zip((A, B), pd.jacobians(model, x, u), strict=True):
        np.testing.assert_array_equal(got, expected)
