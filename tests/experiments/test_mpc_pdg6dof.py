"""``scpformer experiment run mpc-pdg6dof``: closed-loop landing Monte Carlo, three starts."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from scpformer.cli.main import main
from scpformer.experiments import EXPERIMENTS, mpc_pdg6dof


@pytest.fixture(scope="module")
def one_run(tmp_path_factory):
    """One run per warm start, re-planning every 24 intervals (one or two re-plans)."""
    out = tmp_path_factory.mktemp("mpc") / "out"
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(mpc_pdg6dof, "REPLAN_EVERY", 24)
        argv = ["experiment", "run", "mpc-pdg6dof", "--n", "1", "--seed", "5", "--out", str(out)]
        assert main(argv) == 0
    return out


def test_the_experiment_is_registered_with_the_shipped_networks():
    entry = EXPERIMENTS["mpc-pdg6dof"]
    assert entry.module == "scpformer.experiments.mpc_pdg6dof"
    assert "src/scpformer/guidance/pdg6dof_mpc.py" in entry.depends_on


def test_every_start_flies_the_same_run_and_tscvx_is_compared_on_its_re_plans(one_run):
    with (one_run / "results.csv").open(newline="") as fh:
        (row,) = list(csv.DictReader(fh))
    assert row["index"] == "0"
    for warmstart in mpc_pdg6dof.WARMSTARTS:
        assert int(row[f"{warmstart}_replans"]) >= 1
        # the same dispersed instance: one open-loop optimum for all three
        assert row[f"{warmstart}_open_loop_fuel"] == row["cold_open_loop_fuel"]
    with np.load(one_run / "tscvx" / "run-0000.npz") as data:
        flown = data["replan_node"].tolist()
        compared = data["compare_warmstart"].tolist()
        assert compared == ["cold", "previous"] * len(flown)
        assert data["compare_node"].tolist() == [n for n in flown for _ in range(2)]
    with np.load(one_run / "best" / "run-0000.npz") as data:
        assert set(data["replan_used"].tolist()) <= {"previous", "tscvx"}
        assert set(data["replan_warmstart"].tolist()) == {"best"}
        assert data["compare_warmstart"].tolist() == ["cold", "previous"] * len(data["replan_node"])
    results = json.loads((one_run / "results.json").read_text())
    assert results["experiment"] == "mpc-pdg6dof"
    assert len(results["rows"]) == 4 and all(r["status"] == "not rated" for r in results["rows"])
    report = (one_run / "report.md").read_text()
    for section in ("## Summary", "## T-SCvx vs cold on the same re-plans",
                    "## T-SCvx vs previous on the same re-plans",
                    "## best (T-SCvx from the networks' or the shifted guess) vs previous on "
                    "the same re-plans", "## Failures"):  # fmt: skip
        assert section in report
    assert "solved by both / only this / only the baseline / neither" in report
    assert "cost where both solved: lower / tie" in report
    # the re-plans fly the mid-flight networks, named with the commands that made them
    made = report.split("## How the data and models were made", 1)[1].split("##", 1)[0]
    assert "the shipped model tscvx-midflight" in made and "--midflight-nodes 5 35" in made


def test_a_rerun_resumes_and_other_settings_are_refused(one_run, capsys):
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(mpc_pdg6dof, "REPLAN_EVERY", 24)
        argv = ["experiment", "run", "mpc-pdg6dof", "--n", "1", "--seed", "5"]
        assert main([*argv, "--out", str(one_run)]) == 0  # nothing left to fly
        assert "run 1/1" not in capsys.readouterr().err
        assert main([*argv[:-1], "6", "--out", str(one_run)]) == 2
    assert "other settings (seed)" in capsys.readouterr().err
