"""Flags shared by several commands: output files, warm starts, configuration sections; flag
tables (:data:`FlagSpec`, :func:`add_flags`); the solve and bench parsers of the rendezvous
families (:class:`SolveFlags`, :func:`add_solve_parser`, :func:`add_bench_parser`)."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from scpformer.cli.argtypes import count, positive
from scpformer.cli.commands import add_command_parser
from scpformer.cli.dataclass_args import constant, with_default

#: the usage line of the commands with many flags: the groups below list them
USAGE = "%(prog)s [options]"

#: one flag: its name and the keywords of ``add_argument``, where ``choices`` is the values
#: or, as a string, the name of a snapshot constant that holds them
#: (:func:`~scpformer.cli.dataclass_args.constant`)
FlagSpec = tuple[str, dict[str, Any]]


def add_flags(container: argparse._ActionsContainer, flags: tuple[FlagSpec, ...]) -> None:
    """Add the flags of a table to a parser or group, in its order."""
    for name, options in flags:
        if isinstance(options.get("choices"), str):
            options = {**options, "choices": constant(options["choices"])}
        container.add_argument(name, **options)


def add_family_parser(
    sub: argparse._SubParsersAction, command: str, family: str, epilog: str
) -> argparse.ArgumentParser:
    """The parser of ``command family`` (``solve`` or ``bench`` of a problem family): the short
    usage line, and ``epilog`` on the family's constant flags kept out of ``--help``."""
    return add_command_parser(sub, command, family, usage=USAGE, epilog=epilog)


def add_benchmark_arguments(parser: argparse.ArgumentParser) -> argparse._ArgumentGroup:
    """Group ``benchmark`` of ``bench FAMILY``: ``--n`` instances sampled with ``--seed``, for
    the family's flags that the caller adds to the returned group."""
    group = parser.add_argument_group("benchmark")
    group.add_argument("--n", type=positive, default=20,
                       help=with_default("number of instances", 20))  # fmt: skip
    group.add_argument("--seed", type=count, default=0, help=with_default("sampling seed", 0))
    return group


def csv_flag(family: str) -> FlagSpec:
    """``--csv``: the per-instance rows of ``bench FAMILY`` (default ``bench_FAMILY.csv``)."""
    name = f"bench_{family.replace('-', '_')}.csv"
    return ("--csv", {"type": Path, "default": Path(name),
                      "help": with_default("per-instance CSV", name)})  # fmt: skip


def add_csv_argument(group: argparse._ArgumentGroup, family: str) -> None:
    """Add :func:`csv_flag` of ``family`` to ``group``."""
    add_flags(group, (csv_flag(family),))


def add_bench_parser(
    sub: argparse._SubParsersAction, family: str, epilog: str, flags: tuple[FlagSpec, ...]
) -> argparse.ArgumentParser:
    """``bench family`` (:func:`add_family_parser`) whose group ``benchmark`` has ``--n``,
    ``--seed`` (:func:`add_benchmark_arguments`) and then ``flags``."""
    parser = add_family_parser(sub, "bench", family, epilog)
    add_flags(add_benchmark_arguments(parser), flags)
    return parser


@dataclass(frozen=True)
class SolveFlags:
    """The flags of ``solve FAMILY`` of a family whose instance is a file or sampled with a
    seed (rendezvous, robust-rendezvous), in the order of ``--help``.

    Attributes
    ----------
    problem
        What is solved (``--problem``, ``--mode``).
    warmstarts, warmstart, warmstart_help
        The snapshot constant of the family's own warm starts, the default and their help
        (:func:`add_warmstart_arguments`).
    instance_help, seed_help
        The help of ``--instance`` and ``--seed`` (:func:`add_instance_arguments`).
    instance
        The flags of the instance that replace its values, in group ``instance``.
    output
        The flags after ``--out`` and ``--plot`` in group ``output``.
    """

    problem: FlagSpec
    warmstarts: str
    warmstart: str
    warmstart_help: str
    instance_help: str
    seed_help: str
    instance: tuple[FlagSpec, ...]
    output: tuple[FlagSpec, ...]


def add_solve_parser(
    sub: argparse._SubParsersAction, family: str, epilog: str, flags: SolveFlags
) -> argparse.ArgumentParser:
    """``solve family`` (:func:`add_family_parser`) with ``flags``; the caller adds the
    family's configuration and handler."""
    parser = add_family_parser(sub, "solve", family, epilog)
    add_flags(parser, (flags.problem,))
    add_warmstart_arguments(
        parser, constant(flags.warmstarts), flags.warmstart, flags.warmstart_help
    )
    add_flags(add_instance_arguments(parser, flags.instance_help, flags.seed_help), flags.instance)
    add_flags(add_output_arguments(parser), flags.output)
    return parser


def add_output_arguments(
    parser: argparse.ArgumentParser,
    plot_help: str = "write Figs. 7-8 style plots to this .png, .pdf or .svg file",
) -> argparse._ArgumentGroup:
    """``--out FILE.npz`` and ``--plot FIGURE`` of the solve commands, in group ``output``."""
    group = parser.add_argument_group("output")
    group.add_argument("--out", type=Path, help="write the solution to this .npz file")
    group.add_argument("--plot", type=Path, help=plot_help)
    return group


def add_instance_arguments(
    parser: argparse.ArgumentParser, instance_help: str, seed_help: str
) -> argparse._ArgumentGroup:
    """Group ``instance``: ``--instance FILE`` or ``--seed S`` (one of them), for the flags of
    the instance that the caller adds to the returned group."""
    group = parser.add_argument_group("instance")
    source = group.add_mutually_exclusive_group()
    source.add_argument("--instance", type=Path, help=instance_help)
    source.add_argument("--seed", type=count, help=seed_help)
    return group


def add_warmstart_arguments(
    parser: argparse.ArgumentParser, names: tuple[str, ...], default: str, help_names: str
) -> None:
    """``--warmstart`` (the family's ``names`` or ``art``) and the ART flags."""
    group = parser.add_argument_group("warm start")
    group.add_argument(
        "--warmstart",
        choices=(*names, "art"),
        default=default,
        help=with_default(f"{help_names}, or art: the transformer of --model", default),
    )
    group.add_argument(
        "--model",
        type=Path,
        metavar="RUN",
        help=with_default(
            "ART training run folder or checkpoint file, or 'default': the "
            "pretrained model shipped with scpformer",
            "default",
        ),
    )
    group.add_argument(
        "--art-mode",
        choices=constant("art.modes"),
        help=with_default(
            "ART inference: dynamics in the loop (Algorithm 2) or transformer only (Algorithm 1)",
            "dynamics",
        ),
    )
    group.add_argument("--rtg", type=float, metavar="R",
                       help=with_default("R(t_1) [m/s], <= 0", "-J_CVX"))  # fmt: skip
    group.add_argument("--ctg", type=float, metavar="C", help=with_default("C(t_1)", 0))
