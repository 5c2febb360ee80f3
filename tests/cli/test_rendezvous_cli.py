"""``scpformer solve rendezvous`` and ``scpformer bench rendezvous``."""

from __future__ import annotations

import argparse
import csv
import json

import numpy as np
import pytest

from scpformer.cli import main as cli_main
from scpformer.cli.parsers.rendezvous import add_bench_parser, add_solve_parser
from scpformer.cli.rendezvous import BENCH_FIELDS
from scpformer.plotting.rendezvous import plot_trajectory
from scpformer.problems.rendezvous.io import NPZ_FIELDS

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture
def run(monkeypatch):
    """``scpformer`` with the rendezvous family registered, through main's error handling."""

    def build_parser() -> argparse.ArgumentParser:
        parser = argparse.ArgumentParser(prog="scpformer")
        commands = parser.add_subparsers(dest="command", required=True)
        solve = commands.add_parser("solve").add_subparsers(dest="family", required=True)
        bench = commands.add_parser("bench").add_subparsers(dest="family", required=True)
        add_solve_parser(solve)
        add_bench_parser(bench)
        return parser

    monkeypatch.setattr(cli_main, "build_parser", build_parser)
    return cli_main.main


def test_solve_writes_the_npz_fields_and_a_figure(run, tmp_path, capsys):
    out, png = tmp_path / "rdv.npz", tmp_path / "rdv.png"
    assert run(["solve", "rendezvous", "--out", str(out), "--plot", str(png)]) == 0
    text = capsys.readouterr().out
    assert "converged" in text and "terminal miss" in text and "conic solver" in text
    with np.load(out, allow_pickle=False) as data:
        assert set(data.files) == set(NPZ_FIELDS)
        assert data["t"].shape == (101,) and data["roe"].shape == (101, 6)
        assert data["rtn"].shape == (101, 6) and data["dv"].shape == (100, 3)
        assert data["constraint_to_go"].shape == (101,) and str(data["status"]) == "converged"
        assert json.loads(str(data["constants"]))["n_waypoint"] == 90
    assert png.read_bytes()[:8] == PNG_MAGIC


@pytest.mark.parametrize(
    "content, message",
    [
        ("{not json", "malformed JSON"),
        (json.dumps({"roe0_m": [0, 50, 0, 80, 0, 140], "speed": 3}), "unknown instance field(s)"),
        (json.dumps({"target": {"a_m": 6.0e6}}), "target.a_m: semi-major axis"),
        (json.dumps({"target": {"e": 1.2}}), "target.e: eccentricity"),
        ('{"roe0_m": [0, NaN, 0, 80, 0, 140]}', "roe0_m must be finite"),
        (json.dumps({"horizon_orbits": 5.0}), "horizon_orbits must lie in [1.0, 3.0]"),
        (json.dumps({"roe0_m": [0, 0, 0, 10, 0, 10]}), "inside the keep-out zone"),
    ],
)
def test_bad_instance_file_ends_with_one_line_error(run, tmp_path, capsys, content, message):
    path = tmp_path / "instance.json"
    path.write_text(content)
    assert run(["solve", "rendezvous", "--instance", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("scpformer: error:") and message in err
    assert "\n" not in err and "Traceback" not in err


def test_missing_instance_file_and_bad_flags_are_clear_errors(run, tmp_path, capsys):
    assert run(["solve", "rendezvous", "--instance", str(tmp_path / "nope.json")]) == 2
    assert "instance file not found" in capsys.readouterr().err
    assert run(["solve", "rendezvous", "--scp-zeta-k", "500"]) == 2
    assert "scp.zeta_K (500.0) must not exceed" in capsys.readouterr().err
    assert run(["solve", "rendezvous", "--horizon-orbits", "0.2"]) == 2
    assert "horizon_orbits must lie in" in capsys.readouterr().err


def test_problem_and_warmstart_flags_pick_what_is_solved(run, capsys):
    assert run(["solve", "rendezvous", "--problem", "tpbvp", "--no-verify"]) == 0
    out = capsys.readouterr().out
    assert "Problem 1 (tpbvp): optimal" in out and "not verified" in out
    assert run(["solve", "rendezvous", "--seed", "0", "--warmstart", "tpbvp", "--no-verify"]) == 0
    out = capsys.readouterr().out
    assert "warm start (tpbvp): converged" in out and "Eq. 19 met" in out


def test_seed_samples_the_same_instance_every_time(run, capsys):
    outputs = []
    for seed in ("7", "7", "8"):
        assert run(["solve", "rendezvous", "--problem", "convex", "--seed", seed]) == 0
        lines = capsys.readouterr().out.splitlines()
        outputs.append(next(line for line in lines if line.startswith("cost")))
    assert outputs[0] == outputs[1] != outputs[2]


def test_infeasible_scenario_from_flags_reports_its_status(run, capsys):
    assert run(["solve", "rendezvous", "--scenario-cone-vertex-setback-m", "0"]) == 1
    out = capsys.readouterr().out
    assert "infeasible_instance" in out and "warm start failed" in out


def test_help_documents_table_1_defaults(run, capsys):
    assert run(["solve", "rendezvous", "--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())  # undo argparse's line wrapping
    assert "initial (maximum) trust region radius [m] (default: 200.0)" in out
    assert "--scp-j-tol" in out  # the scenario and target constants: in --print-config
    assert "--target-a-m" not in out and "--scenario-n-nodes" not in out


def test_bench_writes_a_csv_row_per_instance_and_a_summary(run, tmp_path, capsys):
    out = tmp_path / "bench.csv"
    assert run(["bench", "rendezvous", "--n", "2", "--seed", "1", "--csv", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == 2 and tuple(rows[0]) == BENCH_FIELDS
    assert all(r["p3_status"] == "converged" and int(r["C_cvx_t1"]) >= 0 for r in rows)
    assert all(float(r["p3_terminal_miss_m"]) < 2.0 for r in rows)
    text = capsys.readouterr().out
    for needle in ("1 tpbvp", "2 convex", "3 scp", "SCP iterations", "C_CVX(t_1)", "solver"):
        assert needle in text


def test_plot_rejects_inconsistent_shapes():
    t = np.linspace(0.0, 100.0, 11)
    constants = {
        "koz_semi_axes_m": [60, 94, 123],
        "n_waypoint": 8,
        "waypoint_m": [0, 104, 0],
        "dock_port_m": [0, 74, 0],
        "cone_vertex_m": [0, 69, 0],
        "approach_axis": [0, 1, 0],
        "cone_half_angle_deg": 30,
        "period_s": 5573.0,
    }
    roe = rtn = np.zeros((11, 6))
    with pytest.raises(ValueError, match=r"dv must have shape \(10, 3\)"):
        plot_trajectory(t, roe, rtn, np.zeros((11, 3)), constants)
    with pytest.raises(ValueError, match="missing required key"):
        plot_trajectory(t, roe, rtn, np.zeros((10, 3)), {"n_waypoint": 8})
