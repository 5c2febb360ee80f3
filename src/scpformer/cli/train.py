"""``scpformer train art|gru|lstm``: train a sequence model on a rendezvous dataset.

Under ``torchrun --nproc_per_node P -m scpformer.cli.main train ...`` the same command trains
with DistributedDataParallel over P processes (process 0 writes the run folder).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from scpformer.cli.commands import command_help
from scpformer.cli.dataclass_args import add_dataclass_arguments, overrides
from scpformer.train.config import TRAIN_PRESETS, TrainConfig

SEQUENCE_MODELS = ("art", "gru", "lstm")
_HELP = {
    "art": "the Autonomous Rendezvous Transformer (ART paper Sec. 3, Table 4)",
    "gru": "the GRU baseline over the same token sequence (ART paper Table 2)",
    "lstm": "the LSTM baseline over the same token sequence (ART paper Table 2)",
}


def add_train_parser(commands: argparse._SubParsersAction) -> None:
    """Register ``train MODEL`` on the top-level subparsers."""
    train = commands.add_parser("train", help=command_help("", "train"))
    models = train.add_subparsers(dest="model", required=True, metavar="MODEL")
    for kind in SEQUENCE_MODELS:
        parser = models.add_parser(kind, help=_HELP[kind], description=_HELP[kind])
        add_sequence_arguments(parser)
        parser.set_defaults(handler=run_train, kind=kind)


def add_sequence_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags of ``train art|gru|lstm``: data, run folder, presets and every TrainConfig field."""
    parser.add_argument("--data", type=Path, required=True, help="dataset folder (split)")
    parser.add_argument("--out", type=Path, required=True, help="run folder RUN")
    parser.add_argument(
        "--preset",
        choices=tuple(TRAIN_PRESETS),
        default=None,
        help="model and training preset: 'paper' (Table 4) or 'small' (two CPU cores) "
        "(default: small; a resumed run keeps its own)",
    )
    parser.add_argument(
        "--frame",
        choices=("rtn", "roe"),
        default=None,
        help="state frame of the sequences (default: rtn; a resumed run keeps its own)",
    )
    parser.add_argument(
        "--resume", action="store_true", help="continue the run in --out from its checkpoint"
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_dataclass_arguments(
        parser, TrainConfig, title="training (default: the preset's values; paper values shown)"
    )


def run_train(args: argparse.Namespace) -> int:
    from scpformer.train.art import train_sequence_model

    result = train_sequence_model(
        args.kind,
        data=args.data,
        out=args.out,
        preset=args.preset,
        frame=args.frame,
        overrides=overrides(args, TrainConfig),
        resume=args.resume,
        progress=not args.no_progress,
    )
    if result.world.is_main:
        print(summary(result))
    return 0


def summary(result) -> str:
    """A few lines on what a run did."""
    state, data = result.state, result.data
    lines = [
        f"{result.run}: {state.epoch} epoch(s) of {result.train_config.epochs}"
        + (f" (resumed after epoch {result.resumed_from})" if result.resumed_from else ""),
        f"data: {len(data.train)} training / {len(data.validation)} validation sequences "
        f"({data.train_instances} / {data.validation_instances} instances), read in "
        f"{data.read_seconds:.2f} s; validation: {data.validation_source}",
    ]
    new = state.history[result.resumed_from :]
    if new:
        last = new[-1]
        seconds = sorted(r.seconds for r in new)[len(new) // 2]
        speed = sorted(r.samples_per_s for r in new)[len(new) // 2]
        loading = sorted(r.loading_share for r in new)[len(new) // 2]
        lines += [
            f"loss: train {last.train_loss:.4g}, validation {last.val_loss:.4g} "
            f"(best {state.best_val_loss:.4g} at epoch {state.best_epoch})",
            f"per epoch (median of {len(new)}): {seconds:.2f} s, {speed:.0f} sequences/s, "
            f"{100 * loading:.1f} % loading",
        ]
    lines.append(f"files: checkpoint.pt best.pt metrics.csv loss.png config.json in {result.run}")
    return "\n".join(lines)
