"""``scpformer experiment list|run``: the papers' tables and figures (handlers; the flags
are in :mod:`scpformer.cli.parsers.experiment`)."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from scpformer.experiments import EXPERIMENTS, RunOptions, run_experiment


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
