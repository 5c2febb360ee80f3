"""ART: shapes, Eq. 8 loss, causal mask, cached generation equal to the full forward."""

import dataclasses

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from scpformer.models.art import ART, ART_PRESETS, TRAIN_DEFAULTS, ArtConfig  # noqa: E402
from scpformer.models.capabilities import unavailable_reason  # noqa: E402

TINY = ArtConfig(n_layer=2, n_head=2, n_embd=16, context=12, dropout=0.0)


def random_batch(b, t, target_dim=0, seed=0):
    gen = torch.Generator().manual_seed(seed)
    sizes = {"rtg": 1, "ctg": 1, "state": 6, "action": 3}
    batch = {key: torch.randn(b, t, d, generator=gen) for key, d in sizes.items()}
    if target_dim:
        batch["target"] = torch.randn(b, target_dim, generator=gen)
    return batch


def tiny_model(target_dim=0, **changes):
    torch.manual_seed(0)
    return ART(dataclasses.replace(TINY, target_dim=target_dim, **changes)).eval()


def generate(model, batch, predict_state_at=()):
    """Algorithm 2's calls over the teacher-forced tokens: actions (B, T, 3) and x_hat."""
    b, t = batch["state"].shape[:2]
    cache = model.start(b, batch.get("target"))
    actions, states = [], {}
    for i in range(t):
        step = {key: batch[key][:, i] for key in ("rtg", "ctg", "state")}
        actions.append(model.predict_action(cache, step["rtg"], step["ctg"], step["state"]))
        if i in predict_state_at:
            states[i] = model.predict_state(cache, batch["action"][:, i])
        else:
            model.feed_action(cache, batch["action"][:, i])
    return torch.stack(actions, 1), states


def test_paper_preset_is_table_4_with_about_11_million_parameters():
    paper = ART_PRESETS["paper"]
    assert (paper.n_layer, paper.n_head, paper.n_embd, paper.context) == (6, 6, 384, 100)
    assert (paper.dropout, paper.activation) == (0.1, "relu")
    assert 10.5e6 < ART(paper).num_parameters() < 11e6
    assert TRAIN_DEFAULTS["learning_rate"] == 3e-5 and TRAIN_DEFAULTS["grad_clip"] == 1.0
    assert TRAIN_DEFAULTS["grad_accumulation"] == 8


@pytest.mark.parametrize("target_dim", [0, 6])
def test_forward_predicts_every_control_and_every_next_state(target_dim):
    model = tiny_model(target_dim)
    predictions, loss = model(random_batch(3, 5, target_dim))
    assert predictions["action"].shape == (3, 5, 3)
    assert predictions["state"].shape == (3, 4, 6)
    assert loss.shape == () and torch.isfinite(loss)


def test_loss_is_the_mean_squared_error_of_controls_plus_next_states():
    model = tiny_model()
    batch = random_batch(2, 4)
    predictions, loss = model(batch)
    action_mse = ((predictions["action"] - batch["action"]) ** 2).mean()
    state_mse = ((predictions["state"] - batch["state"][:, 1:]) ** 2).mean()
    torch.testing.assert_close(loss, action_mse + state_mse)


def test_masked_loss_counts_only_valid_steps():
    model = tiny_model()
    batch = random_batch(2, 4)
    mask = torch.tensor([[True, True, True, False], [True, True, False, False]])
    predictions, loss = model({**batch, "mask": mask})
    a_err = ((predictions["action"] - batch["action"]) ** 2).sum(-1)  # (2, 4)
    s_err = ((predictions["state"] - batch["state"][:, 1:]) ** 2).sum(-1)  # (2, 3)
    pair = mask[:, 1:] & mask[:, :-1]
    expected = a_err[mask].sum() / (3 * mask.sum()) + s_err[pair].sum() / (6 * pair.sum())
    torch.testing.assert_close(loss, expected)


def test_a_target_of_shape_b_g_equals_it_repeated_at_every_step():
    model = tiny_model(6)
    batch = random_batch(2, 4, 6)
    per_step = {**batch, "target": batch["target"][:, None].expand(-1, 4, -1)}
    torch.testing.assert_close(model(batch)[0]["action"], model(per_step)[0]["action"])


@pytest.mark.parametrize("target_dim", [0, 6])
def test_changing_a_later_token_leaves_earlier_predictions_unchanged(target_dim):
    model = tiny_model(target_dim)
    batch = random_batch(2, 6, target_dim)
    before = model(batch)[0]
    for key in ("rtg", "ctg", "state", "action"):
        changed = {k: v.clone() for k, v in batch.items()}
        changed[key][:, 3] += 10.0
        after = model(changed)[0]
        # u_hat(t_i) reads tokens up to x(t_i); x_hat(t_{i+1}) up to u(t_i)
        first_action = 3 if key != "action" else 4
        torch.testing.assert_close(
            after["action"][:, :first_action], before["action"][:, :first_action]
        )
        torch.testing.assert_close(after["state"][:, :3], before["state"][:, :3])
        assert not torch.allclose(after["action"][:, 4:], before["action"][:, 4:])


