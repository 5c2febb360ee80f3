"""Bad input to the ``scpformer`` commands outside solve/bench (train, experiment, report,
export, dataset) and the bench seeds: one ``scpformer: error:`` line naming the bad input,
exit status 2, and no file that existed before is changed.

Each case fails before any dataset is read or model trained (most point ``--data`` at a
missing folder: the bad input is refused first), so the file runs in a few seconds.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from scpformer.cli.main import main


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def one_line_error(capsys, argv: list[str], *texts: str) -> None:
    """Run ``scpformer argv``: status 2 and one stderr line naming each of ``texts``."""
    assert main(argv) == 2
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("scpformer: error: "), err
    assert all(text in lines[0] for text in texts), lines[0]
    assert "Traceback" not in out + err


@pytest.fixture
def places(tmp_path):
    """A file, two folders of someone else's files, and a dataset folder that does not exist."""
    (tmp_path / "file.txt").write_text("precious")
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "config.json").write_text('{"mine": 1}')
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "report.md").write_text("my notes")
    dataset = tmp_path / "dataset"  # what `scpformer generate` leaves
    dataset.mkdir()
    for name in ("manifest.json", "shard-00000.h5", "splits.h5"):
        (dataset / name).write_text(name)
    run = tmp_path / "run"  # what `scpformer train art` leaves
    run.mkdir()
    for name in ("checkpoint.pt", "best.pt", "config.json", "metrics.csv"):
        (run / name).write_text(name)
    tscvx = tmp_path / "tscvx"  # what `scpformer train tscvx` leaves
    for name in ("tight", "solution"):
        (tscvx / name).mkdir(parents=True)
        (tscvx / name / "checkpoint.pt").write_text(name)
    (tscvx / "config.json").write_text("{}")
    (tmp_path / "empty").mkdir()
    return {
        "{tmp}": str(tmp_path),
        "{file}": str(tmp_path / "file.txt"),
        "{mine}": str(mine),
        "{notes}": str(notes),
        "{nodata}": str(tmp_path / "no-dataset"),
        "{dataset}": str(dataset),
        "{run}": str(run),
        "{tscvx}": str(tscvx),
        "{empty}": str(tmp_path / "empty"),
    }


def fill(argv: list[str], places: dict[str, str]) -> list[str]:
    for key, value in places.items():
        argv = [a.replace(key, value) for a in argv]
    return argv


