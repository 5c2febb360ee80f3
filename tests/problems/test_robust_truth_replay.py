"""Every robust plan is verified by replaying its impulses through the two-body + J2 truth model."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from scpformer import robust_rendezvous
from scpformer.cli.robust_rendezvous import summary_rows
from scpformer.problems.robust_rendezvous.problem import PassiveSafetyProblem, replay, replay_miss
from scpformer.problems.robust_rendezvous.scenario import RobustSolverConfig, RobustVerification
from scpformer.scp.solution import Trajectory

INSTANCE = robust_rendezvous.RobustInstance(waypoint="+R")


@pytest.fixture(scope="module")
def solved():
    """The default three-stage chance solve of the nominal instance (waypoint +R)."""
    return robust_rendezvous.solve(INSTANCE, RobustSolverConfig(), method="three_stage")


def _verify(trajectory: Trajectory, verification: RobustVerification | None = None):
    config = RobustSolverConfig(verification=verification or RobustVerification())
    return PassiveSafetyProblem(INSTANCE, config, "chance").verify(trajectory)


def test_the_default_is_a_truth_replay_with_the_rendezvous_tolerances():
    tol = RobustVerification()
    assert tol.truth_replay
    assert (tol.terminal_position_m, tol.terminal_velocity_m_s) == (2.0, 2e-3)
    with pytest.raises(ValueError, match=r"verification\.terminal_velocity_m_s"):
        RobustVerification(terminal_velocity_m_s=0.0)


def test_the_default_solve_replays_and_reports_the_waypoint_miss(solved):
    assert solved.converged, solved.message
    ver = solved.verification
    assert ver is not None and ver.passed
    truth = replay(INSTANCE, solved.trajectory.u)
    expected = replay_miss(INSTANCE, truth.rtn[-1])
    assert ver.terminal_error == pytest.approx(expected)
    assert 0.0 < ver.terminal_error["position_m"] < 2.0
    assert 0.0 < ver.terminal_error["velocity_m_s"] < 2e-3
    miss = truth.rtn[-1] - INSTANCE.xf_rtn
    assert ver.terminal_error["t_m"] == pytest.approx(miss[1])
    assert 0.0 < ver.max_defect < np.inf  # mean plan (first-order RTN) vs truth [m], reported
    rows = dict(summary_rows(solved))
    assert rows["truth replay miss"].startswith(f"{ver.terminal_error['position_m']:.3f} m")


def test_perturbed_impulses_fail_the_check_naming_the_miss(solved):
    x, u = solved.trajectory.x, solved.trajectory.u.copy()
    u[10] += np.array([0.0, 1e-3, 0.0])  # 1 mm/s along-track drifts by metres
    ver = _verify(Trajectory(x=x, u=u, p=np.zeros(0)))
    miss = ver.terminal_error["position_m"]
    assert not ver.passed and miss > 2.0
    assert f"truth replay misses the waypoint by {miss:.3g} m > 2 m" in ver.message


def test_a_velocity_miss_beyond_its_tolerance_fails_naming_it(solved):
    tight = RobustVerification(terminal_velocity_m_s=1e-7)
    ver = _verify(solved.trajectory, tight)
    mm_s = ver.terminal_error["velocity_m_s"] * 1e3
    assert not ver.passed
    assert f"misses the waypoint velocity by {mm_s:.3g} mm/s > 0.0001 mm/s" in ver.message
    assert "misses the waypoint by" not in ver.message  # the position is within 2 m


def test_without_the_replay_nothing_is_replayed(solved):
    ver = _verify(solved.trajectory, RobustVerification(truth_replay=False))
    assert ver.passed and ver.terminal_error == {} and ver.max_defect == 0.0


def test_a_failing_replay_fails_the_verification(solved, monkeypatch):
    def escape(instance, u):
        raise RuntimeError("integration step size underflow")

    monkeypatch.setattr("scpformer.problems.robust_rendezvous.problem.replay", escape)
    ver = _verify(solved.trajectory)
    assert not ver.passed and "truth replay failed: integration step size underflow" in ver.message


def test_verify_false_leaves_no_verification():
    config = dataclasses.replace(RobustSolverConfig(), safety_mode="deterministic")
    sol = robust_rendezvous.solve(INSTANCE, config, method="three_stage", verify=False)
    assert sol.trajectory is not None and sol.verification is None
    assert "truth replay miss" not in dict(summary_rows(sol))
