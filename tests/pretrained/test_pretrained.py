"""The pretrained models shipped in the package: checksums, loading, and the slim copies."""

from __future__ import annotations

import shutil

import pytest
import torch

import scpformer.pretrained as pretrained
from scpformer.cli.main import main
from scpformer.models.tscvx import load_tscvx_predictor
from scpformer.pretrained import (
    FAMILY_MODELS,
    GUIDANCE_MODELS,
    MODEL_FAMILIES,
    PretrainedError,
    default_model,
    model_fingerprint,
    read_manifest,
    verify_model,
)
from scpformer.pretrained.package import MAX_FILE_BYTES
from scpformer.train.checkpoint import load_checkpoint


def test_every_family_has_a_shipped_model_listed_in_the_manifest():
    listed = read_manifest()["models"]
    assert set(listed) == set(MODEL_FAMILIES)
    assert set(MODEL_FAMILIES) == set(FAMILY_MODELS.values()) | set(GUIDANCE_MODELS.values())
    for name, family in MODEL_FAMILIES.items():
        assert listed[name]["family"] == family
        assert (pretrained.PRETRAINED_DIR / name / "MODEL_CARD.md").is_file()


def test_guidance_selects_the_closed_loop_model_where_one_is_shipped():
    """pdg6dof re-plans load the mid-flight networks; the open-loop default and the families
    without a closed-loop model are unchanged."""
    assert default_model("pdg6dof", guidance=True).name == "tscvx-midflight"
    assert default_model("pdg6dof").name == "tscvx"
    assert default_model("rendezvous", guidance=True) == default_model("rendezvous")
    closed_loop = model_fingerprint(None, "pdg6dof", guidance=True)
    assert closed_loop != model_fingerprint(None, "pdg6dof")


@pytest.mark.parametrize("family, frame", [("rendezvous", "rtn"), ("robust-rendezvous", "roe")])
def test_default_art_models_verify_and_load_without_training_state(family, frame):
    ckpt = load_checkpoint(default_model(family), family=family, kind="art")
    assert ckpt.frame == frame and ckpt.normalization is not None
    assert ckpt.extra == {}
    assert all(p.dtype == torch.float32 for p in ckpt.model.parameters())


@pytest.mark.parametrize("guidance", [False, True])
def test_default_tscvx_networks_verify_and_load(guidance):
    predictor = load_tscvx_predictor(default_model("pdg6dof", guidance=guidance))
    assert predictor.n_rows == 7 * predictor.n_nodes


def test_shipped_files_are_a_few_megabytes_at_most():
    for name, entry in read_manifest()["models"].items():
        for relative in entry["files"]:
            assert (pretrained.PRETRAINED_DIR / name / relative).stat().st_size < MAX_FILE_BYTES


@pytest.fixture
def tampered(tmp_path, monkeypatch):
    """A copy of the shipped models with one byte of the rendezvous weights flipped."""
    root = tmp_path / "pretrained"
    shutil.copytree(pretrained.PRETRAINED_DIR, root, ignore=shutil.ignore_patterns("*.py*"))
    path = root / "art-rendezvous" / "checkpoint.pt"
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))
    monkeypatch.setattr(pretrained, "PRETRAINED_DIR", root)
    return path


def test_a_tampered_file_is_a_one_line_error_naming_it(tampered):
    with pytest.raises(PretrainedError, match="SHA-256") as info:
        verify_model("art-rendezvous")
    assert str(tampered) in str(info.value) and "\n" not in str(info.value)
    verify_model("art-robust")  # the other models still verify


def test_a_tampered_default_stops_the_solve_with_one_error_line(tampered, capsys):
    assert main(["solve", "rendezvous", "--warmstart", "art"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("scpformer: error: pretrained model art-rendezvous")
    assert "checkpoint.pt" in err[0]


def test_a_missing_file_is_named(tampered):
    tampered.unlink()
    with pytest.raises(PretrainedError, match="is missing"):
        default_model("rendezvous")


def test_a_models_fingerprint_follows_its_weights_not_its_name(tmp_path):
    """``default``, the shipped folder by path and a copy of it are one model; changing one
    byte of the weights makes another (what keeps a results folder to the model it flew)."""
    shipped = default_model("robust-rendezvous")
    copy = tmp_path / "copy"
    shutil.copytree(shipped, copy)
    digest = model_fingerprint("default", "robust-rendezvous")
    assert model_fingerprint(str(shipped), "robust-rendezvous") == digest
    assert model_fingerprint(str(copy), "robust-rendezvous") == digest
    assert model_fingerprint(str(copy / "checkpoint.pt"), "robust-rendezvous") == digest
    data = bytearray((copy / "checkpoint.pt").read_bytes())
    data[-1] ^= 0xFF
    (copy / "checkpoint.pt").write_bytes(bytes(data))
    assert model_fingerprint(str(copy), "robust-rendezvous") != digest
    assert model_fingerprint(None, "rendezvous") != digest


def test_an_unknown_family_has_no_default():
    with pytest.raises(PretrainedError, match="no pretrained model for family 'pdg3dof'"):
        default_model("pdg3dof")


def test_bench_tscvx_times_the_shipped_networks_with_model_default(capsys):
    from scpformer.cli.main import main

    assert main(["bench", "tscvx", "--model", "default", "--repeats", "3", "--warmup", "1",
                 "--batch", "2"]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "T-SCvx inference (default;" in out and "predict_solution, batch 1" in out
