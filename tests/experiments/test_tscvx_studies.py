"""The T-SCvx experiments on a tiny real 6-DoF dataset (20 nodes, nominal instances)."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from scpformer.cli.main import main
from scpformer.data.augment import RotationAugmentation, augment_dataset
from scpformer.data.generate import GenerateConfig, generate
from scpformer.data.pdg6dof_family import PDG6DoFDataConfig, PDG6DoFFamily
from scpformer.data.splits import SplitConfig, make_splits
from scpformer.experiments import RunOptions, run_experiment
from scpformer.experiments.runner import column
from scpformer.experiments.tscvx.common import COLD, method_stats
from scpformer.experiments.tscvx.lookup import ood_selection
from scpformer.models.predictors import load_predictor, predictor_kind
from scpformer.problems.pdg6dof.problem import PDGSolverConfig
from scpformer.problems.pdg6dof.sampling import PDGSampleRanges

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def tscvx_study(tmp_path_factory):
    """4 nominal instances x 4 rotations, split by instance; a 1-epoch T-SCvx run; a k-d tree."""
    root = tmp_path_factory.mktemp("tscvx-exp")
    config = PDG6DoFDataConfig(ranges=PDGSampleRanges.nominal(), solver=PDGSolverConfig(n_nodes=20))
    generate(PDG6DoFFamily(config), GenerateConfig(n=4, out=root / "base", shard_size=3,
                                                   workers=1, seed=3))  # fmt: skip
    rotations = RotationAugmentation(angles_deg=(0.0, 90.0, 180.0, 270.0))
    augment_dataset(root / "base", root / "ds", rotations)
    make_splits(root / "ds", SplitConfig(fractions=(0.34, 0.33, 0.33), seed=0))
    data, run, table = root / "ds", root / "run", root / "kdtree"
    args = ["--data", str(data), "--no-progress", "--epochs", "1", "--solution-epochs", "1"]
    main(["train", "tscvx", *args, "--out", str(run)])
    main(["train", "kdtree", "--data", str(data), "--out", str(table)])
    assert (run / "tight").is_dir() and (table / "lookup.json").is_file()
    return data, run, table


def test_the_predictor_runs_are_told_apart_and_bad_folders_are_refused(tscvx_study, tmp_path):
    _, run, table = tscvx_study
    assert predictor_kind(run) == "tscvx" and predictor_kind(table) == "kdtree"
    assert load_predictor(table).n_nodes == load_predictor(run).n_nodes == 20
    with pytest.raises(ValueError, match="not a T-SCvx run"):
        predictor_kind(tmp_path)
    with pytest.raises(ValueError, match="a kdtree run, not tscvx"):
        load_predictor(table, "tscvx")
    (tmp_path / "tight").mkdir()
    (tmp_path / "tight" / "checkpoint.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match=str(tmp_path)):
        load_predictor(tmp_path)


def test_solve_time_compares_cold_and_tscvx_on_the_same_instances(tscvx_study, tmp_path):
    data, run, table = tscvx_study
    out = tmp_path / "st"
    options = RunOptions(out=out, data=data, models=(run, table), n=2, workers=1)
    report = run_experiment("tscvx-solve-time", options, command="test").read_text()
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert len(rows) == 2 and (out / "fig2_solve_times.png").is_file()
    assert "T-SCvx mean solve-time reduction" in report
    assert "## Instance by instance" in report and "solved by both" in report
    # T-SCvx converges (fallbacks included) near cold SCvx's verified optimum. The networks of
    # this fixture trained one epoch on four instances, so their guess can lead SCvx to another
    # local optimum: measured 0.55% of the propellant above cold SCvx's on one of these two
    # instances (the 0.5% bound is a claim about trained networks, measured by the experiment)
    assert all(r["tscvx_status"] == "converged" for r in rows)
    assert np.all(column(rows, "tscvx_gap") <= 1e-2)
    assert all(r["tscvx_verified"] == "True" for r in rows)
    stats = method_stats(rows, COLD)
    assert stats["n"] == 2 and math.isfinite(stats["median_s"])
    results = json.loads((out / "results.json").read_text())
    assert results  # the machine-readable rows of docs/RESULTS.md


def test_training_and_trajectory_reports_are_written(tscvx_study, tmp_path):
    data, run, _ = tscvx_study
    for name, files in (
        ("tscvx-training", ["metrics_test.json"]),
        ("tscvx-trajectory", ["fig3_trajectory.png", "fig3_tight_rows.png"]),
    ):
        out = tmp_path / name
        report = run_experiment(name, RunOptions(out=out, data=data, models=(run,)), "test")
        assert report.is_file() and all((out / f).is_file() for f in files)
    text = (tmp_path / "tscvx-training" / "report.md").read_text()
    assert "predict-only-zeros accuracy" in text and "96.45%" in text


def test_the_lookup_study_needs_all_three_predictors(tscvx_study, tmp_path):
    data, run, table = tscvx_study
    options = RunOptions(out=tmp_path, data=data, models=(run, table), n=2)
    with pytest.raises(ValueError, match="tscvx, kdtree, interp"):
        run_experiment("tscvx-lookup", options, "test")


def test_ood_selection_takes_half_from_beyond_the_threshold():
    class Split:
        ood_positions = np.array([7, 8])
        in_distribution_positions = np.arange(7)

    positions, ood = ood_selection(Split(), 6, seed=0)
    assert positions.size == 6 and ood.sum() == 2
    assert set(positions[ood]) == {7, 8} and set(positions[~ood]) <= set(range(7))


def test_the_report_names_the_model_card_of_the_shipped_model_and_the_preset_of_a_run(tmp_path):
    from scpformer.experiments.tscvx.common import train_command
    from scpformer.pretrained import default_model

    shipped = default_model("pdg6dof")
    assert train_command("tscvx", shipped, Path("r8")).endswith(f"{shipped}/MODEL_CARD.md")
    (tmp_path / "config.json").write_text('{"preset": "small"}')
    line = train_command("tscvx", tmp_path, Path("r8"))
    assert line == f"scpformer train tscvx --data r8 --out {tmp_path} --preset small"
    assert "command unknown" in train_command("tscvx", tmp_path / "missing", Path("r8"))
