"""Checkpoints: a round trip restores everything; every mismatch or damage is a one-line error."""

import fractions

import numpy as np
import pytest
import torch
from train_standins import STANDIN_MODELS, TinyNormalization, build_model, preset

from scpformer.train import checkpoint as ckpt
from scpformer.train.checkpoint import CheckpointError, load_checkpoint, save_checkpoint


@pytest.fixture
def normalization():
    rng = np.random.default_rng(0)
    return TinyNormalization(
        state_mean=rng.normal(size=(8, 6)),
        state_std=rng.uniform(1, 2, size=(8, 6)),
        action_mean=rng.normal(size=(8, 3)),
        action_std=rng.uniform(1, 2, size=(8, 3)),
        rtg_scale=12.5,
        ctg_scale=8.0,
        target_mean=rng.normal(size=6),
        target_std=rng.uniform(1, 2, size=6),
    )


def _save(path, normalization, *, kind="art", config=None, **changes):
    torch.manual_seed(0)
    config = config or preset(kind, "small", context=8)
    model = build_model(kind, config)
    fields = dict(
        model=model,
        kind=kind,
        config=config,
        normalization=normalization,
        frame="rtn",
        family="rendezvous",
        manifest_digest="ab" * 32,
        seed=7,
        metrics={"best_val_loss": 0.25, "epoch": 3},
        n_steps=8,
        extra={"rng": {"numpy": np.random.get_state(legacy=False)}},  # noqa: NPY002
    )
    save_checkpoint(path, **(fields | changes))
    return model


def _load(path, **kwargs):
    return load_checkpoint(path, models=STANDIN_MODELS, **kwargs)


def test_round_trip_restores_weights_configuration_normalization_and_identity(
    tmp_path, normalization
):
    model = _save(tmp_path, normalization)
    loaded = _load(tmp_path)  # the run folder
    assert (tmp_path / "checkpoint.pt").is_file() and loaded.path == tmp_path / "checkpoint.pt"
    assert loaded.kind == "art" and loaded.config == model.config
    assert not loaded.model.training
    for name, value in model.state_dict().items():
        torch.testing.assert_close(loaded.model.state_dict()[name], value, rtol=0, atol=0)
    for name, value in normalization.to_dict().items():
        np.testing.assert_array_equal(getattr(loaded.normalization, name), value)
    assert loaded.normalization.state_mean.dtype == np.float64
    assert (loaded.frame, loaded.family, loaded.seed, loaded.n_steps) == ("rtn", "rendezvous", 7, 8)
    assert loaded.manifest_digest == "ab" * 32 and loaded.package_version
    assert loaded.metrics == {"best_val_loss": 0.25, "epoch": 3}
    key = loaded.extra["rng"]["numpy"]["state"]["key"]
    assert key.dtype == np.uint32 and len(key) == 624


def test_a_slim_copy_drops_the_training_state_and_loads_the_same_model(tmp_path, normalization):
    model = _save(tmp_path / "run", normalization)
    slim = ckpt.slim_checkpoint(tmp_path / "run", tmp_path / "slim")
    assert slim == tmp_path / "slim" / "checkpoint.pt"
    loaded = _load(slim)
    assert loaded.extra == {} and _load(tmp_path / "run").extra
    assert (loaded.seed, loaded.n_steps, loaded.metrics["epoch"]) == (7, 8, 3)
    for name, value in model.state_dict().items():
        torch.testing.assert_close(loaded.model.state_dict()[name], value, rtol=0, atol=0)
    assert slim.stat().st_size < (tmp_path / "run" / "checkpoint.pt").stat().st_size


def test_a_new_run_folder_gets_its_checkpoint_file(tmp_path, normalization):
    _save(tmp_path / "run", normalization)
    assert (tmp_path / "run" / "checkpoint.pt").is_file()
    assert _load(tmp_path / "run").path == tmp_path / "run" / "checkpoint.pt"


def test_checkpoint_loads_with_weights_only(tmp_path, normalization):
    _save(tmp_path, normalization)
    payload = torch.load(tmp_path / "checkpoint.pt", weights_only=True)
    assert payload["format"] == ckpt.FORMAT and payload["kind"] == "art"


def test_a_model_without_normalization_round_trips(tmp_path):
    _save(tmp_path / "x.pt", None, frame=None, family="pdg6dof", n_steps=None)
    loaded = _load(tmp_path / "x.pt", family="pdg6dof")
    assert loaded.normalization is None and loaded.frame is None


