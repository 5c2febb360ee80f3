"""Device choice and the process group of a ``torchrun`` launch (DistributedDataParallel).

``torchrun --nproc_per_node P ... scpformer train ...`` starts P processes with ``RANK``,
``LOCAL_RANK`` and ``WORLD_SIZE`` set; :func:`start` joins them in one process group (NCCL on
CUDA, gloo on CPU). A plain launch is a world of one and needs no process group.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import torch
import torch.distributed as dist


@dataclass(frozen=True, kw_only=True)
class World:
    """This process's place among the training processes."""

    rank: int = 0  # global rank (0 writes every file)
    size: int = 1  # number of processes
    local_rank: int = 0  # rank on this node (selects the GPU)

    @property
    def is_main(self) -> bool:
        return self.rank == 0


def select_device(choice: str, world: World) -> torch.device:
    """``cpu``, ``cuda`` (this process's GPU) or ``auto`` (cuda when available)."""
    if choice == "auto":
        choice = "cuda" if torch.cuda.is_available() else "cpu"
    if choice == "cuda":
        if not torch.cuda.is_available():
            raise ValueError("device 'cuda' was asked for but torch sees no CUDA device")
        return torch.device("cuda", world.local_rank % torch.cuda.device_count())
    if choice != "cpu":
        raise ValueError(f"device must be auto, cpu or cuda, got {choice!r}")
    return torch.device("cpu")


def start(device_choice: str) -> tuple[World, torch.device]:
    """Join the ``torchrun`` process group if there is one; this process's world and device."""
    size = int(os.environ.get("WORLD_SIZE", "1"))
    world = World(
        rank=int(os.environ.get("RANK", "0")),
        size=size,
        local_rank=int(os.environ.get("LOCAL_RANK", "0")),
    )
    device = select_device(device_choice, world)
    if size > 1 and not dist.is_initialized():
        if device.type == "cuda":
            torch.cuda.set_device(device)
        dist.init_process_group(backend="nccl" if device.type == "cuda" else "gloo")
    return world, device


def stop(world: World) -> None:
    """Leave the process group (no-op for a world of one)."""
    if world.size > 1 and dist.is_initialized():
        dist.destroy_process_group()


def all_sum(values: list[float], world: World, device: torch.device) -> list[float]:
    """Element-wise sum of ``values`` over every process."""
    if world.size == 1:
        return values
    tensor = torch.tensor(values, dtype=torch.float64, device=device)
    dist.all_reduce(tensor, op=dist.ReduceOp.SUM)
    return tensor.tolist()


def barrier(world: World) -> None:
    """Wait for every process (no-op for a world of one)."""
    if world.size > 1:
        dist.barrier()
