"""``scpformer experiment list|run``: the papers' tables and figures (issue 13)."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from scpformer.cli.argtypes import count, positive
from scpformer.cli.commands import command_help
from scpformer.experiments import EXPERIMENTS, RunOptions, run_experiment


def add_experiment_parser(commands: argparse._SubParsersAction) -> None:
    """Register ``experiment list`` and ``experiment run NAME`` on the top-level subparsers."""
    experiment = commands.add_parser("experiment", help=command_help("", "experiment"))
    actions = experiment.add_subparsers(dest="action", required=True, metavar="ACTION")
    listing = actions.add_parser("list", help="name every experiment and what it reproduces")
    listing.set_defaults(handler=run_list)
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
    run.add_argument("--seed", type=count, default=0, help="seed of the instance selection (0)")
    run.set_defaults(handler=run_run)


def run_list(args: argparse.Namespace) -> int:
    width = max(len(name) for name in EXPERIMENTS)
    for name, e in EXPERIMENTS.items():
        print(f"{name:<{width}}  {e.reproduces}: {e.summary} (default --n {e.default_n})")
    return 0


def run_run(args: argparse.Namespace) -> int:
    if args.name not in EXPERIMENTS:
        raise ValueError(f"unknown experiment {args.name!r}; see `scpformer experiment list`")
    options = RunOptions(
        out=args.out or Path("docs/results") / args.name,
        models=tuple(args.model),
        data=args.data,
        n=args.n,
        workers=args.workers,
        ray=args.ray,
        seed=args.seed,
    )
    command = "scpformer " + shlex.join(sys.argv[1:]) if sys.argv[1:] else ""
    report = run_experiment(args.name, options, command=command)
    print(f"wrote {report.parent}: {report.name} and the CSV and figures beside it")
    return 0
