"""``scpformer experiment run mpc-robust-rendezvous``: closed-loop Monte Carlo of the
chance-constrained rendezvous: the re-plan warm starts cold, previous, art and best."""

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
    assert (
        entry.default_n == 100
        and "src/scpformer/guidance/robust_rendezvous_mpc.py" in entry.depends_on
    )


def test_every_warm_start_flies_the_same_run_and_is_compared_on_its_re_plans(one_run):
    with (one_run / "results.csv").open(newline="") as fh:
        (row,) = list(csv.DictReader(fh))
    for warmstart in mpc_robust_rendezvous.WARMSTARTS:
        assert row[f"{warmstart}_replans"] == "2"
        assert row[f"{warmstart}_open_loop_fuel"] == row["cold_open_loop_fuel"]
    with np.load(one_run / "previous" / "run-0000.npz") as data:
        assert data["replan_node"].tolist() == [45, 90]
        assert data["compare_warmstart"].tolist() == ["cold", "cold"]
    for learned in ("art", "best"):
        with np.load(one_run / learned / "run-0000.npz") as data:
            assert data["compare_warmstart"].tolist() == ["cold", "previous"] * 2
            assert set(data["replan_used"].tolist()) <= {"art", "previous", "tpbvp"}
    report = (one_run / "report.md").read_text()
    for section in ("## Summary", "## Who wins", "## Previous vs cold on the same re-plans",
                    "## ART vs cold and previous on the same re-plans",
                    "## Best (ART or previous by Eq. 8) vs cold and previous on the same "
                    "re-plans", "## Failures"):  # fmt: skip
        assert section in report
    assert "win / tie / loss" in report and "convex solves per re-plan" in report
    assert "solved by both / only this / only the baseline / neither | 2 / 0 / 0 / 0" in report
    assert "The start each of the 2 flown re-plans began from: art " in report


def test_failures_name_what_failed_and_count_drift_entries_against_the_designed_risk(tmp_path):
    from scpformer.experiments.closed_loop import Flights

    fields = {"drift_entries": "0", "passive_safety_nodes": "0", "keep_out_violation": "0.0",
              "terminal_position_error": "2.5", "terminal_velocity_error": "0.001",
              "replans_failed": "0", "replans": "9"}  # fmt: skip
    rows = {"cold": [{"run": "0", "success": "True", **fields},
                     {"run": "1", "success": "False", **fields, "drift_entries": "2"}]}  # fmt: skip
    (tmp_path / "cold").mkdir()
    distances = {0: np.full(100, 3.0), 1: np.r_[np.full(98, 3.0), 0.5, 0.9]}
    for run, distance in distances.items():
        np.savez(tmp_path / "cold" / f"run-{run:04d}.npz", drift_distance=distance)
    text = mpc_robust_rendezvous.failures_text(Flights(rows, {}, tmp_path, ("cold",)))
    assert "| cold | 1 | 2 drift entries" in text and "| cold | 0 |" not in text
    designed = 1.0 - (1.0 - 1e-3) ** 100  # a 100-node flight at Delta = 1e-3
    assert "2 drift entries in 200 flown nodes (1.0e-02 per node" in text
    assert f"probability up to {designed:.1%}" in text
    assert "(0 to 9): 0: 0, 1: 0, 2: 0, 3: 0, 4: 0, 5: 0, 6: 0, 7: 0, 8: 1, 9: 1." in text
