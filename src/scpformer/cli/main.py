"""The ``scpformer`` command: ``solve`` and ``bench`` per family, ``generate``, ``dataset``,
``train``, ``experiment``.

Only this module and :mod:`scpformer.cli.commands` are imported to build the parser; a
command's module (and cvxpy, torch, ...) is imported when the command is used.
"""

from __future__ import annotations

import argparse
import sys

from scpformer.cli.commands import LazySubParsersAction, add_lazy_commands
from scpformer.cli.errors import OneLineParser, run_command


class _VersionAction(argparse._VersionAction):
    """``--version``: reads the package metadata only when asked."""

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        import scpformer

        self.version = f"scpformer {scpformer.__version__}"
        super().__call__(parser, namespace, values, option_string)


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="scpformer",
        description="Sequential convex programming for spacecraft trajectories.",
    )
    parser.add_argument("--version", action=_VersionAction)
    commands = parser.add_subparsers(
        dest="command", required=True, metavar="COMMAND", action=LazySubParsersAction
    )
    solve = commands.add_parser("solve", help="solve one instance of a problem family")
    bench = commands.add_parser("bench", help="benchmark a solver on a seeded instance set")
    for command, sub in (("solve", solve), ("bench", bench)):
        families = sub.add_subparsers(
            dest="family", required=True, metavar="FAMILY", action=LazySubParsersAction
        )
        add_lazy_commands(families, command)
    add_lazy_commands(commands, "")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; every failure ends with one ``scpformer: error:`` line (see cli.errors)."""
    return run_command(build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
