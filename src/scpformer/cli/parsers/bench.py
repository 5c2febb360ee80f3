"""Flags of ``scpformer bench art`` and ``scpformer bench tscvx`` (handlers:
:mod:`scpformer.cli.bench_art`, :mod:`scpformer.cli.bench_tscvx`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from scpformer.cli.argtypes import count, int_at_least
from scpformer.cli.commands import add_command_parser, lazy_handler
from scpformer.cli.dataclass_args import with_default


def add_bench_art_parser(sub: argparse._SubParsersAction) -> None:
    parser = add_command_parser(sub, "bench", "art")
    parser.add_argument("--preset", choices=("small", "paper"), default=None,
                        help=with_default("model size of the random weights", "small"))  # fmt: skip
    parser.add_argument("--model", type=Path, help="trained run folder or checkpoint.pt")
    parser.add_argument("--batch", type=int, default=64,
                        help=with_default("batch of the throughput run", 64))  # fmt: skip
    parser.add_argument("--steps", type=int, default=100, help=with_default("time steps N", 100))
    parser.add_argument("--repeats", type=int, default=5,
                        help=with_default("timed runs per mode", 5))  # fmt: skip
    parser.add_argument("--threads", type=int, default=1, help=with_default("torch threads", 1))
    parser.add_argument("--seed", type=count, default=0,
                        help=with_default("instance and weight seed", 0))  # fmt: skip
    parser.add_argument(
        "--target", action="store_true", help="random weights with the target token (robust ART)"
    )
    parser.add_argument(
        "--skip-uncached", action="store_true", help="skip the (slow) run without the cache"
    )
    parser.add_argument(
        "--bf16",
        action="store_true",
        help="also time generation with bfloat16 weights (where this CPU runs them)",
    )
    parser.add_argument(
        "--int8",
        action="store_true",
        help="also time generation with int8 weights (where this CPU runs them)",
    )
    parser.set_defaults(handler=lazy_handler("scpformer.cli.bench_art:run_bench"))


def add_bench_tscvx_parser(sub: argparse._SubParsersAction) -> None:
    parser = add_command_parser(sub, "bench", "tscvx")
    parser.add_argument("--preset", choices=("small", "paper"), default=None,
                        help=with_default("sizes of random nets", "small"))  # fmt: skip
    parser.add_argument("--tokens", choices=("single", "inputs"), default=None,
                        help="tokenization of random nets (default: the preset's)")  # fmt: skip
    parser.add_argument(
        "--model",
        type=Path,
        help="trained run folder (RUN/tight, RUN/solution), or 'default': the shipped networks",
    )
    at_least_zero, at_least_one = int_at_least(0), int_at_least(1)
    parser.add_argument("--repeats", type=at_least_one, default=500,
                        help=with_default("timed calls per case", 500))  # fmt: skip
    parser.add_argument("--warmup", type=at_least_zero, default=20,
                        help=with_default("untimed calls first", 20))  # fmt: skip
    parser.add_argument("--batch", type=at_least_one, default=64,
                        help=with_default("throughput batch", 64))  # fmt: skip
    parser.add_argument("--threads", type=at_least_one, default=1,
                        help=with_default("torch threads", 1))  # fmt: skip
    parser.add_argument("--seed", type=at_least_zero, default=0,
                        help=with_default("seed of theta and weights", 0))  # fmt: skip
    parser.set_defaults(handler=lazy_handler("scpformer.cli.bench_tscvx:run_bench"))
