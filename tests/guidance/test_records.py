"""The re-plan statistics and tables shared by the closed loops of every family."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scpformer.guidance import pdg6dof_mpc, rendezvous_mpc
from scpformer.guidance.records import check_budget, record_table, replan_statistics, within_budget


def _rendezvous_record(accepted: bool, iterations: int, wall_s: float):
    return rendezvous_mpc.ReplanRecord(
        node=10, warmstart="cold", accepted=accepted, status="converged", cost=0.2,
        iterations=iterations, wall_s=wall_s, message="free text",
    )  # fmt: skip


def test_the_statistics_count_failures_and_take_median_and_p99_of_the_wall_time():
    replans = [_rendezvous_record(i != 2, i, 0.1 * (i + 1)) for i in range(5)]
    stats = replan_statistics(replans)
    assert stats["replans"] == 5 and stats["replans_failed"] == 1
    assert math.isclose(stats["replan_time_median_s"], 0.3)
    assert math.isclose(
        stats["replan_time_p99_s"], float(np.percentile([0.1, 0.2, 0.3, 0.4, 0.5], 99))
    )
    assert stats["replan_iterations_median"] == 2.0


def test_without_re_plans_the_statistics_are_nan_and_the_tables_empty_but_typed():
    stats = replan_statistics([])
    assert stats["replans"] == 0 and math.isnan(stats["replan_time_p99_s"])
    for record_type in (rendezvous_mpc.ReplanRecord, pdg6dof_mpc.ReplanRecord):
        table = record_table([], record_type)
        assert "message" not in table and table["accepted"].dtype == bool
        assert table["iterations"].dtype.kind == "i" and table["wall_s"].dtype == float
        assert table["warmstart"].dtype.kind == "U"


def test_a_table_holds_one_array_per_field_in_record_order():
    replans = [_rendezvous_record(True, 3, 0.5), _rendezvous_record(False, 7, 0.9)]
    table = record_table(replans, rendezvous_mpc.ReplanRecord)
    assert list(table) == [
        "node",
        "warmstart",
        "accepted",
        "status",
        "cost",
        "iterations",
        "wall_s",
        "used",
        "late",
    ]
    assert table["iterations"].tolist() == [3, 7] and table["accepted"].tolist() == [True, False]


@pytest.mark.parametrize("record_type", [rendezvous_mpc.ReplanRecord, pdg6dof_mpc.ReplanRecord])
def test_a_re_plan_over_the_budget_is_late_and_not_accepted(record_type):
    record = _rendezvous_record(True, 3, 0.5)
    if record_type is pdg6dof_mpc.ReplanRecord:
        record = pdg6dof_mpc.ReplanRecord(
            node=5, time=0.5, warmstart="cold", accepted=True, status="converged", cost=-2.0,
            iterations=3, wall_s=0.5, period=0.5, fallback="", message="free text",
        )  # fmt: skip
    assert within_budget(record, None) is record  # no budget
    assert within_budget(record, 0.5) is record  # on the budget is in time
    late = within_budget(record, 0.25)
    assert late.late and not late.accepted and late.wall_s == record.wall_s
    assert late.message.startswith("late: 0.5 s against a budget of 0.25 s")
    assert record_table([late], record_type)["late"].tolist() == [True]
    assert replan_statistics([record, late])["replans_failed"] == 1


@pytest.mark.parametrize(
    ("budget", "match"),
    [(0.0, "positive"), (-1.0, "positive"), (math.inf, "finite"), (math.nan, "finite"),
     ("1", "number of seconds"), (True, "number of seconds")],
)  # fmt: skip
def test_a_bad_budget_is_refused_naming_the_field(budget, match):
    with pytest.raises(ValueError, match=f"time_budget_s.*{match}"):
        check_budget(budget)
    with pytest.raises(ValueError, match="time_budget_s"):
        rendezvous_mpc.MPCConfig(time_budget_s=budget)
    with pytest.raises(ValueError, match="time_budget_s"):
        pdg6dof_mpc.MPCConfig(time_budget_s=budget)
    assert check_budget(2) == 2.0 and check_budget(None) is None
