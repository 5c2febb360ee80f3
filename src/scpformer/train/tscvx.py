"""``scpformer train tscvx``: the T-SCvx networks f2 and f1 (T-SCvx paper Sec. III.E.3).

* **Data, read once.** The solved samples of a ``pdg6dof`` dataset (``dataset augment`` then
  ``dataset split``: splits grouped by base instance, so the eight rotations of one instance
  never straddle splits) are read in one pass over the shards into memory
  (:func:`read_tscvx`); the items are those of the :class:`TightFlagsDataset` and
  :class:`SolutionDataset` views (checked item by item in the tests).
* **Standardization** of theta and of (x, u, t_f): the training split's per-element mean and
  std that ``dataset split`` stored (Sec. III.E.3), kept in both checkpoints.
* **Losses.** f2: binary cross-entropy on the logits with a positive-class weight
  ``(1 - p) / p``, ``p`` the tight share of the fold's training rows (the tight rows are a
  few percent); f1: mean squared error of the standardized outputs.
* **Validation and K-fold.** ``folds=1`` (the default of the ``small`` preset): the dataset's
  validation split, or, when it is empty, ``validation_fraction`` of the training instances
  set aside (grouped). ``folds=K >= 2`` (``paper``: K = 3, Sec. III.E.3): the training and
  validation splits are pooled, their base instances cut into K seeded folds; fold i trains a
  fresh network on the other K - 1 folds and validates on fold i, in ``NET/fold<i>/``;
  ``NET/cv.json`` holds every fold's validation loss and the delivered network is the last
  fold's (Table 3 reports "the third fold"), copied to ``NET/checkpoint.pt``. The
  standardization stays the one of the dataset's training split. The test split is read
  only by :func:`evaluate_tscvx`.
* **Loop.** :func:`scpformer.train.loop.fit` (AdamW, linear warm-up, batch 128, clipping,
  DDP under torchrun, exact ``--resume``), a checkpoint per epoch in the ART format with the
  kind ``tscvx-tight`` / ``tscvx-solution``.

Run folder::

    RUN/config.json                      what was trained on, how, parameter counts
    RUN/tight/checkpoint.pt, best.pt     f2 (last and best validation epoch)
    RUN/tight/metrics.csv, loss.png      per-epoch losses (and fold<i>/ with folds >= 2)
    RUN/solution/...                     f1, the same files
    RUN/metrics_<split>.json, tight_<split>.csv   evaluate_tscvx on a split

The ``small`` preset (``scpformer.models.tscvx.TSCVX_PRESETS``) and its epochs were chosen
by measuring on this machine; see TSCVX_TRAIN_DEFAULTS.
"""

from __future__ import annotations

import dataclasses
import json
import math
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn
from torch.nn import functional

from scpformer import __version__
from scpformer.data.errors import DatasetError
from scpformer.data.splits import SPLIT_NAMES, SPLITS_NAME, load_splits
from scpformer.data.storage import file_sha256
from scpformer.data.torch_views import SolutionDataset
from scpformer.files import write_text_atomic
from scpformer.models.tscvx import (
    CONTROL_DIM,
    FAMILY,
    SOLUTION_KIND,
    STATE_DIM,
    TIGHT_KIND,
    TSCVX_PRESETS,
    TscvxNormalization,
    build_model,
    config_from_dict,
    load_tscvx_predictor,
    preset,
)
from scpformer.train import distributed
from scpformer.train.art import CONFIG_NAME, carve_validation
from scpformer.train.checkpoint import (
    BEST_NAME,
    CHECKPOINT_NAME,
    from_plain,
    manifest_digest,
    read_checkpoint,
    read_resumable,
    refuse_resume_without_checkpoint,
    save_epoch_checkpoints,
)
from scpformer.train.config import TrainConfig, train_config
from scpformer.train.loop import FitState, TensorData, fit, seed_everything
from scpformer.train.metrics import plot_losses, write_metrics
from scpformer.train.tscvx_metrics import (
    format_solution,
    format_tight,
    solution_metrics,
    tight_metrics,
    write_metrics_files,
)
from scpformer.validation import check_int, shown_as

NETWORKS = {"tight": TIGHT_KIND, "solution": SOLUTION_KIND}  # run sub-folder -> model kind
CV_NAME = "cv.json"
PLOT_EVERY = 10  # epochs between redrawings of loss.png (and the last epoch)

