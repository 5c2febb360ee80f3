"""Writing a checkpoint: one file per run, written atomically.

Reading it is the models' (:mod:`scpformer.models.checkpoint`, which describes the format;
its names are re-exported here). Writing stays with training: :func:`save_checkpoint` (after
every epoch :func:`save_epoch_checkpoints`: the run's and, when the epoch improved, the best
one), :func:`slim_checkpoint` for a packaged weights-only copy, and :func:`to_plain`, which
stores numpy arrays as the tensors ``torch.load(weights_only=True)`` accepts;
:func:`read_resumable` reads a run's checkpoint back to resume it.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from scpformer import __version__
from scpformer.data.storage import MANIFEST_NAME, file_sha256
from scpformer.files import atomic_path
from scpformer.models.checkpoint import (
    CHECKPOINT_NAME,
    FORMAT,
    FORMAT_VERSION,
    NUMPY_TAG,
    Checkpoint,
    CheckpointError,
    checkpoint_path,
    from_plain,
    load_checkpoint,
    read_checkpoint,
)

BEST_NAME = "best.pt"  # the checkpoint of the best validation loss, beside the run's

__all__ = [
    "BEST_NAME",
    "CHECKPOINT_NAME",
    "FORMAT",
    "FORMAT_VERSION",
    "Checkpoint",
    "CheckpointError",
    "checkpoint_path",
    "from_plain",
    "load_checkpoint",
    "manifest_digest",
    "read_checkpoint",
    "read_resumable",
    "refuse_resume_without_checkpoint",
    "save_checkpoint",
    "save_epoch_checkpoints",
    "slim_checkpoint",
    "to_plain",
]


def refuse_resume_without_checkpoint(folder: Path) -> None:
    """Raise ``ValueError`` when ``--resume`` points at a run ``folder`` whose checkpoint is
    gone while other files of the run remain: a new run would overwrite them."""
    if (folder / CHECKPOINT_NAME).is_file() or not folder.is_dir():
        return
    if any(path.is_file() for path in folder.iterdir()):
        raise ValueError(
            f"--resume: {folder} holds no {CHECKPOINT_NAME} to resume from; its other files "
            "would be overwritten by a new run (give another --out, or empty the folder)"
        )


def read_resumable(folder: Path, **wanted: str | None) -> dict[str, Any]:
    """The checkpoint payload of run ``folder`` to resume training from.

    Parameters
    ----------
    folder
        The run folder.
    **wanted
        What the checkpoint must hold (``family``, ``frame``, ``kind``; see
        :func:`read_checkpoint`).

    Returns
    -------
    dict
        The checked payload, its ``extra`` (the training state) decoded by :func:`from_plain`.
    """
    payload = read_checkpoint(folder, **wanted)
    payload["extra"] = from_plain(payload["extra"])
    return payload


def save_epoch_checkpoints(
    folder: Path, fields: Mapping[str, Any], extra: Mapping[str, Any], improved: bool
) -> None:
    """After an epoch: the run's checkpoint in ``folder`` and, when the validation loss
    ``improved``, the best one (:data:`BEST_NAME`, without the training state).

    Parameters
    ----------
    folder
        The run folder.
    fields
        The keyword arguments of :func:`save_checkpoint` but ``extra``.
    extra
        The training state (optimizer, schedule, RNG) and what resuming checks.
    improved
        Whether this epoch's validation loss is the best so far.
    """
    save_checkpoint(folder, **fields, extra=extra)
    if improved:
        save_checkpoint(folder / BEST_NAME, **fields)


def manifest_digest(folder: Path | str) -> str:
    """sha256 of ``folder/manifest.json``: the identity of a training dataset."""
    return file_sha256(Path(folder) / MANIFEST_NAME)


def save_checkpoint(
    path: Path | str,
    *,
    model: nn.Module,
    kind: str,
    config: Any,
    normalization: Any,
    frame: str | None,
    family: str,
    manifest_digest: str,
    seed: int,
    metrics: Mapping[str, Any] | None = None,
    n_steps: int | None = None,
    extra: Mapping[str, Any] | None = None,
) -> Path:
    """Write a checkpoint to ``path`` (a file, or a run folder) through a temp file and rename.

    A reader never sees a partial file, and a failed write (full disk, interrupt) leaves the
    previous checkpoint at ``path`` as it was. ``model`` may be wrapped (DDP): its ``module``
    is saved. Returns the file written.
    """
    path = checkpoint_path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    module = getattr(model, "module", model)
    payload = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "kind": kind,
        "config": _config_dict(config),
        "state_dict": {k: v.detach().cpu() for k, v in module.state_dict().items()},
        "normalization": None if normalization is None else to_plain(normalization.to_dict()),
        "frame": frame,
        "family": family,
        "manifest_digest": manifest_digest,
        "package_version": __version__,
        "seed": int(seed),
        "n_steps": None if n_steps is None else int(n_steps),
        "metrics": to_plain(dict(metrics or {})),
        "extra": to_plain(dict(extra or {})),
    }
    return _write_payload(path, payload)


def slim_checkpoint(source: Path | str, destination: Path | str) -> Path:
    """Write a weights-only copy of a checkpoint: the training state dropped, weights fp32.

    The copy keeps everything :func:`load_checkpoint` needs (format, kind, configuration,
    normalization, frame, family, dataset digest, version, seed, ``n_steps``, metrics) and
    drops ``extra`` (optimizer, schedule and RNG states for ``--resume``), so it loads with
    the same loaders but cannot resume training. ``source`` is a file or a run folder;
    ``destination`` a file or a folder (then ``destination/checkpoint.pt``). Returns the file
    written.
    """
    payload = read_checkpoint(source)
    weights = {}
    for name, tensor in payload["state_dict"].items():
        weights[name] = tensor.float() if tensor.is_floating_point() else tensor
    slim = {**payload, "state_dict": weights, "extra": {}}
    destination = checkpoint_path(destination)
    destination.parent.mkdir(parents=True, exist_ok=True)
    return _write_payload(destination, slim)


def _write_payload(path: Path, payload: dict[str, Any]) -> Path:
    """``torch.save`` to ``path`` atomically (:func:`scpformer.files.atomic_path`)."""
    with atomic_path(path) as tmp, tmp.open("wb") as fh:
        torch.save(payload, fh)
    return path


def to_plain(value: Any) -> Any:
    """``value`` with numpy arrays and scalars replaced by what ``weights_only`` loads."""
    if isinstance(value, np.ndarray):
        data = torch.from_numpy(np.ascontiguousarray(value.astype(_storable(value.dtype))))
        return {NUMPY_TAG: data, "dtype": value.dtype.str}
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Mapping):
        return {k: to_plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(to_plain(v) for v in value)
    return value


def _storable(dtype: np.dtype) -> np.dtype:
    """A dtype torch holds exactly (unsigned integers widen to int64)."""
    return np.dtype(np.int64) if dtype.kind == "u" else dtype


def _config_dict(config: Any) -> dict[str, Any]:
    data = config if isinstance(config, Mapping) else config.to_dict()
    return to_plain(dict(data))
