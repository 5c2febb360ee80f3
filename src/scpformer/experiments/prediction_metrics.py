"""Tables 4-5 of the T-SCvx paper for any predictor: inference time, MSE, OOD MSE, memory.

Works on every object with the predictor API of the T-SCvx contract (``predict_tight``,
``predict_tight_proba``, ``predict_solution``, raw theta in): the networks' ``TscvxPredictor``
and the lookup tables of :mod:`scpformer.models.lookup` alike, so that they are measured the
same way, side by side.

=====================  ======================================================================
metric                 how
=====================  ======================================================================
tight MSE (Table 4)    mean over test items (theta, k) and rows of ``(p - y)^2``, ``p`` the
                       predicted probability and ``y`` the 0/1 flag (the Brier score: a
                       thresholded predictor's is its error rate); beside it binary
                       accuracy of ``predict_tight`` and binary cross-entropy
solution MSE (Tab. 5)  mean over test samples and the ``N * 17 + 1`` values of the squared
                       error of the predicted ``(x, u, t_f)`` standardized with the training
                       statistics (those the networks train on)
OOD MSE                the same over the test samples beyond the 95th percentile of the
                       training Mahalanobis distance (:mod:`scpformer.data.ood`)
inference time         one query at batch 1 (``predict_tight(theta, k)``,
                       ``predict_solution(theta)``), ``time.perf_counter``, median (and mean,
                       std) over ``timing_queries`` calls spread over the test items
memory                 bytes of the fitted arrays (``predictor.memory_bytes()``, or the
                       parameters and buffers of its torch modules), and the tracemalloc peak
                       of one query above what was allocated before it (max over a few)
=====================  ======================================================================

The caller fixes the thread count (one CPU thread, as the benchmarks use) before measuring.
"""

from __future__ import annotations

import dataclasses
import time
import tracemalloc
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.data.ood import OOD_PERCENTILE, fit_mahalanobis
from scpformer.data.tscvx_arrays import flatten_solution, read_split_arrays, solution_stats

PROBA_CLIP = 1e-7  # probabilities are clipped to [eps, 1 - eps] in the cross-entropy


