"""Closed-loop guidance of the rendezvous (``scpformer.guidance``) and ``scpformer simulate``."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from scpformer.cli.main import main
from scpformer.cli.parsers import simulate as simulate_parser
from scpformer.guidance import (
    WARMSTARTS,
    DockingTolerance,
    ErrorModels,
    MPCConfig,
    fly,
    open_loop_plan,
    remaining_instance,
)
from scpformer.guidance.campaign import COLUMNS, INSTANCES, Campaign, run_campaign
from scpformer.guidance.rendezvous_art import FlownLog
from scpformer.guidance.rendezvous_mpc import replan_nodes
from scpformer.problems.rendezvous.linear_model import linear_model
from scpformer.rendezvous import RendezvousInstance, RendezvousSolverConfig

INSTANCE = RendezvousInstance()
#: The SCP's cost tolerance (Eq. 19, Table 1): two solves of one problem agree to it.
J_TOL = RendezvousSolverConfig().scp.J_tol
#: Same impulses through the same propagator (DOP853, rtol 1e-10, atol 1e-7 m per step), split
#: into other arcs: the replays agree to micrometres (measured 28 um after 2 orbits).
REPLAY_M = 1e-3
NO_REPLAN = INSTANCE.n_nodes  # K beyond the last re-plan node: the open-loop plan is flown


@pytest.fixture(scope="module")
def plan():
    return open_loop_plan(INSTANCE)


def test_with_no_error_and_no_replan_the_loop_flies_the_open_loop_plan(plan):
    cfg = MPCConfig(replan_every=NO_REPLAN, errors=ErrorModels.none())
    result = fly(INSTANCE, cfg, seed=0, open_loop=plan)
    assert result.replans == []
    np.testing.assert_array_equal(result.dv_applied, plan.trajectory.u)
    assert abs(result.fuel - plan.cost) <= J_TOL
    replay = plan.verification.terminal_error
    assert abs(result.terminal_position_error - replay["position_m"]) <= REPLAY_M
    assert abs(result.terminal_velocity_error - replay["velocity_m_s"]) <= REPLAY_M / 1e3
    assert result.success


def test_with_no_error_the_replans_keep_the_delta_v_and_correct_the_model_error(plan):
    """Re-plans from the true state remove the plan's model error (the mean-ROE model vs the
    truth, up to the verification's 2 m): the miss shrinks (0.45 m -> 0.05 m), the delta-v
    barely moves (+0.11% measured); the last re-plan, at the waypoint node, re-plans the final
    approach."""
    cfg = MPCConfig(replan_every=10, errors=ErrorModels.none())
    result = fly(INSTANCE, cfg, seed=0, open_loop=plan)
    assert [r.node for r in result.replans] == [10, 20, 30, 40, 50, 60, 70, 80, 90]
    assert all(r.accepted for r in result.replans)
    np.testing.assert_allclose(result.estimates, result.truth_roe)
    assert result.terminal_position_error < plan.verification.terminal_error["position_m"]
    assert abs(result.fuel - plan.cost) <= 0.01 * plan.cost
    assert result.success and result.path_violations()["count"] == 0


@pytest.mark.parametrize("seed", [0, 1])
def test_with_table2_errors_seeded_runs_dock(plan, seed):
    result = fly(INSTANCE, MPCConfig(replan_every=10), seed=seed, open_loop=plan)
    assert len(result.replans) == 9 and all(r.accepted for r in result.replans)
    assert result.success, result.summary()
    # the same seed draws the same errors: common random numbers across warm starts
    again = fly(INSTANCE, MPCConfig(replan_every=NO_REPLAN), seed=seed, open_loop=plan)
    np.testing.assert_array_equal(result.dv_applied[:10], again.dv_applied[:10])


def test_the_previous_plan_warm_starts_the_replans(plan):
    cfg = MPCConfig(replan_every=45, warmstart="previous", compare=("cold",))
    result = fly(INSTANCE, cfg, seed=3, open_loop=plan)
    assert [r.node for r in result.replans] == [45, 90]  # 90: the final approach
    assert [r.warmstart for r in result.replans] == ["previous"] * 2
    assert [r.warmstart for r in result.comparisons] == ["cold"] * 2
    assert all(r.accepted for r in result.replans)
    for flown, other in zip(result.replans, result.comparisons, strict=True):
        assert abs(flown.cost - other.cost) <= 1e-3 * other.cost  # one optimum, two starts


def test_re_plans_over_the_time_budget_are_not_flown(plan):
    """A budget no solve can meet: every re-plan is late, recorded, and the loop flies the
    open-loop plan to the end, exactly as without re-plans."""
    cfg = MPCConfig(replan_every=45, errors=ErrorModels.none(), time_budget_s=1e-9,
                    compare=("previous",))  # fmt: skip
    result = fly(INSTANCE, cfg, seed=0, open_loop=plan)
    assert [r.node for r in result.replans] == [45, 90]
    assert all(r.late and not r.accepted for r in [*result.replans, *result.comparisons])
    assert all(r.status == "converged" for r in result.replans)  # solved, but too late
    np.testing.assert_array_equal(result.dv_applied, plan.trajectory.u)
    assert result.summary()["replans_failed"] == 2
    assert result.arrays()["replan_late"].tolist() == [True, True]
    settings = Campaign(runs=1, config=cfg).settings()
    assert settings["time_budget_s"] == 1e-9
    assert "time_budget_s" not in Campaign(runs=1, config=MPCConfig()).settings()


def test_replan_nodes_run_through_the_final_approach_to_two_nodes_before_the_end():
    assert replan_nodes(100, 10, 10) == [10, 20, 30, 40, 50, 60, 70, 80, 90]
    assert replan_nodes(100, 10, 30) == [30, 60, 90]
    assert replan_nodes(100, 10, 88) == [88]
    assert replan_nodes(100, 10, 89) == [88]  # 89 = N_wp - 1: one impulse to the waypoint
    assert replan_nodes(100, 10, 98) == [98] and replan_nodes(100, 10, 99) == []
    assert replan_nodes(100, 10, 1)[-11:] == [87, 88, 90, 91, 92, 93, 94, 95, 96, 97, 98]
    oe = INSTANCE.target.oe.to_array()
    with pytest.raises(ValueError, match="waypoint_offset \\+ 2 = 12 or more"):
        remaining_instance(INSTANCE, 89, INSTANCE.roe0, oe)
    with pytest.raises(ValueError, match="2 to waypoint_offset"):
        remaining_instance(INSTANCE, 99, INSTANCE.roe0, oe)


def test_the_loop_replans_the_final_approach_after_the_waypoint(plan):
    """K = 3: re-plans at 90 (the waypoint node), 93, 96 pose the final approach (no waypoint,
    no keep-out zone: the states lie inside it), are accepted and flown."""
    result = fly(INSTANCE, MPCConfig(replan_every=3), seed=1, open_loop=plan)
    final = [r for r in result.replans if r.node >= INSTANCE.scenario.n_waypoint]
    assert [r.node for r in final] == [90, 93, 96]
    assert all(r.accepted for r in result.replans), [r.message for r in result.replans]
    assert result.success, result.summary()
    # the plan flown after the last re-plan is that re-plan's: its impulses from node 96 on
    assert np.abs(result.dv_planned[96:]).max() > 0.0
    sub = remaining_instance(INSTANCE, 96, result.estimates[-1], linear_model(INSTANCE).oe[96])
    assert sub.scenario.waypoint_passed and sub.n_nodes == 4
    assert sub.scenario.koz_metric(sub.rtn0_linear[:3]) < 1.0  # inside the keep-out ellipsoid


def test_the_derived_tolerance_is_written_down():
    tol = DockingTolerance.derive(INSTANCE)
    assert tol.position_m == pytest.approx(2.63, abs=0.005)  # < cone radius 5 tan 30 = 2.89
    assert tol.velocity_m_s == pytest.approx(3.55e-3, abs=5e-6)
    assert DockingTolerance.derive(INSTANCE, ErrorModels.none()).position_m == 2.0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"replan_every": 0}, "replan_every"),
        ({"replan_every": 1.5}, "replan_every"),
        ({"warmstart": "nope"}, "must be one of cold, previous, art, best"),
        ({"model": "run"}, "used with the warm starts art and best only"),
        ({"warmstart": "art", "model": 3}, "model must be a path or None"),
        ({"compare": ("nope",)}, "must be one of"),
        ({"samples_per_interval": 0}, "samples_per_interval"),
    ],
)
def test_bad_configuration_is_refused_naming_the_field(kwargs, match):
    with pytest.raises(ValueError, match=match):
        MPCConfig(**kwargs)


def test_bad_campaign_is_refused():
    with pytest.raises(ValueError, match="runs"):
        Campaign(runs=0, config=MPCConfig())
    with pytest.raises(ValueError, match="instances must be one of"):
        Campaign(runs=1, instances="all", config=MPCConfig())
    with pytest.raises(ValueError, match="seed"):
        fly(INSTANCE, MPCConfig(), seed=-1)


def test_runs_csv_resumes_and_refuses_other_settings(tmp_path):
    cfg = MPCConfig(replan_every=NO_REPLAN)
    flown = []
    rows = run_campaign(Campaign(runs=1, config=cfg), tmp_path, on_run=flown.append)
    assert [r["run"] for r in rows] == ["0"] and len(flown) == 1
    rows = run_campaign(Campaign(runs=2, config=cfg), tmp_path, on_run=flown.append)
    assert [r["run"] for r in rows] == ["0", "1"] and [f["run"] for f in flown] == [0, 1]
    with (tmp_path / "runs.csv").open(newline="") as fh:
        table = list(csv.DictReader(fh))
    assert tuple(table[0]) == COLUMNS and len(table) == 2
    assert (tmp_path / "run-0001.npz").exists()
    with pytest.raises(ValueError, match="other settings \\(seed differ\\)"):
        run_campaign(Campaign(runs=2, seed=1, config=cfg), tmp_path)


def test_the_simulate_command_writes_runs_npz_and_figure(tmp_path, capsys):
    out = tmp_path / "sim"
    argv = ["simulate", "rendezvous", "--runs", "1", "--replan-every", "1000", "--errors",
            "none", "--out", str(out), "--quiet"]  # fmt: skip
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "1 runs, warm start cold: success 100%" in printed
    with (out / "runs.csv").open(newline="") as fh:
        (row,) = list(csv.DictReader(fh))
    for column in ("run", "warmstart", "success", "terminal_position_error",
                   "terminal_velocity_error", "fuel", "open_loop_fuel", "replans",
                   "replans_failed", "replan_time_median_s", "replan_time_p99_s",
                   "replan_period_s", "violations"):  # fmt: skip
        assert column in row
    with np.load(out / "run-0000.npz") as data:
        assert data["rtn"].shape == (INSTANCE.n_nodes * 10 + 1, 6)
        assert data["dv_applied"].shape == (INSTANCE.n_nodes, 3)
    assert (out / "simulate.png").stat().st_size > 0


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--replan-every", "0"], "--replan-every: must be at least 1"),
        (["--runs", "0"], "--runs: must be at least 1"),
        (["--warmstart", "tscvx"], "invalid choice: 'tscvx'"),
    ],
)
def test_the_simulate_command_refuses_bad_input_in_one_line(argv, match, tmp_path, capsys):
    assert main(["simulate", "rendezvous", "--out", str(tmp_path), *argv]) == 2
    err = capsys.readouterr().err
    assert match in err and err.count("\n") == 1


def test_the_parser_choices_are_the_library_ones():
    assert simulate_parser.WARMSTARTS == WARMSTARTS
    assert simulate_parser.INSTANCES == INSTANCES


def test_art_and_best_replan_from_the_flown_prefix_and_record_the_start_used(plan):
    """K = 45: ART started mid-horizon at nodes 45 and 90 (the final approach), its plans
    flown; ``best`` starts from ART's guess or the previous plan, whichever Eq. 8 prefers."""
    cfg = MPCConfig(replan_every=45, warmstart="art", compare=("cold", "best"))
    result = fly(INSTANCE, cfg, seed=3, open_loop=plan)
    assert [r.node for r in result.replans] == [45, 90]
    assert all(r.accepted for r in result.replans), [r.message for r in result.replans]
    assert [r.used for r in result.replans] == ["art", "art"]
    assert [r.used for r in result.comparisons[::2]] == ["convex", "convex"]
    assert {r.used for r in result.comparisons[1::2]} <= {"art", "previous"}
    for flown, cold in zip(result.replans, result.comparisons[::2], strict=True):
        assert abs(flown.cost - cold.cost) <= 1e-3 * cold.cost  # one optimum, two starts
    assert result.success, result.summary()
    with np.testing.assert_raises(AssertionError):  # the re-plans changed the impulses
        np.testing.assert_array_equal(result.dv_planned[45:], plan.trajectory.u[45:])


