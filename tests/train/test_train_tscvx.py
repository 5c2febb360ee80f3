"""``scpformer train tscvx``: data read once, grouped folds, losses, checkpoints, metrics."""

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="torch is not installed: training is untested")

from fake_pdg6dof import FakePDG6DoFFamily  # noqa: E402

from scpformer.cli.main import main  # noqa: E402
from scpformer.data.errors import DatasetError  # noqa: E402
from scpformer.data.generate import GenerateConfig, generate  # noqa: E402
from scpformer.data.splits import SplitConfig, make_splits  # noqa: E402
from scpformer.data.torch_views import SolutionDataset, TightFlagsDataset  # noqa: E402
from scpformer.models.tscvx import (  # noqa: E402
    TSCVX_MODELS,
    TscvxNormalization,
    load_tscvx_predictor,
)
from scpformer.train.checkpoint import (  # noqa: E402
    CheckpointError,
    load_checkpoint,
    slim_checkpoint,
)
from scpformer.train.tscvx import (  # noqa: E402
    SolutionObjective,
    evaluate_tscvx,
    fold_masks,
    positive_weight,
    read_tscvx,
    solution_tensors,
    tight_tensors,
    train_tscvx,
)
from scpformer.train.tscvx_metrics import solution_metrics, tight_metrics  # noqa: E402

TINY = {"d_model": 16, "n_head": 2, "n_layer": 1, "d_ff": 32}
FAST = {"batch_size": 16, "warmup_steps": 2, "device": "cpu"}


@pytest.fixture(scope="module")
def fake_pdg(tmp_path_factory):
    """40 fake 6-DoF samples (4 nodes, up to 5 iterations) split 50/25/25 by instance."""
    folder = tmp_path_factory.mktemp("fake_pdg") / "ds"
    generate(FakePDG6DoFFamily(), GenerateConfig(n=40, out=folder, shard_size=20, workers=1))
    make_splits(folder, SplitConfig(fractions=(0.5, 0.25, 0.25), seed=0))
    return folder


def train(data, out, **kwargs):
    options = dict(preset_name="small", model_overrides=TINY, overrides=FAST | {"epochs": 2},
                   solution_epochs=2, progress=False, threads=1)  # fmt: skip
    return train_tscvx(data=data, out=out, **(options | kwargs))


def test_items_read_once_equal_those_of_the_views(fake_pdg):
    arrays, norm = read_tscvx(fake_pdg)
    train = arrays.subset(arrays.split == "train")
    items = tight_tensors(train, norm).tensors
    view = TightFlagsDataset(fake_pdg, "train")
    assert len(view) == len(items["k"])
    for i in (0, 7, len(view) - 1):
        item = view[i]
        assert int(item["k"]) == int(items["k"][i])
        np.testing.assert_array_equal(item["flags"].numpy(), items["flags"][i].numpy())
        torch.testing.assert_close(item["theta"], items["theta"][i])
    raw = SolutionDataset(fake_pdg, "train", normalize=False)
    targets = solution_tensors(train, norm).tensors["target"]
    assert len(raw) == len(targets)
    first = raw[0]
    np.testing.assert_allclose(train.x[0], first["x"].numpy(), rtol=1e-6)
    want = norm.encode_solution(first["x"].numpy()[None], first["u"].numpy()[None],
                                first["tf"].numpy()[None])  # fmt: skip
    np.testing.assert_allclose(targets[0].numpy(), want[0], rtol=1e-4, atol=1e-5)


def test_the_solution_network_alone_reads_no_tight_flags_and_the_same_samples(fake_pdg):
    full, norm = read_tscvx(fake_pdg)
    lean, lean_norm = read_tscvx(fake_pdg, flags=False)
    assert full.has_flags and not lean.has_flags and lean.flags.nbytes == 0
    for name in ("theta", "x", "u", "tf", "iterations", "base_index", "split"):
        np.testing.assert_array_equal(getattr(lean, name), getattr(full, name))
    torch.testing.assert_close(
        solution_tensors(lean, lean_norm).tensors["target"],
        solution_tensors(full, norm).tensors["target"],
    )
    with pytest.raises(ValueError, match="tight flags"):
        evaluate_tscvx(fake_pdg, fake_pdg, arrays=(lean, lean_norm))


def test_folds_partition_train_and_validation_by_base_instance(fake_pdg):
    arrays, _ = read_tscvx(fake_pdg)
    masks = fold_masks(arrays, 3, 0.1, seed=0)
    pool = (arrays.split == "train") | (arrays.split == "validation")
    validations = np.stack([val for _, val in masks])
    np.testing.assert_array_equal(validations.sum(axis=0), pool.astype(int))  # each once
    for train, val in masks:
        assert not (train & val).any() and np.array_equal(train | val, pool)
        shared = set(arrays.base_index[train]) & set(arrays.base_index[val])
        assert not shared
    [(train, val)] = fold_masks(arrays, 1, 0.1, seed=0)
    assert np.array_equal(val, arrays.split == "validation")


