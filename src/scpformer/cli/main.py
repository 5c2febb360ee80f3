"""The ``scpformer`` command: ``solve`` and ``bench`` per family, ``generate``, ``dataset``,
``train``, ``experiment``."""

from __future__ import annotations

import argparse
import sys

from scpformer import __version__
from scpformer.cli import (
    bench_art,
    bench_tscvx,
    data,
    experiment,
    export,
    pdg6dof,
    rendezvous,
    report,
    robust_rendezvous,
    train,
)
from scpformer.cli.errors import OneLineParser, run_command


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="scpformer",
        description="Sequential convex programming for spacecraft trajectories.",
    )
    parser.add_argument("--version", action="version", version=f"scpformer {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    solve = commands.add_parser("solve", help="solve one instance of a problem family")
    bench = commands.add_parser("bench", help="benchmark a solver on a seeded instance set")
    solve_families = solve.add_subparsers(dest="family", required=True, metavar="FAMILY")
    bench_families = bench.add_subparsers(dest="family", required=True, metavar="FAMILY")
    pdg6dof.add_solve_parser(solve_families)
    pdg6dof.add_bench_parser(bench_families)
    rendezvous.add_solve_parser(solve_families)
    rendezvous.add_bench_parser(bench_families)
    robust_rendezvous.add_solve_parser(solve_families)
    robust_rendezvous.add_bench_parser(bench_families)
    bench_art.add_bench_parser(bench_families)
    bench_tscvx.add_bench_parser(bench_families)
    data.add_generate_parser(commands)
    data.add_dataset_parser(commands)
    train.add_train_parser(commands)
    experiment.add_experiment_parser(commands)
    report.add_report_parser(commands)
    export.add_export_parser(commands)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; every failure ends with one ``scpformer: error:`` line (see cli.errors)."""
    return run_command(build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
