"""Tables 4-5 measurements on a tiny synthetic evaluation set with stand-in predictors."""

from __future__ import annotations

import numpy as np
import pytest
from torch import nn

from scpformer.data.tscvx_arrays import unflatten_solution
from scpformer.experiments.prediction_metrics import (
    EvalSet,
    MeasureConfig,
    measure_predictor,
    memory_bytes,
)

N = 2  # nodes
R = 7 * N


def tiny_set() -> EvalSet:
    """4 test samples (the last one OOD), 2 iterations each, known flags and targets."""
    rng = np.random.default_rng(0)
    theta = rng.normal(size=(4, 16))
    sample = np.repeat(np.arange(4), 2)
    return EvalSet(
        theta=theta,
        solution=rng.normal(size=(4, 17 * N + 1)),
        solution_mean=rng.normal(size=17 * N + 1),
        solution_std=rng.uniform(0.5, 2.0, size=17 * N + 1),
        item_sample=sample,
        item_k=np.tile([1, 2], 4),
        flags=rng.uniform(size=(8, R)) < 0.3,
        ood=np.array([False, False, False, True]),
        n_nodes=N,
    )


class Oracle:
    """Returns the true flags and solutions of the evaluation set."""

    n_nodes = N

    def __init__(self, data: EvalSet) -> None:
        self.data = data

    def _rows(self, theta: np.ndarray) -> np.ndarray:
        theta = np.atleast_2d(theta)
        return np.array([np.flatnonzero((self.data.theta == t).all(axis=1))[0] for t in theta])

    def predict_tight_proba(self, theta, k):
        rows, ks = self._rows(theta), np.broadcast_to(k, (len(np.atleast_2d(theta)),))
        items = [np.flatnonzero((self.data.item_sample == r) & (self.data.item_k == kk))[0]
                 for r, kk in zip(rows, ks, strict=True)]  # fmt: skip
        out = self.data.flags[items].astype(float)
        return out[0] if np.ndim(theta) == 1 else out

    def predict_tight(self, theta, k):
        return self.predict_tight_proba(theta, k) >= 0.5

    def predict_solution(self, theta):
        d = self.data
        flat = d.solution[self._rows(theta)] * d.solution_std + d.solution_mean
        return unflatten_solution(flat, N)


class Constant:
    """Probability 1/2 for every row (predicted not tight) and the training-mean solution."""

    n_nodes = N

    def __init__(self, data: EvalSet) -> None:
        self.mean = data.solution_mean
        self.layer = nn.Linear(3, 2)  # 8 float32 parameters: 32 bytes

    def predict_tight_proba(self, theta, k):
        return np.full((*np.shape(theta)[:-1], R), 0.5)

    def predict_tight(self, theta, k):
        return np.zeros((*np.shape(theta)[:-1], R), dtype=bool)

    def predict_solution(self, theta):
        batch = np.shape(theta)[:-1]
        return unflatten_solution(np.broadcast_to(self.mean, (*batch, len(self.mean))), N)


FAST = MeasureConfig(timing_queries=5, warmup_queries=1, memory_queries=1)


def test_an_oracle_scores_zero_error():
    metrics = measure_predictor(Oracle(tiny_set()), tiny_set(), FAST)
    assert metrics.tight_mse == 0.0 and metrics.tight_accuracy == 1.0
    assert metrics.tight_bce == pytest.approx(0.0, abs=1e-6)
    assert metrics.solution_mse == pytest.approx(0.0, abs=1e-20)
    assert metrics.n_items == 8 and metrics.n_ood_items == 2 and metrics.n_ood_samples == 1


def test_a_constant_predictor_scores_the_hand_computed_errors():
    data = tiny_set()
    metrics = measure_predictor(Constant(data), data, FAST)
    assert metrics.tight_mse == pytest.approx(0.25)
    assert metrics.tight_bce == pytest.approx(np.log(2.0))
    assert metrics.tight_accuracy == pytest.approx(1.0 - data.flags.mean())
    assert metrics.tight_ood_accuracy == pytest.approx(1.0 - data.flags[6:].mean())
    assert metrics.solution_mse == pytest.approx(np.mean(data.solution**2))
    assert metrics.solution_ood_mse == pytest.approx(np.mean(data.solution[3] ** 2))
    assert metrics.memory_bytes == 32


def test_times_and_query_peaks_are_positive():
    data = tiny_set()
    metrics = measure_predictor(Constant(data), data, FAST)
    assert metrics.timing_queries == 5
    assert 0.0 < metrics.tight_ms_median and 0.0 < metrics.solution_ms_median
    assert metrics.tight_query_peak_bytes > 0 and metrics.solution_query_peak_bytes > 0


def test_max_items_scores_a_random_subset():
    data = tiny_set()
    metrics = measure_predictor(Constant(data), data, MeasureConfig(max_items=3, timing_queries=2))
    assert metrics.n_items == 3


def test_memory_is_unknown_for_a_predictor_without_arrays_or_modules():
    assert memory_bytes(object()) == -1


def test_bad_measure_settings_raise():
    with pytest.raises(ValueError, match=r"timing_queries must be >= 1"):
        MeasureConfig(timing_queries=0)
    with pytest.raises(ValueError, match=r"max_items must be >= 0"):
        MeasureConfig(max_items=-1)
