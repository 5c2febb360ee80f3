"""Training the sequence models (ART, GRU, LSTM) on rendezvous datasets: the ART adapter.

What is specific to ART-style training lives here; the loop is :func:`scpformer.train.loop.fit`.

* **Data, read once.** Every stored sequence the :class:`ArtSequenceDataset` views of the
  ``train`` and validation instances serve is read in one pass over the shards (whole columns,
  raw: ``normalize=False``) and gathered by the views' (sample, twin) items into tensors
  (:func:`read_sequences`; checked against the views item by item in the tests).
* **One normalization.** ``ArtNormalization.from_dataset`` of the training view (training
  statistics only; with ``targets=`` the training trajectories' targets when the model takes
  the target token) encodes every input once; the same object is stored in the checkpoint
  and used at inference.
* **Validation by instance.** The ``validation`` split of ``scpformer dataset split`` when it
  has instances; otherwise (the default fractions are 0.8/0/0.2) a seeded permutation of the
  training split's ``base_index`` values sets ``validation_fraction`` of the training
  instances aside (both twins of an instance together). Training never sees them; the
  choice is written to ``RUN/config.json``. The test split is never read.
* **Target token.** Models whose configuration has ``target_dim > 0`` (robust-rendezvous ART)
  receive ``target`` = the trajectory's final stored state (the waypoint, in the frame).
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from scpformer import __version__
from scpformer.data.errors import DatasetError
from scpformer.data.splits import SPLITS_NAME
from scpformer.data.storage import MANIFEST_NAME, file_sha256
from scpformer.data.torch_views import ArtSequenceDataset
from scpformer.files import write_text_atomic
from scpformer.train import distributed
from scpformer.train.checkpoint import (
    BEST_NAME,
    CHECKPOINT_NAME,
    from_plain,
    manifest_digest,
    read_resumable,
    refuse_resume_without_checkpoint,
    save_epoch_checkpoints,
)
from scpformer.train.config import TrainConfig, train_config
from scpformer.train.loop import FitState, TensorData, fit, seed_everything
from scpformer.train.metrics import LOSS_PLOT_NAME, METRICS_NAME, plot_losses, write_metrics
from scpformer.train.models_api import resolve

CONFIG_NAME = "config.json"
SEQUENCE_KEYS = ("rtg", "ctg", "state", "action")  # model inputs, (n, N, d) each


@dataclass(frozen=True)
class ArtData:
    """Normalized in-memory training and validation sequences of one dataset and frame."""

    train: TensorData
    validation: TensorData
    normalization: Any  # ArtNormalization, from the training split
    family: str
    frame: str
    twins: tuple[str, ...]  # the trajectory twins learned from
    digest: str  # sha256 of manifest.json
    splits_digest: str  # sha256 of splits.h5 (which instances are training ones)
    n_steps: int  # N: impulses per trajectory
    validation_source: str  # how the validation instances were chosen
    train_instances: int
    validation_instances: int
    read_seconds: float  # wall time of the one-pass read and normalization


def read_sequences(view: ArtSequenceDataset) -> dict[str, np.ndarray]:
    """Every item of ``view`` as raw stacked arrays, reading each stored column once.

    Returns ``rtg``, ``ctg`` (n, N, 1), ``state`` (n, N, 6), ``action`` (n, N, 3), ``target``
    (n, 6) (the state at node N), ``base_index`` (n,), the same values the view's items hold
    with ``normalize=False`` (in float64).
    """
    n = view.n_steps
    position, twin = view.items[:, 0], view.items[:, 1]
    out: dict[str, list[np.ndarray]] = {k: [] for k in (*SEQUENCE_KEYS, "target")}
    order = []
    for number, prefix in enumerate(view.twins):
        rows = np.flatnonzero(twin == number)
        chosen = position[rows]
        states = view.samples.column(f"{prefix}_{view.frame}")[chosen]  # (m, N + 1, 6)
        out["rtg"].append(view.samples.column(f"{prefix}_rtg")[chosen, :n, None])
        out["ctg"].append(view.samples.column(f"{prefix}_ctg")[chosen, :n, None])
        out["state"].append(states[:, :n])
        out["action"].append(view.samples.column(f"{prefix}_dv")[chosen])
        out["target"].append(states[:, -1])
        order.append(rows)
    inverse = np.argsort(np.concatenate(order), kind="stable")  # back to the view's item order
    arrays = {k: np.concatenate(v).astype(np.float64)[inverse] for k, v in out.items()}
    arrays["base_index"] = view.base_index[position].astype(np.int64)
    return arrays


def carve_validation(
    base_index: np.ndarray, fraction: float, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Masks (train, validation) over items, setting ``fraction`` of the instances aside.

    Instances (``base_index`` values) are permuted with ``numpy.random.default_rng(seed)``;
    the first ``max(1, round(fraction * instances))`` become validation.
    """
    instances = np.unique(base_index)
    if len(instances) < 2:
        raise DatasetError(
            f"the training split has {len(instances)} instance(s): at least 2 are needed to "
            "set a validation instance aside (or make a validation split with `dataset split`)"
        )
    order = np.random.default_rng(seed).permutation(instances)
    held = order[: max(1, round(fraction * len(instances)))]
    validation = np.isin(base_index, held)
    return ~validation, validation