ART = ["train", "art", "--data", "{nodata}", "--no-progress"]
CASES = {
    # a trained model and a random preset together: was the preset silently ignored
    "bench-tscvx-model-and-preset": (
        ["bench", "tscvx", "--model", "default", "--preset", "small"],
        ["--preset", "--model"],
    ),
    "bench-art-model-and-preset": (
        ["bench", "art", "--model", "default", "--preset", "paper"],
        ["--preset", "--model"],
    ),
    # --seed of numpy's generators: was numpy's "expected non-negative integer", no flag named
    "bench-art-seed-negative": (["bench", "art", "--seed", "-1"], ["--seed", "-1"]),
    "bench-tscvx-seed-negative": (["bench", "tscvx", "--seed", "-1"], ["--seed", "-1"]),
    "train-kdtree-seed-negative": (
        ["train", "kdtree", "--data", "{nodata}", "--out", "{tmp}/k", "--seed", "-1"],
        ["--seed", "-1"],
    ),
    # --out a file: was "File exists" / "Not a directory" with status 1, after reading data
    "train-art-out-is-a-file": ([*ART, "--out", "{file}"], ["--out", "is a file"]),
    "train-tscvx-out-is-a-file": (
        ["train", "tscvx", "--data", "{nodata}", "--out", "{file}"],
        ["--out", "is a file"],
    ),
    "train-interp-out-is-a-file": (
        ["train", "interp", "--data", "{nodata}", "--out", "{file}"],
        ["--out", "is a file"],
    ),
    "experiment-out-is-a-file": (
        ["experiment", "run", "art-forecast-scp", "--out", "{file}"],
        ["--out", "is a file"],
    ),
    # --out a folder of other files: they were overwritten
    "train-art-out-holds-other-files": (
        [*ART, "--out", "{mine}"],
        ["--out", "config.json", "no checkpoint.pt"],
    ),
    "experiment-out-holds-other-files": (
        ["experiment", "run", "art-forecast-scp", "--out", "{notes}"],
        ["--out", "not empty", "report.md"],
    ),
    # training values torch refused in its own words, accepted, or crashed on
    "train-betas-above-one": ([*ART, "--out", "{tmp}/r", "--betas", "2", "3"], ["betas"]),
    "train-betas-nan": ([*ART, "--out", "{tmp}/r", "--betas", "nan", "0.9"], ["betas"]),
    "train-weight-decay-inf": (
        [*ART, "--out", "{tmp}/r", "--weight-decay", "inf"],
        ["weight_decay", "inf"],
    ),
    "train-lr-huge": ([*ART, "--out", "{tmp}/r", "--lr", "1e300"], ["lr must be at most 1"]),
    # report: was "exists and is not a regular file" / "File exists" (status 1), "no such folder"
    "report-out-is-a-folder": (
        ["report", "--results", "{tmp}", "--out", "{mine}"],
        ["--out", "is a folder"],
    ),
    "report-out-under-a-file": (
        ["report", "--results", "{tmp}", "--out", "{file}/RESULTS.md"],
        ["--out", "is a file"],
    ),
    "report-results-is-a-file": (
        ["report", "--results", "{file}", "--out", "{tmp}/RESULTS.md"],
        ["--results", "is a file"],
    ),
    # export: was "folder file.txt does not exist"
    "export-onnx-under-a-file": (
        ["export", "--model", "{nodata}", "--onnx", "{file}/net.onnx"],
        ["--onnx", "is a file, not a folder"],
    ),
    # a dataset path that is missing or a file: was "manifest.json not found" for both
    "dataset-info-no-such-folder": (["dataset", "info", "{nodata}"], ["no such folder"]),
    "dataset-split-of-a-file": (["dataset", "split", "{file}"], ["a file, not a dataset"]),
    # --resume with nothing to resume: was a new run started silently
    "train-art-resume-a-missing-folder": (
        [*ART, "--out", "{tmp}/new", "--resume"],
        ["--resume", "new holds no training run to resume (no such folder)"],
    ),
    "train-art-resume-an-empty-folder": (
        [*ART, "--out", "{empty}", "--resume"],
        ["--resume", "empty holds no training run to resume (no checkpoint.pt)"],
    ),
    "train-tscvx-resume-a-missing-folder": (
        ["train", "tscvx", "--data", "{nodata}", "--out", "{tmp}/new", "--resume"],
        ["--resume", "new holds no T-SCvx run to resume (no such folder)"],
    ),
    "train-tscvx-resume-an-empty-folder": (
        ["train", "tscvx", "--data", "{nodata}", "--out", "{empty}", "--resume"],
        ["--resume", "empty holds no T-SCvx run to resume"],
    ),
    # --out a folder of another kind of run: was written into (a dataset's, an ART run's)
    "train-art-out-is-a-dataset": (
        [*ART, "--out", "{dataset}"],
        ["--out", "is a dataset folder", "manifest.json"],
    ),
    "train-lstm-out-is-a-dataset": (
        ["train", "lstm", "--data", "{nodata}", "--out", "{dataset}"],
        ["--out", "is a dataset folder"],
    ),
    "train-art-out-is-a-tscvx-run": (
        [*ART, "--out", "{tscvx}"],
        ["--out", "holds a T-SCvx training run"],
    ),
    "train-tscvx-out-is-a-dataset": (
        ["train", "tscvx", "--data", "{nodata}", "--out", "{dataset}"],
        ["--out", "not a T-SCvx run's", "manifest.json"],
    ),
    "train-tscvx-out-is-an-art-run": (
        ["train", "tscvx", "--data", "{nodata}", "--out", "{run}"],
        ["--out", "not a T-SCvx run's", "checkpoint.pt"],
    ),
    "train-kdtree-out-is-a-dataset": (
        ["train", "kdtree", "--data", "{nodata}", "--out", "{dataset}"],
        ["--out", "holds a dataset (manifest.json)"],
    ),
    "train-interp-out-is-an-art-run": (
        ["train", "interp", "--data", "{nodata}", "--out", "{run}"],
        ["--out", "holds a training run (checkpoint.pt)"],
    ),
    "train-kdtree-out-is-a-tscvx-run": (
        ["train", "kdtree", "--data", "{nodata}", "--out", "{tscvx}"],
        ["--out", "holds a training run (checkpoint.pt)"],
    ),
    "generate-out-is-an-art-run": (
        ["generate", "rendezvous", "--out", "{run}", "--n", "2"],
        ["run is not empty and holds no dataset", "checkpoint.pt"],
    ),
    "generate-out-is-a-tscvx-run": (
        ["generate", "pdg6dof", "--out", "{tscvx}", "--n", "2"],
        ["tscvx is not empty and holds no dataset", "tight"],
    ),
    "experiment-out-is-a-dataset": (
        ["experiment", "run", "art-forecast-scp", "--out", "{dataset}"],
        ["--out", "not empty", "manifest.json"],
    ),
}


