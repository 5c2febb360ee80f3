import csv

import numpy as np
import pytest

from scpformer.cli.main import main

pytestmark = pytest.mark.slow


def _run(tmp_path, tiny_data, tiny_runs, name, kinds=("art", "gru", "lstm")):
    out = tmp_path / name
    models = [a for k in kinds for a in ("--model", str(tiny_runs[k]))]
    argv = [
        "experiment",
        "run",
        name,
        *models,
        "--data",
        str(tiny_data),
        "--n",
        "2",
        "--workers",
        "1",
        "--out",
        str(out),
    ]
    return main(argv), out


def test_table_3_compares_every_model_in_both_modes_with_the_scp_twin(
    tmp_path, tiny_data, tiny_runs
):
    code, out = _run(tmp_path, tiny_data, tiny_runs, "art-forecast-scp")
    assert code == 0
    with (out / "results.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 2
    for row in rows:
        for kind in ("art", "gru", "lstm"):
            for mode in ("transformer", "dynamics"):
                assert float(row[f"{kind}_{mode}_cost_mm_s"]) > 0.0
                assert float(row[f"{kind}_{mode}_time_s"]) > 0.0
        assert float(row["true_cost_mm_s"]) > 0.0
    text = (out / "report.md").read_text()
    assert "Table 3: ours / paper" in text and "257.28" in text  # the paper's ART cost
    assert (out / "forecast.png").is_file()


def test_table_2_compares_with_the_tpbvp_twin_conditioned_on_its_own_cost(
    tmp_path, tiny_data, tiny_runs
):
    from scpformer.experiments.runner import read_fields

    code, out = _run(tmp_path, tiny_data, tiny_runs, "art-forecast-tpbvp", kinds=("art", "gru"))
    assert code == 0
    with (out / "results.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 2
    positions = [int(r["index"]) for r in rows]
    for row, f in zip(rows, read_fields(tiny_data, positions, ["tpbvp_cost"]), strict=True):
        assert float(row["true_cost_mm_s"]) == pytest.approx(1e3 * f["tpbvp_cost"])
        assert float(row["art_dynamics_cost_mm_s"]) > 0.0
    text = (out / "report.md").read_text()
    assert "Table 2: ours / paper" in text and "226.14" in text  # the paper's ART cost
    assert "R(t_1) = -J_TPBVP (dataset's tpbvp_cost)" in text
    assert "(Table 2: the convex solve is faster) | 0.44 vs 0.28 s" in text


def test_table_2_says_the_tpbvp_twin_is_missing(tmp_path, tiny_data_without_tpbvp, tiny_runs):
    code, out = _run(
        tmp_path, tiny_data_without_tpbvp, tiny_runs, "art-forecast-tpbvp", kinds=("art",)
    )
    assert code == 0
    text = (out / "report.md").read_text()
    assert "dataset has no `tpbvp` twin" in text and "--twin tpbvp" in text
    assert not (out / "results.csv").exists()


def test_two_runs_of_one_kind_are_a_one_line_error(tmp_path, tiny_data, tiny_runs, capsys):
    code, _ = _run(tmp_path, tiny_data, tiny_runs, "art-forecast-scp", kinds=("art", "art"))
    assert code == 2
    assert "one run per model kind" in capsys.readouterr().err


def test_conditioning_sweeps_requested_values_and_records_realized_ones(
    tmp_path, tiny_data, tiny_runs
):
    code, out = _run(tmp_path, tiny_data, tiny_runs, "art-conditioning", kinds=("art",))
    assert code == 0
    with (out / "results.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    for row in rows:
        requested = row["ctg_requested"].split()
        assert requested[0] == "0.0" and len(row["ctg_realized"].split()) == len(requested)
        assert len(row["cost_realized_m_s"].split()) == len(row["cost_requested_m_s"].split())
    assert (out / "fig3_conditioning.png").is_file()
    text = (out / "report.md").read_text()
    assert "realized vs requested C(t_1)" in text and "median per-instance slope" in text
    assert "Why the cost follows the request weakly" in text


def test_the_cost_sweep_lies_mostly_inside_the_dataset_range():
    from scpformer.experiments.conditioning import SWEEP, cost_sweep

    sweep = np.array(cost_sweep((0.2, 0.3)))
    assert sweep.size == SWEEP and np.all(np.diff(sweep) > 0)
    inside = (sweep >= 0.2) & (sweep <= 0.3)
    assert inside.sum() == SWEEP - 4 and sweep[0] == pytest.approx(0.1)
    assert sweep[-1] == pytest.approx(0.45)


def test_the_median_slope_recovers_each_instances_response():
    from scpformer.experiments.conditioning import median_slope

    requested = np.array([1.0, 2.0, 3.0, 4.0])
    realized = np.stack([5.0 + s * requested for s in (0.1, 0.5, 2.0)])  # offsets differ
    assert median_slope(requested, realized) == pytest.approx(0.5)
    assert np.isnan(median_slope(requested[:1], realized[:, :1]))


def test_robust_forecast_compares_the_robust_art_with_the_passively_safe_twin(
    tmp_path, tiny_robust
):
    data, run = tiny_robust
    out = tmp_path / "robust-forecast"
    argv = ["experiment", "run", "robust-forecast", "--model", str(run), "--data", str(data),
            "--n", "1", "--workers", "1", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    with (out / "results.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 1
    for row in rows:
        assert float(row["art_dynamics_cost_mm_s"]) > 0.0
        assert float(row["true_cost_mm_s"]) > 0.0
    text = (out / "report.md").read_text()
    assert "passively safe" in text and "ps` twin" not in text


def test_a_rendezvous_run_is_refused_by_the_robust_forecast(tmp_path, tiny_robust, tiny_runs):
    data, _ = tiny_robust
    argv = ["experiment", "run", "robust-forecast", "--model", str(tiny_runs["art"]),
            "--data", str(data), "--out", str(tmp_path / "o")]  # fmt: skip
    assert main(argv) == 2
