"""``--print-config`` and ``--config FILE.toml``: a command's configuration in a file.

``--print-config`` writes TOML that ``--config`` reads back to the same configuration (the
same bytes printed again, the same solution solved), a flag given beside ``--config``
overrides the file, and a bad entry of the file is one usage line naming it. The flags are
built from a snapshot of the configuration dataclasses (:mod:`scpformer.cli.schema`), which
must match the live classes.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from scpformer.cli.main import main

# the cheapest settings of each solve (a convex problem, a small robust plan, SCvx on the
# nominal 6-DoF instance)
SOLVES = {
    "pdg6dof": ["solve", "pdg6dof"],
    "rendezvous": ["solve", "rendezvous", "--problem", "convex"],
    "robust-rendezvous": [
        "solve", "robust-rendezvous", "--warmstart", "tpbvp", "--scvx-star-iter-max", "2",
        "--scenario-n-nodes", "20", "--scenario-n-ae-to-koz", "10", "--scenario-n-safety", "8",
    ],
}  # fmt: skip
OTHERS = {
    "generate-pdg6dof": ["generate", "pdg6dof", "--n", "4", "--out", "data"],
    "generate-rendezvous": ["generate", "rendezvous", "--n", "4", "--out", "data"],
    "generate-robust-rendezvous": [
        *["generate", "robust-rendezvous", "--n", "4", "--out", "data"],
        *["--range-waypoints", "-T", "+R"],  # values that look like options
    ],
    "train-art": ["train", "art", "--data", "data", "--out", "run", "--lr", "0.002"],
    "train-gru": ["train", "gru", "--data", "data", "--out", "run", "--twin", "cvx"],
    "train-lstm": ["train", "lstm", "--data", "data", "--out", "run", "--preset", "paper"],
    "train-tscvx": ["train", "tscvx", "--data", "data", "--out", "run", "--no-canonical"],
    "train-kdtree": ["train", "kdtree", "--data", "data", "--out", "run"],
    "train-interp": ["train", "interp", "--data", "data", "--out", "run", "--max-points", "7"],
}
COMMANDS = {**{f"solve-{k}": v for k, v in SOLVES.items()}, **OTHERS}


def printed(argv: list[str], capsys) -> str:
    """What ``scpformer ARGV --print-config`` prints (it must succeed)."""
    code = main([*argv, "--print-config"])
    out, err = capsys.readouterr()
    assert code == 0, err
    return out


def command_of(argv: list[str]) -> list[str]:
    """The command words of ``argv`` (its flags left out)."""
    return argv[:2]


@pytest.mark.parametrize("name", list(COMMANDS))
def test_print_config_reads_back_to_the_same_bytes(name, tmp_path, capsys):
    argv = COMMANDS[name]
    text = printed(argv, capsys)
    assert text.strip(), "the configuration is empty"
    path = tmp_path / "c.toml"
    path.write_text(text, encoding="utf-8")
    again = printed([*command_of(argv), "--config", str(path)], capsys)
    assert again == text


def test_print_config_writes_the_resolved_values(tmp_path, capsys):
    text = printed(COMMANDS["train-art"], capsys)
    assert "lr = 0.002" in text.splitlines()
    assert 'data = "data"' in text.splitlines()
    assert "epochs" not in text  # the preset's default is not a value of the command line
    text = printed(SOLVES["rendezvous"], capsys)
    assert 'problem = "convex"' in text.splitlines()
    assert "[scp]" in text.splitlines()  # every solver setting, given or default


def _arrays(path: Path) -> dict[str, object]:
    """The arrays of a solution file; per-iteration timings (of pdg6dof's ``history``) out."""
    with np.load(path, allow_pickle=False) as data:
        out: dict[str, object] = {k: data[k] for k in data.files}
    if "history" in out:
        records = json.loads(str(out["history"]))
        out["history"] = [{k: v for k, v in r.items() if not k.startswith("time_")}
                          for r in records]  # fmt: skip
    return out


@pytest.mark.parametrize("family", list(SOLVES))
def test_a_solve_from_its_printed_config_writes_the_same_solution(family, tmp_path, capsys):
    argv = SOLVES[family]
    path = tmp_path / "c.toml"
    path.write_text(printed(argv, capsys), encoding="utf-8")
    direct, configured = tmp_path / "a.npz", tmp_path / "b.npz"
    code_direct = main([*argv, "--out", str(direct)])
    code_configured = main([*command_of(argv), "--config", str(path), "--out", str(configured)])
    capsys.readouterr()
    assert code_configured == code_direct
    a, b = _arrays(direct), _arrays(configured)
    assert a.keys() == b.keys() and len(a) > 3
    for key in a:
        if key == "history":
            assert a[key] == b[key]
        else:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def test_a_flag_overrides_the_file(tmp_path, capsys):
    path = tmp_path / "c.toml"
    path.write_text(printed(SOLVES["rendezvous"], capsys), encoding="utf-8")
    assert "k = 20" in path.read_text().splitlines()
    base = ["solve", "rendezvous", "--config", str(path)]
    text = printed([*base, "--scp-k", "7", "--problem", "tpbvp"], capsys)
    assert "k = 7" in text.splitlines() and 'problem = "tpbvp"' in text.splitlines()
    assert "k = 20" not in text.splitlines()
    # and the solve follows the flag, not the file
    out_flag, out_plain = tmp_path / "flag.npz", tmp_path / "plain.npz"
    assert main([*base, "--problem", "tpbvp", "--out", str(out_flag)]) == 0
    assert main(["solve", "rendezvous", "--problem", "tpbvp", "--out", str(out_plain)]) == 0
    capsys.readouterr()
    a, b = _arrays(out_flag), _arrays(out_plain)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def test_a_list_flag_and_a_repeated_flag_read_back(tmp_path, capsys):
    argv = ["train", "gru", "--data", "d", "--out", "r", "--twin", "cvx", "--twin", "scp",
            "--betas", "0.8", "0.9"]  # fmt: skip
    text = printed(argv, capsys)
    assert 'twin = ["cvx", "scp"]' in text.splitlines()
    assert "betas = [0.8, 0.9]" in text.splitlines()


@pytest.mark.parametrize(
    ("argv", "content", "names"),
    [
        (SOLVES["rendezvous"], "[scp]\nno-such-key = 1\n", "'scp.no-such-key'"),
        (SOLVES["rendezvous"], "no-such-key = 1\n", "'no-such-key'"),
        (SOLVES["rendezvous"], "[no-such-section]\nk = 1\n", "'no-such-section.k'"),
        (SOLVES["rendezvous"], '[scp]\nk = "many"\n', "scp.k"),
        (SOLVES["rendezvous"], 'problem = "no-such-problem"\n', "problem: invalid choice"),
        (SOLVES["pdg6dof"], "[scvx]\niter-max = 1.5\n", "scvx.iter-max"),
        (SOLVES["robust-rendezvous"], "[scvx-star]\nnope = 1\n", "'scvx-star.nope'"),
        (OTHERS["train-art"], "lr = true\n", "lr: expected"),
        (OTHERS["generate-rendezvous"], "[range]\nda-m = [1.0]\n", "range.da-m"),
        (SOLVES["rendezvous"], "[scp\n", "c.toml"),  # not TOML at all
    ],
)
def test_a_bad_entry_of_the_file_is_one_line_naming_it(argv, content, names, tmp_path, capsys):
    path = tmp_path / "c.toml"
    path.write_text(content, encoding="utf-8")
    code = main([*command_of(argv), *argv[2:], "--config", str(path)])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("scpformer: error: "), err
    assert "--config" in err and names in err, err


def test_a_missing_config_file_is_one_line(tmp_path, capsys):
    missing = tmp_path / "none.toml"
    assert main(["solve", "rendezvous", "--config", str(missing)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(missing) in err


def test_the_schema_snapshot_matches_the_live_classes(tmp_path):
    """``python -m scpformer.cli.dataclass_args`` would write the committed snapshot again."""
    from scpformer.cli import dataclass_args

    written = dataclass_args.write_snapshot(tmp_path / "schema.py")
    committed = Path(dataclass_args.__file__).with_name("schema.py")
    assert written.read_text(encoding="utf-8") == committed.read_text(encoding="utf-8"), (
        "the configuration dataclasses changed: run `python -m scpformer.cli.dataclass_args`"
    )
