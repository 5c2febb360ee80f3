"""Every bad input to ``scpformer solve|bench`` is one ``scpformer: error:`` line, nothing else.

Each case is one probe of a bad input (or the class it stands for). It asserts the exit status,
that stderr is exactly one line naming the flag, field or path, and that no file that existed
before is changed. Every case fails before any solve, so the suite runs in-process and fast.
"""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import pytest

from scpformer.cli.main import main


@pytest.fixture
def read_only_dir(tmp_path):
    """A folder no file can be created in (root ignores permissions; sysfs refuses even root)."""
    if os.geteuid() == 0:
        yield Path("/sys")
        return
    folder = tmp_path / "read-only"
    folder.mkdir()
    folder.chmod(0o555)
    yield folder
    folder.chmod(0o755)


@pytest.fixture
def places(tmp_path, read_only_dir):
    """Placeholders of the cases: an existing folder and file, a read-only folder."""
    folder = tmp_path / "folder"
    folder.mkdir()
    (folder / "keep.txt").write_text("precious")
    (tmp_path / "file.txt").write_text("precious")
    (tmp_path / "old.npz").write_bytes(b"an earlier solution")
    os.mkfifo(tmp_path / "fifo.npz")
    return {
        "{fifo}": str(tmp_path / "fifo.npz"),
        "{name}": tmp_path.name,
        "{tmp}": str(tmp_path),
        "{dir}": str(folder),
        "{file}": str(tmp_path / "file.txt"),
        "{ro}": str(read_only_dir),
    }


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def run_one_line_error(capsys, argv: list[str], status: int, text: str) -> str:
    """Run ``scpformer argv``; check the status and that stderr is one line naming ``text``."""
    assert main(argv) == status
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("scpformer: error: ") and text in lines[0], lines[0]
    assert "Traceback" not in out + err
    return lines[0]


def fill(argv: list[str], places: dict[str, str]) -> list[str]:
    for key, value in places.items():
        argv = [a.replace(key, value) for a in argv]
    return argv


