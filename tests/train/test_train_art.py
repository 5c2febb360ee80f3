"""ART training on rendezvous data: one-pass reading, grouped validation, runs, resume."""

import csv
import json

import numpy as np
import pytest
import torch
from train_standins import STANDIN_MODELS, TinyNormalization

from scpformer.data.torch_views import ArtSequenceDataset
from scpformer.train.art import carve_validation, load_art_data, read_sequences
from scpformer.train.art import train_sequence_model as train
from scpformer.train.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from scpformer.train.metrics import METRIC_COLUMNS

FAST = {"batch_size": 4, "lr": 1e-2, "warmup_steps": 0, "device": "cpu"}


def _train(folder, out, epochs, *, kind="art", resume=False, **overrides):
    return train(
        kind, data=folder, out=out, models=STANDIN_MODELS, overrides=FAST | overrides |
        {"epochs": epochs}, resume=resume, progress=False,
    )  # fmt: skip


def _load(folder, frame="rtn", **kwargs):
    return load_art_data(
        folder, frame=frame, normalization_type=TinyNormalization, validation_fraction=0.25,
        seed=3, **kwargs,
    )  # fmt: skip


@pytest.mark.parametrize("frame", ["rtn", "roe"])
def test_one_pass_read_equals_the_views_items(toy_rdv, frame):
    view = ArtSequenceDataset(toy_rdv, "train", frame=frame, normalize=False)
    arrays = read_sequences(view)
    assert len(arrays["state"]) == len(view) > 0
    for i in range(len(view)):
        item = view[i]
        for key in ("rtg", "ctg", "state", "action"):
            np.testing.assert_allclose(arrays[key][i], item[key].numpy(), rtol=1e-6, atol=1e-6)
        assert arrays["base_index"][i] == int(item["base_index"])
        position, twin = view.items[i]
        final = view.samples.read(f"{view.twins[twin]}_{frame}", position)[-1]
        np.testing.assert_allclose(arrays["target"][i], final)


def test_validation_split_is_used_when_the_dataset_has_one(toy_rdv):
    data = _load(toy_rdv)
    view = ArtSequenceDataset(toy_rdv, "validation", normalize=False)
    assert len(data.validation) == len(view) and data.validation_source.endswith("split")
    assert data.train_instances + data.validation_instances == 12  # 0.5 + 0.25 of 16


def test_without_a_validation_split_whole_training_instances_are_held_out(toy_rdv_no_val):
    data = _load(toy_rdv_no_val)
    assert "no validation split" in data.validation_source
    view = ArtSequenceDataset(toy_rdv_no_val, "train", normalize=False)
    bases = read_sequences(view)["base_index"]
    keep, held = carve_validation(bases, 0.25, seed=3)
    assert not set(bases[keep]) & set(bases[held])  # no instance on both sides
    assert len(set(bases[held])) == round(0.25 * len(set(bases)))
    assert np.all(np.bincount(bases[held])[np.unique(bases[held])] == 2)  # both twins held
    assert (len(data.train), len(data.validation)) == (keep.sum(), held.sum())
    again, _ = carve_validation(bases, 0.25, seed=3)
    other, _ = carve_validation(bases, 0.25, seed=4)
    assert np.array_equal(keep, again) and not np.array_equal(keep, other)


def test_training_inputs_are_encoded_by_the_one_normalization_from_training_statistics(toy_rdv):
    data = _load(toy_rdv)
    stats = ArtSequenceDataset(toy_rdv, "train", normalize=True)
    expected = np.stack([stats[i]["state"].numpy() for i in range(len(stats))])
    np.testing.assert_allclose(data.train.tensors["state"].numpy(), expected, atol=1e-5)
    raw = read_sequences(ArtSequenceDataset(toy_rdv, "validation", normalize=False))
    encoded = data.normalization.encode("action", raw["action"])
    np.testing.assert_allclose(data.validation.tensors["action"].numpy(), encoded, rtol=1e-6)