# Training values per preset. paper: Sec. III.E.3 (batch 128, 4000 warm-up steps, two
# epochs, K = 3); its learning rate is not given. small: measured here (see module docstring).
TSCVX_TRAIN_DEFAULTS: dict[str, dict[str, Any]] = {
    "paper": {"batch_size": 128, "accumulation": 1, "warmup_steps": 4000, "lr": 1e-4,
              "schedule": "constant"},
    "small": {"batch_size": 128, "accumulation": 1, "warmup_steps": 200, "lr": 1e-3,
              "schedule": "cosine"},
}  # fmt: skip
TSCVX_EPOCHS = {  # (f2, f1) epochs per preset; f1 sees ~1/iterations as many items per epoch
    "paper": (2, 2),
    "small": (4, 60),  # f2 reached its best validation loss at epoch 4 of 8 on the dev set
}
TSCVX_FOLDS = {"paper": 3, "small": 1}
# Weight of f1's thrust outputs in its MSE (SolutionObjective). paper: plain MSE. small:
# measured on 30 validation instances of a 1,408-instance dataset (9,792 samples, seed 4):
# cold SCvx from f1's guess took a mean of 9.93 solves with weight 1, 9.47 with 4 (fewer on
# 13 instances, more on 3) and 9.37 with 10 (against 4: fewer on 7, more on 7).
THRUST_WEIGHT = {"paper": 1.0, "small": 4.0}
# f1's warm-up: it takes ~1/iterations as many steps per epoch as f2 (small: a few per epoch
# on the dev set), so 200 steps would hold its learning rate low for most of the run.
SOLUTION_WARMUP = {"paper": 4000, "small": 50}


# ======================================================================================
# data
# ======================================================================================
@dataclass(frozen=True)
class TscvxArrays:
    """Raw arrays of solved samples (one row per sample), read once from the shards."""

    theta: np.ndarray  # (n, 16)
    x: np.ndarray  # (n, N, 14)
    u: np.ndarray  # (n, N, 3)
    tf: np.ndarray  # (n,)
    iterations: np.ndarray  # (n,) SCvx iterations with flags
    flags: np.ndarray  # (n, iter_max, R) bool; (n, 0, 0) when read without flags
    base_index: np.ndarray  # (n,) split group
    split: np.ndarray  # (n,) "train", "validation" or "test"

    def subset(self, mask: np.ndarray) -> TscvxArrays:
        return TscvxArrays(*(getattr(self, f.name)[mask] for f in dataclasses.fields(self)))

    def __len__(self) -> int:
        return len(self.tf)

    @property
    def iter_max(self) -> int:
        return self.flags.shape[1]

    @property
    def has_flags(self) -> bool:
        """Whether the tight flags were read (``read_tscvx(..., flags=True)``)."""
        return self.flags.shape[1] > 0

    def tight_items(self) -> tuple[np.ndarray, np.ndarray]:
        """(rows, k): one item per (sample, iteration k = 1..iterations), sample-major."""
        rows = np.repeat(np.arange(len(self)), self.iterations)
        starts = np.cumsum(self.iterations) - self.iterations
        k = np.arange(len(rows)) - np.repeat(starts, self.iterations) + 1
        return rows, k.astype(np.int64)


def read_tscvx(folder: Path | str, *, flags: bool = True) -> tuple[TscvxArrays, TscvxNormalization]:
    """Every solved sample of a split ``pdg6dof`` dataset, and its training statistics.

    ``flags=False`` skips the ``(iter_max, 7 N)`` tight flags of every sample, most of the
    dataset's bytes, for training the solution network alone.

    Raises
    ------
    DatasetError
        Not a ``pdg6dof`` dataset, no splits, or no solved sample.
    """
    view = SolutionDataset(folder, None, normalize=False)  # family, status and splits checks
    splits = load_splits(folder)
    positions = view.positions
    if len(positions) == 0:
        raise DatasetError(f"{folder} holds no solved sample")
    split = np.full(len(view.samples), "", dtype=object)
    for name, indices in splits.indices.items():
        split[indices] = name
    column = view.samples.column
    iter_max = view.samples.manifest.field("tight_flags").shape[0]
    iterations = np.minimum(column("iterations")[positions], iter_max)  # rows stored
    tight = column("tight_flags")[positions] if flags else np.zeros((len(positions), 0, 0), bool)
    arrays = TscvxArrays(
        theta=column("theta")[positions],
        x=column("x")[positions],
        u=column("u")[positions],
        tf=column("tf")[positions],
        iterations=iterations.astype(np.int64),
        flags=tight,
        base_index=column("base_index")[positions],
        split=split[positions].astype(str),
    )
    view.samples.close()
    return arrays, TscvxNormalization.from_splits(splits)


