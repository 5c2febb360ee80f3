"""``scpformer experiment run mpc-rendezvous``: closed-loop Monte Carlo of the re-plan warm
starts cold, previous, art and best."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from scpformer.cli.main import main
from scpformer.experiments import EXPERIMENTS, mpc_rendezvous
from scpformer.rendezvous import sample_instances


@pytest.fixture(scope="module")
def one_run(tmp_path_factory):
    """One run per warm start, re-planning at nodes 45 and 90 (the final approach) only."""
    out = tmp_path_factory.mktemp("mpc") / "out"
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(mpc_rendezvous, "REPLAN_EVERY", 45)
        argv = ["experiment", "run", "mpc-rendezvous", "--n", "1", "--seed", "3", "--out", str(out)]
        assert main(argv) == 0
    return out


def test_the_experiment_is_registered_without_models_or_data():
    entry = EXPERIMENTS["mpc-rendezvous"]
    assert entry.module == "scpformer.experiments.mpc_rendezvous"
    assert "src/scpformer/guidance/rendezvous_mpc.py" in entry.depends_on


def test_every_warm_start_flies_the_same_run_and_the_report_cites_celestini(one_run):
    with (one_run / "results.csv").open(newline="") as fh:
        (row,) = list(csv.DictReader(fh))
    assert row["index"] == "0"
    for warmstart in mpc_rendezvous.WARMSTARTS:
        assert row[f"{warmstart}_replans"] == "2"
        # the same instance under the same errors: one open-loop plan for both
        assert row[f"{warmstart}_open_loop_fuel"] == row["cold_open_loop_fuel"]
    with np.load(one_run / "previous" / "run-0000.npz") as data:
        assert data["replan_node"].tolist() == [45, 90]
        assert data["compare_warmstart"].tolist() == ["cold", "cold"]
    with np.load(one_run / "art" / "run-0000.npz") as data:
        assert data["compare_warmstart"].tolist() == ["cold", "previous"] * 2
        assert data["replan_used"].tolist() == ["art", "art"]
    results = json.loads((one_run / "results.json").read_text())
    assert results["experiment"] == "mpc-rendezvous"
    rows = {r["metric"]: r for r in results["rows"]}
    assert len(rows) == 2 and all(r["status"] == "not rated" for r in rows.values())
    assert any("45%" in r["paper"] for r in rows.values())
    assert any("7x" in r["paper"] for r in rows.values())
    report = (one_run / "report.md").read_text()
    for section in ("## Summary", "## Who wins", "## Previous vs cold on the same re-plans",
                    "## ART vs cold and previous on the same re-plans", "## Failures"):  # fmt: skip
        assert section in report
    assert "(ART vs cold, 2 re-plans)" in report and "start the SCP began from" in report
    assert "win / tie / loss" in report and "p99 re-plan time / period" in report
    # the model the learned starts flew is named with the commands that made it
    made = report.split("## How the data and models were made", 1)[1].split("##", 1)[0]
    assert "the shipped model art-rendezvous" in made
    assert "scpformer generate rendezvous" in made and "scpformer train art" in made


def test_a_rerun_resumes_and_other_settings_are_refused(one_run, capsys):
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(mpc_rendezvous, "REPLAN_EVERY", 45)
        argv = ["experiment", "run", "mpc-rendezvous", "--n", "1", "--seed", "3"]
        assert main([*argv, "--out", str(one_run)]) == 0  # nothing left to fly
        assert "run 1/1" not in capsys.readouterr().err
        assert main([*argv[:-1], "4", "--out", str(one_run)]) == 2
    assert "other settings (seed)" in capsys.readouterr().err


def test_the_instances_are_not_those_of_a_dataset_of_the_same_seed():
    """Run r of seed S draws from SeedSequence([S, r]); the dataset engine's instance i of
    seed S from SeedSequence(S, spawn_key=(i,)): different streams."""
    campaign = mpc_rendezvous.campaign(2, 3, "cold")
    for r in range(2):
        dataset = np.random.default_rng(np.random.SeedSequence(3, spawn_key=(r,)))
        assert campaign.instance(r) != sample_instances(dataset, 1)[0]
