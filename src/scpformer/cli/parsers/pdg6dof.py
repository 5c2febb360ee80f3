"""Flags of ``scpformer solve pdg6dof`` and ``scpformer bench pdg6dof`` (handlers:
:mod:`scpformer.cli.pdg6dof`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from scpformer.cli.argtypes import count
from scpformer.cli.commands import lazy_handler
from scpformer.cli.config_file import add_config_file_arguments
from scpformer.cli.dataclass_args import add_dataclass_arguments, with_default
from scpformer.cli.parsers.common import add_csv_argument, add_family_parser, add_output_arguments

WARMSTARTS = ("cubic_profile", "straight_line", "tscvx", "kdtree", "interp")
CONSTANTS_NOTE = (
    "Table 1's vehicle constants are flags --const-NAME too, kept out of this list: "
    "--print-config writes them with their values, and --config FILE or the flags set them."
)


def add_config_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags for every solver setting and model constant (Table 1 defaults)."""
    add_dataclass_arguments(parser, "pdg6dof.solver", title="formulation")
    add_dataclass_arguments(parser, "scvx", prefix="scvx", title="SCvx parameters (Table 1)")
    add_dataclass_arguments(
        parser,
        "pdg6dof.constants",
        prefix="const",
        title="Table 1 constants",
        hidden=True,
        defaults_unless="instance",
    )
    add_config_file_arguments(parser)


def add_solve_parser(sub: argparse._SubParsersAction) -> None:
    parser = add_family_parser(sub, "solve", "pdg6dof", CONSTANTS_NOTE)
    parser.add_argument(
        "--instance",
        type=Path,
        help="instance JSON (r0, v0, q0, omega0_deg, m0, gamma_gs_deg, theta_max_deg"
        "[, constants]) (default: the nominal instance)",
    )
    add_output_arguments(parser, "write a trajectory figure to this .png, .pdf or .svg file")
    group = parser.add_argument_group("warm start")
    group.add_argument(
        "--warmstart",
        choices=WARMSTARTS,
        default="cubic_profile",
        help=with_default(
            "cubic_profile or straight_line (analytic guesses), or T-SCvx (Algorithm 2) with "
            "the predictor of --model: tscvx (the networks), kdtree or interp (the lookup "
            "tables of `scpformer train kdtree|interp`)",
            "cubic_profile",
        ),
    )
    group.add_argument(
        "--model",
        type=Path,
        metavar="RUN",
        help="predictor run folder; for tscvx also 'default': the pretrained networks shipped "
        "with scpformer (default: default for tscvx; kdtree and interp need a run)",
    )
    add_config_arguments(parser)
    parser.set_defaults(handler=lazy_handler("scpformer.cli.pdg6dof:run_solve"))


def add_bench_parser(sub: argparse._SubParsersAction) -> None:
    parser = add_family_parser(sub, "bench", "pdg6dof", CONSTANTS_NOTE)
    group = parser.add_argument_group("benchmark")
    group.add_argument("--n-nominal", type=count, default=20,
                       help=with_default("nominal instances", 20))  # fmt: skip
    group.add_argument("--n-table2", type=count, default=10,
                       help=with_default("Table 2 instances", 10))  # fmt: skip
    group.add_argument("--seed", type=count, default=0, help=with_default("sampling seed", 0))
    group.add_argument(
        "--optimality",
        action="store_true",
        help="also continue every solve to full convergence (200 solves, stationarity "
        "tolerance 1e-6; untimed) and report the propellant gap to it",
    )
    add_csv_argument(group, "pdg6dof")
    add_config_arguments(parser)
    parser.set_defaults(handler=lazy_handler("scpformer.cli.pdg6dof:run_bench"))
