"""Out-of-distribution split by Mahalanobis distance (T-SCvx paper Sec. IV.C)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.distance import mahalanobis

from scpformer.data.ood import fit_mahalanobis


def test_distance_and_threshold_match_a_hand_computed_case():
    # mean 0, sample covariance diag(2/3, 8/3): every training point at sqrt(1.5)
    train = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 2.0], [0.0, -2.0]])
    reference = fit_mahalanobis(train)
    np.testing.assert_allclose(reference.distance(train), np.sqrt(1.5))
    assert reference.threshold == pytest.approx(np.sqrt(1.5))
    test = np.array([[2.0, 0.0], [0.5, 0.5]])
    np.testing.assert_allclose(reference.distance(test), [np.sqrt(6.0), np.sqrt(0.46875)])
    np.testing.assert_array_equal(reference.is_ood(test), [True, False])


def test_threshold_is_the_percentile_of_the_training_distances():
    # 1-D: mean 2, variance 2.5; distances [2, 1, 0, 1, 2] / sqrt(2.5), median 1 / sqrt(2.5)
    reference = fit_mahalanobis(np.arange(5.0)[:, None], percentile=50.0)
    assert reference.threshold == pytest.approx(1.0 / np.sqrt(2.5))
    np.testing.assert_array_equal(reference.is_ood(np.array([[3.0], [3.5]])), [False, True])


def test_distance_agrees_with_scipy_for_correlated_inputs():
    rng = np.random.default_rng(0)
    train = rng.normal(size=(200, 4)) @ rng.normal(size=(4, 4))
    reference = fit_mahalanobis(train)
    inverse = np.linalg.inv(np.cov(train, rowvar=False))
    point = rng.normal(size=4)
    expected = mahalanobis(point, train.mean(axis=0), inverse)
    assert reference.distance(point)[0] == pytest.approx(expected, rel=1e-9)
    assert np.mean(reference.is_ood(train)) == pytest.approx(0.05, abs=0.006)


def test_a_constant_input_does_not_count_toward_the_distance():
    train = np.column_stack([np.arange(5.0), np.full(5, 7.0)])
    reference = fit_mahalanobis(train)
    far_in_constant = reference.distance(np.array([[3.0, 100.0]]))[0]
    assert far_in_constant == pytest.approx(1.0 / np.sqrt(2.5))


@pytest.mark.parametrize(
    ("train", "kwargs", "match"),
    [
        (np.zeros((1, 3)), {}, r"train must have shape \(n >= 2, d\)"),
        (np.zeros(5), {}, r"train must have shape"),
        (np.array([[0.0, np.nan], [1.0, 2.0]]), {}, r"train must be finite"),
        (np.eye(3), {"percentile": 100.0}, r"percentile must be in \(0, 100\)"),
    ],
)
def test_bad_training_inputs_raise(train, kwargs, match):
    with pytest.raises(ValueError, match=match):
        fit_mahalanobis(train, **kwargs)


def test_distance_of_inputs_with_the_wrong_width_raises():
    with pytest.raises(ValueError, match=r"inputs must have 2 columns, got shape \(1, 3\)"):
        fit_mahalanobis(np.eye(2) + np.arange(2.0)).distance(np.zeros(3))
