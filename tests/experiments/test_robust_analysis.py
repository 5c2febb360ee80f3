"""The analyses of robust-warmstart, robust-posthoc and robust-trajectory on hand-made rows."""

import math

import numpy as np
import pytest

from scpformer.experiments import report as rep
from scpformer.experiments.robust_posthoc import best_instance, tile_edges, tile_means
from scpformer.experiments.robust_studies import (
    analyse,
    bin_stats,
    cost_differences,
    discordant_outcomes,
    status_counts,
    with_check,
)


def _row(index, j_cvx, cvx, art, *, art_status="converged", cvx_status="converged", c=5.0):
    """One chance-mode row with an RTN model: costs, statuses and the check's numbers."""
    row = {"index": str(index), "j_cvx": str(j_cvx)}
    for mode in ("deterministic", "chance"):
        row[f"{mode}_c_cvx_t1"] = str(c)
        for source, cost, status in (("cvx", cvx, cvx_status), ("art_rtn", art, art_status)):
            ok = status == "converged"
            row |= {
                f"{mode}_{source}_status": status,
                f"{mode}_{source}_cost": str(cost) if ok else "",
                f"{mode}_{source}_iterations": "6" if source == "cvx" else "4",
                f"{mode}_{source}_ws_time": "0.5",
                f"{mode}_{source}_scp_time": "1.0",
                f"{mode}_{source}_converged": str(ok),
                f"{mode}_{source}_accepted": "True",
                f"{mode}_{source}_E_R": "0.01" if source != "cvx" else "",
                f"{mode}_{source}_E_C": "0.0" if source != "cvx" else "",
                f"{mode}_{source}_would_accept": "True" if source != "cvx" else "",
            }
    return row


ROWS = [
    _row(0, 1.0, 1.2, 1.1),  # ART halves the suboptimality
    _row(1, 2.0, 2.0, 2.0),
    _row(2, 1.0, 1.3, 1.5, art_status="max_iterations"),
]


def test_bin_stats_gives_the_improvement_ratio_of_the_bin_means_and_the_infeasibility_rate():
    stats = bin_stats(ROWS, "chance", ("rtn",), np.ones(3, dtype=bool))
    # PS-CVX alone: all three rows; against ART, rows 0 and 1 where both converged
    assert stats["cvx_gap"] == pytest.approx(0.5 / 3)
    assert stats["art_rtn_cvx_gap"] == pytest.approx(0.1)
    assert stats["art_rtn_gap"] == pytest.approx(0.05)
    assert stats["art_rtn_improvement"] == pytest.approx(50.0)
    assert stats["art_rtn_infeasible_pct"] == pytest.approx(100.0 / 3)
    assert stats["cvx_infeasible_pct"] == 0.0
    assert stats["art_rtn_time"] == pytest.approx(1.5)
    assert stats["art_rtn_iterations"] == pytest.approx(4.0)


def test_cost_differences_keep_the_instances_where_both_scp_runs_converged():
    diff = cost_differences(ROWS, "chance", "art_rtn")
    np.testing.assert_allclose(diff, [0.1, 0.0], atol=1e-12)


def test_status_counts_split_the_infeasible_runs_by_cause():
    assert status_counts(ROWS, "chance", "art_rtn") == {"converged": 2, "max_iterations": 1}


def test_analyse_writes_both_figures_and_names_every_model(tmp_path):
    report = rep.Report(name="robust-warmstart", reproduces="Figs. 5-6", command="", settings={})
    analyse(ROWS, ("rtn",), report, tmp_path)
    assert (tmp_path / "fig5_deterministic.png").is_file()
    assert (tmp_path / "fig6_chance.png").is_file()
    quantities = [c.quantity for c in report.comparisons]
    assert any("PS-ART-C (RTN)" in q and "infeasibility" in q for q in quantities)
    outcomes = dict(report.sections)["Fig. 6: how the SCvx* runs ended (chance)"]
    assert "max_iterations" in outcomes and "1 (33%)" in outcomes


def test_tiles_start_at_the_acceptance_region_and_grow_outwards():
    e_r = np.array([-4.0, 0.0, 20.0])
    e_c = np.array([0.0, 3.0, 7.0])
    r_edges, c_edges = tile_edges(e_r, e_c)
    np.testing.assert_allclose(r_edges, [-11.5, -1.5, 3.5, 13.5, 33.5])  # widths 10, 5, 10, 20
    np.testing.assert_allclose(c_edges, [-0.5, 0.5, 1.5, 2.5, 4.5, 8.5])  # {0} {1} {2} {3,4} ...