def test_positive_weight_balances_the_tight_rows():
    assert positive_weight(torch.tensor([[1, 0, 0, 0]], dtype=torch.uint8)) == pytest.approx(3.0)
    assert positive_weight(torch.zeros(2, 3, dtype=torch.uint8)) == 1.0


def test_both_losses_decrease_and_the_run_loads_as_a_predictor(fake_pdg, tmp_path):
    run = tmp_path / "run"
    result = train(fake_pdg, run, overrides=FAST | {"epochs": 30, "lr": 3e-3},
                   solution_epochs=15)  # fmt: skip
    for name in ("tight", "solution"):
        history = result.networks[name].states[-1].history
        assert history[-1].train_loss < 0.8 * history[0].train_loss, name
        assert (run / name / "checkpoint.pt").is_file() and (run / name / "metrics.csv").is_file()
    predictor = load_tscvx_predictor(run)
    arrays, _ = read_tscvx(fake_pdg)
    train_split = arrays.subset(arrays.split == "train")
    norm = TscvxNormalization.canonical_from_arrays(
        train_split.theta, train_split.x, train_split.u, train_split.tf
    )
    assert predictor.normalization.canonical
    theta = arrays.theta[:3]
    loaded = load_checkpoint(run / "tight" / "best.pt", models=TSCVX_MODELS)
    z = torch.tensor(norm.encode_theta(theta), dtype=torch.float32)
    with torch.no_grad():
        logits = loaded.model(z, torch.tensor([1, 2, 3])).numpy()
    np.testing.assert_allclose(predictor.predict_tight_proba(theta, np.array([1, 2, 3])),
                               1 / (1 + np.exp(-logits)), rtol=1e-5)  # fmt: skip
    np.testing.assert_allclose(predictor.normalization.theta_mean, norm.theta_mean)
    config = json.loads((run / "config.json").read_text())
    assert config["networks"]["tight"]["parameters"] > 0 and config["folds"] == 1
    assert result.metrics["split"] == "validation"
    assert (run / "metrics_validation.json").is_file() and (run / "tight_validation.csv").is_file()


def test_raw_frame_training_uses_the_splits_statistics_and_resume_keeps_the_frame(
    fake_pdg, tmp_path
):
    run = tmp_path / "raw"
    train(fake_pdg, run, networks=("solution",), canonical=False)
    _, norm = read_tscvx(fake_pdg)
    stored = load_checkpoint(run / "solution", models=TSCVX_MODELS).normalization
    assert stored.canonical is False
    np.testing.assert_allclose(stored.x_mean, norm.x_mean)
    with pytest.raises(ValueError, match="canonical = False"):
        train(fake_pdg, run, networks=("solution",), resume=True, solution_epochs=3)


def test_the_thrust_weight_scales_the_thrust_errors_of_the_solution_loss():
    n = 4  # nodes: 14 n state outputs, 3 n thrust outputs, t_f
    net = torch.nn.Identity()
    target = torch.zeros(2, 17 * n + 1)
    pred = torch.zeros(2, 17 * n + 1)
    pred[:, 14 * n] = 1.0  # one thrust error
    pred[:, 0] = 1.0  # one state error of the same size
    plain = SolutionObjective(net, n)({"theta": pred, "target": target})[1]
    assert float(plain) == pytest.approx(float(torch.nn.functional.mse_loss(pred, target)))
    weighted = SolutionObjective(net, n, thrust_weight=4.0)({"theta": pred, "target": target})[1]
    mean_weight = (14 * n + 4.0 * 3 * n + 1) / (17 * n + 1)
    assert float(weighted) == pytest.approx((1.0 + 4.0) / mean_weight / (17 * n + 1))


def test_resume_keeps_the_thrust_weight(fake_pdg, tmp_path):
    run = tmp_path / "weighted"
    train(fake_pdg, run, networks=("solution",), thrust_weight=3.0)
    assert json.loads((run / "config.json").read_text())["thrust_weight"] == 3.0
    with pytest.raises(ValueError, match="thrust-weight 3"):
        train(fake_pdg, run, networks=("solution",), resume=True, solution_epochs=3)
    with pytest.raises(ValueError, match="thrust_weight"):
        train(fake_pdg, tmp_path / "bad", thrust_weight=0.0)


