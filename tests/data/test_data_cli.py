"""``generate`` and ``dataset`` on the command line: output, progress and one-line errors."""

from pathlib import Path

import pytest
import toy_families  # noqa: F401  (registers the toy family)
from toy_families import MisbehavingFamily

from scpformer.cli.data import main
from scpformer.data import storage
from scpformer.data.family import BUILTIN_MODULES, FamilySpec, register_family


def one_line_error(capsys, text):
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("scpformer: error:") and text in err, err
    assert "Traceback" not in err


def generate_toy(out, *extra):
    return main(["generate", "toy", "--n", "5", "--out", str(out), "--workers", "1", *extra])


def test_generate_shows_progress_and_a_summary(tmp_path, capsys):
    assert generate_toy(tmp_path / "ds", "--shard-size", "2") == 0
    out, err = capsys.readouterr()
    assert "5 of 5 instances in 3 shard(s)" in out and "solved " in out
    assert "solved=" in err and "failed=" in err and "inst/s" in err  # the tqdm bar


def test_a_larger_n_on_the_command_line_grows_the_dataset_and_info_says_so(tmp_path, capsys):
    generate_toy(tmp_path / "ds", "--shard-size", "2")
    capsys.readouterr()
    argv = ["generate", "toy", "--n", "8", "--out", str(tmp_path / "ds"), "--workers", "1"]
    assert main([*argv, "--shard-size", "2"]) == 0
    out, err = capsys.readouterr()
    assert "growing the dataset from 5 to 8 instances" in err
    assert "8 of 8 instances in 5 shard(s)" in out and "this run: 3 instances" in out
    assert main(["dataset", "info", str(tmp_path / "ds")]) == 0
    assert "5 -> 8 instances" in capsys.readouterr().out


def test_info_and_verify_describe_a_dataset(tmp_path, capsys):
    generate_toy(tmp_path / "ds")
    capsys.readouterr()
    assert main(["dataset", "info", str(tmp_path / "ds")]) == 0
    out = capsys.readouterr().out
    assert "family" in out and "toy (generated)" in out and "field theta" in out
    assert main(["dataset", "verify", str(tmp_path / "ds")]) == 0
    assert "ok:" in capsys.readouterr().out


def test_verify_names_a_corrupt_shard_and_fails(tmp_path, capsys):
    generate_toy(tmp_path / "ds", "--shard-size", "2")
    shard = tmp_path / "ds" / "shard-00001.h5"
    shard.write_bytes(shard.read_bytes()[:-10])
    capsys.readouterr()
    assert main(["dataset", "verify", str(tmp_path / "ds")]) == 1
    out = capsys.readouterr().out
    assert "shard-00001.h5: truncated" in out and "1 problem(s) found" in out


def test_generating_into_another_familys_or_seeds_folder_is_one_line_error(tmp_path, capsys):
    generate_toy(tmp_path / "ds")
    args = ["generate", "pdg6dof", "--n", "5", "--out", str(tmp_path / "ds")]
    assert main(args) == 2
    one_line_error(capsys, "holds another dataset (toy, seed 0, n 5)")
    assert generate_toy(tmp_path / "ds", "--seed", "4") == 2
    one_line_error(capsys, "differs in seed 0 (this run: 4)")


@pytest.mark.parametrize(
    "argv, text",
    [
        (["generate", "toy", "--n", "0", "--out", "X"], "argument --n: must be at least 1"),
        (["generate", "future", "--n", "2", "--out", "X"], "not available yet"),
        (["dataset", "info", "X"], "no dataset in"),
        (["dataset", "split", "X"], "no dataset in"),
    ],
)
def test_bad_input_is_a_one_line_error(tmp_path, capsys, monkeypatch, argv, text):
    monkeypatch.setitem(BUILTIN_MODULES, "future", "scpformer.data.future_family")
    argv = [str(tmp_path / a) if a == "X" else a for a in argv]
    assert main(argv) == 2
    one_line_error(capsys, text)


def test_an_unwritable_folder_is_a_one_line_error(tmp_path, capsys, monkeypatch):
    def refuse(self, *args, **kwargs):
        raise PermissionError(13, "Permission denied", str(self))

    monkeypatch.setattr(Path, "mkdir", refuse)  # as for a read-only folder, even for root
    assert generate_toy(tmp_path / "ds") == 1  # a file-system failure (exit 1) naming the path
    one_line_error(capsys, f"Permission denied: {tmp_path / 'ds'}")


def test_a_hanging_instance_is_reported_on_one_line_and_the_run_completes(tmp_path, capsys):
    register_family(
        FamilySpec(
            name="toy-hang", summary="hangs", build=lambda _: MisbehavingFamily(hang_index=1)
        ),
        replace=True,
    )
    argv = ["generate", "toy-hang", "--n", "3", "--out", str(tmp_path / "ds"), "--time-limit", "1"]
    assert main([*argv, "--workers", "2"]) == 0
    out, err = capsys.readouterr()
    assert "scpformer: instance 1: timeout: exceeded the 1 s time limit" in err
    assert "timeout 1" in out
    assert storage.read_manifest(tmp_path / "ds").complete