def load_art_data(
    folder: Path | str,
    *,
    frame: str,
    normalization_type: Any,
    validation_fraction: float,
    seed: int,
    target: bool = False,
    twins: Sequence[str] | None = None,
) -> ArtData:
    """Read, split and normalize a rendezvous dataset for training (see the module docstring).

    ``twins`` names the trajectory twins to learn from (default: the dataset's training twins,
    :func:`~scpformer.data.torch_views.training_twins`).
    """
    start = time.perf_counter()
    folder = Path(folder)
    views = {"frame": frame, "normalize": False, "twins": twins}
    train_view = ArtSequenceDataset(folder, "train", **views)
    val_view = ArtSequenceDataset(folder, "validation", **views)
    train = read_sequences(train_view)
    if len(train["base_index"]) == 0:
        raise DatasetError(f"the training split of {folder} holds no solved trajectory")
    if len(val_view) > 0:
        validation = read_sequences(val_view)
        source = "the dataset's validation split"
    else:
        keep, held = carve_validation(train["base_index"], validation_fraction, seed)
        validation = {k: v[held] for k, v in train.items()}
        train = {k: v[keep] for k, v in train.items()}
        source = (
            f"no validation split: {validation_fraction:g} of the training instances "
            f"(grouped by base_index, permutation seed {seed}) held out"
        )
    # state/action statistics: the training split's (dataset split); target: the kept ones'
    targets = {"targets": train["target"]} if target else {}
    normalization = normalization_type.from_dataset(train_view, **targets)
    return ArtData(
        train=_encoded(train, normalization, target),
        validation=_encoded(validation, normalization, target),
        normalization=normalization,
        family=train_view.samples.manifest.family,
        frame=frame,
        twins=train_view.twins,
        digest=manifest_digest(folder),
        splits_digest=file_sha256(folder / SPLITS_NAME),
        n_steps=train_view.n_steps,
        validation_source=source,
        train_instances=len(np.unique(train["base_index"])),
        validation_instances=len(np.unique(validation["base_index"])),
        read_seconds=time.perf_counter() - start,
    )


def _encoded(arrays: dict[str, np.ndarray], normalization: Any, target: bool) -> TensorData:
    keys = (*SEQUENCE_KEYS, "target") if target else SEQUENCE_KEYS
    tensors = {}
    for key in keys:
        value = np.asarray(normalization.encode(key, arrays[key]), dtype=np.float32)
        tensors[key] = torch.from_numpy(value)
    return TensorData(tensors)