GENERATE = ["generate", "rendezvous", "--n", "2", "--out", "{tmp}/gen"]
FLAG_CASES = {
    # counts and seeds: refused by the argument's type, naming the flag
    "bench-n-nominal-negative": (["bench", "pdg6dof", "--n-nominal", "-1"], "--n-nominal"),
    "bench-n-table2-negative": (["bench", "pdg6dof", "--n-table2", "-3"], "--n-table2"),
    "bench-n-not-an-integer": (["bench", "pdg6dof", "--n-nominal", "2.5"], "--n-nominal"),
    "bench-nothing-to-run": (
        ["bench", "pdg6dof", "--n-nominal", "0", "--n-table2", "0"],
        "nothing to benchmark",
    ),
    "bench-seed-negative": (["bench", "pdg6dof", "--seed", "-1"], "--seed"),
    "rendezvous-bench-n-zero": (["bench", "rendezvous", "--n", "0"], "--n"),
    "tscvx-bench-warmup-negative": (["bench", "tscvx", "--warmup", "-1"], "--warmup"),
    "robust-bench-n-negative": (["bench", "robust-rendezvous", "--n", "-1"], "--n"),
    "rendezvous-seed-negative": (["solve", "rendezvous", "--seed", "-1"], "--seed"),
    "robust-seed-negative": (["solve", "robust-rendezvous", "--seed", "-1"], "--seed"),
    "robust-monte-carlo-negative": (
        ["solve", "robust-rendezvous", "--monte-carlo", "-5"],
        "--monte-carlo",
    ),
    "robust-mc-seed-negative": (["solve", "robust-rendezvous", "--mc-seed", "-2"], "--mc-seed"),
    "unknown-flag": (["solve", "pdg6dof", "--bogus"], "--bogus"),
    "unknown-choice": (["solve", "rendezvous", "--problem", "fastest"], "--problem"),
    "nan-horizon": (["solve", "rendezvous", "--horizon-orbits", "nan"], "horizon_orbits"),
    "huge-roe0": (
        ["solve", "rendezvous", "--roe0", "0", "1e8", "0", "80", "0", "140", "--problem", "convex"],
        "roe0_m",
    ),
    "bad-scvx-setting": (["solve", "pdg6dof", "--scvx-rho-1", "0.9"], "rho"),
    "scvx-iter-max-negative": (["solve", "pdg6dof", "--scvx-iter-max", "-1"], "iter_max"),
    "constant-nan": (["solve", "pdg6dof", "--const-t-max", "nan"], "T_max"),
    "rendezvous-int-field-float": (["solve", "rendezvous", "--scenario-n-nodes", "2.5"], "n-nodes"),
    # silent before: a negative or NaN tolerance flags no row as tight
    "tight-tol-negative": (["solve", "pdg6dof", "--tight-tol", "-1"], "tight_tol"),
    "tight-tol-nan": (["solve", "pdg6dof", "--tight-tol", "nan"], "tight_tol must be finite"),
    # sizes bounded by memory, refused before any work (the OOM killer took them before)
    "pdg6dof-nodes-huge": (["solve", "pdg6dof", "--n-nodes", "100000000"], "n_nodes"),
    "rendezvous-nodes-huge": (
        ["solve", "rendezvous", "--scenario-n-nodes", "100000000"],
        "scenario.n_nodes",
    ),
    "robust-nodes-huge": (
        ["solve", "robust-rendezvous", "--scenario-n-nodes", "100000000"],
        "scenario.n_nodes",
    ),
    "robust-approach-ellipsoid-inside-keep-out": (
        ["solve", "robust-rendezvous", "--scenario-ae-semi-axes-m", "50", "100", "50"],
        "must contain the keep-out zone",
    ),
    "monte-carlo-huge": (
        ["solve", "robust-rendezvous", "--monte-carlo", "1000000000000"],
        "monte_carlo.n_samples",
    ),
    # output paths: checked before solving
    "out-existing-folder": (["solve", "pdg6dof", "--out", "{dir}"], "is a folder"),
    "out-under-a-file": (["solve", "pdg6dof", "--out", "{file}/sub/x.npz"], "is a file"),
    "out-read-only-folder": (["solve", "pdg6dof", "--out", "{ro}/x.npz"], "cannot write"),
    "plot-read-only-folder": (["solve", "pdg6dof", "--plot", "{ro}/x.png"], "cannot write"),
    "plot-unknown-format": (["solve", "pdg6dof", "--plot", "{tmp}/x.xyz"], "figure format"),
    "plot-without-suffix": (["solve", "pdg6dof", "--plot", "{tmp}/x"], "figure format"),
    "plot-onto-a-folder": (["solve", "pdg6dof", "--plot", "{dir}"], "--plot"),
    "rendezvous-out-folder": (["solve", "rendezvous", "--out", "{dir}"], "is a folder"),
    "rendezvous-plot-format": (["solve", "rendezvous", "--plot", "{tmp}/x.jpg"], "figure format"),
    "robust-out-under-a-file": (
        ["solve", "robust-rendezvous", "--out", "{file}/x.npz"],
        "is a file",
    ),
    "robust-plot-read-only": (
        ["solve", "robust-rendezvous", "--plot", "{ro}/x.svg"],
        "cannot write",
    ),
    "bench-csv-onto-a-folder": (
        ["bench", "pdg6dof", "--n-nominal", "1", "--n-table2", "0", "--csv", "{dir}"],
        "is a folder",
    ),
    "rendezvous-bench-csv-under-a-file": (
        ["bench", "rendezvous", "--n", "1", "--csv", "{file}/b.csv"],
        "is a file",
    ),
    "robust-bench-csv-read-only": (
        ["bench", "robust-rendezvous", "--n", "1", "--csv", "{ro}/b.csv"],
        "cannot write",
    ),
    "instance-is-a-folder": (["solve", "pdg6dof", "--instance", "{dir}"], "is a folder"),
    "rendezvous-instance-is-a-folder": (
        ["solve", "rendezvous", "--instance", "{dir}"],
        "is a folder",
    ),
    "instance-missing": (["solve", "pdg6dof", "--instance", "{tmp}/nope.json"], "not found"),
    "generate-range-inverted": (
        [*GENERATE, "--range-horizon-orbits", "3", "1"],
        "ranges.horizon_orbits must satisfy low <= high",
    ),
    "generate-range-nan": (
        [*GENERATE, "--range-da-m", "nan", "1"],
        "ranges.da_m must be finite",
    ),
    "rendezvous-horizon-absurd": (
        ["solve", "rendezvous", "--scenario-horizon-range-orbits", "1", "1e6"],
        "scenario.horizon_range_orbits must be at most 200 orbits",
    ),
    "robust-horizon-absurd": (
        ["solve", "robust-rendezvous", "--scenario-horizon-orbits", "1e6"],
        "scenario.horizon_orbits must be at most 200 orbits",
    ),
    "generate-range-horizon-absurd": (
        [*GENERATE, "--range-horizon-orbits", "1", "1e6"],
        "ranges.horizon_orbits must be at most 200 orbits",
    ),
    "rendezvous-art-rtg-huge": (
        ["solve", "rendezvous", "--warmstart", "art", "--rtg=-1e300"],
        "art warm start produced non-finite states",
    ),
    "generate-n-beyond-the-plan": (
        ["generate", "rendezvous", "--n", "1000000000000", "--out", "{tmp}/gen"],
        "n must be at most 100,000,000",
    ),
    "out-is-a-device": (["solve", "pdg6dof", "--out", "/dev/null"], "not a regular file"),
    "out-is-a-pipe": (["solve", "pdg6dof", "--out", "{fifo}"], "not a regular file"),
    "out-and-plot-the-same-file": (
        ["solve", "pdg6dof", "--out", "{tmp}/same.png", "--plot", "{tmp}/same.png"],
        "both write",
    ),
    "rendezvous-out-and-plot-the-same-file": (
        ["solve", "rendezvous", "--out", "{tmp}/r.svg", "--plot", "{tmp}/../{name}/r.svg"],
        "both write",
    ),
}


