"""Test-time metrics of the T-SCvx networks (T-SCvx paper Sec. IV.B, Table 3).

Tight-constraint classifier (f2): binary accuracy over every (item, row) beside the two
trivial baselines Table 3 lists -- predict all zeros (accuracy ``1 - p``, with ``p`` the tight
share) and predict all ones (accuracy ``p``) -- and, because accuracy hides a model that
predicts zeros, precision, recall and F1 of the tight rows, overall and per constraint name
(rows name-major, :func:`scpformer.problems.pdg6dof.constraints.constraint_index`). ``covered``
is the share of items whose predicted set holds every truly tight row (the reduced subproblem
of Algorithm 2 then misses no tight row).

Solution regressor (f1): mean squared error of the standardized outputs (Table 3's "MSE"),
per field (x, u, t_f) and in physical units (root mean square error) per state group.

Both are computed by :func:`evaluate_tscvx` on any split of a dataset for a trained run and
written to ``RUN/metrics_<split>.json`` and ``RUN/tight_<split>.csv`` (one row per name).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.files import atomic_path, write_text_atomic
from scpformer.problems.pdg6dof.constraints import CONSTRAINT_NAMES

# state groups of x (Eq. 24) and their slices; u is the thrust, tf the final time
STATE_GROUPS = {"r": slice(0, 3), "v": slice(3, 6), "q": slice(6, 10), "omega": slice(10, 13),
                "m": slice(13, 14)}  # fmt: skip


@dataclass(frozen=True, kw_only=True)
class BinaryCounts:
    """Confusion counts of tight (positive) rows."""

    tp: int
    fp: int
    fn: int
    tn: int

    @classmethod
    def of(cls, truth: np.ndarray, predicted: np.ndarray) -> BinaryCounts:
        truth, predicted = np.asarray(truth, bool), np.asarray(predicted, bool)
        return cls(
            tp=int(np.sum(truth & predicted)),
            fp=int(np.sum(~truth & predicted)),
            fn=int(np.sum(truth & ~predicted)),
            tn=int(np.sum(~truth & ~predicted)),
        )

    def summary(self) -> dict[str, float]:
        """accuracy, the two baselines, precision, recall, F1, tight share (NaN if 0/0)."""
        total = self.tp + self.fp + self.fn + self.tn
        positives = self.tp + self.fn
        precision = _ratio(self.tp, self.tp + self.fp)
        recall = _ratio(self.tp, positives)
        return {
            "accuracy": _ratio(self.tp + self.tn, total),
            "all_zeros_accuracy": _ratio(total - positives, total),
            "all_ones_accuracy": _ratio(positives, total),
            "precision": precision,
            "recall": recall,
            "f1": _ratio(2 * precision * recall, precision + recall),
            "tight_share": _ratio(positives, total),
            "predicted_share": _ratio(self.tp + self.fp, total),
            "rows": total,
        }


def _ratio(a: float, b: float) -> float:
    return float(a / b) if b else float("nan")


def tight_metrics(
    truth: np.ndarray, predicted: np.ndarray, names: Sequence[str] = CONSTRAINT_NAMES
) -> dict[str, Any]:
    """Accuracy beside the baselines, precision/recall overall and per constraint name.

    Parameters
    ----------
    truth, predicted
        (n, R) flags with R = len(names) * N, rows name-major.
    names
        Constraint names in row order.

    Returns
    -------
    dict
        ``overall`` (see :meth:`BinaryCounts.summary`), ``per_name`` (name -> summary),
        ``covered`` (share of items with every tight row predicted), ``items``.
    """
    truth, predicted = np.asarray(truth, bool), np.asarray(predicted, bool)
    if truth.shape != predicted.shape or truth.ndim != 2:
        raise ValueError(f"truth and predicted must be equal (n, R), got {truth.shape}, "
                         f"{predicted.shape}")  # fmt: skip
    if truth.shape[1] % len(names):
        raise ValueError(f"R = {truth.shape[1]} is not a multiple of {len(names)} names")
    n = truth.shape[0]
    by_name_truth = truth.reshape(n, len(names), -1)
    by_name_pred = predicted.reshape(n, len(names), -1)
    per_name = {
        name: BinaryCounts.of(by_name_truth[:, i], by_name_pred[:, i]).summary()
        for i, name in enumerate(names)
    }
    covered = np.all(predicted | ~truth, axis=1)
    return {
        "overall": BinaryCounts.of(truth, predicted).summary(),
        "per_name": per_name,
        "covered": float(covered.mean()) if n else float("nan"),
        "items": n,
    }


def solution_metrics(
    predicted_std: np.ndarray,
    truth_std: np.ndarray,
    predicted: tuple[np.ndarray, np.ndarray, np.ndarray],
    truth: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> dict[str, Any]:
    """Standardized MSE (overall, x, u, t_f) and physical RMSE per state group.

    Parameters
    ----------
    predicted_std, truth_std
        (n, 17 N + 1) standardized outputs (layout of :mod:`scpformer.models.tscvx`).
    predicted, truth
        (x (n, N, 14), u (n, N, 3), tf (n,)) in physical units.
    """
    predicted_std, truth_std = np.asarray(predicted_std), np.asarray(truth_std)
    if predicted_std.shape != truth_std.shape:
        raise ValueError(f"shapes differ: {predicted_std.shape} vs {truth_std.shape}")
    x, u, tf = predicted
    x_true, u_true, tf_true = truth
    n_x, n_u = x_true[0].size, u_true[0].size
    err2 = (predicted_std - truth_std) ** 2
    rmse = {g: float(np.sqrt(np.mean((x[..., s] - x_true[..., s]) ** 2)))
            for g, s in STATE_GROUPS.items()}  # fmt: skip
    rmse["u"] = float(np.sqrt(np.mean((u - u_true) ** 2)))
    rmse["tf"] = float(np.sqrt(np.mean((np.asarray(tf) - tf_true) ** 2)))
    return {
        "mse": float(err2.mean()),
        "mse_x": float(err2[:, :n_x].mean()),
        "mse_u": float(err2[:, n_x : n_x + n_u].mean()),
        "mse_tf": float(err2[:, -1].mean()),
        "rmse_physical": rmse,  # [U_L], [U_L/U_T], [-], [rad/U_T], [U_M], thrust, [U_T]
        "final_mass_abs_error_mean": float(np.mean(np.abs(x[:, -1, 13] - x_true[:, -1, 13]))),
        "samples": len(truth_std),
    }


def format_tight(metrics: dict[str, Any]) -> list[str]:
    """Printable lines: overall accuracy beside the baselines, then one line per name."""
    o = metrics["overall"]
    lines = [
        f"tight: accuracy {100 * o['accuracy']:.2f} % (all zeros "
        f"{100 * o['all_zeros_accuracy']:.2f} %, all ones {100 * o['all_ones_accuracy']:.2f} %), "
        f"precision {o['precision']:.3f}, "
        f"recall {o['recall']:.3f}, F1 {o['f1']:.3f}; every tight row predicted in "
        f"{100 * metrics['covered']:.1f} % of {metrics['items']} items",
        f"  {'name':<11} {'tight %':>8} {'pred %':>8} {'precision':>9} {'recall':>7} "
        f"{'accuracy %':>10}",
    ]
    for name, m in metrics["per_name"].items():
        lines.append(
            f"  {name:<11} {100 * m['tight_share']:8.2f} {100 * m['predicted_share']:8.2f} "
            f"{m['precision']:9.3f} {m['recall']:7.3f} {100 * m['accuracy']:10.2f}"
        )
    return lines


def format_solution(metrics: dict[str, Any]) -> list[str]:
    """Printable lines of :func:`solution_metrics`."""
    r = metrics["rmse_physical"]
    return [
        f"solution: standardized MSE {metrics['mse']:.4g} (x {metrics['mse_x']:.4g}, "
        f"u {metrics['mse_u']:.4g}, t_f {metrics['mse_tf']:.4g}) over {metrics['samples']} samples",
        "  RMSE " + ", ".join(f"{k} {v:.3g}" for k, v in r.items()),
    ]


def write_metrics_files(
    run: Path, split: str, metrics: dict[str, Any], tag: str = ""
) -> list[Path]:
    """``run/metrics_<split><tag>.json`` and, with tight metrics, ``run/tight_<split><tag>.csv``
    (``tag`` tells apart evaluations of one split, e.g. at another threshold)."""
    run.mkdir(parents=True, exist_ok=True)
    written = [run / f"metrics_{split}{tag}.json"]
    write_text_atomic(written[0], json.dumps(metrics, indent=2, default=float) + "\n")
    if "tight" in metrics:
        path = run / f"tight_{split}{tag}.csv"
        rows = [{"name": "all", **metrics["tight"]["overall"]}]
        rows += [{"name": k, **v} for k, v in metrics["tight"]["per_name"].items()]
        with atomic_path(path) as tmp, tmp.open("w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
        written.append(path)
    return written
