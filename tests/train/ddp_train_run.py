"""Run by ``torchrun`` in test_train_ddp.py: train the stand-in model, save each rank's weights.

Usage: ``torchrun --standalone --nproc_per_node 2 ddp_train_run.py DATA RUN EPOCHS``.
"""

import sys
from pathlib import Path

import torch
import torch.distributed as dist
from train_standins import STANDIN_MODELS

from scpformer.train import art


def main() -> None:
    data, out, epochs = Path(sys.argv[1]), Path(sys.argv[2]), int(sys.argv[3])
    weights = {}
    build = STANDIN_MODELS.build_model

    def build_and_keep(kind, config):
        weights["model"] = build(kind, config)
        return weights["model"]

    STANDIN_MODELS.build_model = build_and_keep
    overrides = {"epochs": epochs, "batch_size": 4, "lr": 1e-2, "device": "cpu"}
    art.train_sequence_model(
        "art", data=data, out=out, models=STANDIN_MODELS, overrides=overrides, progress=False
    )
    rank = int(__import__("os").environ["RANK"])
    torch.save(weights["model"].state_dict(), out / f"rank{rank}.pt")
    assert not dist.is_initialized()  # the run left the process group


if __name__ == "__main__":
    main()
