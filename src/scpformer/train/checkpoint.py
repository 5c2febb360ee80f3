"""One-file checkpoints, written atomically and checked when read.

A checkpoint (``RUN/checkpoint.pt``) is a ``torch.save`` of plain containers and tensors only,
so that it loads with ``torch.load(weights_only=True)`` (no pickled code runs on load):

==================  ===========================================================================
key                 value
==================  ===========================================================================
format              ``"scpformer.checkpoint"`` and ``format_version`` (1)
kind                model kind (``art``, ``gru``, ``lstm``, ...)
config              the model configuration's ``to_dict()``
state_dict          the weights (CPU tensors)
normalization       the normalization's ``to_dict()`` (arrays as tensors), or None
frame, family       state frame (``rtn``/``roe``) and dataset family
n_steps             N, time steps of the training sequences (None when not sequences)
manifest_digest     sha256 of the training dataset's ``manifest.json``
package_version     scpformer version that trained it
seed                the run's seed
metrics             best and last validation losses, epochs
extra               what ``--resume`` needs: optimizer, schedule, RNG states, history
==================  ===========================================================================

Numpy arrays inside ``normalization`` and ``extra`` are stored as tensors tagged with their
dtype (:func:`to_plain`) and come back as arrays (:func:`from_plain`).
"""

from __future__ import annotations

import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from scpformer import __version__
from scpformer.data.storage import MANIFEST_NAME, file_sha256
from scpformer.files import atomic_path
from scpformer.train.models_api import resolve
from scpformer.validation import shown

CHECKPOINT_NAME = "checkpoint.pt"
FORMAT = "scpformer.checkpoint"
FORMAT_VERSION = 1
_NUMPY_TAG = "__numpy__"


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


class CheckpointError(ValueError):
    """A checkpoint that is missing, unreadable or does not fit what it is loaded for."""


@dataclass(frozen=True)
class Checkpoint:
    """A loaded checkpoint: the model in eval mode and everything it was trained with."""

    model: nn.Module  # in eval mode, on the requested device
    kind: str  # model kind ("art", "gru", "lstm", ...)
    config: Any  # model configuration object (config_from_dict of the stored dict)
    normalization: Any  # ArtNormalization, or None for models without one
    frame: str | None  # state frame of the training data ("rtn" or "roe")
    family: str  # dataset family it was trained on
    manifest_digest: str  # sha256 of the training dataset's manifest.json
    package_version: str  # scpformer version that wrote it
    seed: int  # seed of the training run
    n_steps: int | None = None  # N, time steps of the training sequences
    metrics: dict[str, Any] = field(default_factory=dict)  # best/last losses, epoch
    path: Path | None = None  # the file it was read from
    extra: dict[str, Any] = field(default_factory=dict)  # training state for --resume


def manifest_digest(folder: Path | str) -> str:
    """sha256 of ``folder/manifest.json``: the identity of a training dataset."""
    return file_sha256(Path(folder) / MANIFEST_NAME)


def checkpoint_path(path: Path | str) -> Path:
    """The checkpoint file of a run folder (an existing folder, or a path without a suffix),
    or ``path`` itself (a file such as ``RUN/best.pt``)."""
    path = Path(path)
    return path / CHECKPOINT_NAME if path.is_dir() or not path.suffix else path


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


def _not_an_archive(path: Path) -> str | None:
    """Why ``path`` cannot be a checkpoint before unpickling it, or None.

    ``torch.save`` writes a zip archive; a file that is not one (empty, cut short before the
    archive's central directory, text, or another binary format) is named as such instead of
    by the unpickler's opcode numbers.
    """
    if zipfile.is_zipfile(path):
        return None
    with path.open("rb") as fh:
        head = fh.read(32)
    if not head:
        return "the file is empty"
    if head.startswith(b"PK"):
        return "a zip archive cut short (truncated)"
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError:
        text = "\0"
    if not all(c.isprintable() or c.isspace() for c in text):
        return "not the zip archive that torch.save writes (another binary format)"
    first = text.strip().splitlines()[0] if text.strip() else "blank"
    return f"not the zip archive that torch.save writes (text starting {first[:24]!r})"


def _load_failure_reason(err: Exception) -> str:
    """One line on why ``torch.load`` failed on a zip archive: the unpickler's own words.

    The weights-only unpickler raises a long message whose first lines advise
    ``weights_only=False``; the cause (e.g. "Unsupported global: GLOBAL fractions.Fraction was
    not an allowed global") sits after ``WeightsUnpickler error:`` and before its advice, so
    that part is kept.
    """
    text = str(err).strip()
    if not text:
        return type(err).__name__
    marker = "WeightsUnpickler error:"
    if marker in text:
        text = text.split(marker, 1)[1].strip()
    return text.splitlines()[0].split(". Please use", 1)[0][:160]


