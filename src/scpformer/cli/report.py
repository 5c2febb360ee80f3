"""``scpformer report``: gather every experiment's results into one page (docs/RESULTS.md)."""

from __future__ import annotations

import argparse
from pathlib import Path

from scpformer.cli.commands import add_command_parser


def add_report_parser(commands: argparse._SubParsersAction) -> None:
    """Register ``report`` on the top-level subparsers."""
    report = add_command_parser(commands, "", "report")
    report.add_argument(
        "--results",
        type=Path,
        default=Path("docs/results"),
        metavar="DIR",
        help="folder of experiment folders (default: docs/results)",
    )
    report.add_argument(
        "--out",
        type=Path,
        default=Path("docs/RESULTS.md"),
        metavar="FILE",
        help="the page to write (default: docs/RESULTS.md)",
    )
    report.set_defaults(handler=run_report)


def run_report(args: argparse.Namespace) -> int:
    from scpformer.experiments.summary import write_summary

    path = write_summary(args.results, args.out)
    print(f"wrote {path}")
    return 0