# -- a run -----------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class RunResult:
    """What :func:`train_sequence_model` did."""

    run: Path
    state: FitState
    data: ArtData
    model_config: dict[str, Any]
    train_config: TrainConfig
    resumed_from: int  # epochs finished before this launch (0 for a new run)
    world: distributed.World  # this process's place in a torchrun launch


def train_sequence_model(
    kind: str,
    *,
    data: Path | str,
    out: Path | str,
    preset: str | None = None,
    frame: str | None = None,
    twins: Sequence[str] | None = None,
    overrides: dict[str, Any] | None = None,
    resume: bool = False,
    models: Any | None = None,
    progress: bool = True,
) -> RunResult:
    """Train (or resume) model ``kind`` on the rendezvous dataset ``data`` into run folder ``out``.

    Parameters
    ----------
    kind
        ``art``, ``gru`` or ``lstm`` (any kind the models API builds).
    data, out
        Dataset folder (split with ``scpformer dataset split``) and run folder.
    preset
        Model and training preset (``small`` or ``paper``; default ``small``; a resumed run
        keeps its own).
    frame
        ``rtn`` or ``roe`` (default ``rtn``; a resumed run keeps its own).
    twins
        Trajectory twins to learn from, e.g. ``("tpbvp",)`` for the ART paper's Table 2
        (default: the dataset's training twins, ``cvx`` and ``scp`` for rendezvous data; a
        resumed run keeps its own).
    overrides
        :class:`TrainConfig` fields to change (None values ignored), e.g. ``epochs``, ``lr``.
    resume
        Continue the run in ``out`` from its checkpoint (``ValueError`` when there is none).
        The stored model and training configuration are kept; only ``epochs`` and ``device``
        may change.
    models
        The models API (default :mod:`scpformer.models`).
    progress
        Show a progress bar.

    Raises
    ------
    ValueError
        Bad arguments, a dataset that cannot be trained on (``DatasetError``), a run folder that
        already holds a checkpoint without ``resume`` or none with it, a folder of a dataset or
        of a T-SCvx run, or a checkpoint that does not match (``CheckpointError``).
    """
    api = resolve(models)
    kinds = tuple(getattr(api, "MODEL_KINDS", ()))
    if kinds and kind not in kinds:
        raise ValueError(f"model must be one of {kinds}, got {kind!r}")
    out = Path(out)
    overrides = dict(overrides or {})
    previous = _previous_run(out, kind, frame, resume)
    if previous is not None:
        frame, preset, config = _resumed_settings(previous, preset, overrides)
        twins = _resumed_twins(previous, twins)
    else:
        frame, preset = frame or "rtn", preset or "small"
        config = train_config(preset, model_defaults=api.TRAIN_DEFAULTS, **overrides)
    world, device = distributed.start(config.device)
    try:
        return _run(kind, api, Path(data), out, preset, (frame, twins), config, previous, world,
                    device, progress)  # fmt: skip
    finally:
        distributed.stop(world)


def _previous_run(out: Path, kind: str, frame: str | None, resume: bool) -> dict[str, Any] | None:
    """The checkpoint payload to resume from (None for a new run)."""
    exists = (out / CHECKPOINT_NAME).is_file()
    if exists and not resume:
        raise ValueError(
            f"{out} already holds a training run: pass --resume to continue it, or another --out"
        )
    if not exists:
        if resume:
            refuse_resume_without_checkpoint(out)
            raise ValueError(
                f"--resume: {out} holds no training run to resume "
                f"({'no such folder' if not out.exists() else f'no {CHECKPOINT_NAME}'}); "
                "leave out --resume to start a new run"
            )
        _refuse_overwrite(out, kind)
        return None
    return read_resumable(out, kind=kind, frame=frame)


