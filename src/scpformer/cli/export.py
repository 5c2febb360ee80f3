"""``scpformer export``: a training run's networks as ONNX, checked with onnxruntime."""

from __future__ import annotations

import argparse
from pathlib import Path

from scpformer.cli.argtypes import positive
from scpformer.cli.commands import add_command_parser


def add_export_parser(commands: argparse._SubParsersAction) -> None:
    """Register ``export`` on the top-level subparsers."""
    export = add_command_parser(commands, "", "export")
    export.add_argument(
        "--model", type=Path, required=True, metavar="RUN", help="training run folder or checkpoint"
    )
    export.add_argument("--onnx", type=Path, required=True, metavar="FILE", help="FILE.onnx")
    export.add_argument(
        "--tolerance",
        type=float,
        default=None,
        help="largest |onnxruntime - PyTorch| accepted (default 1e-4)",
    )
    export.add_argument("--opset", type=positive, default=None, help="ONNX opset (default 17)")
    export.set_defaults(handler=run_export)


def run_export(args: argparse.Namespace) -> int:
    from scpformer.train.export import DEFAULT_OPSET, DEFAULT_TOLERANCE, export_run

    tolerance = DEFAULT_TOLERANCE if args.tolerance is None else args.tolerance
    opset = DEFAULT_OPSET if args.opset is None else args.opset
    for result in export_run(args.model, args.onnx, tolerance=tolerance, opset=opset):
        shapes = ", ".join(f"{k} {v}" for k, v in result.inputs.items())
        print(
            f"wrote {result.path} ({result.kind}): max |onnxruntime - PyTorch| = "
            f"{result.max_abs_diff:.2g} on {shapes}"
        )
    return 0
