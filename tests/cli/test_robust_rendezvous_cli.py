"""``scpformer solve robust-rendezvous`` and ``scpformer bench robust-rendezvous``."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from scpformer.cli.main import main
from scpformer.cli.robust_rendezvous import BENCH_FIELDS
from scpformer.problems.robust_rendezvous.io import NPZ_FIELDS

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def test_solve_writes_npz_figure_and_monte_carlo_report(tmp_path, capsys):
    out, png = tmp_path / "r.npz", tmp_path / "r.png"
    argv = ["solve", "robust-rendezvous", "--mode", "chance", "--waypoint", "-T",
            "--out", str(out), "--plot", str(png), "--monte-carlo", "4"]  # fmt: skip
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "converged" in text and "passive_safety" in text and "design level Delta" in text
    assert "nonlinear mean elements" in text
    with np.load(out, allow_pickle=False) as data:
        assert set(data.files) == set(NPZ_FIELDS)
        assert data["roe"].shape == (101, 6) and data["dv"].shape == (100, 3)
        assert data["covariance"].shape == (100, 6, 6) and data["safety"].shape == (100,)
        assert np.all(data["safety"] >= data["safety_mean"])
        # the mean state's first-order RTN: the osculating one is the waypoint (J2 short-period)
        assert np.allclose(data["rtn"][-1], [0, -750, 0, 0, 0, 0], atol=2.0)
        constants = json.loads(str(data["constants"]))
        assert constants["mode"] == "chance" and constants["instance"]["waypoint"] == "-T"
    assert png.read_bytes()[:8] == PNG_MAGIC


def test_solve_reads_an_instance_file(tmp_path, capsys):
    path = tmp_path / "i.json"
    path.write_text(json.dumps({"x0_rtn": [-4200, -17000, 0, 0, 7.0, 0], "waypoint": "+R"}))
    code = main(["solve", "robust-rendezvous", "--instance", str(path), "--mode",
                 "deterministic", "--warmstart", "tpbvp"])  # fmt: skip
    assert code in (0, 1)  # 1: SCvx* did not converge, reported as a status
    assert "status" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--waypoint", "+N"], "argument --waypoint: invalid choice: '+N'"),
        (["--delta", "1.5"], "delta must lie in the open interval (0, 1)"),
        (["--delta", "0"], "delta must lie in the open interval (0, 1)"),
        (["--instance", "/nonexistent/i.json"], "instance file not found"),
        (["--monte-carlo", "-1"], "argument --monte-carlo: must be at least 0"),
        (["--scenario-n-safety", "0"], "scenario.n_safety"),
        (["--scvx-star-gamma", "1.5"], "gamma must lie in (0, 1)"),
    ],
)
def test_bad_input_is_a_one_line_error(argv, message, capsys):
    assert main(["solve", "robust-rendezvous", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


@pytest.mark.parametrize(
    ("values", "expected"),
    [
        (["+T", "-T"], ("+T", "-T")),
        (["-R"], ("-R",)),
        (["-T", "+R", "-R", "+T"], ("-T", "+R", "-R", "+T")),
    ],
)
def test_generate_range_waypoints_reads_signed_waypoints(values, expected):
    from scpformer.cli.data import FAMILY_ARGUMENTS
    from scpformer.cli.main import build_parser

    argv = ["generate", "robust-rendezvous", "--range-waypoints", *values, "--n", "1"]
    args = build_parser().parse_args([*argv, "--out", "unused"])
    family = FAMILY_ARGUMENTS["robust-rendezvous"].build(args)
    assert family.config.ranges.waypoints == expected


@pytest.mark.parametrize(
    ("values", "message"),
    [
        (["+T", "X"], "argument --range-waypoints: invalid choice: 'X'"),
        (["-N"], "argument --range-waypoints: invalid choice: '-N'"),
        (["T"], "argument --range-waypoints: invalid choice: 'T'"),
        ([], "argument --range-waypoints: expected at least one argument"),
    ],
)
def test_generate_bad_range_waypoints_is_a_one_line_error(tmp_path, capsys, values, message):
    out = tmp_path / "data"
    argv = ["generate", "robust-rendezvous", "--range-waypoints", *values, "--n", "1"]
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not out.exists()


def test_bad_instance_file_names_the_field(tmp_path, capsys):
    path = tmp_path / "i.json"
    path.write_text(json.dumps({"uncertainty": {"process_noise": {"Q_roe": [[0.0] * 6] * 6}}}))
    assert main(["solve", "robust-rendezvous", "--instance", str(path)]) == 2
    assert "Q_roe must be positive definite" in capsys.readouterr().err


def test_bench_writes_csv_and_summary(tmp_path, capsys):
    path = tmp_path / "b.csv"
    assert main(["bench", "robust-rendezvous", "--n", "2", "--seed", "4", "--csv", str(path)]) == 0
    text = capsys.readouterr().out
    assert "PS-CVX-C (chance)" in text and "PS-CVX-D (det.)" in text and "solver" in text
    rows = list(csv.DictReader(path.open()))
    assert len(rows) == 2 and tuple(rows[0]) == BENCH_FIELDS
    assert all(float(r["cc_wall_s"]) > 0 and int(r["cc_iterations"]) >= 1 for r in rows)
