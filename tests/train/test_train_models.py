"""Training the real scpformer.models (ART, GRU, LSTM) end to end, shrunk to test size."""

import dataclasses
from types import SimpleNamespace

import pytest
import torch

models = pytest.importorskip("scpformer.models", reason="scpformer.models is not merged yet")

from scpformer.train.art import train_sequence_model  # noqa: E402
from scpformer.train.checkpoint import load_checkpoint  # noqa: E402
from scpformer.train.distributed import World  # noqa: E402
from scpformer.train.loop import evaluate  # noqa: E402
from scpformer.train.models_api import default_models  # noqa: E402

TINY = {"art": {"n_layer": 1, "n_head": 2, "n_embd": 16}, "gru": {"n_layer": 1, "n_embd": 16}}


def _tiny_models():
    """The real models API whose presets are shrunk to a few thousand parameters."""
    real = default_models()

    def tiny_preset(kind, name, **overrides):
        return real.preset(kind, name, **(TINY.get(kind, TINY["gru"]) | overrides))

    return SimpleNamespace(**(vars(real) | {"preset": tiny_preset}))


@pytest.mark.parametrize("kind", ["art", "gru", "lstm"])
def test_real_models_train_and_come_back_from_their_checkpoint(toy_rdv, tmp_path, kind):
    api = _tiny_models()
    overrides = {"epochs": 2, "batch_size": 4, "lr": 3e-3, "device": "cpu"}
    result = train_sequence_model(
        kind, data=toy_rdv, out=tmp_path, models=api, overrides=overrides, progress=False
    )
    assert len(result.state.history) == 2
    loaded = load_checkpoint(tmp_path, family="rendezvous", frame="rtn", kind=kind, models=api)
    assert dataclasses.asdict(loaded.config) == result.model_config
    assert type(loaded.normalization) is api.ArtNormalization
    val_loss, _ = evaluate(loaded.model, result.data.validation, result.train_config, World(),
                           torch.device("cpu"))  # fmt: skip
    assert val_loss == pytest.approx(result.state.history[-1].val_loss, rel=1e-5)


def test_real_art_on_robust_data_takes_the_target_token(toy_robust, tmp_path):
    api = _tiny_models()
    result = train_sequence_model(
        "art", data=toy_robust, out=tmp_path, models=api,
        overrides={"epochs": 1, "batch_size": 4, "device": "cpu"}, progress=False,
    )  # fmt: skip
    loaded = load_checkpoint(tmp_path, family="robust-rendezvous", models=api)
    assert loaded.config.target_dim == 6 and loaded.normalization.target_mean.shape == (6,)
    assert result.data.train.tensors["target"].shape[1:] == (6,)