@pytest.mark.parametrize("target_dim", [0, 6])
def test_cached_generation_equals_the_full_forward_for_a_batch(target_dim):
    model = tiny_model(target_dim)
    batch = random_batch(3, 9, target_dim)
    full = model(batch)[0]
    actions, states = generate(model, batch, predict_state_at={0, 4, 8})
    torch.testing.assert_close(actions, full["action"], rtol=1e-5, atol=1e-5)
    for i in (0, 4):
        torch.testing.assert_close(states[i], full["state"][:, i], rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("batch_size", [2, 9])  # 9: linear layers on oneDNN when available
def test_cached_generation_with_gelu_equals_the_full_forward(batch_size):
    model = tiny_model(activation="gelu")
    batch = random_batch(batch_size, 5)
    actions, _ = generate(model, batch)
    torch.testing.assert_close(actions, model(batch)[0]["action"], rtol=1e-5, atol=1e-5)


def test_cached_generation_of_the_small_preset_equals_the_full_forward():
    torch.manual_seed(1)
    model = ART(dataclasses.replace(ART_PRESETS["small"], context=20)).eval()
    batch = random_batch(2, 20)
    actions, _ = generate(model, batch)
    torch.testing.assert_close(actions, model(batch)[0]["action"], rtol=1e-4, atol=1e-5)


def test_generation_is_independent_across_the_batch():
    model = tiny_model()
    batch = random_batch(3, 5)
    alone = {k: v[1:2] for k, v in batch.items()}
    torch.testing.assert_close(generate(model, batch)[0][1:2], generate(model, alone)[0])


def test_generation_steps_out_of_order_are_errors():
    model = tiny_model()
    cache = model.start(1)
    x, r = torch.zeros(1, 6), torch.zeros(1, 1)
    with pytest.raises(ValueError, match="must follow predict_action"):
        model.predict_state(cache, torch.zeros(1, 3))
    model.predict_action(cache, r, r, x)
    with pytest.raises(ValueError, match="called twice"):
        model.predict_action(cache, r, r, x)
    short = model.start(1, max_steps=1)
    model.predict_action(short, r, r, x)
    model.feed_action(short, torch.zeros(1, 3))
    with pytest.raises(ValueError, match="holds 1 steps"):
        model.predict_action(short, r, r, x)


def test_target_must_match_the_configuration():
    with pytest.raises(ValueError, match="target_dim = 0"):
        tiny_model().start(1, torch.zeros(1, 6))
    with pytest.raises(ValueError, match=r"target must be \(2, 6\)"):
        tiny_model(6).start(2)
    with pytest.raises(ValueError, match="batch\\['target'\\]"):
        tiny_model(6)(random_batch(2, 3))


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"n_embd": 10, "n_head": 3}, "divisible by n_head"),
        ({"n_layer": 0}, "n_layer must be an integer >= 1"),
        ({"dropout": 1.0}, "dropout"),
        ({"activation": "tanh"}, "activation"),
        ({"target_dim": -1}, "target_dim"),
    ],
)
def test_bad_configurations_are_errors_naming_the_field(changes, message):
    with pytest.raises(ValueError, match=message):
        dataclasses.replace(TINY, **changes)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: dataclasses.replace(TINY, dropout=np.float64(1.0)), "in [0, 1), got 1.0"),
        (lambda: dataclasses.replace(TINY, attn_dropout=np.float64(1.0)), "in [0, 1), got 1.0"),
        (lambda: dataclasses.replace(TINY, attn_dropout=np.float32(0.5)), "got float32 0.5"),
        (lambda: tiny_model().start(np.int64(0)), "batch_size must be an integer >= 1, got 0"),
        (lambda: tiny_model().start(1, max_steps=np.float64(2)), "1 to 12, got float64 2.0"),
    ],
)
def test_numpy_values_are_printed_as_plain_numbers(make, message):
    with pytest.raises(ValueError) as err:
        make()
    assert message in str(err.value) and "np." not in str(err.value)


def test_bad_batches_are_errors_naming_the_key():
    model = tiny_model()
    batch = random_batch(2, 3)
    with pytest.raises(ValueError, match="batch\\['action'\\]"):
        model({**batch, "action": torch.zeros(2, 3, 4)})
    with pytest.raises(ValueError, match="longer than the context"):
        model(random_batch(1, 13))
    with pytest.raises(ValueError, match="'ctg'"):
        model({k: v for k, v in batch.items() if k != "ctg"})


def assert_training_reduces_loss(model):
    """Five AdamW steps on one fixed batch lower its loss."""
    model.train()
    batch = random_batch(4, 6)
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-2)
    before = model(batch)[1]
    for _ in range(5):
        optimizer.zero_grad()
        model(batch)[1].backward()
        optimizer.step()
    assert model(batch)[1] < before


