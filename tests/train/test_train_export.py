import os

import numpy as np
import onnxruntime
import pytest
import torch

from scpformer.cli.main import main
from scpformer.models import build_model, preset
from scpformer.train import export as export_module
from scpformer.train.checkpoint import CheckpointError, save_checkpoint
from scpformer.train.export import SequenceForward, check_opset, export_run, run_networks

TINY = {"n_layer": 1, "n_embd": 12, "context": 10}


def save_tiny(run, kind, **overrides):
    """A randomly initialized tiny model saved as a training run would save it."""
    extra = {"n_head": 2} if kind == "art" else {}
    config = preset(kind, "small", **TINY, **extra, **overrides)
    torch.manual_seed(1)
    model = build_model(kind, config)
    save_checkpoint(
        run, model=model, kind=kind, config=config, normalization=None, frame="rtn",
        family="rendezvous", manifest_digest="0" * 64, seed=0, n_steps=6,
    )  # fmt: skip
    return model.eval()


KINDS = [("art", {}), ("gru", {}), ("lstm", {}), ("art", {"target_dim": 6})]


@pytest.mark.parametrize(("kind", "overrides"), KINDS)
def test_exported_networks_match_pytorch_on_other_batch_sizes_and_lengths(
    tmp_path, kind, overrides
):
    model = save_tiny(tmp_path / "run", kind, **overrides)
    (result,) = export_run(tmp_path / "run", tmp_path / "net.onnx")
    assert result.path == tmp_path / "net.onnx" and result.max_abs_diff < 1e-5
    assert result.inputs["state"] == (3, 6, 6)  # checked on the training length, not the traced
    session = onnxruntime.InferenceSession(str(result.path))
    for batch, steps in ((1, 1), (5, 10)):
        rng = np.random.default_rng(batch)
        inputs = {
            "rtg": rng.normal(size=(batch, steps, 1)),
            "ctg": rng.normal(size=(batch, steps, 1)),
            "state": rng.normal(size=(batch, steps, 6)),
            "action": rng.normal(size=(batch, steps, 3)),
        }
        if overrides:
            inputs["target"] = rng.normal(size=(batch, 6))
        inputs = {k: v.astype(np.float32) for k, v in inputs.items()}
        action, state = session.run(None, inputs)
        with torch.no_grad():
            want = SequenceForward(model)(*(torch.from_numpy(v) for v in inputs.values()))
        assert action.shape == (batch, steps, 3) and state.shape == (batch, steps - 1, 6)
        np.testing.assert_allclose(action, want[0].numpy(), atol=1e-5)
        np.testing.assert_allclose(state, want[1].numpy(), atol=1e-5)


def test_a_run_with_sub_folders_exports_one_file_per_network(tmp_path, capsys):
    save_tiny(tmp_path / "run" / "tight", "gru")
    save_tiny(tmp_path / "run" / "solution", "lstm")
    assert [n for n, _ in run_networks(tmp_path / "run")] == ["solution", "tight"]
    assert (
        main(["export", "--model", str(tmp_path / "run"), "--onnx", str(tmp_path / "t.onnx")]) == 0
    )
    assert (tmp_path / "t.tight.onnx").is_file() and (tmp_path / "t.solution.onnx").is_file()
    out = capsys.readouterr().out
    assert "t.tight.onnx (gru): max |onnxruntime - PyTorch| = " in out


def test_a_difference_above_the_tolerance_fails_naming_the_file(tmp_path, monkeypatch):
    save_tiny(tmp_path / "run", "gru")
    monkeypatch.setattr(export_module, "max_abs_diff", lambda *args: 0.5)
    with pytest.raises(ValueError, match=r"net.onnx: onnxruntime differs from PyTorch by 0.5"):
        export_run(tmp_path / "run", tmp_path / "net.onnx")


def test_bad_input_is_a_one_line_error(tmp_path, capsys):
    save_tiny(tmp_path / "run", "gru")
    (tmp_path / "empty").mkdir()
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "checkpoint.pt").write_bytes(b"not a checkpoint")
    (tmp_path / "ro").mkdir(mode=0o500)
    cases = [
        (tmp_path / "nothing", tmp_path / "a.onnx", "no such run folder or checkpoint file"),
        (tmp_path / "empty", tmp_path / "a.onnx", "not a training run (no checkpoint.pt"),
        (tmp_path / "bad", tmp_path / "a.onnx", "is not a readable scpformer checkpoint"),
        (tmp_path / "run", tmp_path / "no" / "a.onnx", "folder " + str(tmp_path / "no")),
        (tmp_path / "run", tmp_path / "a.txt", "must end in .onnx"),
    ]
    if os.geteuid() != 0:  # root may write into a read-only folder
        cases.append((tmp_path / "run", tmp_path / "ro" / "a.onnx", "is not writable"))
    for run, onnx_file, message in cases:
        assert main(["export", "--model", str(run), "--onnx", str(onnx_file)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], (run, err)
    with pytest.raises(CheckpointError, match="is not a readable"):
        export_run(tmp_path / "bad", tmp_path / "a.onnx")
    for opset in ("5", "99"):  # before LayerNormalization; beyond the exporter
        argv = ["export", "--model", str(tmp_path / "run"), "--onnx", str(tmp_path / "a.onnx")]
        assert main([*argv, "--opset", opset]) == 2
        captured = capsys.readouterr()
        err = captured.err.strip().splitlines()
        assert len(err) == 1 and "opset must be an integer from 17 to" in err[0], err
        assert captured.out == ""  # no graph dumped


def test_a_kind_without_an_export_entry_is_an_error_naming_it(tmp_path):
    model = build_model("gru", preset("gru", "small", **TINY))
    save_checkpoint(
        tmp_path, model=model, kind="mlp", config={}, normalization=None, frame=None,
        family="pdg6dof", manifest_digest="0" * 64, seed=0,
    )  # fmt: skip
    with pytest.raises(CheckpointError, match="no ONNX export for model kind 'mlp'"):
        export_run(tmp_path, tmp_path / "a.onnx")


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda tmp: check_opset(np.int64(5)), "opset must be an integer from 17 to"),
        (lambda tmp: check_opset(np.float64(18.0)), "got float64 18.0"),
        (
            lambda tmp: export_run(tmp / "run", tmp / "a.onnx", tolerance=np.float64(-1.0)),
            "tolerance must be positive, got -1.0",
        ),
    ],
)
def test_numpy_arguments_are_printed_as_plain_numbers(tmp_path, call, message):
    with pytest.raises(ValueError) as err:
        call(tmp_path)
    assert message in str(err.value) and "np." not in str(err.value)
