"""The ``scpformer`` command: ``solve`` and ``bench`` per family, ``generate``, ``dataset``,
``train``."""

from __future__ import annotations

import argparse
import sys

from scpformer import __version__
from scpformer.cli import bench_art, data, pdg6dof, rendezvous, robust_rendezvous, train


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
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
    data.add_generate_parser(commands)
    data.add_dataset_parser(commands)
    train.add_train_parser(commands)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; bad input ends with a one-line ``error:`` message and exit status 2."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.handler(args)
    except ValueError as err:
        print(f"scpformer: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("scpformer: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