@pytest.mark.parametrize("argv, texts", CASES.values(), ids=CASES.keys())
def test_bad_input_is_one_line_naming_it_and_changes_no_file(tmp_path, places, capsys, argv, texts):
    before = snapshot(tmp_path)
    one_line_error(capsys, fill(argv, places), *texts)
    assert snapshot(tmp_path) == before


def test_a_new_run_may_rewrite_the_config_of_its_own_interrupted_start(tmp_path, capsys):
    """A ``config.json`` written by an ``art`` run stopped in its first epoch is not refused
    (the missing dataset is what stops this run), but a ``gru`` run would overwrite it."""
    run = tmp_path / "run"
    run.mkdir()
    own = {"kind": "art", "manifest_digest": "0" * 64, "package_version": "0", "train": {}}
    (run / "config.json").write_text(json.dumps(own))
    args = ["--data", str(tmp_path / "no-dataset"), "--out", str(run), "--no-progress"]
    one_line_error(capsys, ["train", "art", *args], "no dataset in")
    one_line_error(capsys, ["train", "gru", *args], "--out", "config.json")


def test_train_lookup_into_a_folder_holding_a_table_is_refused(tmp_path, capsys):
    """Was: the earlier table's lookup.json silently replaced."""
    table = tmp_path / "table"
    table.mkdir()
    (table / "lookup.json").write_text('{"kind": "kdtree"}')
    before = snapshot(tmp_path)
    argv = ["train", "kdtree", "--data", str(tmp_path / "no-dataset"), "--out", str(table)]
    one_line_error(capsys, argv, "--out", "already holds a lookup table")
    assert snapshot(tmp_path) == before


def test_a_manifest_that_is_not_a_json_object_is_called_damaged(tmp_path, capsys):
    """Was: "cannot convert dictionary update sequence element #0 to a sequence"."""
    (tmp_path / "ds").mkdir()
    (tmp_path / "ds" / "manifest.json").write_text("[1, 2]")
    argv = ["dataset", "info", str(tmp_path / "ds")]
    one_line_error(capsys, argv, "manifest.json: the manifest is damaged", "JSON list")


@pytest.mark.parametrize(
    "argv",
    [
        ["solve", "pdg6dof", "--warmstart", "tscvx", "--model", "{run}"],
        ["solve", "rendezvous", "--warmstart", "art", "--model", "{run}"],
        ["bench", "art", "--model", "{run}"],
        ["bench", "tscvx", "--model", "{run}"],
        ["export", "--model", "{run}", "--onnx", "{out}"],
    ],
)
def test_every_command_words_a_missing_model_run_the_same(tmp_path, capsys, argv):
    run, out = tmp_path / "no-such-run", tmp_path / "a.onnx"
    argv = [a.format(run=run, out=out) for a in argv]
    one_line_error(capsys, argv, f"--model {run}: no such run folder or checkpoint file")
    assert list(tmp_path.iterdir()) == []


# -- export: a network whose check fails leaves no file -------------------------------------
def save_tiny_gru(run: Path) -> None:
    """A randomly initialized tiny GRU saved as a training run saves it."""
    import torch

    from scpformer.models import build_model, preset
    from scpformer.train.checkpoint import save_checkpoint

    config = preset("gru", "small", n_layer=1, n_embd=12, context=10)
    torch.manual_seed(1)
    save_checkpoint(
        run, model=build_model("gru", config), kind="gru", config=config, normalization=None,
        frame="rtn", family="rendezvous", manifest_digest="0" * 64, seed=0, n_steps=6,
    )  # fmt: skip


def refuse_graph(*args, **kwargs):
    import onnx

    raise onnx.checker.ValidationError("Field 'type' of 'value_info' is required but missing.")


