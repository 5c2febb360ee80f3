"""ONNX export of a training run's networks, checked against PyTorch with onnxruntime.

``scpformer export --model RUN --onnx FILE`` writes each network of ``RUN`` as ONNX (the
full-sequence forward, batch and sequence axes dynamic), then runs the file with onnxruntime
and PyTorch on the same random inputs of another batch size and length than the traced ones,
and fails when the largest absolute difference exceeds the tolerance.

The networks of a run are found by its layout (:func:`run_networks`): ``RUN/checkpoint.pt``
(ART, GRU, LSTM: one network, written to ``FILE``) or ``RUN/*/checkpoint.pt`` (T-SCvx:
``RUN/tight`` and ``RUN/solution``, written to ``FILE`` with the sub-folder's name before the
suffix: ``nets.tight.onnx``, ``nets.solution.onnx``).

How a network kind is exported is one :class:`NetworkExport` entry of :data:`EXPORTS`, keyed
by the checkpoint's ``kind``: example inputs, the module whose ``forward(*inputs)`` returns the
outputs, the output names, the dynamic axes, and the models API that rebuilds the network from
its checkpoint. A new kind (e.g. the T-SCvx classifier, ``forward(theta_std (B, 16), k (B,))
-> logits (B, R)``) is one more entry::

    EXPORTS["tscvx-tight"] = NetworkExport(
        inputs=lambda ckpt, b, t: {"theta": torch.randn(b, 16), "k": torch.zeros(b).long()},
        module=lambda model: model,
        outputs=("logits",),
        dynamic=lambda ckpt: {name: {0: "batch"} for name in ("theta", "k", "logits")},
        models=tscvx_models_api,  # what load_checkpoint(models=...) needs for that kind
    )
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from scpformer.files import atomic_path, require_model_path
from scpformer.train.checkpoint import (
    CHECKPOINT_NAME,
    Checkpoint,
    CheckpointError,
    load_checkpoint,
    read_checkpoint,
)
from scpformer.validation import check_int, shown

DEFAULT_TOLERANCE = 1e-4  # max |onnxruntime - PyTorch| accepted (outputs are normalized, O(1))
DEFAULT_OPSET = 17  # ONNX opset (LayerNormalization is in the standard domain from 17)
EXPORT_STEPS = 4  # sequence length traced; the check runs another one


@dataclass(frozen=True, kw_only=True)
class NetworkExport:
    """How one network kind is exported (see the module docstring)."""

    inputs: Callable[[Checkpoint, int, int], dict[str, Tensor]]  # (ckpt, batch, steps) -> inputs
    module: Callable[[nn.Module], nn.Module]  # the model as forward(*inputs) -> outputs
    outputs: tuple[str, ...]  # names of the outputs, in order
    dynamic: Callable[[Checkpoint], dict[str, dict[int, str]]]  # axis names per input/output
    models: Callable[[], Any] | None = None  # models API for load_checkpoint (None: the default)


class SequenceForward(nn.Module):
    """The full-sequence forward of a token-sequence model (ART, GRU, LSTM) without the loss.

    ``forward(rtg, ctg, state, action[, target])`` -> ``action_pred`` (B, T, a) and
    ``state_pred`` (B, T-1, s): the teacher-forced predictions of
    :meth:`scpformer.models.sequence.TokenSequenceModel.forward`, normalized like its inputs.
    """

    def __init__(self, model: nn.Module) -> None:
        super().__init__()
        self.model = model

    def forward(
        self, rtg: Tensor, ctg: Tensor, state: Tensor, action: Tensor, target: Tensor | None = None
    ) -> tuple[Tensor, Tensor]:
        batch = {"rtg": rtg, "ctg": ctg, "state": state, "action": action}
        if target is not None:
            batch["target"] = target  # (B, g)
        predictions, _ = self.model(batch)
        return predictions["action"], predictions["state"]  # (B, T, a), (B, T-1, s)


def sequence_inputs(ckpt: Checkpoint, batch: int, steps: int) -> dict[str, Tensor]:
    """Random normalized tokens of ``batch`` sequences of ``steps`` steps."""
    config = ckpt.config
    steps = min(steps, config.context)
    inputs = {
        "rtg": torch.randn(batch, steps, 1),
        "ctg": torch.randn(batch, steps, 1),
        "state": torch.randn(batch, steps, config.state_dim),
        "action": torch.randn(batch, steps, config.action_dim),
    }
    if config.target_dim:
        inputs["target"] = torch.randn(batch, config.target_dim)
    return inputs


def sequence_axes(ckpt: Checkpoint) -> dict[str, dict[int, str]]:
    """Batch and sequence axes of every input and output (the target has no sequence axis)."""
    axes = {"batch": {0: "batch"}, "sequence": {0: "batch", 1: "steps"}}
    names = ["rtg", "ctg", "state", "action", "action_pred"]
    out = {name: axes["sequence"] for name in names}
    out["state_pred"] = {0: "batch", 1: "steps_minus_1"}
    if ckpt.config.target_dim:
        out["target"] = axes["batch"]
    return out


_SEQUENCE = NetworkExport(
    inputs=sequence_inputs,
    module=SequenceForward,
    outputs=("action_pred", "state_pred"),
    dynamic=sequence_axes,
)
EXPORTS: dict[str, NetworkExport] = {"art": _SEQUENCE, "gru": _SEQUENCE, "lstm": _SEQUENCE}


def _tscvx_models() -> Any:
    from scpformer.models.tscvx import TSCVX_MODELS

    return TSCVX_MODELS


def _theta_input(batch: int) -> Tensor:
    return torch.randn(batch, 16)


def _iteration_input(ckpt: Checkpoint, batch: int) -> Tensor:
    return torch.randint(1, int(ckpt.config.iter_max) + 1, (batch,))


EXPORTS["tscvx-tight"] = NetworkExport(  # f2(theta_std, k) -> logits (B, 7 N)
    inputs=lambda ckpt, b, t: {"theta": _theta_input(b), "k": _iteration_input(ckpt, b)},
    module=lambda model: model,
    outputs=("logits",),
    dynamic=lambda ckpt: {name: {0: "batch"} for name in ("theta", "k", "logits")},
    models=_tscvx_models,
)
EXPORTS["tscvx-solution"] = NetworkExport(  # f1(theta_std) -> standardized (x, u, t_f)
    inputs=lambda ckpt, b, t: {"theta": _theta_input(b)},
    module=lambda model: model,
    outputs=("solution",),
    dynamic=lambda ckpt: {name: {0: "batch"} for name in ("theta", "solution")},
    models=_tscvx_models,
)


@dataclass(frozen=True)
class ExportResult:
    """One exported network and its check."""

    name: str  # sub-folder of the run ("" for a one-network run)
    kind: str
    path: Path  # the .onnx file written
    inputs: dict[str, tuple[int, ...]]  # shapes of the check's inputs
    max_abs_diff: float  # max |onnxruntime - PyTorch| over every output


def run_networks(run: Path | str) -> list[tuple[str, Path]]:
    """(name, checkpoint file) of each network of a run folder or checkpoint file.

    Raises
    ------
    ValueError
        When ``run`` is neither a checkpoint file nor a folder holding ``checkpoint.pt`` or
        sub-folders that do.
    """
    run = require_model_path(run)
    if run.is_file():
        return [("", run)]
    if (run / CHECKPOINT_NAME).is_file():
        return [("", run / CHECKPOINT_NAME)]
    found = sorted(p.parent.name for p in run.glob(f"*/{CHECKPOINT_NAME}"))
    if not found:
        raise ValueError(
            f"--model {run}: not a training run (no {CHECKPOINT_NAME} in it or its sub-folders)"
        )
    return [(name, run / name / CHECKPOINT_NAME) for name in found]


def output_path(onnx_file: Path, name: str) -> Path:
    """``FILE`` for a one-network run, ``FILE`` with ``.name`` before its suffix otherwise."""
    return onnx_file if not name else onnx_file.with_name(f"{onnx_file.stem}.{name}.onnx")


def check_output(onnx_file: Path) -> None:
    """``ValueError`` naming ``--onnx`` when the file cannot be written there."""
    folder = onnx_file.parent
    if onnx_file.suffix != ".onnx":
        raise ValueError(f"--onnx {onnx_file}: the file name must end in .onnx")
    if onnx_file.is_dir():
        raise ValueError(f"--onnx {onnx_file}: is a folder")
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"--onnx {onnx_file}: {folder} is a file, not a folder")
    if not folder.is_dir():
        raise ValueError(f"--onnx {onnx_file}: folder {folder} does not exist")
    if not os.access(folder, os.W_OK):
        raise ValueError(f"--onnx {onnx_file}: folder {folder} is not writable")


def check_opset(opset: int) -> int:
    """``opset`` as an int if the TorchScript exporter writes it and it has LayerNormalization
    (17 on), else ``ValueError`` naming the range."""
    from torch.onnx import _constants  # the exporter's own limit (private; 20 in torch 2.13)

    highest = int(getattr(_constants, "ONNX_TORCHSCRIPT_EXPORTER_MAX_OPSET", 20))
    return check_int("opset", opset, least=17, most=highest)


def export_run(
    run: Path | str,
    onnx_file: Path | str,
    *,
    tolerance: float = DEFAULT_TOLERANCE,
    opset: int = DEFAULT_OPSET,
    seed: int = 0,
) -> list[ExportResult]:
    """Export every network of ``run`` to ONNX and check each with onnxruntime.

    Raises
    ------
    ValueError
        Bad ``run`` or ``onnx_file``, a corrupt checkpoint (:class:`CheckpointError`), a kind
        without an :data:`EXPORTS` entry, a network the ONNX checker refuses, or an ONNX output
        farther than ``tolerance`` from PyTorch's. The file of a network that fails a check is
        not written (an earlier one is kept).
    """
    onnx_file = Path(onnx_file)
    if not tolerance > 0.0:
        raise ValueError(f"tolerance must be positive, got {shown(tolerance)}")
    opset = check_opset(opset)
    check_output(onnx_file)
    networks = run_networks(run)
    checkpoints = [(name, load_for_export(path)) for name, path in networks]
    results = []
    for name, ckpt in checkpoints:
        path = output_path(onnx_file, name)
        results.append(
            export_network(ckpt, path, name=name, opset=opset, seed=seed, tolerance=tolerance)
        )
    return results


def load_for_export(path: Path) -> Checkpoint:
    """The checkpoint at ``path``, rebuilt with its kind's models API."""
    kind = read_checkpoint(path)["kind"]
    if kind not in EXPORTS:
        raise CheckpointError(
            f"{path}: no ONNX export for model kind {kind!r} (known: {', '.join(EXPORTS)})"
        )
    models = EXPORTS[kind].models
    return load_checkpoint(path, models=None if models is None else models())


