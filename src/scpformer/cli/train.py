"""``scpformer train art|gru|lstm``: train a sequence model on a rendezvous dataset.

Under ``torchrun --nproc_per_node P -m scpformer.cli.main train ...`` the same command trains
with DistributedDataParallel over P processes (process 0 writes the run folder).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from scpformer.cli.argtypes import count
from scpformer.cli.commands import add_command_parser
from scpformer.cli.config_file import add_config_file_arguments
from scpformer.cli.dataclass_args import add_dataclass_arguments, constant, overrides
from scpformer.cli.parsers.common import FlagSpec, add_flags

#: the training flags' defaults are the preset's (``--print-config`` writes given values only)
TRAINING_TITLE = "training (default: the preset's values)"

SEQUENCE_MODELS = ("art", "gru", "lstm")
_HELP = {
    "art": "the Autonomous Rendezvous Transformer (ART paper Sec. 3, Table 4)",
    "gru": "the GRU baseline over the same token sequence (ART paper Table 2)",
    "lstm": "the LSTM baseline over the same token sequence (ART paper Table 2)",
}


def add_train_parser(commands: argparse._SubParsersAction) -> None:
    """Register ``train MODEL`` on the top-level subparsers."""
    train = add_command_parser(commands, "", "train")
    models = train.add_subparsers(dest="model", required=True, metavar="MODEL")
    for kind in SEQUENCE_MODELS:
        parser = models.add_parser(kind, help=_HELP[kind], description=_HELP[kind])
        add_sequence_arguments(parser)
        parser.set_defaults(handler=run_train, kind=kind)
    add_tscvx_parser(models)
    add_lookup_parsers(models)


#: the model flags of ``train art|gru|lstm`` (None: the preset's or, resumed, the run's)
SEQUENCE_FLAGS: tuple[FlagSpec, ...] = (
    ("--preset", {"choices": "train.presets", "default": None,
                  "help": "model and training preset: 'paper' (Table 4) or 'small' (two CPU "
                  "cores) (default: small; a resumed run keeps its own)"}),
    ("--frame", {"choices": ("rtn", "roe"), "default": None,
                 "help": "state frame of the sequences (default: rtn; a resumed run keeps its "
                 "own)"}),
    ("--twin", {"action": "append", "choices": ("cvx", "scp", "tpbvp", "ps"), "default": None,
                "metavar": "TWIN",
                "help": "trajectory twin to learn from, repeatable: cvx (Problem 2), scp "
                "(Problem 3), tpbvp (Problem 1, Table 2), ps (robust) (default: the dataset's "
                "cvx and scp, or ps and cvx; a resumed run keeps its own)"}),
)  # fmt: skip


def add_sequence_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags of ``train art|gru|lstm``: data, run folder, presets and every TrainConfig field."""
    _add_folder_arguments(parser, "dataset folder (split)")
    add_flags(parser, SEQUENCE_FLAGS)
    _add_resume_arguments(parser, "checkpoint")
    add_training_arguments(parser)


def add_training_arguments(parser: argparse.ArgumentParser) -> None:
    """Every ``TrainConfig`` field as a flag (default: the preset's) and ``--config``."""
    add_dataclass_arguments(parser, "train", title=TRAINING_TITLE, print_defaults=False,
                            default_note="default: the preset's")  # fmt: skip
    add_config_file_arguments(parser)


def _add_folder_arguments(parser: argparse.ArgumentParser, data_help: str) -> None:
    """``--data`` (the dataset folder, ``data_help``) and ``--out`` (the run folder) of every
    ``train MODEL``."""
    parser.add_argument("--data", type=Path, required=True, help=data_help)
    parser.add_argument("--out", type=Path, required=True, help="run folder RUN")