def test_a_packaged_network_beside_a_new_one_counts_as_trained(fake_pdg, tmp_path):
    trained, run = tmp_path / "trained", tmp_path / "run"
    train(fake_pdg, trained, networks=("tight",))
    slim_checkpoint(trained / "tight" / "checkpoint.pt", run / "tight" / "checkpoint.pt")
    result = train(fake_pdg, run, networks=("solution",))  # was: KeyError 'train_config'
    assert "tight" in result.metrics and "solution" in result.metrics


def test_three_folds_deliver_the_last_folds_network(fake_pdg, tmp_path):
    run = tmp_path / "cv"
    result = train(fake_pdg, run, folds=3, networks=("solution",))
    assert len(result.networks["solution"].states) == 3
    cv = json.loads((run / "solution" / "cv.json").read_text())
    assert cv["folds"] == 3 and len(cv["best_val_loss"]) == 3
    last = load_checkpoint(run / "solution" / "fold3", models=TSCVX_MODELS).model.state_dict()
    delivered = load_checkpoint(run / "solution", models=TSCVX_MODELS).model.state_dict()
    for key, value in last.items():
        torch.testing.assert_close(delivered[key], value)


def test_resume_continues_and_an_existing_run_is_not_overwritten(fake_pdg, tmp_path):
    run = tmp_path / "resume"
    train(fake_pdg, run, networks=("tight",), overrides=FAST | {"epochs": 1})
    with pytest.raises(ValueError, match="--resume"):
        train(fake_pdg, run, networks=("tight",))
    result = train(fake_pdg, run, networks=("tight",), overrides=FAST | {"epochs": 2},
                   resume=True)  # fmt: skip
    assert [r.epoch for r in result.networks["tight"].states[-1].history] == [1, 2]
    lost = next(run.rglob("checkpoint.pt"))  # a network that lost its checkpoint
    lost.unlink()
    kept = {str(f): f.read_bytes() for f in run.rglob("*") if f.is_file()}
    with pytest.raises(ValueError, match=r"holds no checkpoint\.pt to resume from"):
        train(fake_pdg, run, networks=("tight",), overrides=FAST | {"epochs": 3}, resume=True)
    assert {str(f): f.read_bytes() for f in run.rglob("*") if f.is_file()} == kept


def test_a_folder_of_other_files_is_refused_and_the_other_network_welcome(fake_pdg, tmp_path):
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "manifest.json").write_text("{}")
    with pytest.raises(ValueError, match=r"not a T-SCvx run's \(manifest\.json\)"):
        train(fake_pdg, tmp_path / "data", networks=("tight",))
    assert [f.name for f in (tmp_path / "data").iterdir()] == ["manifest.json"]
    run = tmp_path / "side_by_side"
    train(fake_pdg, run, networks=("tight",), overrides=FAST | {"epochs": 1})
    train(fake_pdg, run, networks=("solution",), solution_epochs=1)
    assert (run / "solution" / "checkpoint.pt").is_file() and (
        run / "metrics_validation.json"
    ).is_file()


def test_evaluation_on_the_test_split_writes_its_files(fake_pdg, tmp_path):
    run = tmp_path / "eval"
    train(fake_pdg, run)
    metrics = evaluate_tscvx(run, fake_pdg, split="test")
    arrays, _ = read_tscvx(fake_pdg)
    assert metrics["solution"]["samples"] == int(np.sum(arrays.split == "test"))
    overall = metrics["tight"]["overall"]
    assert overall["all_zeros_accuracy"] + overall["all_ones_accuracy"] == pytest.approx(1.0)
    assert set(metrics["tight"]["per_name"]) >= {"mass", "gimbal"}
    assert (run / "metrics_test.json").is_file() and (run / "tight_test.csv").is_file()
    strict = evaluate_tscvx(run, fake_pdg, split="test", threshold=0.9)
    assert strict["tight"]["overall"]["predicted_share"] <= overall["predicted_share"]
    assert (run / "metrics_test_best_t0.9.json").is_file()
    with pytest.raises(ValueError, match="split"):
        evaluate_tscvx(run, fake_pdg, split="train ")


def test_bad_data_and_arguments_are_refused(fake_pdg, toy_rdv, tmp_path):
    with pytest.raises(DatasetError, match="pdg6dof"):
        read_tscvx(toy_rdv)  # a rendezvous dataset
    with pytest.raises(ValueError, match="folds"):
        train(fake_pdg, tmp_path / "a", folds=0)
    with pytest.raises(ValueError, match="networks"):
        train(fake_pdg, tmp_path / "b", networks=("both",))
    with pytest.raises(CheckpointError, match="no checkpoint"):
        load_tscvx_predictor(tmp_path / "nothing")


