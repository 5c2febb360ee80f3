"""One training loop for every model whose forward is ``model(batch) -> (pred, loss)``.

The data are in memory (:class:`TensorData`): tensors already normalized and on the device,
so an epoch spends almost nothing loading (one gather per epoch). Each epoch:

1. the training indices of this process come from a ``DistributedSampler`` (a world of one
   outside ``torchrun``), shuffled by a generator seeded with (seed, epoch) -- the batch order
   is a function of the seed and the epoch alone, which makes ``--resume`` exact;
2. the epoch's samples are gathered once in that order, and micro-batches of ``batch_size``
   (contiguous slices of it) are grouped by ``accumulation``; the loss of a group is the
   sample-weighted mean of its micro-batches' losses, back-propagated (gradients synchronized
   by DDP on the group's last micro-batch only), clipped to ``grad_clip`` in global norm, and
   applied by AdamW; the learning rate follows :func:`lr_factor` per optimizer step;
3. the validation loss is the sample-weighted mean over the validation set in eval mode;
4. ``on_epoch`` receives the updated :class:`FitState` and the training state to checkpoint.
"""

from __future__ import annotations

import dataclasses
import math
import random
import time
from collections.abc import Callable, Mapping
from contextlib import nullcontext
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn
from torch.utils.data import DistributedSampler
from tqdm import tqdm

from scpformer.train.config import TrainConfig
from scpformer.train.distributed import World, all_sum
from scpformer.train.metrics import EpochRecord


@dataclass(frozen=True)
class TensorData:
    """Equal-length tensors (first dimension = samples), batched by indexing."""

    tensors: dict[str, Tensor]

    def __post_init__(self) -> None:
        lengths = {name: len(value) for name, value in self.tensors.items()}
        if len(set(lengths.values())) > 1:
            raise ValueError(f"tensors must have one length, got {lengths}")

    def __len__(self) -> int:
        return len(next(iter(self.tensors.values()))) if self.tensors else 0

    def batch(self, index: Tensor) -> dict[str, Tensor]:
        """The samples at ``index`` (a gather: copies)."""
        return {name: value[index] for name, value in self.tensors.items()}

    def slice(self, start: int, stop: int) -> dict[str, Tensor]:
        """Samples ``start:stop`` (views: no copy)."""
        return {name: value[start:stop] for name, value in self.tensors.items()}

    def to(self, device: torch.device) -> TensorData:
        return TensorData({name: value.to(device) for name, value in self.tensors.items()})


@dataclass(frozen=True, kw_only=True)
class FitState:
    """Progress of a run: finished epochs and their records, best validation loss."""

    epoch: int = 0  # epochs finished
    history: tuple[EpochRecord, ...] = ()
    best_val_loss: float = math.inf
    best_epoch: int = 0

    def after(self, record: EpochRecord) -> FitState:
        better = record.val_loss < self.best_val_loss
        return dataclasses.replace(
            self,
            epoch=record.epoch,
            history=(*self.history, record),
            best_val_loss=record.val_loss if better else self.best_val_loss,
            best_epoch=record.epoch if better else self.best_epoch,
        )

    @property
    def improved(self) -> bool:
        """Whether the last epoch set the best validation loss."""
        return self.epoch > 0 and self.best_epoch == self.epoch

    def metrics(self) -> dict[str, Any]:
        last = self.history[-1] if self.history else None
        return {
            "epoch": self.epoch,
            "best_val_loss": self.best_val_loss,
            "best_epoch": self.best_epoch,
            "val_loss": last.val_loss if last else math.nan,
            "train_loss": last.train_loss if last else math.nan,
        }

    def to_dict(self) -> dict[str, Any]:
        return self.metrics() | {"history": [r.to_dict() for r in self.history]}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> FitState:
        return cls(
            epoch=int(data["epoch"]),
            history=tuple(EpochRecord.from_dict(r) for r in data["history"]),
            best_val_loss=float(data["best_val_loss"]),
            best_epoch=int(data["best_epoch"]),
        )


EpochCallback = Callable[[FitState, dict[str, Any]], None]


