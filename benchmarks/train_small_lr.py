"""Learning-rate sweep of the ``small`` training preset: same data, budget and seed.

Trains each model kind's ``small`` preset on a subset of a split rendezvous dataset for a few
epochs at each learning rate (warm-up then cosine, as the preset) and prints the validation
loss per epoch, so that the preset's ``lr`` is chosen by measurement. Needs scpformer.models.

    python benchmarks/train_small_lr.py DATA [--kind art] [--train 1000] [--val 300]
        [--epochs 4] [--lrs 3e-4 1e-3 3e-3]
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import torch

from scpformer.train.art import load_art_data
from scpformer.train.config import train_config
from scpformer.train.loop import TensorData, fit
from scpformer.train.models_api import default_models


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data")
    parser.add_argument("--kind", default="art")
    parser.add_argument("--train", type=int, default=1000, help="training sequences used")
    parser.add_argument("--val", type=int, default=300, help="validation sequences used")
    parser.add_argument("--epochs", type=int, default=4)
    parser.add_argument("--lrs", type=float, nargs="+", default=[3e-4, 1e-3, 3e-3])
    args = parser.parse_args()
    api = default_models()
    data = load_art_data(args.data, frame="rtn", normalization_type=api.ArtNormalization,
                         validation_fraction=0.1, seed=0)  # fmt: skip
    train = TensorData(data.train.slice(0, args.train))
    val = TensorData(data.validation.slice(0, args.val))
    model_config = api.preset(args.kind, "small", context=data.n_steps)
    base = train_config("small", model_defaults=api.TRAIN_DEFAULTS, device="cpu")
    steps = args.epochs * -(-len(train) // base.batch_size)
    print(f"{args.kind} small, {len(train)} train / {len(val)} val sequences, {steps} steps")
    for lr in args.lrs:
        config = dataclasses.replace(base, lr=lr, epochs=args.epochs, warmup_steps=steps // 10)
        torch.manual_seed(0)
        model = api.build_model(args.kind, model_config)
        start = time.perf_counter()
        state = fit(model, train, val, config, progress=False)
        losses = " ".join(f"{r.val_loss:.4f}" for r in state.history)
        print(f"lr {lr:g}: val loss per epoch {losses} ({time.perf_counter() - start:.0f} s)")


if __name__ == "__main__":
    main()
