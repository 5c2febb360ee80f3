"""The art-warmstart analysis on hand-made columns: the bootstrap interval of the improvement."""

import math

import numpy as np
import pytest

from scpformer.experiments.warmstart_study import (
    WARMSTARTS,
    Bootstrap,
    Columns,
    analyse,
    bin_stats,
    improvement_interval,
    iterations_saved_interval,
)


def _columns(gaps: dict[str, np.ndarray], feasible: np.ndarray | None = None) -> Columns:
    """Columns with J_CVX = 1 m/s, C_CVX(t_1) = 5 and the given gaps [mm/s] per warm start."""
    n = len(gaps["art"])
    ok = np.ones(n, dtype=bool) if feasible is None else feasible
    ones = np.ones(n)
    return Columns(
        c=5.0 * ones,
        j_cvx=ones,
        cost={ws: 1.0 + 1e-3 * np.asarray(gaps[ws], dtype=float) for ws in WARMSTARTS},
        feasible={ws: ok.copy() for ws in WARMSTARTS},
        iterations={ws: 4.0 * ones for ws in WARMSTARTS},
        ws_time={ws: 0.1 * ones for ws in WARMSTARTS},
        scp_time={ws: 0.1 * ones for ws in WARMSTARTS},
        history={ws: [np.ones(1)] * n for ws in WARMSTARTS},
        generation=0.05 * ones,
        ws_cost={ws: ones for ws in WARMSTARTS},
        waypoint_miss={ws: np.zeros(n) for ws in WARMSTARTS},
    )


def test_an_exact_halving_has_a_point_interval_at_fifty_percent():
    reference = np.random.default_rng(1).uniform(0.1, 2.0, 40)
    cols = _columns({"tpbvp": reference, "convex": reference, "art": 0.5 * reference})
    lo, hi = improvement_interval(cols, "convex", np.ones(40, dtype=bool))
    assert lo == pytest.approx(50.0) and hi == pytest.approx(50.0)


def _noisy_columns(rng: np.random.Generator, n: int) -> Columns:
    """ART's gap is 0.7 times CVX's plus zero-mean noise: a true improvement of 30%."""
    reference = rng.exponential(1.0, n)
    art = 0.7 * reference + rng.normal(0.0, 0.3, n)
    return _columns({"tpbvp": reference, "convex": reference, "art": art})


def test_the_interval_holds_the_point_estimate_narrows_with_more_instances_and_is_seeded():
    rng = np.random.default_rng(2)
    widths = []
    for n in (30, 3000):
        cols, mask = _noisy_columns(rng, n), np.ones(n, dtype=bool)
        point = bin_stats(cols, mask)["improvement_vs_convex"]
        lo, hi = improvement_interval(cols, "convex", mask)
        assert (lo, hi) == improvement_interval(cols, "convex", mask)  # seeded
        assert lo < point < hi
        widths.append(hi - lo)
    assert widths[1] < 0.2 * widths[0]  # ~ 1 / sqrt(n)


def test_the_ninety_percent_interval_covers_the_true_improvement_about_ninety_percent_of_the_time():
    rng = np.random.default_rng(3)
    trials, n = 200, 60
    covered = 0
    for trial in range(trials):
        cols = _noisy_columns(rng, n)
        lo, hi = improvement_interval(
            cols, "convex", np.ones(n, dtype=bool), Bootstrap(draws=500, seed=trial)
        )
        covered += lo <= 30.0 <= hi
    assert 0.8 * trials <= covered <= 0.97 * trials


def test_only_instances_where_every_scp_solved_count_and_too_few_give_nan():
    reference = np.array([1.0, 1.0, 1.0, 50.0])
    feasible = np.array([True, True, True, False])  # the outlier's runs failed: left out
    cols = _columns({"tpbvp": reference, "convex": reference, "art": 0.5 * reference}, feasible)
    assert improvement_interval(cols, "convex", np.ones(4, dtype=bool)) == pytest.approx(
        (50.0, 50.0)
    )
    lo, hi = improvement_interval(cols, "convex", np.array([True, False, False, False]))
    assert math.isnan(lo) and math.isnan(hi)


def test_iterations_saved_are_paired_per_instance():
    # ART always needs one iteration fewer than CVX on the same instance, while the counts
    # spread from 2 to 10 across instances: a paired interval is the point 1, an unpaired
    # one would be wide
    rng = np.random.default_rng(6)
    cvx = rng.integers(2, 11, 50).astype(float)
    cols = _columns({ws: np.ones(50) for ws in WARMSTARTS})
    cols.iterations.update(convex=cvx, art=cvx - 1.0)
    assert iterations_saved_interval(cols, np.ones(50, dtype=bool)) == pytest.approx((1.0, 1.0))
    noise = rng.integers(-2, 3, 50)  # now a saving of 1 +- noise: the interval holds the mean
    cols.iterations.update(art=cvx - 1.0 + noise)
    lo, hi = iterations_saved_interval(cols, np.ones(50, dtype=bool))
    assert lo < 1.0 - noise.mean() < hi and hi - lo < 1.0


def _csv_rows(n: int, seed: int) -> list[dict[str, str]]:
    """Result rows as the study writes them (only the cells the analysis reads)."""
    rng = np.random.default_rng(seed)
    rows = []
    for index in range(n):
        gap_cvx = rng.exponential(1e-3)
        gaps = {"tpbvp": 2 * gap_cvx, "convex": gap_cvx, "art": 0.8 * gap_cvx}
        row = {"index": str(index), "c_cvx_t1": str(int(rng.integers(0, 45))), "j_cvx": "0.2",
               "art_generation_s": "0.05"}  # fmt: skip
        for ws in WARMSTARTS:
            cost = 0.2 + gaps[ws] + rng.normal(0.0, 2e-4)
            row |= {f"{ws}_cost": repr(cost), f"{ws}_feasible": "True",
                    f"{ws}_iterations": str(int(rng.integers(2, 7))), f"{ws}_ws_time": "0.01",
                    f"{ws}_scp_time": "0.05", f"{ws}_history": f"{cost + 1e-3} {cost}",
                    f"{ws}_ws_cost": "0.21", f"{ws}_ws_waypoint_miss_m": "0.0"}  # fmt: skip
        rows.append(row)
    return rows


def test_the_report_does_not_depend_on_the_order_the_workers_finished_in(tmp_path):
    rows = _csv_rows(80, seed=4)
    shuffled = [rows[i] for i in np.random.default_rng(5).permutation(len(rows))]
    first = analyse(rows, tmp_path).comparisons
    second = analyse(shuffled, tmp_path).comparisons
    assert [c.ours for c in first] == [c.ours for c in second]
    assert [c.note for c in first] == [c.note for c in second]
    assert any("bootstrap interval" in c.note for c in first)