def lr_factor(step: int, config: TrainConfig, total_steps: int) -> float:
    """Learning-rate multiplier of optimizer step ``step`` (0-based).

    Linear warm-up ``(step + 1) / warmup_steps`` for the first ``warmup_steps`` steps, then 1
    (``constant``, ART Table 4: no decay) or a cosine from 1 down to ``min_lr_ratio`` at
    ``total_steps`` (``cosine``).
    """
    if step < config.warmup_steps:
        return (step + 1) / config.warmup_steps
    if config.schedule == "constant":
        return 1.0
    progress = min(1.0, (step - config.warmup_steps) / max(1, total_steps - config.warmup_steps))
    floor = config.min_lr_ratio
    return floor + (1.0 - floor) * 0.5 * (1.0 + math.cos(math.pi * progress))


def seed_everything(seed: int) -> None:
    """Seed python, numpy's legacy global generator (for code that uses it) and torch."""
    random.seed(seed)
    np.random.seed(seed % 2**32)  # noqa: NPY002
    torch.manual_seed(seed)


def rng_state() -> dict[str, Any]:
    """The python, numpy and torch (CPU and CUDA) random states."""
    state = {
        "python": random.getstate(),
        "numpy": np.random.get_state(legacy=False),  # noqa: NPY002
        "torch": torch.get_rng_state(),
    }
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def set_rng_state(state: Mapping[str, Any]) -> None:
    """Inverse of :func:`rng_state`."""
    version, internal, gauss = state["python"]
    random.setstate((version, tuple(internal), gauss))
    np.random.set_state(state["numpy"])  # noqa: NPY002
    torch.set_rng_state(state["torch"])
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


def fit(
    model: nn.Module,
    train: TensorData,
    validation: TensorData,
    config: TrainConfig,
    *,
    device: torch.device | str = "cpu",
    world: World | None = None,
    resume: Mapping[str, Any] | None = None,
    on_epoch: EpochCallback | None = None,
    progress: bool = True,
) -> FitState:
    """Train ``model`` on ``train`` for ``config.epochs`` epochs, validating on ``validation``.

    Parameters
    ----------
    model
        ``model(batch) -> (pred, loss)`` with ``batch`` a dict of ``train``'s tensors.
    train, validation
        In-memory data; moved to ``device`` here.
    config
        Optimizer, schedule and batching.
    device, world
        Where this process trains, and its place in a ``torchrun`` launch (default: alone).
    resume
        A training state given earlier to ``on_epoch`` (from a checkpoint's ``extra``): the
        run continues after its epoch with its optimizer, schedule and random states.
    on_epoch
        Called by every process after every epoch with the :class:`FitState` and the training
        state (``optimizer``, ``scheduler``, ``rng``, ``fit``) to store for ``resume``.
    progress
        Show a progress bar (process 0 only).

    Returns
    -------
    FitState
        Every epoch's record and the best validation loss.
    """
    world = world or World()
    device = torch.device(device)
    if len(validation) == 0 or len(train) == 0:
        raise ValueError(f"training needs samples: {len(train)} train, {len(validation)} val")
    model.to(device)
    train, validation = train.to(device), validation.to(device)
    trained = _wrap(model, world, device)
    optimizer = torch.optim.AdamW(
        model.parameters(), lr=config.lr, betas=config.betas, weight_decay=config.weight_decay
    )
    sampler = DistributedSampler(
        range(len(train)), num_replicas=world.size, rank=world.rank, seed=config.seed
    )
    steps_per_epoch = math.ceil(math.ceil(len(sampler) / config.batch_size) / config.accumulation)
    total = steps_per_epoch * config.epochs
    scheduler = torch.optim.lr_scheduler.LambdaLR(
        optimizer, lambda step: lr_factor(step, config, total)
    )
    state = FitState()
    if resume is not None:
        optimizer.load_state_dict(resume["optimizer"])
        scheduler.load_state_dict(resume["scheduler"])
        set_rng_state(resume["rng"])
        state = FitState.from_dict(resume["fit"])
    for epoch in range(state.epoch + 1, config.epochs + 1):
        sampler.set_epoch(epoch)
        start = time.perf_counter()
        loss, loading_s, train_s, samples = _train_epoch(
            trained, model, optimizer, scheduler, train, list(sampler), config, world, device,
            progress=progress and world.is_main, label=f"epoch {epoch}/{config.epochs}",
        )  # fmt: skip
        val_loss, val_loading_s = evaluate(model, validation, config, world, device)
        seconds = time.perf_counter() - start
        record = EpochRecord(
            epoch=epoch,
            train_loss=loss,
            val_loss=val_loss,
            lr=optimizer.param_groups[0]["lr"],
            seconds=seconds,
            samples_per_s=samples / train_s,
            loading_share=(loading_s + val_loading_s) / seconds,
        )
        state = state.after(record)
        if on_epoch is not None:
            training_state = {
                "optimizer": optimizer.state_dict(),
                "scheduler": scheduler.state_dict(),
                "rng": rng_state(),
                "fit": state.to_dict(),
            }
            on_epoch(state, training_state)
    return state