def _refuse_overwrite(out: Path, kind: str) -> None:
    """Raise ``ValueError`` when a new run in ``out`` would overwrite files it did not write.

    A run writes its files beside its checkpoint, except the ``config.json`` of a start that
    stopped before its first epoch ended: that one (of a ``kind`` run) is the run's to rewrite.
    """
    if (out / MANIFEST_NAME).exists():
        raise ValueError(
            f"--out {out} is a dataset folder (it holds {MANIFEST_NAME}): a training run "
            "would write its files among the dataset's; give another --out"
        )
    if any((out / name / CHECKPOINT_NAME).exists() for name in ("tight", "solution")):
        raise ValueError(
            f"--out {out} holds a T-SCvx training run (tight/, solution/): give another --out"
        )
    names = (CONFIG_NAME, BEST_NAME, METRICS_NAME, LOSS_PLOT_NAME)
    taken = [name for name in names if (out / name).exists()]
    if taken == [CONFIG_NAME] and _describes_a_run(out / CONFIG_NAME, kind):
        return
    if taken:
        raise ValueError(
            f"--out {out} holds {', '.join(taken)} but no {CHECKPOINT_NAME}: a new run would "
            f"overwrite {'it' if len(taken) == 1 else 'them'} (give another --out, or delete "
            f"{'it' if len(taken) == 1 else 'them'})"
        )


def _describes_a_run(path: Path, kind: str) -> bool:
    """Whether ``path`` is the ``config.json`` written at the start of a ``kind`` run."""
    try:
        description = json.loads(path.read_text())
    except (OSError, ValueError):
        return False
    return (
        isinstance(description, dict)
        and description.get("kind") == kind
        and all(key in description for key in ("manifest_digest", "package_version", "train"))
    )


def _resumed_settings(
    previous: dict[str, Any], preset: str | None, overrides: dict[str, Any]
) -> tuple[str, str, TrainConfig]:
    """(frame, preset, config) of a resumed run: the stored ones, new epochs and device only."""
    stored_preset = previous["extra"]["preset"]
    if preset is not None and preset != stored_preset:
        raise ValueError(f"the run to resume used preset {stored_preset!r}, not {preset!r}")
    stored = TrainConfig.from_dict(previous["extra"]["train_config"])
    changed = sorted(
        k
        for k, v in overrides.items()
        if v is not None and k not in ("epochs", "device") and v != getattr(stored, k)
    )
    if changed:
        raise ValueError(
            f"a resumed run keeps its training settings; only epochs and device may change, "
            f"not {', '.join(changed)}"
        )
    kept = {k: overrides[k] for k in ("epochs", "device") if overrides.get(k) is not None}
    done = int(previous["extra"]["fit"]["epoch"])
    if kept.get("epochs", stored.epochs) < done:  # would train nothing and record fewer epochs
        raise ValueError(
            f"--epochs {kept['epochs']}: the run to resume has finished {done} epochs already; "
            f"give at least {done}"
        )
    return previous["frame"], stored_preset, dataclasses.replace(stored, **kept)


def _resumed_twins(previous: dict[str, Any], twins: Sequence[str] | None) -> tuple[str, ...] | None:
    """The twins of a resumed run: the ones it named (None: the dataset's default twins, also for
    runs that predate the choice); asking for others is an error."""
    stored = previous["extra"].get("twins")
    stored = None if stored is None else tuple(stored)
    if twins is not None and tuple(twins) != stored:
        what = "the dataset's default twins" if stored is None else f"twins {stored}"
        raise ValueError(f"the run to resume learned from {what}, not {tuple(twins)}")
    return stored


