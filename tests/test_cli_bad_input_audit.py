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
    return {
        "{tmp}": str(tmp_path),
        "{file}": str(tmp_path / "file.txt"),
        "{mine}": str(mine),
        "{notes}": str(notes),
        "{nodata}": str(tmp_path / "no-dataset"),
    }


def fill(argv: list[str], places: dict[str, str]) -> list[str]:
    for key, value in places.items():
        argv = [a.replace(key, value) for a in argv]
    return argv


ART = ["train", "art", "--data", "{nodata}", "--no-progress"]
CASES = {
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


def test_a_manifest_that_is_not_a_json_object_is_called_corrupt(tmp_path, capsys):
    """Was: "cannot convert dictionary update sequence element #0 to a sequence"."""
    (tmp_path / "ds").mkdir()
    (tmp_path / "ds" / "manifest.json").write_text("[1, 2]")
    one_line_error(capsys, ["dataset", "info", str(tmp_path / "ds")], "manifest.json is corrupt",
                   "JSON list")  # fmt: skip


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