def tight_tensors(arrays: TscvxArrays, norm: TscvxNormalization) -> TensorData:
    """f2's items: ``theta`` (float32, standardized), ``k`` (int64), ``flags`` (uint8)."""
    rows, k = arrays.tight_items()
    flags = arrays.flags[rows, k - 1]  # (items, R)
    return TensorData({
        "theta": _float32(norm.encode_theta(arrays.theta)[rows]),
        "k": torch.from_numpy(k),
        "flags": torch.from_numpy(flags.astype(np.uint8)),
    })  # fmt: skip


def solution_tensors(arrays: TscvxArrays, norm: TscvxNormalization) -> TensorData:
    """f1's items: ``theta`` and ``target`` (standardized x, u, t_f), float32."""
    return TensorData({
        "theta": _float32(norm.encode_theta(arrays.theta)),
        "target": _float32(norm.encode_solution(arrays.x, arrays.u, arrays.tf, arrays.theta)),
    })  # fmt: skip


def _float32(value: np.ndarray) -> Tensor:
    return torch.from_numpy(np.ascontiguousarray(value, dtype=np.float32))


def fold_masks(
    arrays: TscvxArrays, folds: int, validation_fraction: float, seed: int
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(train, validation) sample masks per fold, grouped by base instance (module docstring)."""
    in_train, in_val = arrays.split == "train", arrays.split == "validation"
    if folds == 1:
        if in_val.any():
            return [(in_train, in_val)]
        keep, held = carve_validation(arrays.base_index[in_train], validation_fraction, seed)
        train, val = in_train.copy(), in_train.copy()
        train[in_train], val[in_train] = keep, held
        return [(train, val)]
    pool = in_train | in_val
    groups = np.unique(arrays.base_index[pool])
    if len(groups) < folds:
        raise DatasetError(f"{folds} folds need at least {folds} base instances, got {len(groups)}")
    chunks = np.array_split(np.random.default_rng(seed).permutation(groups), folds)
    out = []
    for chunk in chunks:
        val = pool & np.isin(arrays.base_index, chunk)
        out.append((pool & ~val, val))
    return out


# ======================================================================================
# training objectives (model(batch) -> (pred, loss) for the loop)
# ======================================================================================
class TightObjective(nn.Module):
    """f2 with its loss: BCE on the logits, tight rows weighted by ``pos_weight``."""

    def __init__(self, net: nn.Module, pos_weight: float) -> None:
        super().__init__()
        self.net = net
        self.register_buffer("pos_weight", torch.tensor(float(pos_weight)))

    def forward(self, batch: dict[str, Tensor]) -> tuple[Tensor, Tensor]:
        logits = self.net(batch["theta"], batch["k"])  # (B, R)
        loss = functional.binary_cross_entropy_with_logits(
            logits, batch["flags"].float(), pos_weight=self.pos_weight
        )
        return logits, loss


class SolutionObjective(nn.Module):
    """f1 with its loss: MSE of the standardized (x, u, t_f), the thrust's outputs weighted.

    ``thrust_weight`` multiplies the squared errors of the ``3 N`` thrust outputs (1: the
    paper's plain MSE); the loss is divided by the sum of the weights, so 1 gives the mean.
    """

    def __init__(self, net: nn.Module, n_nodes: int, thrust_weight: float = 1.0) -> None:
        super().__init__()
        self.net = net
        weights = torch.ones((STATE_DIM + CONTROL_DIM) * n_nodes + 1)
        weights[STATE_DIM * n_nodes : -1] = float(thrust_weight)
        self.register_buffer("weights", weights / weights.mean())

    def forward(self, batch: dict[str, Tensor]) -> tuple[Tensor, Tensor]:
        pred = self.net(batch["theta"])  # (B, 17 N + 1)
        return pred, ((pred - batch["target"]) ** 2 * self.weights).mean()


def positive_weight(flags: Tensor) -> float:
    """``(1 - p) / p`` with ``p`` the share of tight rows (1 when there are none or all)."""
    p = float(flags.float().mean()) if flags.numel() else 0.0
    return (1.0 - p) / p if 0.0 < p < 1.0 else 1.0


# ======================================================================================
# a run
# ======================================================================================
@dataclass(frozen=True, kw_only=True)
class NetworkResult:
    """What training one network did."""

    kind: str
    folder: Path
    states: tuple[FitState, ...]  # one per fold
    parameters: int
    seconds: float  # wall time of this launch's training (all folds, without evaluation)
    train_items: int  # of the delivered (last) fold
    validation_items: int


@dataclass(frozen=True, kw_only=True)
class TscvxRunResult:
    """What :func:`train_tscvx` did."""

    run: Path
    networks: dict[str, NetworkResult]
    metrics: dict[str, Any]  # evaluate_tscvx on ``report_split`` (empty if not main process)
    report_split: str
    world: distributed.World


def train_tscvx(
    *,
    data: Path | str,
    out: Path | str,
    preset_name: str = "small",
    networks: tuple[str, ...] = ("tight", "solution"),
    folds: int | None = None,
    overrides: dict[str, Any] | None = None,
    solution_epochs: int | None = None,
    model_overrides: dict[str, Any] | None = None,
    resume: bool = False,
    report_split: str = "validation",
    threads: int | None = None,
    progress: bool = True,
    canonical: bool = True,
    thrust_weight: float | None = None,
) -> TscvxRunResult:
    """Train (or resume) f2 and f1 on the ``pdg6dof`` dataset ``data`` into run folder ``out``.

    Parameters
    ----------
    data, out
        Split dataset folder and run folder.
    preset_name
        ``small`` or ``paper`` (networks, training values, epochs, folds).
    networks
        Which of ``tight`` and ``solution`` to train.
    folds
        K of the K-fold procedure (default: the preset's; 1 = one validation split).
    overrides
        :class:`TrainConfig` fields (None ignored); ``epochs`` is f2's.
    solution_epochs
        f1's epochs (default: the preset's).
    model_overrides
        Fields of both network configurations (e.g. ``{"tokens": "inputs"}``).
    resume
        Continue the networks' runs from their checkpoints (only epochs and device may change);
        ``ValueError`` when ``out`` holds nothing of them.
    report_split
        Split evaluated at the end (``validation`` or ``test``), written to RUN.
    threads
        torch threads (default: torch's). On a loaded shared machine one thread per process
        trains several times faster than two (threads wait for each other's cores).
    canonical
        Let both networks see every instance in its canonical frame and f1 predict the
        solution there (:class:`TscvxNormalization`, :mod:`scpformer.problems.pdg6dof.symmetry`);
        ``False``: the raw instance frame, as the paper. A resumed run keeps its own choice.
    thrust_weight
        Weight of f1's thrust outputs in its MSE (:class:`SolutionObjective`; default: the
        preset's, :data:`THRUST_WEIGHT`; 1: the paper's plain MSE). The thrust is the part
        of the predicted guess that limits T-SCvx.
        Measured with the shipped networks on 10 nominal instances (numpy seed 0), mean
        T-SCvx solves from: the prediction 8.0; the optimum with the predicted thrust 7.9;
        the prediction with the optimal thrust 5.5; the prediction with the optimal states
        7.9 or the optimal final time 8.0; the optimum 1.3.

    Raises
    ------
    ValueError
        Bad arguments, unusable data (``DatasetError``: also a ``report_split`` without a
        solved sample, checked before training), an existing run without ``resume``.
    """
    if preset_name not in TSCVX_PRESETS:
        raise ValueError(f"preset must be one of {tuple(TSCVX_PRESETS)}, got {preset_name!r}")
    unknown = sorted(set(networks) - set(NETWORKS))
    if unknown or not networks:
        raise ValueError(f"networks must be a non-empty subset of {tuple(NETWORKS)}")
    folds = TSCVX_FOLDS[preset_name] if folds is None else folds
    folds = check_int("folds", folds, least=1)
    if thrust_weight is None:
        thrust_weight = THRUST_WEIGHT[preset_name]
    if not (isinstance(thrust_weight, int | float) and 0.0 < thrust_weight < math.inf):
        raise ValueError(
            f"thrust_weight must be a positive number, got {shown_as(thrust_weight, int | float)}"
        )
    if report_split not in ("validation", "test"):
        raise ValueError(f"report_split must be validation or test, got {report_split!r}")
    if threads is not None:
        threads = check_int("threads", threads, least=1)
        torch.set_num_threads(threads)
    out, data = Path(out), Path(data)
    overrides = {k: v for k, v in (overrides or {}).items() if v is not None}
    epochs = TSCVX_EPOCHS[preset_name]
    configs = {
        "tight": train_config(preset_name, model_defaults=TSCVX_TRAIN_DEFAULTS,
                              **{"epochs": epochs[0], **overrides}),
        "solution": train_config(preset_name, model_defaults=TSCVX_TRAIN_DEFAULTS,
                                 **{"warmup_steps": SOLUTION_WARMUP[preset_name], **overrides,
                                    "epochs": solution_epochs or epochs[1]}),
    }  # fmt: skip
    _check_run_folder(out)
    for name in networks:
        _check_new_or_resume(out / name, resume)
    if resume and not any(path.is_file() for name in networks for path in (out / name).rglob("*")):
        where = "no such folder" if not out.exists() else f"nothing in {'/, '.join(networks)}/"
        raise ValueError(f"--resume: {out} holds no T-SCvx run to resume ({where}); leave out "
                         "--resume to start a new run")  # fmt: skip
    world, device = distributed.start(configs["tight"].device)
    try:
        arrays, norm = read_tscvx(data, flags="tight" in networks)
        others = [out / name / CHECKPOINT_NAME for name in NETWORKS if name not in networks]
        may_report = not others or any(path.is_file() for path in others)
        if may_report and not np.any(arrays.split == report_split):  # fail before training
            raise DatasetError(
                f"the {report_split} split of {data} holds no solved sample, and the run is "
                f"evaluated on it at the end: pass --report-split "
                f"{'test' if report_split == 'validation' else 'validation'}, or re-split the "
                "dataset (scpformer dataset split --fractions ... --force)"
            )
        if canonical:
            train = arrays.subset(arrays.split == "train")
            norm = TscvxNormalization.canonical_from_arrays(train.theta, train.x, train.u, train.tf)
        masks = fold_masks(arrays, folds, configs["tight"].validation_fraction,
                           configs["tight"].seed)  # fmt: skip
        for fold, (train_mask, val_mask) in enumerate(masks, start=1):  # all before training
            if not (train_mask.any() and val_mask.any()):
                raise DatasetError(f"fold {fold} of {data} has {int(train_mask.sum())} training "
                                   f"and {int(val_mask.sum())} validation samples")  # fmt: skip
        context = _RunContext(data=data, arrays=arrays, norm=norm, masks=masks,
                              preset=preset_name, model_overrides=dict(model_overrides or {}),
                              thrust_weight=float(thrust_weight),
                              world=world, device=device, progress=progress)  # fmt: skip
        results = {name: _train_network(context, name, out / name, configs[name], resume)
                   for name in networks}  # fmt: skip
        if world.is_main:
            _write_run_config(out, context, results, configs)
        distributed.barrier(world)
        metrics = {}
        if world.is_main and all(_finished(out / name) for name in NETWORKS):
            read = (arrays, norm) if arrays.has_flags else None
            metrics = evaluate_tscvx(out, data, split=report_split, arrays=read)
        return TscvxRunResult(run=out, networks=results, metrics=metrics,
                              report_split=report_split, world=world)  # fmt: skip
    finally:
        distributed.stop(world)


@dataclass(frozen=True, kw_only=True)
class _RunContext:
    data: Path
    arrays: TscvxArrays
    norm: TscvxNormalization
    masks: list[tuple[np.ndarray, np.ndarray]]
    preset: str
    model_overrides: dict[str, Any]
    world: distributed.World
    device: torch.device
    progress: bool
    thrust_weight: float = 1.0


RUN_ENTRIES = (CONFIG_NAME, *NETWORKS, "MODEL_CARD.md", "metrics_*.json", "tight_*.csv")


def _check_run_folder(out: Path) -> None:
    """Refuse an ``out`` that holds files of something else than a T-SCvx run (a dataset, an
    experiment): training would write its networks among them. A run of the other network
    (``--networks tight`` and ``--networks solution`` side by side) is welcome."""
    if not out.is_dir():
        return
    strangers = sorted(
        entry.name
        for entry in out.iterdir()
        if not entry.name.startswith(".") and not any(entry.match(p) for p in RUN_ENTRIES)
    )
    if strangers:
        raise ValueError(
            f"--out {out} holds files that are not a T-SCvx run's ({', '.join(strangers[:3])}"
            f"{', ...' if len(strangers) > 3 else ''}); choose an empty or new folder"
        )


def _check_new_or_resume(folder: Path, resume: bool) -> None:
    """Refuse to overwrite a network's run (or one of its folds) without ``resume``."""
    if not resume and folder.is_dir() and any(folder.rglob(CHECKPOINT_NAME)):
        raise ValueError(
            f"{folder} already holds a training run: pass --resume to continue it, or another --out"
        )


def _finished(folder: Path) -> bool:
    """Whether the network in ``folder`` has run all its epochs (another launch may still be
    training it: ``--networks tight`` and ``--networks solution`` side by side). A packaged
    (weights-only) network, e.g. a shipped pretrained one copied in, is a trained one."""
    if not (folder / CHECKPOINT_NAME).is_file():
        return False
    payload = read_checkpoint(folder)
    train_config = from_plain(payload.get("extra") or {}).get("train_config")
    if train_config is None:
        return True
    return int(payload["metrics"]["epoch"]) >= int(train_config["epochs"])


def _fold_folder(folder: Path, fold: int, folds: int) -> Path:
    return folder if folds == 1 else folder / f"fold{fold}"


def _train_network(
    ctx: _RunContext, name: str, folder: Path, config: TrainConfig, resume: bool
) -> NetworkResult:
    """Every fold of one network; the last fold's checkpoint becomes ``folder``'s."""
    kind = NETWORKS[name]
    start = time.perf_counter()
    states, model_config, sizes = [], None, (0, 0)
    for fold, (train_mask, val_mask) in enumerate(ctx.masks, start=1):
        fold_dir = _fold_folder(folder, fold, len(ctx.masks))
        tensors = tight_tensors if name == "tight" else solution_tensors
        train = tensors(ctx.arrays.subset(train_mask), ctx.norm)
        validation = tensors(ctx.arrays.subset(val_mask), ctx.norm)
        if len(train) == 0 or len(validation) == 0:
            raise DatasetError(f"fold {fold} has {len(train)} training and {len(validation)} "
                               "validation items")  # fmt: skip
        state, model_config = _fit_fold(ctx, kind, fold_dir, config, train, validation, resume)
        states.append(state)
        sizes = (len(train), len(validation))
    if len(ctx.masks) > 1 and ctx.world.is_main:
        shutil.copyfile(fold_dir / CHECKPOINT_NAME, folder / CHECKPOINT_NAME)
        shutil.copyfile(fold_dir / BEST_NAME, folder / BEST_NAME)
        losses = [s.best_val_loss for s in states]
        cv = {"folds": len(states), "best_val_loss": losses, "mean": float(np.mean(losses)),
              "std": float(np.std(losses)), "delivered": f"fold{len(states)}"}  # fmt: skip
        write_text_atomic(folder / CV_NAME, json.dumps(cv, indent=2) + "\n")
    return NetworkResult(
        kind=kind,
        folder=folder,
        states=tuple(states),
        parameters=sum(p.numel() for p in build_model(kind, model_config).parameters()),
        seconds=time.perf_counter() - start,
        train_items=sizes[0],
        validation_items=sizes[1],
    )


def _fit_fold(
    ctx: _RunContext,
    kind: str,
    folder: Path,
    config: TrainConfig,
    train: TensorData,
    validation: TensorData,
    resume: bool,
) -> tuple[FitState, Any]:
    """Train one network on one fold in ``folder`` (resuming its checkpoint when asked)."""
    previous = None
    if resume:
        refuse_resume_without_checkpoint(folder)
    if resume and (folder / CHECKPOINT_NAME).is_file():
        previous = read_resumable(folder, kind=kind, family=FAMILY)
        config = _resumed_config(previous, ctx.preset, config)
    seed_everything(config.seed)
    if previous is not None:
        model_config = config_from_dict(kind, from_plain(previous["config"]))
    else:
        model_config = _model_config(kind, ctx)
    net = build_model(kind, model_config)
    if previous is not None:
        net.load_state_dict(previous["state_dict"])
        if previous["extra"]["fit"]["epoch"] >= config.epochs:  # finished fold: keep it
            return FitState.from_dict(previous["extra"]["fit"]), model_config
    pos_weight = positive_weight(train.tensors["flags"]) if kind == TIGHT_KIND else None
    if kind == TIGHT_KIND:
        objective: nn.Module = TightObjective(net, pos_weight)
    else:
        objective = SolutionObjective(net, model_config.n_nodes, ctx.thrust_weight)
    digest = manifest_digest(ctx.data)
    splits_digest = file_sha256(ctx.data / SPLITS_NAME)
    if previous is not None and previous["extra"].get("splits_digest") != splits_digest:
        raise ValueError(f"{folder} was trained on other data or splits than {ctx.data}")
    stored_weight = None if previous is None else previous["extra"].get("thrust_weight", 1.0)
    if kind == SOLUTION_KIND and stored_weight not in (None, ctx.thrust_weight):
        raise ValueError(
            f"{folder} was trained with --thrust-weight {stored_weight:g}: resume it with that"
        )
    if previous is not None and _stored_canonical(previous) != ctx.norm.canonical:
        raise ValueError(
            f"{folder} was trained with canonical = {_stored_canonical(previous)}: resume it "
            f"with {'--canonical' if _stored_canonical(previous) else '--no-canonical'}"
        )
    torch.manual_seed(config.seed + ctx.world.rank)
    if ctx.world.is_main:
        folder.mkdir(parents=True, exist_ok=True)

    def save(state: FitState, training_state: dict[str, Any]) -> None:
        if not ctx.world.is_main:
            return
        extra = training_state | {
            "preset": ctx.preset,
            "train_config": config.to_dict(),
            "splits_digest": splits_digest,
            "pos_weight": pos_weight,
            "thrust_weight": ctx.thrust_weight if kind == SOLUTION_KIND else None,
        }
        fields = dict(model=net, kind=kind, config=model_config, normalization=ctx.norm,
                      frame=None, family=FAMILY, manifest_digest=digest, seed=config.seed,
                      metrics=state.metrics(), n_steps=model_config.n_nodes)  # fmt: skip
        save_epoch_checkpoints(folder, fields, extra, state.improved)
        write_metrics(folder, state.history)
        if state.epoch % PLOT_EVERY == 0 or state.epoch == config.epochs:  # f1: many short epochs
            plot_losses(folder, state.history, title=f"{kind} ({ctx.preset})")

    resume_state = None if previous is None else previous["extra"]
    state = fit(objective, train, validation, config, device=ctx.device, world=ctx.world,
                resume=resume_state, on_epoch=save, progress=ctx.progress)  # fmt: skip
    return state, model_config


def _stored_canonical(previous: dict[str, Any]) -> bool:
    """Whether a stored checkpoint's networks see canonical-frame instances."""
    return bool(from_plain(previous.get("normalization") or {}).get("canonical", False))


def _resumed_config(previous: dict[str, Any], preset_name: str, config: TrainConfig) -> TrainConfig:
    """The stored training configuration with this launch's epochs and device."""
    stored_preset = previous["extra"]["preset"]
    if stored_preset != preset_name:
        raise ValueError(f"the run to resume used preset {stored_preset!r}, not {preset_name!r}")
    stored = TrainConfig.from_dict(previous["extra"]["train_config"])
    return dataclasses.replace(stored, epochs=config.epochs, device=config.device)


def _model_config(kind: str, ctx: _RunContext) -> Any:
    """The preset's configuration with the dataset's N (and iter_max for f2)."""
    changes = dict(ctx.model_overrides) | {"n_nodes": ctx.norm.n_nodes}
    if kind == TIGHT_KIND:
        changes["iter_max"] = ctx.arrays.iter_max
    return preset(kind, ctx.preset, **changes)


def _write_run_config(
    out: Path, ctx: _RunContext, results: dict[str, NetworkResult], configs: dict[str, Any]
) -> None:
    """Write ``out/config.json``; entries of networks trained by another launch into the same
    run (``--networks tight`` and ``--networks solution`` side by side) are kept."""
    path = out / CONFIG_NAME
    earlier = json.loads(path.read_text()).get("networks", {}) if path.is_file() else {}
    networks = {
        name: {
            "kind": r.kind,
            "parameters": r.parameters,
            "train_items": r.train_items,
            "validation_items": r.validation_items,
            "train_seconds_this_launch": r.seconds,
            "best_val_loss": [s.best_val_loss for s in r.states],
            "train": configs[name].to_dict(),
        }
        for name, r in results.items()
    }
    description = {
        "preset": ctx.preset,
        "data": str(ctx.data.resolve()),
        "family": FAMILY,
        "manifest_digest": manifest_digest(ctx.data),
        "splits_digest": file_sha256(ctx.data / SPLITS_NAME),
        "folds": len(ctx.masks),
        "canonical": ctx.norm.canonical,
        "thrust_weight": ctx.thrust_weight,
        "samples": {s: int(np.sum(ctx.arrays.split == s)) for s in SPLIT_NAMES},
        "networks": earlier | networks,
        "device": str(ctx.device),
        "world_size": ctx.world.size,
        "package_version": __version__,
    }
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, json.dumps(description, indent=2, default=str) + "\n")


# ======================================================================================
# evaluation
# ======================================================================================
def evaluate_tscvx(
    run: Path | str,
    data: Path | str,
    *,
    split: str = "test",
    threshold: float = 0.5,
    checkpoint: str = "best",
    batch: int = 4096,
    arrays: tuple[TscvxArrays, TscvxNormalization] | None = None,
) -> dict[str, Any]:
    """Metrics of run ``run``'s networks on ``split`` of ``data`` (see tscvx_metrics).

    The networks are ``checkpoint`` (``best`` or ``last``, see :func:`load_tscvx_predictor`).
    Writes ``run/metrics_<split>.json`` and ``run/tight_<split>.csv`` (with a suffix
    ``_<checkpoint>_t<threshold>`` unless ``best`` at 0.5) and returns
    ``{"tight": ..., "solution": ..., "split": ..., "threshold": ..., "checkpoint": ...}``.
    """
    if split not in SPLIT_NAMES:
        raise ValueError(f"split must be one of {SPLIT_NAMES}, got {split!r}")
    run = Path(run)
    arrays, _ = read_tscvx(data) if arrays is None else arrays
    if not arrays.has_flags:
        raise ValueError("evaluate_tscvx needs arrays read with their tight flags")
    predictor = load_tscvx_predictor(run, threshold=threshold, checkpoint=checkpoint)
    chosen = arrays.subset(arrays.split == split)
    if len(chosen) == 0:
        raise DatasetError(f"the {split} split of {data} holds no solved sample")
    rows, k = chosen.tight_items()
    truth = chosen.flags[rows, k - 1]
    predicted = np.concatenate([
        predictor.predict_tight(chosen.theta[rows[a : a + batch]], k[a : a + batch])
        for a in range(0, len(rows), batch)
    ])  # fmt: skip
    norm = predictor.normalization
    x, u, tf = predictor.predict_solution(chosen.theta)
    metrics = {
        "split": split,
        "threshold": threshold,
        "checkpoint": checkpoint,
        "tight": tight_metrics(truth, predicted),
        "solution": solution_metrics(
            norm.encode_solution(x, u, tf, chosen.theta),
            norm.encode_solution(chosen.x, chosen.u, chosen.tf, chosen.theta),
            (x, u, tf),
            (chosen.x, chosen.u, chosen.tf),
        ),
    }
    tag = "" if threshold == 0.5 and checkpoint == "best" else f"_{checkpoint}_t{threshold:g}"
    write_metrics_files(run, split, metrics, tag)
    return metrics


def format_metrics(metrics: dict[str, Any]) -> str:
    """Printable summary of :func:`evaluate_tscvx`'s result."""
    lines = [
        f"on the {metrics['split']} split ({metrics['checkpoint']} checkpoints, threshold "
        f"{metrics['threshold']}):"
    ]
    return "\n".join(lines + format_tight(metrics["tight"]) + format_solution(metrics["solution"]))
