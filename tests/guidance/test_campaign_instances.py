"""Which instance a campaign run flies: the first draw of its stream with a flyable plan."""

from __future__ import annotations

from itertools import islice

import pytest

from scpformer.guidance import campaign as campaign_module
from scpformer.guidance.campaign import MAX_DRAWS, Campaign
from scpformer.guidance.rendezvous_mpc import MPCConfig


@pytest.fixture
def plans(monkeypatch):
    """A stand-in open-loop planner that fails on the instances listed in ``failing`` and
    records every instance it is asked to plan (the real solve is not the point here)."""
    state = {"failing": [], "asked": []}

    def open_loop_plan(self, instance):
        state["asked"].append(instance)
        if instance in state["failing"]:
            raise ValueError("the open-loop plan failed (max_iterations): stand-in")
        return ("plan of", instance)

    monkeypatch.setattr(Campaign, "open_loop_plan", open_loop_plan)
    monkeypatch.setattr(campaign_module, "_PLANS", {})
    return state


def test_a_draw_without_a_flyable_plan_is_replaced_by_the_next_of_the_stream(plans):
    campaign = Campaign(runs=2, instances="sampled", config=MPCConfig())
    stream = campaign._draws(1)
    first, second = next(stream), next(stream)
    assert first != second and campaign.instance(1) == first
    assert campaign.planned(1) == (first, ("plan of", first), 0)  # flyable: flown as drawn
    plans["failing"].append(first)
    campaign_module._PLANS.clear()
    assert campaign.planned(1) == (second, ("plan of", second), 1)


def test_no_flyable_draw_or_a_fixed_instance_that_fails_is_an_error_naming_the_run(plans):
    sampled = Campaign(runs=1, instances="sampled", config=MPCConfig())
    plans["failing"].extend(islice(sampled._draws(0), MAX_DRAWS))
    with pytest.raises(ValueError, match=f"run 0: no flyable open-loop plan in {MAX_DRAWS}"):
        sampled.planned(0)
    fixed = Campaign(runs=1, instances="default", config=MPCConfig())
    plans["failing"].append(fixed.instance(0))
    plans["asked"].clear()
    with pytest.raises(ValueError, match="run 0: no flyable open-loop plan in 1 draw"):
        fixed.planned(0)
    assert len(plans["asked"]) == 1  # the default instance is never replaced


def test_the_wall_time_histogram_counts_every_re_plan_and_marks_the_budget(tmp_path):
    """The fastest re-plan sits on the first bin's edge: it is counted all the same (with
    bins from ``np.logspace`` the round-off of 10**log10(x) put that edge above this one)."""
    import json

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    wall = np.array([0.05056378869683274, 0.07626872, 3.0])
    np.savez(tmp_path / "run-0000.npz", replan_wall_s=wall)
    (tmp_path / "settings.json").write_text(json.dumps({"time_budget_s": 0.06}))
    figure, ax = plt.subplots()
    campaign_module._plot_wall_times([{"run": "0", "replan_period_s": "710"}], tmp_path, ax, "s")
    assert sum(patch.get_height() for patch in ax.patches) == wall.size
    assert [line.get_xdata()[0] for line in ax.lines] == [710.0, 0.06]  # period, budget
    plt.close(figure)
