"""Flags of ``scpformer demo`` (handler: :mod:`scpformer.cli.demo`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from scpformer.cli.commands import add_command_parser, lazy_handler


def add_demo_parser(sub: argparse._SubParsersAction) -> None:
    parser = add_command_parser(sub, "", "demo")
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        metavar="DIR",
        help="also draw one figure per solve into DIR (default: no figures)",
    )
    parser.set_defaults(handler=lazy_handler("scpformer.cli.demo:run_demo"))