def test_tile_means_average_each_tile_and_leave_empty_tiles_nan():
    e_r = np.array([-1.0, -0.9, 5.0, np.nan])
    e_c = np.array([0.0, 0.0, 2.0, 1.0])
    values = np.array([1.0, 3.0, 10.0, 5.0])
    edges = tile_edges(e_r, e_c)
    grid = tile_means(e_r, e_c, values, edges)
    assert grid.shape == (3, 2)  # (E_C tiles {0} {1} {2}, E_R tiles [-1.5, 3.5] [3.5, 13.5])
    assert grid[0, 0] == pytest.approx(2.0) and grid[2, 1] == pytest.approx(10.0)
    assert math.isnan(grid[1, 0]) and math.isnan(grid[1, 1])  # the NaN E_R row is left out


def test_best_instance_takes_the_largest_gain_over_every_model():
    rows = [dict(r) for r in ROWS]
    for r, cost in zip(rows, ("1.19", "1.5", ""), strict=True):  # an ROE model
        r |= {
            "chance_art_roe_cost": cost,
            "chance_art_roe_converged": str(bool(cost)),
        }
    rows[1]["chance_art_roe_cost"] = "1.9"  # 0.1 below CVX on row 1: ties RTN's row 0 gain
    rows[1]["chance_cvx_cost"] = "2.15"
    position, frame, why = best_instance(rows, ("rtn", "roe"))
    assert (position, frame) == (1, "roe") and "largest gain" in why


def test_best_instance_says_so_when_nothing_converged():
    rows = [_row(0, 1.0, 1.2, 1.1, art_status="max_iterations", cvx_status="max_iterations")]
    assert best_instance(rows, ("rtn",))[0] == -1


def test_posthoc_counts_a_rejected_guess_as_no_gain_and_writes_figures_per_model(tmp_path):
    from scpformer.experiments.robust_posthoc import analyse_posthoc

    rows = [dict(r) for r in ROWS]
    rows[0]["chance_art_rtn_would_accept"] = "False"  # its 100 mm/s gain is dropped
    rows[0]["chance_art_rtn_E_R"] = "0.2"
    report = rep.Report(name="robust-posthoc", reproduces="Figs. 9-10", command="", settings={})
    analyse_posthoc(rows, ("rtn",), report, tmp_path)
    assert (tmp_path / "fig9_posthoc_rtn.png").is_file()
    assert (tmp_path / "fig10_posthoc_histogram_rtn.png").is_file()
    table = report.sections[0][1].splitlines()
    without, checked = table[2].split(" | "), table[3].split(" | ")
    assert without[1] == "50" and checked[1] == "0"  # mean gain [mm/s]: (100 + 0) / 2, then 0
    ours = {c.quantity: c.ours for c in report.comparisons}
    rescued = "PS-ART-C (RTN) without the check: converged where PS-CVX-C did not, and the reverse"
    assert ours[rescued] == "0 vs 1"


def test_with_check_replaces_a_rejected_art_run_by_the_cvx_started_one():
    rows = [dict(r) for r in ROWS]
    rows[2]["chance_art_rtn_would_accept"] = "False"  # ART hit max_iterations; CVX converged
    checked = with_check(rows, "chance", ("rtn",))
    assert checked[2]["chance_art_rtn_status"] == "converged"
    assert checked[2]["chance_art_rtn_cost"] == rows[2]["chance_cvx_cost"]
    assert checked[2]["chance_art_rtn_accepted"] == "False"
    assert checked[0] == rows[0] and rows[2]["chance_art_rtn_status"] == "max_iterations"
    stats = bin_stats(checked, "chance", ("rtn",), np.ones(3, dtype=bool))
    assert stats["art_rtn_infeasible_pct"] == 0.0


def test_discordant_outcomes_count_the_paired_runs_and_give_the_exact_sign_test():
    # row 2: CVX converged, ART not; rows 0 and 1 concordant
    assert discordant_outcomes(ROWS, "chance", "art_rtn") == (0, 1, 1.0)
    rescued = [_row(i, 1.0, 1.2, 1.1, cvx_status="max_iterations") for i in range(5)]
    only_art, only_cvx, p = discordant_outcomes(rescued + ROWS[:2], "chance", "art_rtn")
    assert (only_art, only_cvx) == (5, 0)
    assert p == pytest.approx(2 / 2**5)  # five of five one way: 2 * (1/2)^5
    balanced = rescued + [_row(9, 1.0, 1.3, 1.5, art_status="max_iterations")] * 5
    assert discordant_outcomes(balanced, "chance", "art_rtn")[2] == pytest.approx(1.0)