@pytest.mark.parametrize("argv, text", FLAG_CASES.values(), ids=FLAG_CASES.keys())
def test_a_bad_flag_or_output_path_is_one_line_and_changes_no_file(
    tmp_path, places, capsys, argv, text
):
    before = snapshot(tmp_path)
    run_one_line_error(capsys, fill(argv, places), 2, text)
    assert snapshot(tmp_path) == before


INSTANCE_CASES = {
    "rendezvous-j2-string": ("rendezvous", {"scenario": {"j2": "false"}}, "scenario.j2"),
    "rendezvous-horizon-string": ("rendezvous", {"horizon_orbits": "2"}, "horizon_orbits"),
    "rendezvous-roe0-huge": (
        "rendezvous",
        {"roe0_m": [0, 1e8, 0, 80, 0, 140], "horizon_orbits": 2},
        "roe0_m",
    ),
    "rendezvous-target-bool": ("rendezvous", {"target": {"e": True}}, "target.e"),
    "robust-j2-string": ("robust-rendezvous", {"scenario": {"j2": "no"}}, "scenario.j2"),
    "pdg6dof-r0-string": ("pdg6dof", {"r0": ["4", 4, 0]}, "r0"),
    "pdg6dof-m0-bool": ("pdg6dof", {"m0": True}, "m0"),
    "pdg6dof-m0-null": ("pdg6dof", {"m0": None}, "m0"),
    "pdg6dof-r0-huge": ("pdg6dof", {"r0": [1e9, 0, 0]}, "r0"),
    "pdg6dof-v0-wrong-length": ("pdg6dof", {"v0": [1, 2]}, "v0"),
    "pdg6dof-unknown-field": ("pdg6dof", {"r00": [4, 4, 0]}, "r00"),
    "pdg6dof-not-an-object": ("pdg6dof", [1, 2, 3], "JSON object"),
}


