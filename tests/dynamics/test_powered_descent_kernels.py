"""The compiled 6-DoF kernels against the numpy reference and finite differences."""

import numpy as np
import pytest
from test_powered_descent import random_states

from scpformer.dynamics import powered_descent as pd
from scpformer.dynamics import powered_descent_kernels as pdk
from scpformer.problems.pdg6dof.constants import VehicleConstants

MODELS = {
    "nominal": VehicleConstants(),
    "offset_cp": VehicleConstants(r_cp_B=(0.05, 0.02, -0.03), J_B_diag=(0.001, 0.01, 0.02)),
    "vacuum": VehicleConstants(r_cp_B=(0.05, 0.02, -0.03), rho_SA_CA=0.0),
}


@pytest.mark.parametrize("name", MODELS)
def test_kernels_agree_with_the_numpy_reference(name):
    model = MODELS[name].model()
    x, u = random_states(np.random.default_rng(11), 40)
    x[0, 3:6] = 0.0  # at rest: no drag, a zero drag Jacobian
    u[1] = 0.0  # no thrust: a zero mass-rate gradient
    constants = pdk.packed_constants(model)
    f, A, B = pdk.linearize(constants, x, u)
    f_ref, A_ref, B_ref = pd.linearize(model, x, u)
    np.testing.assert_allclose(f, f_ref, rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(A, A_ref, rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(B, B_ref, rtol=1e-13, atol=1e-12)
    np.testing.assert_array_equal(pdk.dynamics(constants, x, u), f)


def test_kernel_jacobians_match_central_finite_differences_of_the_kernel():
    constants = pdk.packed_constants(MODELS["offset_cp"].model())
    x, u = random_states(np.random.default_rng(12), 5)
    _, A, B = pdk.linearize(constants, x, u)
    h = 1e-6
    for j, e in enumerate(np.eye(14)):
        column = pdk.dynamics(constants, x + h * e, u) - pdk.dynamics(constants, x - h * e, u)
        np.testing.assert_allclose(A[:, :, j], column / (2 * h), atol=1e-7)
    for j, e in enumerate(np.eye(3)):
        column = pdk.dynamics(constants, x, u + h * e) - pdk.dynamics(constants, x, u - h * e)
        np.testing.assert_allclose(B[:, :, j], column / (2 * h), atol=1e-7)


def test_packed_constants_carry_a_full_inertia_matrix():
    """The kernels read J and J^-1 as matrices, not only their diagonals."""
    model = MODELS["offset_cp"].model()
    J = np.array([[0.02, 0.001, -0.002], [0.001, 0.03, 0.0005], [-0.002, 0.0005, 0.025]])
    full = pd.RigidBodyModel(**{**model.__dict__, "J_B": J, "J_B_inv": np.linalg.inv(J)})
    x, u = random_states(np.random.default_rng(13), 7)
    f, A, B = pdk.linearize(pdk.packed_constants(full), x, u)
    for got, expected in zip((f, A, B), pd.linearize(full, x, u), strict=True):
        np.testing.assert_allclose(got, expected, rtol=1e-13, atol=1e-11)


@pytest.mark.parametrize(
    "x_shape, u_shape", [((14,), (3,)), ((5, 13), (5, 3)), ((5, 14), (4, 3)), ((5, 14), (5, 2))]
)
def test_kernels_reject_wrong_shapes_by_name(x_shape, u_shape):
    constants = pdk.packed_constants(MODELS["nominal"].model())
    with pytest.raises(ValueError, match=r"expected x \(K, 14\) and u \(K, 3\)"):
        pdk.linearize(constants, np.ones(x_shape), np.ones(u_shape))


def test_a_zero_mass_gives_non_finite_rates_not_an_exception():
    """The SCP loops evaluate candidates far from the linearization point; a mass of zero must
    come back as inf or nan (which the ratio test rejects), as with numpy, not raise."""
    constants = pdk.packed_constants(MODELS["nominal"].model())
    x, u = random_states(np.random.default_rng(14), 3)
    x[1, 13] = 0.0
    f, A, _ = pdk.linearize(constants, x, u)
    assert not np.isfinite(f[1]).all() and not np.isfinite(A[1]).all()
    assert np.isfinite(f[[0, 2]]).all() and np.isfinite(A[[0, 2]]).all()
    assert not np.isfinite(pd.dynamics_scalar(MODELS["nominal"].model(), x[1], u[1])).all()
