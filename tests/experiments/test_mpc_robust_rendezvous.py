"""``scpformer experiment run mpc-robust-rendezvous``: closed-loop Monte Carlo of the
chance-constrained rendezvous, cold against previous-plan re-plans."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from scpformer.cli.main import main
from scpformer.experiments import EXPERIMENTS, mpc_robust_rendezvous


@pytest.fixture(scope="module")
def one_run(tmp_path_factory):
    """One run per warm start, re-planning at nodes 45 and 90 only, few Monte Carlo draws."""
    out = tmp_path_factory.mktemp("mpc") / "out"
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(mpc_robust_rendezvous, "REPLAN_EVERY", 45)
        patch.setattr(mpc_robust_rendezvous, "SAFETY_SAMPLES", 5)
        argv = ["experiment", "run", "mpc-robust-rendezvous", "--n", "1", "--out", str(out)]
        assert main(argv) == 0
    return out


def test_the_experiment_is_registered_without_models_or_data():
    entry = EXPERIMENTS["mpc-robust-rendezvous"]
    assert entry.module == "scpformer.experiments.mpc_robust_rendezvous"
    assert entry.default_n == 100 and "src/scpformer/guidance" in entry.depends_on


def test_both_warm_starts_fly_the_same_run_and_previous_is_compared_with_cold(one_run):
    with (one_run / "results.csv").open(newline="") as fh:
        (row,) = list(csv.DictReader(fh))
    for warmstart in mpc_robust_rendezvous.WARMSTARTS:
        assert row[f"{warmstart}_replans"] == "2"
        assert row[f"{warmstart}_open_loop_fuel"] == row["cold_open_loop_fuel"]
    with np.load(one_run / "previous" / "run-0000.npz") as data:
        assert data["replan_node"].tolist() == [45, 90]
        assert data["compare_warmstart"].tolist() == ["cold", "cold"]
    report = (one_run / "report.md").read_text()
    for section in ("## Summary", "## Previous vs cold on the same re-plans"):
        assert section in report
    assert "win / tie / loss" in report and "convex solves per re-plan" in report
