"""Flags of ``scpformer solve rendezvous`` and ``scpformer bench rendezvous`` (handlers:
:mod:`scpformer.cli.rendezvous`)."""

from __future__ import annotations

import argparse

from scpformer.cli.commands import lazy_handler
from scpformer.cli.config_file import add_config_file_arguments
from scpformer.cli.dataclass_args import add_dataclass_arguments, with_default
from scpformer.cli.parsers import common
from scpformer.cli.parsers.common import FlagSpec, SolveFlags, csv_flag

CONSTANTS_NOTE = (
    "Table 1's scenario and target-orbit constants are flags --scenario-NAME and "
    "--target-NAME too, kept out of this list: --print-config writes them with their values, "
    "and --config FILE or the flags set them."
)


def add_config_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags for every solver setting and scenario constant (Table 1 defaults)."""
    add_dataclass_arguments(parser, "rendezvous.solver", title="formulation")
    add_dataclass_arguments(
        parser, "scp", prefix="scp", title="SCP parameters (Table 1, Eqs. 17-19)",
        renames={"stop_test": "stopping"},
    )  # fmt: skip
    add_dataclass_arguments(parser, "rendezvous.verification", prefix="verify",
                            title="verification (nonlinear replay)")  # fmt: skip
    add_dataclass_arguments(parser, "rendezvous.scenario", prefix="scenario",
                            title="OCP (Table 1)", hidden=True,
                            defaults_unless="instance")  # fmt: skip
    add_dataclass_arguments(parser, "rendezvous.target", prefix="target",
                            title="target orbit (Table 1)", hidden=True,
                            defaults_unless="instance")  # fmt: skip
    add_config_file_arguments(parser)


SOLVE_FLAGS = SolveFlags(
    problem=("--problem", {
        "choices": "rendezvous.problems",
        "default": "scp",
        "help": with_default("which OCP: tpbvp (1), convex (2) or scp (3)", "scp"),
    }),
    warmstarts="rendezvous.warmstarts",
    warmstart="convex",
    warmstart_help="initial guess of Problem 3: Problem 1 (tpbvp), 2 (convex)",
    instance_help="instance JSON (roe0_m, horizon_orbits[, target, scenario]) (default: "
    "Table 1's)",
    seed_help="sample the instance from Table 1's last column with this seed",
    instance=(
        ("--roe0", {
            "type": float,
            "nargs": 6,
            "metavar": "M",
            "help": "initial mean ROE a*dalpha (da, dlambda, dex, dey, dix, diy) [m] (default: "
            "the instance's)",
        }),
        ("--horizon-orbits", {"type": float,
                              "help": "OCP horizon [orbits] (default: the instance's)"}),
    ),
    output=(
        ("--no-verify", {"action": "store_true",
                         "help": "skip the nonlinear replay of the impulses"}),
    ),
)  # fmt: skip
BENCH_FLAGS: tuple[FlagSpec, ...] = (
    ("--warmstart", {"choices": "rendezvous.warmstarts", "default": "convex",
                     "help": with_default("warm start of Problem 3", "convex")}),
    csv_flag("rendezvous"),
    ("--no-verify", {"action": "store_true",
                     "help": "skip the nonlinear replay (the default replays every solution)"}),
)  # fmt: skip


def add_solve_parser(sub: argparse._SubParsersAction) -> None:
    parser = common.add_solve_parser(sub, "rendezvous", CONSTANTS_NOTE, SOLVE_FLAGS)
    add_config_arguments(parser)
    parser.set_defaults(handler=lazy_handler("scpformer.cli.rendezvous:run_solve"))


def add_bench_parser(sub: argparse._SubParsersAction) -> None:
    parser = common.add_bench_parser(sub, "rendezvous", CONSTANTS_NOTE, BENCH_FLAGS)
    add_config_arguments(parser)
    parser.set_defaults(handler=lazy_handler("scpformer.cli.rendezvous:run_bench"))
