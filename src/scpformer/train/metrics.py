"""Per-epoch training records: ``RUN/metrics.csv`` and ``RUN/loss.png``.

Both files are rewritten whole from the run's history after every epoch (through a temporary
name), so after ``--resume`` they hold exactly the epochs of the checkpoint resumed from.
"""

from __future__ import annotations

import csv
import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from scpformer.files import atomic_path

METRICS_NAME = "metrics.csv"
LOSS_PLOT_NAME = "loss.png"


@dataclass(frozen=True, kw_only=True)
class EpochRecord:
    """What one epoch did."""

    epoch: int  # 1-based
    train_loss: float  # mean training loss over the epoch's samples (dropout on)
    val_loss: float  # mean validation loss (eval mode)
    lr: float  # learning rate at the end of the epoch
    seconds: float  # wall time of the epoch (training and validation)
    samples_per_s: float  # training sequences per second of the training phase, all processes
    loading_share: float  # share of the epoch spent fetching batches from memory

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> EpochRecord:
        return cls(**{f.name: data[f.name] for f in dataclasses.fields(cls)})


METRIC_COLUMNS = tuple(f.name for f in dataclasses.fields(EpochRecord))


def write_metrics(run: Path, history: Sequence[EpochRecord]) -> Path:
    """Write ``run/metrics.csv``: one row per epoch, columns :data:`METRIC_COLUMNS`."""
    path = Path(run) / METRICS_NAME
    with atomic_path(path) as tmp, tmp.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=METRIC_COLUMNS)
        writer.writeheader()
        for record in history:
            writer.writerow(record.to_dict())
    return path


def plot_losses(run: Path, history: Sequence[EpochRecord], title: str = "") -> Path:
    """Write ``run/loss.png``: training and validation loss per epoch (log scale)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    path = Path(run) / LOSS_PLOT_NAME
    figure = Figure(figsize=(6.0, 4.0), layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.add_subplot()
    epochs = [r.epoch for r in history]
    axes.plot(epochs, [r.train_loss for r in history], "o-", label="training")
    axes.plot(epochs, [r.val_loss for r in history], "s-", label="validation")
    if all(r.train_loss > 0 and r.val_loss > 0 for r in history):
        axes.set_yscale("log")
    axes.set_xlabel("epoch")
    axes.set_ylabel("loss (Eq. 8, normalized units)")
    axes.set_title(title)
    axes.grid(True, alpha=0.3)
    axes.legend()
    with atomic_path(path, suffix=".png") as tmp:
        figure.savefig(tmp, dpi=100)
    return path
