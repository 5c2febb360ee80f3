"""Flags of ``scpformer experiment list|run`` (handlers: :mod:`scpformer.cli.experiment`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from scpformer.cli.argtypes import count, positive
from scpformer.cli.commands import add_command_parser, lazy_handler
from scpformer.cli.dataclass_args import with_default


def add_experiment_parser(commands: argparse._SubParsersAction) -> None:
    """Register ``experiment list`` and ``experiment run NAME`` on the top-level subparsers."""
    experiment = add_command_parser(commands, "", "experiment")
    actions = experiment.add_subparsers(dest="action", required=True, metavar="ACTION")
    listing = actions.add_parser("list", help="name every experiment and what it reproduces")
    listing.set_defaults(handler=lazy_handler("scpformer.cli.experiment:run_list"))
    run = actions.add_parser(
        "run",
        help="run one experiment into a folder (CSV, PNG, report.md)",
        description="Run one experiment; an interrupted run resumes where it stopped.",
    )
    run.add_argument("name", metavar="NAME", help="experiment name (see `experiment list`)")
    run.add_argument(
        "--model",
        type=Path,
        action="append",
        default=[],
        metavar="RUN",
        help="training run folder or checkpoint (repeat for several models)",
    )
    run.add_argument("--data", type=Path, metavar="DIR", help="dataset folder (split)")
    run.add_argument("--n", type=positive, help="test instances (default: the experiment's)")
    run.add_argument("--workers", type=positive, help="local worker processes (default: every CPU)")
    run.add_argument(
        "--ray",
        metavar="ADDRESS",
        help="run on a Ray cluster ('local' starts one) instead of local processes",
    )
    run.add_argument("--out", type=Path, help="output folder (default: docs/results/NAME)")
    run.add_argument("--seed", type=count, default=0,
                     help=with_default("seed of the instance selection", 0))  # fmt: skip
    run.set_defaults(handler=lazy_handler("scpformer.cli.experiment:run_run"))