@dataclass(frozen=True, kw_only=True)
class MeasureConfig:
    """How many queries each measurement takes."""

    timing_queries: int = 200  # batch-1 calls timed per quantity (median reported)
    warmup_queries: int = 5  # untimed calls first
    memory_queries: int = 3  # calls under tracemalloc (max peak reported)
    max_items: int = 0  # test (theta, k) items scored, drawn at random (0: all)
    batch_size: int = 1024  # items per call when scoring
    seed: int = 0  # seed of the draw of max_items

    def __post_init__(self) -> None:
        for name in ("timing_queries", "memory_queries", "batch_size"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        for name in ("warmup_queries", "max_items"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")


@dataclass(frozen=True, eq=False)
class EvalSet:
    """A test split with its targets, standardized as the networks see them, and OOD mask."""

    theta: np.ndarray  # (S, 16) raw
    solution: np.ndarray  # (S, N * 17 + 1) standardized (x, u, t_f)
    solution_mean: np.ndarray  # (N * 17 + 1,) training statistics
    solution_std: np.ndarray  # (N * 17 + 1,)
    item_sample: np.ndarray  # (I,) row of theta of each tight item
    item_k: np.ndarray  # (I,) int, 1-based SCvx iteration
    flags: np.ndarray  # (I, R) bool
    ood: np.ndarray  # (S,) bool, beyond the Mahalanobis threshold of the training inputs
    n_nodes: int  # N


def load_eval_set(
    folder: Path | str, split: str = "test", *, percentile: float = OOD_PERCENTILE
) -> EvalSet:
    """``split`` of the dataset at ``folder``, OOD as judged against its training split."""
    train = read_split_arrays(folder, "train", tight=False)
    reference = fit_mahalanobis(train.theta, percentile=percentile)
    arrays = read_split_arrays(folder, split)
    mean, std = solution_stats(arrays.splits)
    return EvalSet(
        theta=arrays.theta,
        solution=(arrays.solution - mean) / std,
        solution_mean=mean,
        solution_std=std,
        item_sample=arrays.item_sample,
        item_k=arrays.item_k.astype(np.int64),
        flags=arrays.flags,
        ood=reference.is_ood(arrays.theta) if len(arrays.theta) else np.zeros(0, bool),
        n_nodes=arrays.n_nodes,
    )


@dataclass(frozen=True, kw_only=True)
class PredictionMetrics:
    """One predictor's row of Tables 4-5 (module docstring for how each is measured)."""

    tight_mse: float  # Table 4 MSE: mean (p - y)^2
    tight_accuracy: float  # binary accuracy of predict_tight
    tight_bce: float  # binary cross-entropy of p
    tight_ood_mse: float  # Table 4 OOD MSE (NaN without OOD test samples)
    tight_ood_accuracy: float
    solution_mse: float  # Table 5 MSE on standardized (x, u, t_f)
    solution_ood_mse: float  # Table 5 OOD MSE (NaN without OOD test samples)
    tight_ms_median: float  # batch-1 predict_tight [ms]
    tight_ms_mean: float
    tight_ms_std: float
    solution_ms_median: float  # batch-1 predict_solution [ms]
    solution_ms_mean: float
    solution_ms_std: float
    timing_queries: int  # calls behind each time
    memory_bytes: int  # bytes of the fitted arrays or parameters (-1: unknown)
    tight_query_peak_bytes: int  # tracemalloc peak of one predict_tight call
    solution_query_peak_bytes: int  # tracemalloc peak of one predict_solution call
    n_samples: int  # test samples (solution)
    n_ood_samples: int
    n_items: int  # test (theta, k) items scored (tight)
    n_ood_items: int

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def measure_predictor(
    predictor: Any, data: EvalSet, config: MeasureConfig | None = None
) -> PredictionMetrics:
    """Tables 4-5 for ``predictor`` on ``data`` (module docstring)."""
    config = config or MeasureConfig()
    if len(data.theta) == 0 or len(data.item_k) == 0:
        raise ValueError("the evaluation set holds no test sample or no tight item")
    items = _chosen_items(len(data.item_k), config)
    tight = _tight_scores(predictor, data, items, config.batch_size)
    solution = _solution_errors(predictor, data, config.batch_size)  # (S,)
    ood_items = data.ood[data.item_sample[items]]
    queries = _queries(data, config.timing_queries + config.warmup_queries)
    tight_call = _tight_call(predictor, data)
    solution_call = _solution_call(predictor, data)
    tight_ms = _times_ms(tight_call, queries, config.warmup_queries)
    solution_ms = _times_ms(solution_call, queries, config.warmup_queries)
    return PredictionMetrics(
        tight_mse=_mean(tight["squared"]),
        tight_accuracy=_mean(tight["correct"]),
        tight_bce=_mean(tight["bce"]),
        tight_ood_mse=_mean(tight["squared"][ood_items]),
        tight_ood_accuracy=_mean(tight["correct"][ood_items]),
        solution_mse=_mean(solution),
        solution_ood_mse=_mean(solution[data.ood]),
        tight_ms_median=float(np.median(tight_ms)),
        tight_ms_mean=float(tight_ms.mean()),
        tight_ms_std=float(tight_ms.std()),
        solution_ms_median=float(np.median(solution_ms)),
        solution_ms_mean=float(solution_ms.mean()),
        solution_ms_std=float(solution_ms.std()),
        timing_queries=config.timing_queries,
        memory_bytes=memory_bytes(predictor),
        tight_query_peak_bytes=_query_peak(tight_call, queries[: config.memory_queries]),
        solution_query_peak_bytes=_query_peak(solution_call, queries[: config.memory_queries]),
        n_samples=len(data.theta),
        n_ood_samples=int(data.ood.sum()),
        n_items=len(items),
        n_ood_items=int(ood_items.sum()),
    )


def memory_bytes(predictor: Any) -> int:
    """``predictor.memory_bytes()``, else the bytes of its torch modules' tensors, else -1."""
    if callable(getattr(predictor, "memory_bytes", None)):
        return int(predictor.memory_bytes())
    from torch import nn

    attributes = getattr(predictor, "__dict__", {}).values()
    modules = [v for v in attributes if isinstance(v, nn.Module)]
    if not modules:
        return -1
    tensors = [t for m in modules for t in (*m.parameters(), *m.buffers())]
    return int(sum(t.numel() * t.element_size() for t in tensors))


def _chosen_items(n_items: int, config: MeasureConfig) -> np.ndarray:
    if not config.max_items or config.max_items >= n_items:
        return np.arange(n_items)
    rng = np.random.default_rng(config.seed)
    return np.sort(rng.choice(n_items, size=config.max_items, replace=False))


def _tight_scores(
    predictor: Any, data: EvalSet, items: np.ndarray, batch: int
) -> dict[str, np.ndarray]:
    """Per item: mean squared error, accuracy and cross-entropy over the R rows."""
    out: dict[str, list[np.ndarray]] = {"squared": [], "correct": [], "bce": []}
    for start in range(0, len(items), batch):
        chosen = items[start : start + batch]
        theta, k = data.theta[data.item_sample[chosen]], data.item_k[chosen]
        y = data.flags[chosen].astype(float)
        p = np.asarray(predictor.predict_tight_proba(theta, k), dtype=float)
        flags = np.asarray(predictor.predict_tight(theta, k), dtype=bool)
        q = np.clip(p, PROBA_CLIP, 1.0 - PROBA_CLIP)
        out["squared"].append(((p - y) ** 2).mean(axis=1))
        out["correct"].append((flags == data.flags[chosen]).mean(axis=1))
        out["bce"].append(-(y * np.log(q) + (1 - y) * np.log(1 - q)).mean(axis=1))
    return {key: np.concatenate(parts) for key, parts in out.items()}


def _solution_errors(predictor: Any, data: EvalSet, batch: int) -> np.ndarray:
    """Per test sample: mean squared error of the standardized predicted solution."""
    errors = []
    for start in range(0, len(data.theta), batch):
        x, u, tf = predictor.predict_solution(data.theta[start : start + batch])
        flat = flatten_solution(np.asarray(x), np.asarray(u), np.asarray(tf, dtype=float))
        predicted = (flat - data.solution_mean) / data.solution_std
        errors.append(((predicted - data.solution[start : start + batch]) ** 2).mean(axis=1))
    return np.concatenate(errors)


def _queries(data: EvalSet, count: int) -> np.ndarray:
    """Item indices of ``count`` batch-1 queries, spread evenly over the test items."""
    return np.linspace(0, len(data.item_k) - 1, count).round().astype(np.int64)


def _tight_call(predictor: Any, data: EvalSet) -> Callable[[int], Any]:
    return lambda i: predictor.predict_tight(data.theta[data.item_sample[i]], int(data.item_k[i]))


def _solution_call(predictor: Any, data: EvalSet) -> Callable[[int], Any]:
    return lambda i: predictor.predict_solution(data.theta[data.item_sample[i]])


def _times_ms(call: Callable[[int], Any], queries: np.ndarray, warmup: int) -> np.ndarray:
    times = []
    for number, i in enumerate(queries):
        start = time.perf_counter()
        call(int(i))
        if number >= warmup:
            times.append(1e3 * (time.perf_counter() - start))
    return np.array(times)


def _query_peak(call: Callable[[int], Any], queries: np.ndarray) -> int:
    """Max over ``queries`` of the tracemalloc peak of one call above the memory before it."""
    was_tracing = tracemalloc.is_tracing()
    if not was_tracing:
        tracemalloc.start()
    try:
        peaks = []
        for i in queries:
            tracemalloc.reset_peak()
            before = tracemalloc.get_traced_memory()[0]
            call(int(i))
            peaks.append(tracemalloc.get_traced_memory()[1] - before)
    finally:
        if not was_tracing:
            tracemalloc.stop()
    return int(max(peaks))


def _mean(values: np.ndarray) -> float:
    return float(values.mean()) if values.size else float("nan")