@pytest.mark.parametrize("earlier", [None, b"an earlier export"], ids=["new", "replacing"])
@pytest.mark.parametrize(
    "failure, texts",
    [
        ("checker", ["net.onnx: the ONNX checker refused the exported network", "required"]),
        ("tolerance", ["net.onnx: onnxruntime differs from PyTorch by 0.5", "nothing was"]),
    ],
)
def test_an_export_that_fails_its_check_leaves_no_file(
    tmp_path, capsys, monkeypatch, earlier, failure, texts
):
    """Was: the file that failed onnxruntime's comparison left at --onnx (the ONNX checker
    failed as an internal error)."""
    pytest.importorskip("onnxruntime", reason="ONNX export needs onnx and onnxruntime")
    import onnx

    from scpformer.train import export

    save_tiny_gru(tmp_path / "run")
    onnx_file = tmp_path / "out" / "net.onnx"
    onnx_file.parent.mkdir()
    if earlier is not None:
        onnx_file.write_bytes(earlier)
    if failure == "checker":
        monkeypatch.setattr(onnx.checker, "check_model", refuse_graph)
    else:
        monkeypatch.setattr(export, "max_abs_diff", lambda *args: 0.5)
    argv = ["export", "--model", str(tmp_path / "run"), "--onnx", str(onnx_file)]
    one_line_error(capsys, argv, *texts)
    assert [p.name for p in onnx_file.parent.iterdir()] == ([] if earlier is None else ["net.onnx"])
    if earlier is not None:
        assert onnx_file.read_bytes() == earlier


# -- train tscvx: a validation split without a solved sample --------------------------------
def test_train_tscvx_refuses_a_dataset_without_validation_samples_before_training(
    tmp_path, capsys, monkeypatch
):
    """Was: both networks trained, then "the validation split ... holds no solved sample"
    from the final evaluation (the default split, 80/0/20, has no validation samples)."""
    import importlib

    from scpformer.data.generate import GenerateConfig, generate
    from scpformer.data.splits import SplitConfig, make_splits
    from scpformer.train import tscvx

    monkeypatch.syspath_prepend(str(Path(__file__).parent / "train"))  # workers import it
    family = importlib.import_module("fake_pdg6dof").FakePDG6DoFFamily()
    data = tmp_path / "ds"
    generate(family, GenerateConfig(n=8, out=data, shard_size=8, workers=1))
    make_splits(data, SplitConfig(fractions=(0.75, 0.0, 0.25)))

    def no_training(*args, **kwargs):
        raise AssertionError("a network was trained")

    monkeypatch.setattr(tscvx, "fit", no_training)
    run = tmp_path / "run"
    argv = ["train", "tscvx", "--data", str(data), "--out", str(run), "--no-progress"]
    one_line_error(capsys, argv, f"the validation split of {data} holds no solved sample",
                   "--report-split test")  # fmt: skip
    assert not run.exists()


# -- SCPFORMER_CACHE_DIR naming a file ------------------------------------------------------
@pytest.mark.parametrize("under", [False, True], ids=["a-file", "under-a-file"])
def test_a_cache_dir_that_is_a_file_is_said_once_on_stderr(tmp_path, capsys, monkeypatch, under):
    from scpformer import cache

    blocker = tmp_path / "not-a-folder"
    blocker.write_text("mine")
    folder = blocker / "cache" if under else blocker
    monkeypatch.setenv("SCPFORMER_CACHE_DIR", str(folder))
    monkeypatch.setattr(cache, "_warned", set())
    assert cache.cached_pickle("one", lambda: 1) == 1
    assert cache.cached_pickle("two", lambda: 2) == 2
    assert cache.cached_pickle("one", lambda: 3) == 3  # nothing was cached
    out, err = capsys.readouterr()
    assert out == ""
    (line,) = err.strip().splitlines()
    assert line.startswith("scpformer: warning: the cache folder ") and str(folder) in line
    assert "nothing is cached" in line
    assert blocker.read_text() == "mine"
    monkeypatch.setenv("SCPFORMER_CACHE_DIR", str(tmp_path / "cache"))  # a folder: silent
    assert cache.cached_pickle("one", lambda: 4) == 4
    assert cache.cached_pickle("one", lambda: 5) == 4
    assert capsys.readouterr().err == ""


def test_a_model_of_another_kind_is_named_by_its_kind(tmp_path, capsys):
    """Was: "no checkpoint at RUN/checkpoint.pt" for a T-SCvx run given where ART is needed."""
    run = tmp_path / "tscvx-run"
    (run / "tight").mkdir(parents=True)
    (run / "solution").mkdir()
    argv = ["solve", "rendezvous", "--warmstart", "art", "--model", str(run)]
    one_line_error(capsys, argv, "is a T-SCvx run", "not a single-network run")
