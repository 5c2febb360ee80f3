"""Per-draw comparisons of a method with a baseline (``scpformer.experiments.paired``)."""

from __future__ import annotations

import numpy as np
import pytest

from scpformer.experiments.paired import Outcomes, exact_sign_test, paired_rows, paired_table


def _outcomes(time, iterations, solved, cost) -> Outcomes:
    return Outcomes(time=np.array(time, float), iterations=np.array(iterations, float),
                    solved=np.array(solved, bool), cost=np.array(cost, float))  # fmt: skip


OURS = _outcomes([1.0, 1.0, 2.0, 4.0], [2, 5, 5, 9], [True, True, False, True],
                 [1.0, 2.0, np.nan, 3.0])  # fmt: skip
BASE = _outcomes([2.0, 1.02, 1.0, 4.0], [4, 5, 3, 9], [True, True, True, False],
                 [1.0, 2.5, 1.0, np.nan])  # fmt: skip


def test_every_draw_is_counted_failures_included():
    rows = {q: (a, b) for q, a, b in paired_rows(OURS, BASE, cost_tie=1e-6)}
    assert rows["draws (all, failures included)"] == ("4", "4")
    assert rows["solved"] == ("3", "3")
    assert rows["solved by both / only this / only the baseline / neither"][0] == "2 / 1 / 1 / 0"
    # 1.0 vs 2.0 faster; 1.0 vs 1.02 within 5%; 2.0 vs 1.0 slower; 4.0 vs 4.0 tie
    assert rows["wall time per draw: faster / tie (within 5%) / slower"][0] == "1 / 2 / 1"
    assert rows["iterations per draw: fewer / same / more"][0] == "1 / 2 / 1"
    # the cost is compared where both solved: draws 0 (tie) and 1 (lower)
    assert rows["cost where both solved: lower / tie (within 1e-06) / higher"][0] == "1 / 1 / 0"
    speedup = rows["speed-up: baseline over this, per-draw median / of the totals"][0]
    assert speedup.endswith(f"/ {8.02 / 8.0:.3g}x")


def test_the_table_names_both_methods_and_an_empty_comparison_says_so():
    text = paired_table("tscvx", OURS, "cold", BASE, cost_tie=1e-6)
    assert text.splitlines()[0] == "| quantity | tscvx | cold |"
    empty = _outcomes([], [], [], [])
    assert "No draw" in paired_table("a", empty, "b", empty, cost_tie=1.0)


def test_mismatched_draws_are_refused():
    with pytest.raises(ValueError, match="same draws"):
        paired_rows(OURS, _outcomes([1.0], [1], [True], [1.0]), cost_tie=1.0)
    with pytest.raises(ValueError, match="1-D of one length"):
        _outcomes([1.0, 2.0], [1], [True], [1.0])


def test_the_exact_sign_test_matches_the_binomial_tail():
    from scipy.stats import binomtest

    for a, b in ((0, 0), (0, 1), (3, 9), (12, 4), (20, 20)):
        expected = binomtest(a, a + b, 0.5).pvalue if a + b else 1.0
        assert exact_sign_test(a, b) == pytest.approx(expected, rel=1e-12)
    assert exact_sign_test(0, 10) == pytest.approx(2.0 / 2**10, rel=1e-12)  # 2 P(X = 0)
    assert exact_sign_test(5, 3) == exact_sign_test(3, 5)  # symmetric


def test_the_exact_sign_test_refuses_negative_counts():
    with pytest.raises(ValueError, match="discordant"):
        exact_sign_test(-1, 2)