def _run(
    kind: str,
    api: Any,
    data_folder: Path,
    out: Path,
    preset: str,
    selection: tuple[str, Sequence[str] | None],
    config: TrainConfig,
    previous: dict[str, Any] | None,
    world: distributed.World,
    device: torch.device,
    progress: bool,
) -> RunResult:
    frame, twins = selection  # state frame and trajectory twins learned from
    seed_everything(config.seed)
    if previous is not None:
        model_config = api.config_from_dict(kind, from_plain(previous["config"]))
    else:
        model_config = _model_config(api, kind, preset, data_folder, frame)
    wants_target = int(model_config.to_dict().get("target_dim", 0) or 0) > 0
    data = load_art_data(
        data_folder,
        frame=frame,
        normalization_type=api.ArtNormalization,
        validation_fraction=config.validation_fraction,
        seed=config.seed,
        target=wants_target,
        twins=twins,
    )
    if previous is not None:
        stored = (previous["manifest_digest"], previous["extra"].get("splits_digest"))
        if stored != (data.digest, data.splits_digest):
            raise ValueError(
                f"{out} was trained on other data or splits than those of {data_folder}"
            )
    model = api.build_model(kind, model_config)
    if previous is not None:
        model.load_state_dict(previous["state_dict"])
    torch.manual_seed(config.seed + world.rank)  # dropout streams differ between processes
    description = {
        "kind": kind,
        "preset": preset,
        "data": str(data_folder.resolve()),
        "family": data.family,
        "frame": frame,
        "twins": list(data.twins),
        "twin_option": None if twins is None else list(twins),  # --twin (None: the default)
        "manifest_digest": data.digest,
        "splits_digest": data.splits_digest,
        "n_steps": data.n_steps,
        "train_sequences": len(data.train),
        "train_instances": data.train_instances,
        "validation_sequences": len(data.validation),
        "validation_instances": data.validation_instances,
        "validation": data.validation_source,
        "data_read_seconds": data.read_seconds,
        "model": model_config.to_dict(),
        "parameters": sum(p.numel() for p in model.parameters()),
        "train": config.to_dict(),
        "device": str(device),
        "world_size": world.size,
        "package_version": __version__,
    }
    if world.is_main:
        out.mkdir(parents=True, exist_ok=True)
        _write_json(out / CONFIG_NAME, description)

    def save(state: FitState, training_state: dict[str, Any]) -> None:
        if not world.is_main:
            return
        extra = training_state | {
            "preset": preset,
            "train_config": config.to_dict(),
            "splits_digest": data.splits_digest,
            "twins": None if twins is None else list(twins),  # None: the dataset's default
        }
        fields = dict(
            model=model,
            kind=kind,
            config=model_config,
            normalization=data.normalization,
            frame=frame,
            family=data.family,
            manifest_digest=data.digest,
            seed=config.seed,
            metrics=state.metrics(),
            n_steps=data.n_steps,
        )
        save_epoch_checkpoints(out, fields, extra, state.improved)
        write_metrics(out, state.history)
        plot_losses(out, state.history, title=f"{kind} ({preset}, {frame}) on {data.family}")

    resume_state = None if previous is None else previous["extra"]
    state = fit(model, data.train, data.validation, config, device=device, world=world,
                resume=resume_state, on_epoch=save, progress=progress)  # fmt: skip
    distributed.barrier(world)
    return RunResult(
        run=out,
        state=state,
        data=data,
        model_config=model_config.to_dict(),
        train_config=config,
        resumed_from=0 if previous is None else int(previous["extra"]["fit"]["epoch"]),
        world=world,
    )


def _model_config(api: Any, kind: str, preset: str, folder: Path, frame: str) -> Any:
    """The preset's configuration, with the context set to the dataset's N and the target token
    switched on for robust-rendezvous data (when the configuration has those fields)."""
    probe = ArtSequenceDataset(folder, None, frame=frame, normalize=False)
    fields = api.preset(kind, preset).to_dict()
    changes: dict[str, Any] = {}
    if "context" in fields:
        changes["context"] = probe.n_steps
    if "target_dim" in fields and probe.samples.manifest.family == "robust-rendezvous":
        changes["target_dim"] = 6
    return api.preset(kind, preset, **changes)


def _write_json(path: Path, value: dict[str, Any]) -> None:
    write_text_atomic(path, json.dumps(value, indent=2, default=str) + "\n")