def export_network(
    ckpt: Checkpoint,
    path: Path,
    *,
    name: str = "",
    opset: int = DEFAULT_OPSET,
    seed: int = 0,
    tolerance: float | None = None,
) -> ExportResult:
    """Write ``ckpt``'s network to ``path`` (atomically) and compare onnxruntime with PyTorch.

    The check's inputs have another batch size (3) and length (the training sequences' N, or
    the context) than the traced ones (2 x :data:`EXPORT_STEPS`), so that a shape frozen
    into the graph shows as a failure. Both checks (the ONNX checker, then onnxruntime
    against PyTorch) run on the temporary file: ``path`` is written only when they pass, and
    an earlier file there is kept otherwise.

    Raises
    ------
    ValueError
        Naming ``path`` when the ONNX checker refuses the network, or onnxruntime differs
        from PyTorch by more than ``tolerance`` (``None``: no limit).
    """
    onnx, ort = _onnx_modules()
    spec = EXPORTS[ckpt.kind]
    module = spec.module(ckpt.model).eval()
    torch.manual_seed(seed)
    example = spec.inputs(ckpt, 2, EXPORT_STEPS)
    with atomic_path(path) as tmp:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the TorchScript exporter's deprecation notices
            torch.onnx.export(
                module,
                tuple(example.values()),
                str(tmp),
                input_names=list(example),
                output_names=list(spec.outputs),
                dynamic_axes=spec.dynamic(ckpt),
                opset_version=opset,
                dynamo=False,
            )
        try:
            onnx.checker.check_model(str(tmp))
        except onnx.checker.ValidationError as err:
            raise ValueError(
                f"{path}: the ONNX checker refused the exported network ({_first_line(err)}); "
                "nothing was written"
            ) from None
        steps = ckpt.n_steps or getattr(ckpt.config, "context", EXPORT_STEPS)
        check = spec.inputs(ckpt, 3, steps)
        diff = max_abs_diff(module, ort.InferenceSession(str(tmp)), check)
        if tolerance is not None and not diff <= tolerance:
            raise ValueError(
                f"{path}: onnxruntime differs from PyTorch by {diff:.3g} "
                f"(tolerance {tolerance:g}); nothing was written"
            )
    shapes = {k: tuple(v.shape) for k, v in check.items()}
    return ExportResult(name, ckpt.kind, path, shapes, diff)


def max_abs_diff(module: nn.Module, session: Any, inputs: Mapping[str, Tensor]) -> float:
    """Largest ``|onnxruntime - PyTorch|`` over every output on the same ``inputs``."""
    with torch.no_grad():
        expected = module(*inputs.values())
    expected = expected if isinstance(expected, tuple | list) else (expected,)
    got = session.run(None, {k: v.numpy() for k, v in inputs.items()})
    diffs = [np.max(np.abs(g - e.numpy()), initial=0.0) for g, e in zip(got, expected, strict=True)]
    return float(max(diffs))


def _first_line(err: BaseException) -> str:
    """The first line of ``err``'s message (at most 200 characters), or its class name."""
    text = str(err).strip()
    return text.splitlines()[0][:200] if text else type(err).__name__


def _onnx_modules() -> tuple[Any, Any]:
    try:
        import onnx
        import onnxruntime
    except ImportError as err:
        raise ValueError(
            f"ONNX export needs onnx and onnxruntime ({err.name} is missing): "
            "pip install 'scpformer[export]'"
        ) from None
    return onnx, onnxruntime
