"""The generic loop: schedule, accumulation, per-epoch records and files."""

import csv
import math

import numpy as np
import pytest
import torch
from train_standins import TinyConfig, TinyModel

from scpformer.train.config import TRAIN_PRESETS, TrainConfig, train_config
from scpformer.train.loop import TensorData, fit, lr_factor
from scpformer.train.metrics import METRIC_COLUMNS, plot_losses, write_metrics


def _data(n: int, seed: int) -> TensorData:
    """Sequences whose action is a fixed linear function of the state (learnable)."""
    g = torch.Generator().manual_seed(seed)
    state = torch.randn(n, 8, 6, generator=g)
    action = state[..., :3] - 0.5 * state[..., 3:]
    rtg, ctg = torch.randn(n, 8, 1, generator=g), torch.zeros(n, 8, 1)
    return TensorData({"rtg": rtg, "ctg": ctg, "state": state, "action": action})


def _model(dropout: float = 0.0) -> TinyModel:
    torch.manual_seed(0)
    return TinyModel(TinyConfig(hidden=16, context=8, dropout=dropout))


def test_warm_up_is_linear_then_constant_or_cosine_down_to_the_floor():
    constant = TrainConfig(warmup_steps=4)
    assert [lr_factor(s, constant, 100) for s in range(6)] == [0.25, 0.5, 0.75, 1.0, 1.0, 1.0]
    cosine = TrainConfig(warmup_steps=2, schedule="cosine", min_lr_ratio=0.1)
    assert lr_factor(2, cosine, 12) == pytest.approx(1.0)
    assert lr_factor(7, cosine, 12) == pytest.approx(0.55)  # half way: (1 + 0.1) / 2
    assert lr_factor(12, cosine, 12) == pytest.approx(0.1)
    assert lr_factor(0, TrainConfig(warmup_steps=0), 10) == 1.0


def test_accumulated_micro_batches_take_the_step_of_one_large_batch():
    train, val = _data(32, 1), _data(8, 2)
    common = dict(epochs=2, lr=1e-2, grad_clip=0.0, warmup_steps=0, device="cpu")
    accumulated = _model()
    fit(
        accumulated, train, val, TrainConfig(batch_size=4, accumulation=2, **common), progress=False
    )
    large = _model()
    fit(large, train, val, TrainConfig(batch_size=8, accumulation=1, **common), progress=False)
    for name, value in large.state_dict().items():
        torch.testing.assert_close(accumulated.state_dict()[name], value, rtol=1e-5, atol=1e-6)


def test_an_epoch_record_holds_losses_rate_and_timing():
    config = TrainConfig(epochs=3, batch_size=8, accumulation=1, lr=3e-3, warmup_steps=0)
    seen = []
    state = fit(
        _model(0.1), _data(64, 1), _data(16, 2), config, progress=False,
        on_epoch=lambda s, training: seen.append((s.epoch, sorted(training))),
    )  # fmt: skip
    assert [r.epoch for r in state.history] == [1, 2, 3]
    assert seen == [(e, ["fit", "optimizer", "rng", "scheduler"]) for e in (1, 2, 3)]
    losses = [r.val_loss for r in state.history]
    assert losses[-1] < losses[0] and state.best_val_loss == min(losses)
    for record in state.history:
        assert record.lr == pytest.approx(3e-3) and record.samples_per_s > 0
        assert 0.0 <= record.loading_share < 1.0 and record.seconds > 0


def test_metrics_file_has_one_row_per_epoch_with_the_named_columns(tmp_path):
    config = TrainConfig(epochs=2, batch_size=8, accumulation=1, lr=1e-3)
    state = fit(_model(), _data(16, 1), _data(8, 2), config, progress=False)
    write_metrics(tmp_path, state.history)
    plot_losses(tmp_path, state.history, title="tiny")
    with (tmp_path / "metrics.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert METRIC_COLUMNS == (
        "epoch", "train_loss", "val_loss", "lr", "seconds", "samples_per_s", "loading_share"
    )  # fmt: skip
    assert tuple(rows[0]) == METRIC_COLUMNS and [int(r["epoch"]) for r in rows] == [1, 2]
    assert all(math.isfinite(float(r["val_loss"])) for r in rows)
    assert (tmp_path / "loss.png").read_bytes()[:4] == b"\x89PNG"


def test_training_without_validation_samples_is_refused():
    with pytest.raises(ValueError, match="0 val"):
        fit(_model(), _data(8, 1), _data(0, 2), TrainConfig(epochs=1), progress=False)


def test_presets_and_model_defaults_resolve_with_overrides_last():
    assert train_config("paper") == TrainConfig()  # ART Table 4
    paper = train_config("paper")
    assert (paper.lr, paper.grad_clip, paper.accumulation, paper.batch_size) == (3e-5, 1.0, 8, 4)
    defaults = {"small": {"learning_rate": 5e-4, "grad_norm_clip": 0.5, "n_layer": 3}}
    small = train_config("small", model_defaults=defaults, lr=None, epochs=2)
    assert (small.lr, small.grad_clip, small.epochs) == (5e-4, 0.5, 2)
    assert train_config("small", model_defaults=defaults, lr=1e-2).lr == 1e-2
    table4 = {"learning_rate": 2e-5, "grad_accumulation": 4, "lr_decay": None}  # flat: paper
    paper = train_config("paper", model_defaults=table4)
    assert (paper.lr, paper.accumulation, paper.schedule) == (2e-5, 4, "constant")
    assert train_config("small", model_defaults=table4).lr == TRAIN_PRESETS["small"].lr
    with pytest.raises(ValueError, match="preset must be one of"):
        train_config("huge")
    with pytest.raises(ValueError, match="batch_size must be an integer >= 1"):
        TrainConfig(batch_size=0)
    with pytest.raises(ValueError, match="schedule must be one of"):
        TrainConfig(schedule="linear")


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("batch_size", np.int64(0), "batch_size must be an integer >= 1, got 0"),
        ("epochs", np.float64(3.0), "epochs must be an integer >= 1, got float64 3.0"),
        ("lr", np.float64(-1.0), "lr must be a positive finite number, got -1.0"),
        ("grad_clip", np.float64(-1.0), "grad_clip must be nonnegative, got -1.0"),
        ("warmup_steps", np.int64(-1), "warmup_steps must be nonnegative, got -1"),
        ("min_lr_ratio", np.float64(2.0), "min_lr_ratio must be in [0, 1], got 2.0"),
        ("validation_fraction", np.float64(1.0), "validation_fraction must be in (0, 1), got 1.0"),
    ],
)
def test_numpy_config_values_are_printed_as_plain_numbers(field, value, message):
    with pytest.raises(ValueError) as err:
        TrainConfig(**{field: value})
    assert message in str(err.value) and "np." not in str(err.value)
