"""Out-of-distribution split by Mahalanobis distance to the training inputs.

T-SCvx paper, Sec. IV.C: a test instance is out of distribution (OOD) when its Mahalanobis
distance to the training inputs

    d_M(x, Q) = sqrt((x - mu)^T S^-1 (x - mu))

(``mu``, ``S``: mean and covariance of the training inputs) lies beyond the 95th percentile
of the training inputs' own distances. The inputs are theta (16,). ``S`` is the sample
covariance (``ddof=1``); a singular ``S`` (a parameter held constant in the dataset) is
inverted with the pseudo-inverse, so a constant parameter does not count toward the
distance.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scpformer.data.tscvx_arrays import read_split_arrays

OOD_PERCENTILE = 95.0  # paper Sec. IV.C
PINV_RCOND = 1e-10  # relative cutoff of the covariance's pseudo-inverse


@dataclass(frozen=True, eq=False)
class MahalanobisReference:
    """Mean, inverse covariance and distance threshold of the training inputs."""

    mean: np.ndarray  # (d,) mu
    precision: np.ndarray  # (d, d) S^-1 (pseudo-inverse)
    threshold: float  # the percentile of the training distances
    percentile: float  # which percentile (paper: 95)

    def distance(self, inputs: np.ndarray) -> np.ndarray:
        """d_M of each row of ``inputs`` (B, d) -> (B,)."""
        inputs = np.atleast_2d(np.asarray(inputs, dtype=float))
        if inputs.ndim != 2 or inputs.shape[1] != len(self.mean):
            raise ValueError(f"inputs must have {len(self.mean)} columns, got shape {inputs.shape}")
        delta = inputs - self.mean
        squared = np.einsum("bi,ij,bj->b", delta, self.precision, delta)
        return np.sqrt(np.maximum(squared, 0.0))

    def is_ood(self, inputs: np.ndarray) -> np.ndarray:
        """Whether each row is beyond the threshold (strictly): bool (B,)."""
        return self.distance(inputs) > self.threshold


def fit_mahalanobis(
    train: np.ndarray, *, percentile: float = OOD_PERCENTILE
) -> MahalanobisReference:
    """The reference of the training inputs ``train`` (n, d), n >= 2."""
    train = np.asarray(train, dtype=float)
    if train.ndim != 2 or len(train) < 2:
        raise ValueError(f"train must have shape (n >= 2, d), got {train.shape}")
    if not np.isfinite(train).all():
        raise ValueError("train must be finite (it holds NaN or inf)")
    if not 0.0 < percentile < 100.0:
        raise ValueError(f"percentile must be in (0, 100), got {percentile}")
    covariance = np.atleast_2d(np.cov(train, rowvar=False, ddof=1))
    precision = np.linalg.pinv(covariance, rcond=PINV_RCOND, hermitian=True)
    reference = MahalanobisReference(
        mean=train.mean(axis=0), precision=precision, threshold=0.0, percentile=percentile
    )
    threshold = float(np.percentile(reference.distance(train), percentile))
    return MahalanobisReference(
        mean=reference.mean, precision=precision, threshold=threshold, percentile=percentile
    )


@dataclass(frozen=True, eq=False)
class OodSplit:
    """Which samples of a split are out of distribution."""

    positions: np.ndarray  # (S,) sample positions of the split's solved samples
    distance: np.ndarray  # (S,) d_M to the training inputs
    ood: np.ndarray  # (S,) bool, d_M > threshold
    reference: MahalanobisReference  # fitted on the training split

    @property
    def in_distribution(self) -> np.ndarray:
        """(S,) bool, the complement of :attr:`ood`."""
        return ~self.ood

    @property
    def ood_positions(self) -> np.ndarray:
        """Sample positions of the OOD samples."""
        return self.positions[self.ood]

    @property
    def in_distribution_positions(self) -> np.ndarray:
        """Sample positions of the in-distribution samples."""
        return self.positions[~self.ood]


def ood_split(
    folder: Path | str, split: str = "test", *, percentile: float = OOD_PERCENTILE
) -> OodSplit:
    """OOD mask of ``split``'s solved samples, the threshold taken on the training split."""
    reference = fit_mahalanobis(
        read_split_arrays(folder, "train", tight=False).theta, percentile=percentile
    )
    arrays = read_split_arrays(folder, split, tight=False)
    distance = reference.distance(arrays.theta) if len(arrays.theta) else np.zeros(0)
    return OodSplit(
        positions=arrays.positions,
        distance=distance,
        ood=distance > reference.threshold,
        reference=reference,
    )