def _wrap(model: nn.Module, world: World, device: torch.device) -> nn.Module:
    if world.size == 1:
        return model
    from torch.nn.parallel import DistributedDataParallel

    ids = [device.index] if device.type == "cuda" else None
    return DistributedDataParallel(model, device_ids=ids)


def _train_epoch(
    trained: nn.Module,
    model: nn.Module,
    optimizer: torch.optim.Optimizer,
    scheduler: torch.optim.lr_scheduler.LRScheduler,
    data: TensorData,
    indices: list[int],
    config: TrainConfig,
    world: World,
    device: torch.device,
    *,
    progress: bool,
    label: str,
) -> tuple[float, float, float, float]:
    """One pass: (mean loss, seconds loading, seconds training, samples over all processes).

    The epoch's samples are gathered once in their shuffled order; micro-batches are then
    contiguous slices of it (views).
    """
    trained.train()
    start = time.perf_counter()
    shuffled = TensorData(data.batch(torch.tensor(indices, dtype=torch.int64, device=device)))
    loading_s = time.perf_counter() - start
    n, size, accumulation = len(indices), config.batch_size, config.accumulation
    bounds = [(a, min(a + size, n)) for a in range(0, n, size)]  # micro-batches
    groups = [bounds[i : i + accumulation] for i in range(0, len(bounds), accumulation)]
    loss_sum, count = 0.0, 0
    bar = tqdm(total=len(indices), desc=label, disable=not progress, leave=False, unit="seq",
               mininterval=1.0)  # fmt: skip
    for group in groups:
        group_size = group[-1][1] - group[0][0]
        for j, (a, b) in enumerate(group):
            fetched = time.perf_counter()
            batch = shuffled.slice(a, b)
            loading_s += time.perf_counter() - fetched
            last = j == len(group) - 1
            sync = nullcontext() if last or world.size == 1 else trained.no_sync()
            with sync:
                _, loss = trained(batch)
                (loss * ((b - a) / group_size)).backward()
            loss_sum += loss.item() * (b - a)
            count += b - a
            bar.update(b - a)
        if config.grad_clip > 0:
            nn.utils.clip_grad_norm_(model.parameters(), config.grad_clip)
        optimizer.step()
        scheduler.step()
        optimizer.zero_grad(set_to_none=True)
        bar.set_postfix(loss=f"{loss_sum / count:.4g}", refresh=False)
    bar.close()
    train_s = time.perf_counter() - start
    loss_sum, count = all_sum([loss_sum, float(count)], world, device)
    return loss_sum / count, loading_s, train_s, count


@torch.no_grad()
def evaluate(
    model: nn.Module, data: TensorData, config: TrainConfig, world: World, device: torch.device
) -> tuple[float, float]:
    """Mean loss over ``data`` in eval mode, shared out over the processes; and seconds loading.

    Runs the unwrapped model (no DDP collectives), so processes may hold unequal shares; each
    takes one contiguous share, in batches of ``batch_size * accumulation``.
    """
    model.eval()
    share = -(-len(data) // world.size)
    first, end = world.rank * share, min((world.rank + 1) * share, len(data))
    step = config.batch_size * config.accumulation
    loss_sum, count, loading_s = 0.0, 0, 0.0
    for a in range(first, end, step):
        b = min(a + step, end)
        fetched = time.perf_counter()
        batch = data.slice(a, b)
        loading_s += time.perf_counter() - fetched
        _, loss = model(batch)
        loss_sum += loss.item() * (b - a)
        count += b - a
    loss_sum, count = all_sum([loss_sum, float(count)], world, device)
    return loss_sum / count, loading_s