def test_a_gradient_step_reduces_the_loss_on_a_fixed_batch():
    torch.manual_seed(0)
    assert_training_reduces_loss(ART(TINY))


def test_config_round_trips_through_its_dict():
    config = dataclasses.replace(TINY, target_dim=6)
    assert ArtConfig(**config.to_dict()) == config


@pytest.mark.parametrize("batch_size", [2, 9])  # 9: linear layers on oneDNN when available
def test_generation_with_prepacked_weights_follows_weight_updates(batch_size):
    model = tiny_model(6)
    batch = random_batch(batch_size, 6, 6)
    for _ in range(2):
        actions, _ = generate(model, batch)
        torch.testing.assert_close(actions, model(batch)[0]["action"], rtol=1e-5, atol=1e-5)
        with torch.no_grad():
            for p in model.parameters():
                p.mul_(1.5)  # in place, as an optimizer step: the packed copies must follow


def teacher_forced_actions(model, batch, **weights):
    b, t = batch["state"].shape[:2]
    cache = model.start(b, **weights)
    actions = []
    for i in range(t):
        step = [batch[key][:, i] for key in ("rtg", "ctg", "state")]
        actions.append(model.predict_action(cache, *step))
        model.feed_action(cache, batch["action"][:, i])
    return torch.stack(actions, 1)


def needs(weights):
    """Skip where this CPU cannot run ``weights`` kernels (saying why)."""
    reason = unavailable_reason(weights)
    return pytest.mark.skipif(reason is not None, reason=f"{weights} kernels: {reason}")


@pytest.mark.parametrize(
    ("weights", "tolerance"),
    [
        pytest.param("bf16", 2e-2, marks=needs("bf16")),
        pytest.param("int8", 6e-2, marks=needs("int8")),
    ],
)
def test_low_precision_generation_agrees_with_the_full_forward_to_its_accuracy(weights, tolerance):
    model = tiny_model()
    batch = random_batch(3, 8)
    full = model(batch)[0]["action"]
    actions = teacher_forced_actions(model, batch, **{weights: True})
    error = (actions - full).norm() / full.norm()
    assert 0 < error < tolerance


@needs("int8")
def test_int8_generation_follows_weight_updates():
    model = tiny_model()
    batch = random_batch(2, 4)
    before = teacher_forced_actions(model, batch, int8=True)
    with torch.no_grad():
        model.codec.predict_action.bias.add_(1.0)
        for p in model.blocks.parameters():
            p.mul_(1.5)
    after = teacher_forced_actions(model, batch, int8=True)
    full = model(batch)[0]["action"]
    assert (after - full).norm() / full.norm() < 6e-2 < (after - before).norm() / full.norm()


@pytest.mark.parametrize("weights", ["bf16", "int8"])
def test_low_precision_generation_where_the_cpu_lacks_it_is_a_clear_error(monkeypatch, weights):
    monkeypatch.setenv(f"SCPFORMER_DISABLE_{weights.upper()}", "1")
    with pytest.raises(ValueError, match=f"^{weights} generation is not available on this mach"):
        tiny_model().start(1, **{weights: True})
    tiny_model().start(1)  # float32 still runs


def test_bf16_and_int8_together_are_an_error():
    with pytest.raises(ValueError, match="bf16 and int8"):
        tiny_model().start(1, bf16=True, int8=True)


def test_one_product_embeds_a_step_as_the_encoders_and_time_embedding_do():
    model = tiny_model(6)
    batch = random_batch(2, 3, 6)
    tokens = model.codec.embed_sequence(batch).view(2, 3, 5, -1)  # (B, T, k, C)
    codec = model.codec.step_codec(3)
    step = [batch["target"], *(batch[key][:, 2] for key in ("rtg", "ctg", "state"))]
    new = codec.step_tokens(2, [batch["action"][:, 1], *step], True)
    torch.testing.assert_close(new[:, 0], tokens[:, 1, 4])  # u(t_1), time embedding of 1
    torch.testing.assert_close(new[:, 1:], tokens[:, 2, :4])
    first = codec.step_tokens(
        0, [batch["target"], *(batch[k][:, 0] for k in ("rtg", "ctg", "state"))], False
    )
    torch.testing.assert_close(first, tokens[:, 0, :4])
    torch.testing.assert_close(codec.action_token(2, batch["action"][:, 2]), tokens[:, 2, 4:])


def test_a_control_changed_after_feed_action_does_not_change_the_generation():
    model = tiny_model()
    batch = random_batch(2, 3)
    reference = teacher_forced_actions(model, batch)
    cache = model.start(2)
    actions = []
    for i in range(3):
        step = [batch[key][:, i] for key in ("rtg", "ctg", "state")]
        actions.append(model.predict_action(cache, *step))
        control = batch["action"][:, i].clone()
        model.feed_action(cache, control)
        control.fill_(7.0)  # the caller reuses its buffer
    torch.testing.assert_close(torch.stack(actions, 1), reference)
