"""build_model, preset and config_from_dict: every kind, round trips, clear errors."""

import pytest

torch = pytest.importorskip("torch")

from scpformer.models import (  # noqa: E402
    MODEL_KINDS,
    ArtConfig,
    RnnConfig,
    build_model,
    config_from_dict,
    preset,
)


@pytest.mark.parametrize("kind", MODEL_KINDS)
def test_every_kind_builds_from_its_small_preset_and_round_trips(kind):
    config = preset(kind, "small", target_dim=6)
    model = build_model(kind, config)
    assert model.config == config and config.target_dim == 6
    assert config_from_dict(kind, config.to_dict()) == config


def test_recurrent_presets_carry_their_cell():
    assert preset("lstm", "paper").cell == "lstm"
    assert isinstance(preset("gru", "small"), RnnConfig)
    assert isinstance(preset("art", "paper"), ArtConfig)


def test_bad_kinds_presets_and_fields_are_errors():
    with pytest.raises(ValueError, match="kind must be one of"):
        preset("mamba", "small")
    with pytest.raises(ValueError, match="preset must be one of"):
        preset("art", "huge")
    with pytest.raises(ValueError, match=r"unknown ArtConfig field\(s\) \['n_heads'\]"):
        preset("art", "small", n_heads=2)
    with pytest.raises(ValueError, match="contradicts kind"):
        config_from_dict("gru", {"cell": "lstm"})
    with pytest.raises(TypeError, match="RnnConfig"):
        build_model("gru", preset("art", "small"))