@pytest.mark.parametrize(
    ("check", "message"),
    [
        ({"family": "robust-rendezvous"}, "family 'rendezvous', not 'robust-rendezvous'"),
        ({"frame": "roe"}, "frame 'rtn', not 'roe'"),
        ({"kind": "gru"}, "kind 'art', not 'gru'"),
        ({"n_steps": 100}, "n_steps 8, not 100"),
        ({"n_steps": np.int64(100)}, "n_steps 8, not 100"),
    ],
)
def test_a_checkpoint_of_another_family_frame_kind_or_length_is_refused(
    tmp_path, normalization, check, message
):
    _save(tmp_path, normalization)
    with pytest.raises(CheckpointError, match=message) as err:
        _load(tmp_path, **check)
    assert "\n" not in str(err.value) and "np." not in str(err.value)


def test_weights_of_another_shape_are_refused(tmp_path, normalization):
    small = build_model("art", preset("art", "small", context=8))
    _save(tmp_path, normalization, model=small, config=preset("art", "paper", context=8))
    with pytest.raises(CheckpointError, match="weights do not fit") as err:
        _load(tmp_path)
    assert "\n" not in str(err.value)


def test_a_truncated_checkpoint_is_refused(tmp_path, normalization):
    _save(tmp_path, normalization)
    path = tmp_path / "checkpoint.pt"
    data = path.read_bytes()
    for cut, cause in ((len(data) // 2, "truncated"), (100, "truncated"), (0, "empty")):
        path.write_bytes(data[:cut])
        with pytest.raises(CheckpointError, match="not a readable scpformer checkpoint") as err:
            _load(tmp_path)
        assert cause in str(err.value)
        assert "\n" not in str(err.value)


def test_files_that_are_not_checkpoints_are_refused(tmp_path):
    text = tmp_path / "notes.pt"
    text.write_text("hello\n")
    with pytest.raises(CheckpointError, match="text starting 'hello'"):
        _load(text)
    binary = tmp_path / "binary.pt"
    binary.write_bytes(b"\x00\x01garbage")
    with pytest.raises(CheckpointError, match="not a readable") as err:
        _load(binary)
    assert "another binary format" in str(err.value)  # the cause, not the unpickler's opcodes
    assert "weights_only" not in str(err.value)
    tensor = tmp_path / "tensor.pt"
    torch.save({"weights": torch.zeros(3)}, tensor)
    with pytest.raises(CheckpointError, match="not an scpformer checkpoint"):
        _load(tensor)
    with pytest.raises(CheckpointError, match="no checkpoint at"):
        _load(tmp_path / "missing")


def test_an_archive_that_holds_no_weights_names_the_unpickler_cause(tmp_path):
    path = tmp_path / "checkpoint.pt"
    torch.save({"format": "scpformer", "value": fractions.Fraction(1, 3)}, path)
    with pytest.raises(CheckpointError, match="does not load as weights only") as err:
        _load(path)
    assert "fractions.Fraction" in str(err.value)  # the unpickler's cause, not its advice
    assert "Please use" not in str(err.value)
    assert "\n" not in str(err.value)


def test_a_checkpoint_of_another_format_version_is_refused(tmp_path, normalization):
    _save(tmp_path, normalization)
    payload = torch.load(tmp_path / "checkpoint.pt", weights_only=True)
    torch.save(payload | {"format_version": 99}, tmp_path / "checkpoint.pt")
    with pytest.raises(CheckpointError, match="format 99"):
        _load(tmp_path)


def test_a_failed_write_leaves_the_previous_checkpoint_intact(tmp_path, normalization, monkeypatch):
    _save(tmp_path, normalization, seed=1)
    before = (tmp_path / "checkpoint.pt").read_bytes()

    def torch_save_dies_halfway(obj, fh):
        fh.write(b"PK\x03\x04 partial")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(ckpt.torch, "save", torch_save_dies_halfway)
    with pytest.raises(OSError, match="No space left"):
        _save(tmp_path, normalization, seed=2)
    monkeypatch.undo()
    assert (tmp_path / "checkpoint.pt").read_bytes() == before
    assert _load(tmp_path).seed == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["checkpoint.pt"]  # no temp left
