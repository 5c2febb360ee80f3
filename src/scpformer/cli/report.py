"""``scpformer report``: gather every experiment's results into one page (docs/RESULTS.md)."""

from __future__ import annotations

import argparse
from pathlib import Path

from scpformer.cli.commands import add_command_parser
from scpformer.cli.dataclass_args import with_default

#: ``(flag, metavar, default, what it is)`` of the two paths of ``report``
PATH_FLAGS: tuple[tuple[str, str, str, str], ...] = (
    ("--results", "DIR", "docs/results", "folder of experiment folders"),
    ("--out", "FILE", "docs/RESULTS.md", "the page to write"),
)


def add_report_parser(commands: argparse._SubParsersAction) -> None:
    """Register ``report`` on the top-level subparsers."""
    report = add_command_parser(commands, "", "report")
    for name, metavar, default, what in PATH_FLAGS:
        help_text = with_default(what, default)
        report.add_argument(name, type=Path, default=Path(default), metavar=metavar, help=help_text)
    report.set_defaults(handler=run_report)


def run_report(args: argparse.Namespace) -> int:
    from scpformer.experiments.summary import write_summary

    path = write_summary(args.results, args.out)
    print(f"wrote {path}")
    return 0
