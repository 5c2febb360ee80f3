"""Flags of ``scpformer solve robust-rendezvous`` and ``scpformer bench robust-rendezvous``
(handlers: :mod:`scpformer.cli.robust_rendezvous`)."""

from __future__ import annotations

import argparse
import re

from scpformer.cli.argtypes import count
from scpformer.cli.commands import lazy_handler
from scpformer.cli.config_file import add_config_file_arguments
from scpformer.cli.dataclass_args import add_dataclass_arguments, constant, with_default
from scpformer.cli.parsers import common
from scpformer.cli.parsers.common import SolveFlags, csv_flag

CONSTANTS_NOTE = (
    "Tables 1-2's scenario and target-orbit constants are flags --scenario-NAME and "
    "--target-NAME too, kept out of this list: --print-config writes them with their values, "
    "and --config FILE or the flags set them. SCvx* flags are --scvx-star-NAME (the former "
    "--scvx-NAME spellings still work, with a warning)."
)


def add_config_arguments(parser: argparse.ArgumentParser, unless: str | None = None) -> None:
    """Flags for every solver setting and scenario constant (robust Tables 1-2 defaults);
    ``unless``: the flag (dest) of an instance file whose values replace the defaults.

    The waypoints ``-T`` and ``-R`` are values (``--waypoint -T``, ``--range-waypoints +T -T``),
    not options: ``parser`` reads them as it reads negative numbers.
    """
    parser._negative_number_matcher = re.compile(r"^-(\d+\.?\d*|\.\d+|[A-Z])$")
    add_dataclass_arguments(parser, "robust.solver", title="formulation")
    add_dataclass_arguments(parser, "scvx_star", prefix="scvx-star", legacy_prefix="scvx",
                            title="SCvx* parameters (Table 1)")  # fmt: skip
    add_dataclass_arguments(parser, "robust.verification", prefix="verify", title="verification")
    add_dataclass_arguments(parser, "robust.scenario", prefix="scenario", title="OCP (Table 1)",
                            hidden=True, defaults_unless=unless)  # fmt: skip
    add_dataclass_arguments(parser, "robust.target", prefix="target",
                            title="target orbit (Table 1)", hidden=True,
                            defaults_unless=unless)  # fmt: skip
    delta = parser.add_argument(
        "--delta",
        type=float,
        help=with_default("Delta: chance-constraint level", constant("robust.delta")),
    )
    delta.config_default = constant("robust.delta")
    delta.config_default_unless = unless
    add_config_file_arguments(parser)


SOLVE_FLAGS = SolveFlags(
    problem=("--mode", {
        "choices": "robust.modes",
        "default": "chance",
        "help": with_default("passive safety: deterministic or chance-constrained", "chance"),
    }),
    warmstarts="robust.warmstarts",
    warmstart="three_stage",
    warmstart_help="three_stage (dataset procedure), tpbvp (PS-CVX)",
    instance_help="instance JSON (x0_rtn, waypoint, ...) (default: Table 1's)",
    seed_help="sample the instance (Table 1) with this seed",
    instance=(
        ("--waypoint", {"choices": "robust.waypoints",
                        "help": "pre-docking state (default: the instance's)"}),
    ),
    output=(
        ("--monte-carlo", {
            "type": count, "default": 0, "metavar": "N",
            "help": with_default("Monte Carlo draws per node through the two-body + J2 "
                                 "propagator (0: skip)", 0),
        }),
        ("--mc-seed", {"type": count, "default": 0, "help": with_default("Monte Carlo seed", 0)}),
    ),
)  # fmt: skip


def add_solve_parser(sub: argparse._SubParsersAction) -> None:
    parser = common.add_solve_parser(sub, "robust-rendezvous", CONSTANTS_NOTE, SOLVE_FLAGS)
    add_config_arguments(parser, unless="instance")
    parser.set_defaults(handler=lazy_handler("scpformer.cli.robust_rendezvous:run_solve"))


def add_bench_parser(sub: argparse._SubParsersAction) -> None:
    flags = (csv_flag("robust-rendezvous"),)
    parser = common.add_bench_parser(sub, "robust-rendezvous", CONSTANTS_NOTE, flags)
    add_config_arguments(parser)
    parser.set_defaults(handler=lazy_handler("scpformer.cli.robust_rendezvous:run_bench"))
