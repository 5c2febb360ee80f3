"""Runs flown by a pool of processes or by Ray tasks are the runs flown one after the other.

Each run draws its errors from its own seed (``SeedSequence([seed, run])``), so the numbers of
``runs.csv`` and of ``run-NNNN.npz`` cannot depend on the number of workers; only the wall
times of the re-plans may differ.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from scpformer.guidance.campaign import Campaign, read_rows, run_campaign
from scpformer.guidance.rendezvous_mpc import MPCConfig

TIMED = ("replan_time_median_s", "replan_time_p99_s")


CAMPAIGN = Campaign(runs=3, seed=5, config=MPCConfig(replan_every=30))


@pytest.fixture(scope="module")
def one_by_one(tmp_path_factory):
    folder = tmp_path_factory.mktemp("campaign") / "one"
    run_campaign(CAMPAIGN, folder)
    return folder


@pytest.mark.parametrize("pool", ["workers", "ray"])
def test_two_workers_fly_the_same_runs_as_one(one_by_one, tmp_path, pool):
    run_campaign(CAMPAIGN, tmp_path / "two", workers=2, ray="local" if pool == "ray" else None)
    one, two = read_rows(one_by_one / "runs.csv"), read_rows(tmp_path / "two" / "runs.csv")
    assert [r["run"] for r in two] == ["0", "1", "2"]
    for a, b in zip(one, two, strict=True):
        assert {k: v for k, v in a.items() if k not in TIMED} == {
            k: v for k, v in b.items() if k not in TIMED
        }
    for run in range(3):
        a = np.load(one_by_one / f"run-{run:04d}.npz")
        b = np.load(tmp_path / "two" / f"run-{run:04d}.npz")
        np.testing.assert_array_equal(a["rtn"], b["rtn"])
        np.testing.assert_array_equal(a["dv_applied"], b["dv_applied"])


def test_workers_must_be_a_positive_count(tmp_path):
    with pytest.raises(ValueError, match="workers"):
        run_campaign(Campaign(runs=1, config=MPCConfig()), tmp_path, workers=0)


def test_a_pool_worker_is_limited_to_one_torch_thread():
    """The pool's processes share the cores; without the limit each would start one torch
    thread per core (the machine's count)."""
    pytest.importorskip("torch")
    code = ("import torch; torch.set_num_threads(4); "
            "from scpformer.guidance.campaign import one_torch_thread; one_torch_thread(); "
            "print(torch.get_num_threads())")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "1"
