"""Flags of ``scpformer demo`` (handler: :mod:`scpformer.cli.demo`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from scpformer.cli.commands import command_help, lazy_handler


def add_demo_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "demo",
        help=command_help("", "demo"),
        description="The papers' learned warm starts beside the classical ones, in seconds: "
        "the ISS rendezvous (SCP from the convex solution and from ART), the passively safe "
        "rendezvous (PS-CVX and PS-ART) and the 6-DoF Mars landing (SCvx from the cubic "
        "profile and T-SCvx), each solve timed and verified; with --out, one figure per solve.",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        metavar="DIR",
        help="also draw one figure per solve into DIR (default: no figures)",
    )
    parser.set_defaults(handler=lazy_handler("scpformer.cli.demo:run_demo"))
