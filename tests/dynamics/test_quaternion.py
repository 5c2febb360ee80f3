import numpy as np
import pytest

from scpformer.dynamics import quaternion as quat

rng = np.random.default_rng(1)
Q = quat.normalize(rng.normal(size=(20, 4)))
W = rng.normal(size=(20, 3))


def test_dcm_of_unit_quaternion_is_a_rotation():
    C = quat.dcm(Q)
    np.testing.assert_allclose(
        C @ np.swapaxes(C, -1, -2), np.broadcast_to(np.eye(3), C.shape), atol=1e-12
    )
    np.testing.assert_allclose(np.linalg.det(C), 1.0, atol=1e-12)


def test_rotate_matches_quaternion_sandwich_product():
    pure = np.concatenate([np.zeros((20, 1)), W], axis=1)
    sandwich = quat.multiply(quat.multiply(Q, pure), quat.conjugate(Q))
    np.testing.assert_allclose(quat.rotate(Q, W), sandwich[:, 1:], atol=1e-12)
    np.testing.assert_allclose(np.einsum("kij,kj->ki", quat.dcm(Q), W), sandwich[:, 1:], atol=1e-12)


def test_rotate_inverse_undoes_rotate():
    np.testing.assert_allclose(quat.rotate_inverse(Q, quat.rotate(Q, W)), W, atol=1e-12)


def test_omega_and_xi_matrices_give_the_kinematics_product():
    pure = np.concatenate([np.zeros((20, 1)), W], axis=1)
    expected = quat.multiply(Q, pure)
    np.testing.assert_allclose(
        np.einsum("kij,kj->ki", quat.omega_matrix(W), Q), expected, atol=1e-12
    )
    np.testing.assert_allclose(np.einsum("kij,kj->ki", quat.xi_matrix(Q), W), expected, atol=1e-12)


def test_product_matrices_give_left_and_right_products_and_are_rotations_for_unit_q():
    P = rng.normal(size=(20, 4))  # any quaternion, not only unit ones
    left, right = quat.product_matrices(P)
    np.testing.assert_allclose(np.einsum("kij,kj->ki", left, Q), quat.multiply(P, Q), atol=1e-12)
    np.testing.assert_allclose(np.einsum("kij,kj->ki", right, Q), quat.multiply(Q, P), atol=1e-12)
    unit_left, unit_right = quat.product_matrices(Q)
    for m in (unit_left, unit_right):
        np.testing.assert_allclose(m @ np.swapaxes(m, -1, -2), np.broadcast_to(np.eye(4), m.shape),
                                   atol=1e-12)  # fmt: skip


@pytest.mark.parametrize(
    "fn, jac",
    [(quat.rotate, quat.rotate_jacobian), (quat.rotate_inverse, quat.rotate_inverse_jacobian)],
)
def test_rotation_jacobians_match_finite_differences(fn, jac):
    q = rng.normal(size=4)  # not unit: the SCP iterates are not normalized either
    w = rng.normal(size=3)
    h = 1e-6
    fd = np.stack([(fn(q + h * e, w) - fn(q - h * e, w)) / (2 * h) for e in np.eye(4)], axis=1)
    np.testing.assert_allclose(jac(q, w), fd, atol=1e-8)


def test_tilt_angle_of_a_rotation_about_a_horizontal_axis_is_its_angle():
    q = quat.from_axis_angle([0.0, 1.0, 0.0], 0.3)
    assert quat.tilt_angle(q) == pytest.approx(0.3)
    q_roll = quat.from_axis_angle([1.0, 0.0, 0.0], 1.0)
    assert quat.tilt_angle(q_roll) == pytest.approx(0.0, abs=1e-12)


def test_normalize_rejects_zero_quaternion():
    with pytest.raises(ValueError, match="zero quaternion"):
        quat.normalize(np.zeros(4))