def test_the_flown_log_rebuilds_the_commanded_impulses_and_the_known_states(plan):
    log = FlownLog(INSTANCE, plan)
    fix = INSTANCE.roe0 + 1.0
    first = log.history(45, fix, plan, 45)
    np.testing.assert_array_equal(first.u, plan.trajectory.u[:45])
    np.testing.assert_array_equal(first.x[0], INSTANCE.roe0)
    m = linear_model(INSTANCE)  # between fixes: x_{j+1} = Phi_j (x_j + B_j u_j) (Eq. 10)
    pred = np.einsum("kij,kj->ki", m.Phi[:44], first.x[:44] + np.einsum("kij,kj->ki", m.B[:44],
                                                                        first.u[:44]))  # fmt: skip
    np.testing.assert_allclose(first.x[1:], pred, rtol=0.0, atol=1e-9)
    np.testing.assert_allclose(first.x, plan.trajectory.x[:45], rtol=0.0, atol=1e-6)  # metres
    # the re-plan at 45 failed: the open-loop plan flies on; node 45 is known by its fix
    second = log.history(90, fix, plan, 90)
    np.testing.assert_array_equal(second.u, plan.trajectory.u[:90])
    np.testing.assert_array_equal(second.x[45], fix)
    np.testing.assert_array_equal(second.x[:45], first.x)


def test_the_simulate_command_flies_the_art_start(tmp_path, capsys):
    out = tmp_path / "art"
    argv = ["simulate", "rendezvous", "--runs", "1", "--replan-every", "45", "--warmstart",
            "art", "--model", "default", "--out", str(out), "--quiet", "--no-figure"]  # fmt: skip
    assert main(argv) == 0
    assert "1 runs, warm start art: success 100%" in capsys.readouterr().out
    with np.load(out / "run-0000.npz") as data:
        assert data["replan_used"].tolist() == ["art", "art"]
        assert data["replan_warmstart"].tolist() == ["art", "art"]