def test_a_run_writes_checkpoint_metrics_plot_and_configuration(toy_rdv, tmp_path):
    result = _train(toy_rdv, tmp_path / "run", 8, lr=3e-2)
    run = tmp_path / "run"
    assert {p.name for p in run.iterdir()} == {
        "checkpoint.pt", "best.pt", "metrics.csv", "loss.png", "config.json"
    }  # fmt: skip
    with (run / "metrics.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert tuple(rows[0]) == METRIC_COLUMNS and len(rows) == 8
    losses = [float(r["val_loss"]) for r in rows]
    assert losses[-1] < 0.5 * losses[0]  # the toy trajectories are learnable
    config = json.loads((run / "config.json").read_text())
    assert config["validation"] == "the dataset's validation split"
    assert config["train"]["epochs"] == 8 and config["model"]["context"] == 8
    loaded = load_checkpoint(run, family="rendezvous", frame="rtn", kind="art", n_steps=8,
                             models=STANDIN_MODELS)  # fmt: skip
    assert loaded.metrics["best_val_loss"] == pytest.approx(min(losses))
    best = load_checkpoint(run / "best.pt", models=STANDIN_MODELS)
    assert best.metrics["epoch"] == result.state.best_epoch


def _killed_in_epoch(epoch, monkeypatch):
    """Make the run die (as on Ctrl-C) when it is about to checkpoint ``epoch``."""
    from scpformer.train import checkpoint

    def save(path, **fields):
        if fields["metrics"]["epoch"] == epoch:
            raise KeyboardInterrupt
        return save_checkpoint(path, **fields)

    monkeypatch.setattr(checkpoint, "save_checkpoint", save)


def _assert_same_weights(run_a, run_b):
    a = load_checkpoint(run_a, models=STANDIN_MODELS)
    b = load_checkpoint(run_b, models=STANDIN_MODELS)
    for name, value in a.model.state_dict().items():
        torch.testing.assert_close(b.model.state_dict()[name], value, rtol=0, atol=0)
    return a, b


def test_resuming_a_killed_run_gives_the_weights_of_an_uninterrupted_run(
    toy_rdv, tmp_path, monkeypatch
):
    straight = _train(toy_rdv, tmp_path / "straight", 3)  # cosine schedule, dropout on
    with monkeypatch.context() as patch:
        _killed_in_epoch(2, patch)
        with pytest.raises(KeyboardInterrupt):
            _train(toy_rdv, tmp_path / "killed", 3)
    resumed = _train(toy_rdv, tmp_path / "killed", 3, resume=True)
    assert resumed.resumed_from == 1 and resumed.state.epoch == 3
    a, b = _assert_same_weights(tmp_path / "straight", tmp_path / "killed")
    losses = [(r.train_loss, r.val_loss, r.lr) for r in straight.state.history]
    assert [(r.train_loss, r.val_loss, r.lr) for r in resumed.state.history] == losses
    optimizer = (a.extra["optimizer"]["state"], b.extra["optimizer"]["state"])
    for key, state in optimizer[0].items():
        torch.testing.assert_close(optimizer[1][key]["exp_avg_sq"], state["exp_avg_sq"])


def test_two_epochs_equal_one_epoch_then_one_resumed_epoch(toy_rdv, tmp_path):
    constant = {"schedule": "constant", "warmup_steps": 3}  # the paper's: no decay
    _train(toy_rdv, tmp_path / "straight", 2, **constant)
    _train(toy_rdv, tmp_path / "split", 1, **constant)
    resumed = _train(toy_rdv, tmp_path / "split", 2, resume=True, **constant)
    assert resumed.resumed_from == 1
    _assert_same_weights(tmp_path / "straight", tmp_path / "split")


def test_an_existing_run_is_not_overwritten_and_resumes_only_as_itself(toy_rdv, tmp_path):
    _train(toy_rdv, tmp_path / "run", 1)
    with pytest.raises(ValueError, match="pass --resume"):
        _train(toy_rdv, tmp_path / "run", 2)
    with pytest.raises(CheckpointError, match="kind 'art', not 'gru'"):
        _train(toy_rdv, tmp_path / "run", 2, kind="gru", resume=True)
    with pytest.raises(ValueError, match=r"--resume: .*new holds no training run to resume"):
        _train(toy_rdv, tmp_path / "new", 1, resume=True)  # nothing to resume
    assert not (tmp_path / "new").exists()
    result = _train(toy_rdv, tmp_path / "new", 1)
    assert result.resumed_from == 0
    (tmp_path / "new" / "checkpoint.pt").unlink()  # a run that lost its checkpoint
    kept = {f.name: f.read_bytes() for f in (tmp_path / "new").iterdir() if f.is_file()}
    with pytest.raises(ValueError, match=r"holds no checkpoint\.pt to resume from"):
        _train(toy_rdv, tmp_path / "new", 2, resume=True)
    assert {f.name: f.read_bytes() for f in (tmp_path / "new").iterdir() if f.is_file()} == kept
    with pytest.raises(ValueError, match="only epochs and device may change, not lr"):
        _train(toy_rdv, tmp_path / "run", 2, resume=True, lr=0.5)
    (tmp_path / "run2").mkdir()
    _train(toy_rdv, tmp_path / "run2", 2)
    config = (tmp_path / "run2" / "config.json").read_bytes()
    with pytest.raises(ValueError, match="--epochs 1: the run to resume has finished 2 epochs"):
        _train(toy_rdv, tmp_path / "run2", 1, resume=True)
    assert (tmp_path / "run2" / "config.json").read_bytes() == config  # not rewritten
    with pytest.raises(ValueError, match="used preset 'small', not 'paper'"):
        train("art", data=toy_rdv, out=tmp_path / "run", preset="paper", resume=True,
              models=STANDIN_MODELS)  # fmt: skip


def test_resuming_on_other_data_or_other_splits_is_refused(
    toy_rdv, toy_rdv_no_val, toy_robust, tmp_path
):
    _train(toy_rdv, tmp_path / "run", 1)
    for other in (toy_rdv_no_val, toy_robust):  # same instances split otherwise; other data
        with pytest.raises(ValueError, match="other data or splits"):
            _train(other, tmp_path / "run", 2, resume=True)


def test_robust_rendezvous_models_get_the_target_token(toy_robust, tmp_path):
    result = _train(toy_robust, tmp_path / "run", 1)
    assert result.model_config["target_dim"] == 6
    assert result.data.train.tensors["target"].shape[1:] == (6,)
    loaded = load_checkpoint(tmp_path / "run", family="robust-rendezvous", models=STANDIN_MODELS)
    assert loaded.config.target_dim == 6


def test_training_learns_from_the_named_twins_only_and_resumes_with_them(toy_rdv_tpbvp, tmp_path):
    default = _load(toy_rdv_tpbvp)
    assert default.twins == ("scp", "cvx")  # the Problem 1 twin is a reference by default
    tpbvp = _load(toy_rdv_tpbvp, twins=["tpbvp"])
    view = ArtSequenceDataset(toy_rdv_tpbvp, "train", twins=["tpbvp"], normalize=False)
    assert tpbvp.twins == ("tpbvp",) and len(tpbvp.train) == len(view)

    def run(epochs, **kwargs):
        overrides = FAST | {"epochs": epochs}
        return train("art", data=toy_rdv_tpbvp, out=tmp_path / "run", models=STANDIN_MODELS,
                     overrides=overrides, progress=False, **kwargs)  # fmt: skip

    assert run(1, twins=["tpbvp"]).data.twins == ("tpbvp",)
    assert json.loads((tmp_path / "run" / "config.json").read_text())["twins"] == ["tpbvp"]
    resumed = run(2, resume=True)
    assert resumed.data.twins == ("tpbvp",) and resumed.resumed_from == 1
    with pytest.raises(ValueError, match=r"learned from twins \('tpbvp',\), not \('cvx',\)"):
        run(3, resume=True, twins=["cvx"])