@pytest.mark.parametrize(
    ("argument", "message"),
    [
        ({"folds": np.int64(0)}, "folds must be an integer >= 1, got 0"),
        ({"thrust_weight": np.float64(-1.0)}, "thrust_weight must be a positive number, got -1.0"),
        ({"threads": np.float64(2.0)}, "threads must be an integer >= 1, got float64 2.0"),
    ],
)
def test_numpy_arguments_are_printed_as_plain_numbers(tmp_path, argument, message):
    with pytest.raises(ValueError) as err:
        train(tmp_path / "data", tmp_path / "run", **argument)
    assert message in str(err.value) and "np." not in str(err.value)


def test_command_line_trains_and_reports(fake_pdg, tmp_path, capsys):
    run = tmp_path / "cli"
    args = ["train", "tscvx", "--data", str(fake_pdg), "--out", str(run), "--epochs", "1",
            "--solution-epochs", "1", "--batch-size", "16", "--warmup-steps", "1",
            "--threads", "1", "--no-progress", "--report-split", "test"]  # fmt: skip
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "all zeros" in out and "standardized MSE" in out and "gimbal" in out
    assert main(args) == 2
    assert "--resume" in capsys.readouterr().err


# -- metrics against hand counts ----------------------------------------------------------
def test_tight_metrics_match_hand_counts():
    names = ("a", "b")  # R = 2 names x 2 nodes, name-major
    truth = np.array([[1, 0, 0, 0], [1, 1, 0, 1]], dtype=bool)
    predicted = np.array([[1, 1, 0, 0], [0, 1, 0, 1]], dtype=bool)
    m = tight_metrics(truth, predicted, names)
    o = m["overall"]  # tp 3, fp 1, fn 1, tn 3
    assert o["accuracy"] == pytest.approx(6 / 8)
    assert (o["precision"], o["recall"]) == (pytest.approx(0.75), pytest.approx(0.75))
    assert o["all_zeros_accuracy"] == pytest.approx(4 / 8)
    assert o["all_ones_accuracy"] == pytest.approx(4 / 8)
    a = m["per_name"]["a"]  # truth [1,0],[1,1]; predicted [1,1],[0,1]: tp 2, fp 1, fn 1, tn 0
    assert (a["precision"], a["recall"], a["accuracy"]) == (
        pytest.approx(2 / 3), pytest.approx(2 / 3), pytest.approx(0.5))  # fmt: skip
    b = m["per_name"]["b"]  # truth [0,0],[0,1]; predicted [0,0],[0,1]
    assert (b["precision"], b["recall"], b["accuracy"]) == (1.0, 1.0, 1.0)
    assert m["covered"] == pytest.approx(0.5)  # item 2 misses row 0


def test_tight_metrics_refuse_mismatched_shapes():
    with pytest.raises(ValueError, match="equal"):
        tight_metrics(np.zeros((2, 14), bool), np.zeros((2, 7), bool))


def test_solution_metrics_match_hand_computed_errors():
    n = 2
    truth = (np.zeros((1, n, 14)), np.zeros((1, n, 3)), np.array([1.0]))
    x = np.zeros((1, n, 14))
    x[0, :, 0] = 2.0  # r error 2 on one of three components
    predicted = (x, np.ones((1, n, 3)), np.array([1.5]))
    z_true = np.zeros((1, 17 * n + 1))
    z_pred = z_true.copy()
    z_pred[0, -1] = 2.0
    m = solution_metrics(z_pred, z_true, predicted, truth)
    assert m["mse"] == pytest.approx(4.0 / (17 * n + 1)) and m["mse_tf"] == pytest.approx(4.0)
    assert m["mse_x"] == 0.0
    assert m["rmse_physical"]["r"] == pytest.approx(np.sqrt(4.0 / 3.0))
    assert m["rmse_physical"]["u"] == pytest.approx(1.0)
    assert m["rmse_physical"]["tf"] == pytest.approx(0.5)


def test_command_line_errors_are_one_line(toy_rdv, fake_pdg, tmp_path, capsys):
    base = ["train", "tscvx", "--out", str(tmp_path / "x"), "--no-progress"]
    assert main([*base, "--data", str(toy_rdv)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("scpformer: error:") and "pdg6dof" in err[0]
    assert main([*base, "--data", str(fake_pdg), "--folds", "0"]) == 2
    assert "folds" in capsys.readouterr().err


def test_bench_times_the_predictor_calls(capsys):
    args = ["bench", "tscvx", "--repeats", "3", "--warmup", "1", "--batch", "2"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "predict_tight, batch 1" in out and "predict_solution, batch 2" in out
    assert "predict_tight, batch 1, caches cold" in out  # as between two conic solves


def test_the_bench_runs_the_cache_eviction_untimed_before_every_timed_call():
    from scpformer.cli.bench_tscvx import median_seconds

    events = []
    median_seconds(lambda: events.append("call"), 3, 2, between=lambda: events.append("evict"))
    assert events == ["call", "call"] + ["evict", "call"] * 3
