"""A T-SCvx run that stalls (an infeasible stationary point) is reported as stalled at once.

Draw 25 of the feasible sampler with seed 90210 is one on which cold SCvx and T-SCvx both
stall (measured: cold SCvx after 27 solves, T-SCvx after 26 with the 15-iterate stall test).
With T-SCvx's own 5-iterate stall test the run stops sooner, and without the cold fallback
the solution is T-SCvx's own: its iterations are the T-SCvx run's, and the warm-start record
still names the learned guess. ``fallback_after_stall`` restores the cold run.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from scpformer import pdg6dof
from scpformer.problems.pdg6dof.config import PDGSolverConfig
from scpformer.problems.pdg6dof.sampling import PDGSampleRanges, sample_instances
from scpformer.problems.pdg6dof.tscvx import TscvxParameters, needs_cold_fallback
from scpformer.scp.solution import Solution, Status
from scpformer.scp.warmstart import resolve
from scpformer.warmstart.tscvx import TscvxWarmStart


@pytest.fixture(scope="module")
def stalling_instance():
    draws = sample_instances(np.random.default_rng(90210), 26, PDGSampleRanges.feasible())
    return draws[25]


def _provider(**changes):
    provider = resolve("tscvx", "pdg6dof", {}, PDGSolverConfig())
    assert isinstance(provider, TscvxWarmStart)
    return dataclasses.replace(provider, params=dataclasses.replace(provider.params, **changes))


def test_a_stalled_run_is_returned_without_the_cold_fallback(stalling_instance):
    solution = pdg6dof.solve(stalling_instance, method="tscvx", verify=False)
    assert solution.status is Status.STALLED
    assert solution.extras["tscvx"]["fallback"] != "cold"
    assert "tscvx_iterations" not in solution.extras
    assert solution.extras["warmstart"]["used"] == "tscvx"
    # the 5-iterate window ends the run well before the 15-iterate one could
    accepted = sum(record.accepted for record in solution.history)
    assert accepted <= 5 + 8, f"stalled after {accepted} accepted iterates"


def test_fallback_after_stall_runs_cold_scvx_as_before(stalling_instance):
    provider = _provider(fallback_after_stall=True)
    solution = pdg6dof.solve(stalling_instance, method="tscvx", warmstart=provider, verify=False)
    assert solution.extras["tscvx"]["fallback"] == "cold"
    assert solution.iterations > solution.extras["tscvx_iterations"]


@pytest.mark.parametrize(
    ("status", "params", "expected"),
    [
        (Status.STALLED, TscvxParameters(), False),
        (Status.STALLED, TscvxParameters(fallback_after_stall=True), True),
        (Status.MAX_ITERATIONS, TscvxParameters(), True),
        (Status.MAX_ITERATIONS, TscvxParameters(cold_fallback=False), False),
        (Status.CONVERGED, TscvxParameters(), False),
    ],
)
def test_which_ended_runs_fall_back(status, params, expected):
    solution = Solution(status=status, trajectory=None, t=None, cost=float("nan"), iterations=3)
    assert needs_cold_fallback(solution, params) is expected


def test_the_stall_window_is_checked():
    with pytest.raises(ValueError, match="stall_window"):
        TscvxParameters(stall_window=-1)
