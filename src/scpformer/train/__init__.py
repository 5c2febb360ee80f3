"""Training: one loop for every model, atomic checked checkpoints, the ART adapter.

* :func:`fit` (:mod:`scpformer.train.loop`) -- the loop (AdamW, warm-up then constant or
  cosine, clipping, accumulation, DDP under ``torchrun``) for any
  ``model(batch) -> (pred, loss)`` over in-memory :class:`TensorData`;
* :mod:`scpformer.train.checkpoint` -- :func:`save_checkpoint`, :func:`load_checkpoint`,
  :class:`Checkpoint`, :class:`CheckpointError`;
* :func:`train_sequence_model` (:mod:`scpformer.train.art`) -- ``scpformer train
  art|gru|lstm``: a rendezvous dataset read once into memory, one normalization, grouped
  validation, a run folder with ``checkpoint.pt``, ``best.pt``, ``metrics.csv``, ``loss.png``
  and ``config.json``.

Names are imported on first use (PEP 562), so that ``import scpformer.train.config`` (the
command line's flags) does not import torch.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "Checkpoint": "scpformer.train.checkpoint",
    "CheckpointError": "scpformer.train.checkpoint",
    "load_checkpoint": "scpformer.train.checkpoint",
    "save_checkpoint": "scpformer.train.checkpoint",
    "TRAIN_PRESETS": "scpformer.train.config",
    "TrainConfig": "scpformer.train.config",
    "train_config": "scpformer.train.config",
    "FitState": "scpformer.train.loop",
    "TensorData": "scpformer.train.loop",
    "fit": "scpformer.train.loop",
    "load_art_data": "scpformer.train.art",
    "train_sequence_model": "scpformer.train.art",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module 'scpformer.train' has no attribute {name!r}")
    return getattr(importlib.import_module(_EXPORTS[name]), name)
