"""Training: one loop for every model, atomic checked checkpoints, the ART adapter.

* :func:`scpformer.train.loop.fit` -- the loop (AdamW, warm-up then constant or cosine,
  clipping, accumulation, DDP under ``torchrun``) for any ``model(batch) -> (pred, loss)``
  over in-memory tensors;
* :mod:`scpformer.train.checkpoint` -- :func:`save_checkpoint`, :func:`load_checkpoint`,
  :class:`Checkpoint`, :class:`CheckpointError`;
* :func:`scpformer.train.art.train_sequence_model` -- ``scpformer train art|gru|lstm``: a
  rendezvous dataset read once into memory, one normalization, grouped validation, a run
  folder with ``checkpoint.pt``, ``best.pt``, ``metrics.csv``, ``loss.png``, ``config.json``.
"""

from scpformer.train.checkpoint import (
    Checkpoint,
    CheckpointError,
    load_checkpoint,
    save_checkpoint,
)
from scpformer.train.config import TRAIN_PRESETS, TrainConfig, train_config

__all__ = [
    "TRAIN_PRESETS",
    "Checkpoint",
    "CheckpointError",
    "TrainConfig",
    "load_checkpoint",
    "save_checkpoint",
    "train_config",
]
