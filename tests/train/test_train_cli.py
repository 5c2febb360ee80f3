"""``scpformer train art|gru|lstm`` on the command line: a run, a resume, one-line errors."""

import subprocess
import sys

import pytest
from train_standins import STANDIN_MODELS

from scpformer.cli.main import main
from scpformer.train import models_api


@pytest.fixture(autouse=True)
def standin_models(monkeypatch):
    """The command builds the stand-in models (scpformer.models is another helper's)."""
    monkeypatch.setattr(models_api, "default_models", lambda: STANDIN_MODELS)


def _train(*args):
    return main(["train", *args, "--no-progress", "--device", "cpu", "--batch-size", "4"])


def one_line_error(capsys, text):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("scpformer: error:") and text in err[0], err


@pytest.mark.parametrize("kind", ["art", "gru", "lstm"])
def test_train_runs_and_summarizes(toy_rdv, tmp_path, capsys, kind):
    run = tmp_path / kind
    assert _train(kind, "--data", str(toy_rdv), "--out", str(run), "--epochs", "1") == 0
    out = capsys.readouterr().out
    assert "1 epoch(s) of 1" in out and "sequences/s" in out and "% loading" in out
    assert (run / "checkpoint.pt").is_file() and (run / "metrics.csv").is_file()


def test_resume_continues_and_a_second_run_into_the_folder_is_refused(toy_rdv, tmp_path, capsys):
    args = ["art", "--data", str(toy_rdv), "--out", str(tmp_path / "run"), "--frame", "roe"]
    assert _train(*args, "--epochs", "1") == 0
    assert _train(*args, "--epochs", "2") == 2
    one_line_error(capsys, "pass --resume")
    assert _train(*args, "--epochs", "2", "--resume") == 0
    assert "2 epoch(s) of 2 (resumed after epoch 1)" in capsys.readouterr().out
    assert _train(*args[:-1], "rtn", "--epochs", "3", "--resume") == 2
    one_line_error(capsys, "frame 'roe', not 'rtn'")


def test_bad_data_is_a_one_line_error(toy_unsplit, toy_other_family, tmp_path, capsys):
    out = ["--out", str(tmp_path / "run")]
    assert _train("art", "--data", str(tmp_path / "missing"), *out) == 2
    one_line_error(capsys, "missing")
    assert _train("art", "--data", str(toy_unsplit), *out) == 2
    one_line_error(capsys, "no splits in")
    assert _train("gru", "--data", str(toy_other_family), *out) == 2
    one_line_error(capsys, "reads rendezvous or robust-rendezvous data, not pdg6dof")
    assert _train("lstm", "--data", str(toy_unsplit), *out, "--lr", "-1") == 2
    one_line_error(capsys, "lr must be a positive finite number")
    assert _train("art", "--data", str(toy_unsplit), *out, "--lr", "inf") == 2
    one_line_error(capsys, "lr must be a positive finite number, got inf")
    assert _train("art", "--data", str(toy_unsplit), *out, "--twin", "tpbvp") == 2
    one_line_error(capsys, "no splits in")


def test_an_unknown_twin_is_a_one_line_error(toy_rdv, tmp_path, capsys):
    out = ["--out", str(tmp_path / "run")]
    assert _train("art", "--data", str(toy_rdv), *out, "--twin", "tpbvp") == 2
    one_line_error(capsys, "twins must be a non-empty subset of ('scp', 'cvx'), got ('tpbvp',)")
    assert not (tmp_path / "run").exists()
    assert not (tmp_path / "run").exists()


def test_unknown_models_are_refused_by_the_parser(capsys):
    assert main(["train", "gpt", "--data", "x", "--out", "y"]) == 2
    assert "invalid choice: 'gpt'" in capsys.readouterr().err


def test_the_command_line_loads_without_torch():
    code = "import sys, scpformer.cli.train; assert 'torch' not in sys.modules"
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0