@pytest.mark.parametrize("family, data, text", INSTANCE_CASES.values(), ids=INSTANCE_CASES.keys())
def test_a_bad_instance_file_is_one_line_naming_the_field(tmp_path, capsys, family, data, text):
    path = tmp_path / "instance.json"
    path.write_text(json.dumps(data))
    before = snapshot(tmp_path)
    run_one_line_error(capsys, ["solve", family, "--instance", str(path)], 2, text)
    assert snapshot(tmp_path) == before


def test_malformed_instance_json_names_the_file(tmp_path, capsys):
    path = tmp_path / "instance.json"
    path.write_text('{"r0": [4, 4,')
    run_one_line_error(capsys, ["solve", "pdg6dof", "--instance", str(path)], 2, str(path))
    path.write_text('{"r0": ' + "[" * 100_000 + "]" * 100_000 + "}")  # beyond the recursion limit
    argv = ["solve", "rendezvous", "--instance", str(path)]
    run_one_line_error(capsys, argv, 2, "nested too deeply")


def test_a_full_disk_at_out_names_the_path_and_keeps_the_earlier_file(
    tmp_path, capsys, monkeypatch
):
    import numpy as np

    def no_space(file, **arrays):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(np, "savez", no_space)
    out = tmp_path / "old.npz"
    out.write_bytes(b"an earlier solution")
    argv = ["solve", "rendezvous", "--problem", "tpbvp", "--no-verify", "--out", str(out)]
    line = run_one_line_error(capsys, argv, 1, "No space left on device")
    assert str(out) in line
    assert out.read_bytes() == b"an earlier solution"
    assert [p.name for p in tmp_path.iterdir()] == ["old.npz"]  # no temporary file left


def test_help_still_exits_zero(capsys):
    assert main(["solve", "pdg6dof", "--help"]) == 0
    assert "--plot" in capsys.readouterr().out


def raise_(error: BaseException):
    def solve(*args, **kwargs):
        raise error

    return solve


FAILURE_CASES = {
    "ctrl-c": (KeyboardInterrupt(), 130, "interrupted"),
    "solver-crash": ("solver", 1, "the conic solver failed: CLARABEL crashed"),
    "permission": (PermissionError(13, "Permission denied", "/x/y.npz"), 1, "/x/y.npz"),
    "bug": (ZeroDivisionError("division by zero"), 1, "internal error (ZeroDivisionError"),
    "bug-type-error": (TypeError("unsupported operand"), 1, "internal error (TypeError"),
    "out-of-memory": (MemoryError(), 1, "out of memory"),
}


@pytest.mark.parametrize("error, status, text", FAILURE_CASES.values(), ids=FAILURE_CASES.keys())
def test_every_failure_during_a_solve_is_one_line_with_its_status(
    capsys, monkeypatch, error, status, text
):
    import scpformer.cli.pdg6dof as command

    if error == "solver":
        from cvxpy.error import SolverError

        error = SolverError("CLARABEL crashed\nwith details on a second line")
    monkeypatch.delenv("SCPFORMER_DEBUG", raising=False)
    monkeypatch.setattr(command, "solve", raise_(error))
    run_one_line_error(capsys, ["solve", "pdg6dof"], status, text)


def test_debug_mode_shows_the_traceback(monkeypatch):
    import scpformer.cli.pdg6dof as command

    monkeypatch.setenv("SCPFORMER_DEBUG", "1")
    monkeypatch.setattr(command, "solve", raise_(ZeroDivisionError("bug")))
    with pytest.raises(ZeroDivisionError):
        main(["solve", "pdg6dof"])