def read_checkpoint(
    path: Path | str,
    *,
    family: str | None = None,
    frame: str | None = None,
    kind: str | None = None,
    n_steps: int | None = None,
) -> dict[str, Any]:
    """The checked payload of a checkpoint file (no model built): see :func:`load_checkpoint`."""
    path = checkpoint_path(path)
    if not path.is_file():
        raise CheckpointError(f"no checkpoint at {path}")
    reason = _not_an_archive(path)
    if reason is not None:
        raise CheckpointError(f"{path} is not a readable scpformer checkpoint: {reason}")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # any failure to unpickle means unreadable
        reason = _load_failure_reason(err)
        raise CheckpointError(
            f"{path} is not a readable scpformer checkpoint: a torch archive that does not load "
            f"as weights only ({reason})"
        ) from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise CheckpointError(f"{path} is not an scpformer checkpoint")
    if payload.get("format_version") != FORMAT_VERSION:
        raise CheckpointError(
            f"{path} has checkpoint format {payload.get('format_version')!r}; this scpformer "
            f"reads format {FORMAT_VERSION}"
        )
    wanted = {"family": family, "frame": frame, "kind": kind, "n_steps": n_steps}
    for name, value in wanted.items():
        if value is not None and payload.get(name) != value:
            raise CheckpointError(
                f"{path} holds a model with {name} {payload.get(name)!r}, not {shown(value)}"
            )
    return payload


def load_checkpoint(
    path: Path | str,
    *,
    family: str | None = None,
    frame: str | None = None,
    kind: str | None = None,
    n_steps: int | None = None,
    device: str | torch.device = "cpu",
    models: Any | None = None,
) -> Checkpoint:
    """Read a checkpoint (a file or a run folder) and rebuild its model in eval mode.

    Parameters
    ----------
    path
        ``RUN`` or ``RUN/checkpoint.pt``.
    family, frame, kind, n_steps
        When given, the checkpoint must have been trained on this family, in this frame, as
        this model kind, on sequences of ``n_steps`` time steps.
    device
        Where the model goes.
    models
        The models API (default :mod:`scpformer.models`; see :mod:`scpformer.train.models_api`).

    Raises
    ------
    CheckpointError
        One line saying why: missing, truncated or not a checkpoint, another format version,
        another family, frame, kind or sequence length, or weights that do not fit the stored
        configuration.
    """
    payload = read_checkpoint(path, family=family, frame=frame, kind=kind, n_steps=n_steps)
    path = checkpoint_path(path)
    api = resolve(models)
    try:
        config = api.config_from_dict(payload["kind"], from_plain(payload["config"]))
        model = api.build_model(payload["kind"], config)
    except (KeyError, TypeError, ValueError) as err:
        raise CheckpointError(
            f"{path}: its model configuration is not valid here ({err})"
        ) from None
    try:
        model.load_state_dict(payload["state_dict"], strict=True)
    except RuntimeError as err:
        detail = " ".join(str(err).split())[:200]
        raise CheckpointError(
            f"{path}: weights do not fit the model configuration ({detail})"
        ) from None
    normalization = payload["normalization"]
    if normalization is not None:
        normalization = api.ArtNormalization.from_dict(from_plain(normalization))
    return Checkpoint(
        model=model.to(device).eval(),
        kind=payload["kind"],
        config=config,
        normalization=normalization,
        frame=payload["frame"],
        family=payload["family"],
        manifest_digest=payload["manifest_digest"],
        package_version=payload["package_version"],
        seed=payload["seed"],
        n_steps=payload.get("n_steps"),
        metrics=from_plain(payload["metrics"]),
        path=path,
        extra=from_plain(payload["extra"]),
    )


def to_plain(value: Any) -> Any:
    """``value`` with numpy arrays and scalars replaced by what ``weights_only`` loads."""
    if isinstance(value, np.ndarray):
        data = torch.from_numpy(np.ascontiguousarray(value.astype(_storable(value.dtype))))
        return {_NUMPY_TAG: data, "dtype": value.dtype.str}
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Mapping):
        return {k: to_plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(to_plain(v) for v in value)
    return value


def from_plain(value: Any) -> Any:
    """Inverse of :func:`to_plain`."""
    if isinstance(value, Mapping):
        if _NUMPY_TAG in value:
            return value[_NUMPY_TAG].numpy().astype(np.dtype(value["dtype"]))
        return {k: from_plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(from_plain(v) for v in value)
    return value


def _storable(dtype: np.dtype) -> np.dtype:
    """A dtype torch holds exactly (unsigned integers widen to int64)."""
    return np.dtype(np.int64) if dtype.kind == "u" else dtype


def _config_dict(config: Any) -> dict[str, Any]:
    data = config if isinstance(config, Mapping) else config.to_dict()
    return to_plain(dict(data))
