"""GRU and LSTM baselines: ART's interface, hidden-state generation equal to the full pass."""

import dataclasses

import pytest

torch = pytest.importorskip("torch")

from test_models_art import assert_training_reduces_loss, generate, random_batch  # noqa: E402

from scpformer.models.rnn import RNN_PRESETS, RnnConfig, SequenceRNN  # noqa: E402

TINY = RnnConfig(n_layer=2, n_embd=16, context=12, dropout=0.0)


def tiny_rnn(cell, target_dim=0):
    torch.manual_seed(0)
    return SequenceRNN(dataclasses.replace(TINY, cell=cell, target_dim=target_dim)).eval()


@pytest.mark.parametrize("cell", ["gru", "lstm"])
@pytest.mark.parametrize("target_dim", [0, 6])
def test_generation_from_the_hidden_state_equals_the_full_pass(cell, target_dim):
    model = tiny_rnn(cell, target_dim)
    batch = random_batch(3, 8, target_dim)
    full, loss = model(batch)
    assert full["action"].shape == (3, 8, 3) and full["state"].shape == (3, 7, 6)
    assert torch.isfinite(loss)
    actions, states = generate(model, batch, predict_state_at={2})
    torch.testing.assert_close(actions, full["action"], rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(states[2], full["state"][:, 2], rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("cell", ["gru", "lstm"])
def test_a_gradient_step_reduces_the_rnn_loss(cell):
    torch.manual_seed(0)
    assert_training_reduces_loss(SequenceRNN(dataclasses.replace(TINY, cell=cell)))


def test_unknown_cells_and_sizes_are_errors():
    with pytest.raises(ValueError, match="cell must be one of"):
        RnnConfig(cell="rnn")
    with pytest.raises(ValueError, match="n_embd must be an integer >= 1"):
        RnnConfig(n_embd=0)
    with pytest.raises(TypeError, match="RnnConfig"):
        SequenceRNN(object())
    with pytest.raises(ValueError, match="ART only"):
        tiny_rnn("gru").start(1, bf16=True)


def test_presets_exist_for_both_sizes():
    assert set(RNN_PRESETS) == {"paper", "small"}
    assert RnnConfig(**RNN_PRESETS["small"].to_dict()) == RNN_PRESETS["small"]