def _add_resume_arguments(parser: argparse.ArgumentParser, checkpoint: str) -> None:
    """``--resume`` (from the run's ``checkpoint``, as ``--help`` names it) and
    ``--no-progress`` of the trained models."""
    parser.add_argument(
        "--resume", action="store_true", help=f"continue the run in --out from its {checkpoint}"
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def _check_output_folder(path: Path) -> None:
    from scpformer.files import check_output_folder

    check_output_folder(path, "--out")


def _run_options(args: argparse.Namespace) -> dict[str, Any]:
    """The keyword arguments of a training function given by the flags of
    :func:`_add_folder_arguments`, :func:`_add_resume_arguments` and
    :func:`add_training_arguments` (``--out`` is checked first).

    Parameters
    ----------
    args
        The parsed flags of ``train art|gru|lstm|tscvx``.

    Returns
    -------
    dict
        ``data``, ``out``, ``overrides`` (the ``TrainConfig`` fields given), ``resume`` and
        ``progress``.
    """
    from scpformer.train.config import TrainConfig

    _check_output_folder(args.out)
    return {
        "data": args.data,
        "out": args.out,
        "overrides": overrides(args, TrainConfig),
        "resume": args.resume,
        "progress": not args.no_progress,
    }


def run_train(args: argparse.Namespace) -> int:
    from scpformer.train.art import train_sequence_model

    options = _run_options(args)
    result = train_sequence_model(
        args.kind, preset=args.preset, frame=args.frame, twins=args.twin, **options
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
        f"of twin(s) {', '.join(data.twins)} "
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


# -- T-SCvx ---------------------------------------------------------------------------------
_TSCVX_HELP = (
    "the T-SCvx networks: tight-constraint classifier f2(theta, k) and solution regressor "
    "f1(theta) on a split pdg6dof dataset (T-SCvx paper Sec. III.D-E)"
)


#: the network and evaluation flags of ``train tscvx`` (None: the preset's or the library's)
TSCVX_FLAGS: tuple[FlagSpec, ...] = (
    ("--preset", {"choices": ("small", "paper"), "default": "small",
                  "help": "network sizes, training values, epochs and folds: 'paper' (Sec. "
                  "IV.A, III.E.3: 384/768 dims, 2 heads, 4 layers, 2 epochs, 3 folds) or "
                  "'small' (default)"}),
    ("--networks", {"nargs": "+", "choices": ("tight", "solution"),
                    "default": ("tight", "solution"), "help": "which networks to train (both)"}),
    ("--folds", {"type": int, "default": None,
                 "help": "K-fold over train+validation (preset's: 3/1)"}),
    ("--solution-epochs", {"type": int, "default": None,
                           "help": "epochs of f1 (--epochs is f2's)"}),
    ("--tokens", {"choices": ("single", "inputs"), "default": None,
                  "help": "tokenization of both networks (preset's: single)"}),
    ("--report-split", {"choices": ("validation", "test"), "default": "validation",
                        "help": "split evaluated and written to RUN at the end (validation)"}),
    ("--threads", {"type": int, "default": None, "help": "torch threads (torch's default)"}),
    ("--canonical", {"action": argparse.BooleanOptionalAction, "default": True,
                     "help": "networks see each instance in its canonical frame (yawed about "
                     "Up, body rolled; exact symmetries of the problem) and f1 predicts there "
                     "(default); --no-canonical: the raw frame, as the paper"}),
    ("--thrust-weight", {"type": float, "default": None,
                         "help": "weight of f1's thrust outputs in its MSE (preset's: paper 1, "
                         "the plain MSE; small 4)"}),
)  # fmt: skip


def add_tscvx_parser(models: argparse._SubParsersAction) -> None:
    """``train tscvx``: both networks into RUN/tight and RUN/solution."""
    parser = models.add_parser("tscvx", help=_TSCVX_HELP, description=_TSCVX_HELP)
    _add_folder_arguments(parser, "pdg6dof dataset folder (split)")
    add_flags(parser, TSCVX_FLAGS)
    _add_resume_arguments(parser, "checkpoints")
    add_training_arguments(parser)
    parser.set_defaults(handler=run_train_tscvx)


def run_train_tscvx(args: argparse.Namespace) -> int:
    from scpformer.train.tscvx import format_metrics, train_tscvx

    if args.solution_epochs is not None and args.solution_epochs < 1:
        raise ValueError(f"--solution-epochs must be positive, got {args.solution_epochs}")
    options = _run_options(args)
    result = train_tscvx(
        preset_name=args.preset,
        networks=tuple(args.networks),
        folds=args.folds,
        solution_epochs=args.solution_epochs,
        model_overrides={"tokens": args.tokens} if args.tokens else None,
        report_split=args.report_split,
        threads=args.threads,
        canonical=args.canonical,
        thrust_weight=args.thrust_weight,
        **options,
    )
    if not result.world.is_main:
        return 0
    for name, net in result.networks.items():
        state = net.states[-1]
        print(
            f"{name}: {net.parameters} parameters, {len(net.states)} fold(s), "
            f"{net.train_items} / {net.validation_items} training / validation items, "
            f"{net.seconds:.1f} s; last fold: {state.epoch} epoch(s), validation loss "
            f"{state.best_val_loss:.4g} (best, epoch {state.best_epoch})"
        )
    if result.metrics:
        print(format_metrics(result.metrics))
    split = result.report_split
    print(f"files: config.json, tight/, solution/, metrics_{split}.json in {result.run}")
    return 0


# -- lookup-table baselines of T-SCvx (paper Sec. IV.C) -------------------------------------------
LOOKUP_HELP = {
    "kdtree": "k-d tree nearest-neighbour lookup table (T-SCvx paper Sec. IV.C, Tables 4-5)",
    "interp": "linear-interpolation lookup table (T-SCvx paper Sec. IV.C, Tables 4-5)",
}


def add_lookup_parsers(models: argparse._SubParsersAction) -> None:
    """``train kdtree|interp --data DIR --out RUN``: fit a lookup table on the training split."""
    for kind, help_text in LOOKUP_HELP.items():
        preset = argparse.Namespace(**constant("lookup")[kind])
        parser = models.add_parser(kind, help=help_text, description=help_text)
        _add_folder_arguments(parser, "dataset folder (split)")
        group = parser.add_argument_group("lookup table")
        group.add_argument(
            "--n-components",
            type=int,
            default=preset.n_components,
            help=f"PCA components of the standardized inputs (paper: 10; default: "
            f"{preset.n_components})",
        )
        group.add_argument(
            "--max-points",
            type=int,
            default=preset.max_points,
            help=f"training points in the table, drawn at random; 0: all (paper: 100 for "
            f"interpolation; default: {preset.max_points})",
        )
        group.add_argument("--seed", type=count, default=preset.seed, help="seed of the draw")
        group.add_argument(
            "--threshold",
            type=float,
            default=preset.threshold,
            help=f"probability from which a row is predicted tight (default: {preset.threshold})",
        )
        add_config_file_arguments(parser)
        parser.set_defaults(handler=run_train_lookup, kind=kind)


def run_train_lookup(args: argparse.Namespace) -> int:
    import dataclasses

    from scpformer.models.lookup import LOOKUP_PRESETS, train_lookup

    _check_output_folder(args.out)
    config = dataclasses.replace(
        LOOKUP_PRESETS[args.kind],
        n_components=args.n_components,
        max_points=args.max_points,
        seed=args.seed,
        threshold=args.threshold,
    )
    predictor = train_lookup(args.kind, data=args.data, out=args.out, config=config)
    parts = {name: getattr(predictor, name) for name in ("tight", "solution")}
    for name, part in parts.items():
        print(f"{name}: {len(part.table.points)} points in {part.inputs.dims} PCA dimensions")
    print(f"table: {predictor.memory_bytes() / 1e6:.3f} MB; files: lookup.npz lookup.json in "
          f"{args.out}")  # fmt: skip
    return 0
