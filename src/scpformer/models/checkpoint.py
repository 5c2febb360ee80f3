"""Reading a checkpoint: one file per run, checked when read.

Writing stays with training (:mod:`scpformer.train.checkpoint`); the models read their own.

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

import importlib
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import torch
from torch import nn

from scpformer.validation import shown

CHECKPOINT_NAME = "checkpoint.pt"
FORMAT = "scpformer.checkpoint"
FORMAT_VERSION = 1
NUMPY_TAG = "__numpy__"  # marks a numpy array stored as a tensor (see from_plain)


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


def _other_kind(folder: Path) -> str:
    """What else ``folder`` holds, said beside a missing checkpoint (``""``: nothing known)."""
    if (folder / "tight").is_dir() or (folder / "solution").is_dir():
        return f": {folder} is a T-SCvx run (tight/, solution/), not a single-network run"
    if (folder / "lookup.json").is_file():
        return f": {folder} is a lookup table (lookup.json), not a network run"
    if (folder / "manifest.json").is_file():
        return f": {folder} is a dataset, not a training run"
    return ""


def checkpoint_path(path: Path | str) -> Path:
    """The checkpoint file of a run folder (an existing folder, or a path without a suffix),
    or ``path`` itself (a file such as ``RUN/best.pt``)."""
    path = Path(path)
    return path / CHECKPOINT_NAME if path.is_dir() or not path.suffix else path


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
        raise CheckpointError(f"no checkpoint at {path}{_other_kind(path.parent)}")
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
        An object with ``config_from_dict``, ``build_model`` and ``ArtNormalization``
        (default: :mod:`scpformer.models`), e.g. a test's stand-in.

    Raises
    ------
    CheckpointError
        One line saying why: missing, truncated or not a checkpoint, another format version,
        another family, frame, kind or sequence length, or weights that do not fit the stored
        configuration.
    """
    payload = read_checkpoint(path, family=family, frame=frame, kind=kind, n_steps=n_steps)
    path = checkpoint_path(path)
    api = models if models is not None else _package_models()
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


def from_plain(value: Any) -> Any:
    """Inverse of :func:`to_plain`."""
    if isinstance(value, Mapping):
        if NUMPY_TAG in value:
            return value[NUMPY_TAG].numpy().astype(np.dtype(value["dtype"]))
        return {k: from_plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(from_plain(v) for v in value)
    return value


def _package_models() -> Any:
    """What :func:`load_checkpoint` needs of :mod:`scpformer.models` (imported when needed)."""
    models = importlib.import_module("scpformer.models")
    normalization = importlib.import_module("scpformer.models.normalization")
    return SimpleNamespace(
        config_from_dict=models.config_from_dict,
        build_model=models.build_model,
        ArtNormalization=normalization.ArtNormalization,
    )
