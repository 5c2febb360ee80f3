"""Closed-loop guidance of the chance-constrained, passively safe rendezvous
(``scpformer.guidance.robust_rendezvous_mpc``) and ``scpformer simulate robust-rendezvous``."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from scpformer.cli.main import main
from scpformer.cli.parsers import simulate as simulate_parser
from scpformer.guidance import robust_rendezvous_mpc as robust
from scpformer.guidance.campaign import ROBUST_COLUMNS, Campaign, run_campaign
from scpformer.guidance.rendezvous_mpc import ErrorModels
from scpformer.problems.rendezvous.linear_model import linear_model
from scpformer.robust_rendezvous import RobustInstance, RobustSolverConfig
from scpformer.scp.solution import Trajectory
from scpformer.scp.warmstart import WarmStartRecord, WarmStartResult
from scpformer.warmstart.art import AcceptanceCheck

INSTANCE = RobustInstance()
#: One re-plan, at node 50 (halfway): the loop corrects the plan's model error once.
K_ONE = 50
#: The flown trajectory's Monte Carlo with few draws keeps the tests short.
FEW = 5
#: The columns ``runs.csv`` must have.
REQUIRED = (
    "run", "warmstart", "success", "terminal_position_error", "terminal_velocity_error",
    "fuel", "open_loop_fuel", "replans", "replans_failed", "replan_time_median_s",
    "replan_time_p99_s", "replan_period_s", "violations",
)  # fmt: skip


def _config(**kw) -> robust.MPCConfig:
    base = {"replan_every": K_ONE, "errors": ErrorModels.none(), "safety_samples": FEW}
    return robust.MPCConfig(**(base | kw))


@pytest.fixture(scope="module")
def plan():
    return robust.open_loop_plan(INSTANCE, _config())


def test_with_no_error_the_closed_loop_reproduces_the_open_loop_delta_v(plan):
    """Without errors the re-plan at node 50 only corrects the plan's model error, which the
    verification bounds by its truth replay's miss of the waypoint: 2 m and 2 mm/s at t_N.
    Nulling a miss (dr, dv) over the remaining T = 50 dt costs at most about
    |dv| + 2 |dr| / T (a burn starting the correction, one stopping it): 3.1 mm/s on the
    default instance (T = 3550 s). The closed loop's delta-v stays within that of the plan's
    (measured: 0.01 mm/s), and it docks within the replay thresholds."""
    cfg = _config(warmstart="previous", compare=("cold",))
    result = robust.fly(INSTANCE, cfg, seed=0, open_loop=plan)
    tol = cfg.solver.verification
    remaining_s = (INSTANCE.n_nodes - K_ONE) * INSTANCE.horizon_s / INSTANCE.n_nodes
    bound = tol.terminal_velocity_m_s + 2.0 * tol.terminal_position_m / remaining_s
    assert [r.node for r in result.replans] == [K_ONE]
    assert all(r.accepted for r in result.replans + result.comparisons)
    assert abs(result.fuel - result.open_loop_fuel) <= bound
    assert result.terminal_position_error <= tol.terminal_position_m
    assert result.terminal_velocity_error <= tol.terminal_velocity_m_s
    assert result.success and result.path_violations()["count"] == 0
    # the warm start is recorded, and the comparison is the cold solve of the same problem
    assert result.replans[0].warmstart == "previous" and result.comparisons[0].warmstart == "cold"
    assert result.replans[0].iterations >= 1 and result.replans[0].wall_s > 0.0


def test_a_mission_risk_is_spread_over_the_nodes_of_every_flown_plan():
    """epsilon = 1% over the N = 100 guarded nodes: Delta = 1e-4 per node in the open-loop
    plan and in the re-plan (Boole's inequality), the Eq. 16 margins grow by q(1e-4) / q(1e-3)
    = 3.72 / 3.09, so the plan may only cost more than at the paper's Delta (a local optimum
    of a problem with the same objective and tighter constraints, from the same TPBVP start;
    tie within SCvx*'s eps_opt on the cost), and the campaign records the setting."""
    eq14 = _config(covariance="eq14")
    assert robust.designed_instance(INSTANCE, eq14) is INSTANCE  # the instance's Delta
    cfg = _config(warmstart="previous", mission_risk=0.01, covariance="eq14")
    designed = robust.designed_instance(INSTANCE, cfg)
    assert designed.uncertainty.delta == pytest.approx(1e-4)
    assert designed.uncertainty.navigation == INSTANCE.uncertainty.navigation
    tight = robust.open_loop_plan(INSTANCE, cfg)
    paper = robust.open_loop_plan(INSTANCE, eq14)
    assert tight.cost >= paper.cost - cfg.solver.scvx.eps_opt
    result = robust.fly(INSTANCE, cfg, seed=0, open_loop=tight)
    assert [r.accepted for r in result.replans] == [True]
    assert [f.instance.uncertainty.delta for f in result.flown] == pytest.approx([1e-4] * 2)
    assert Campaign(runs=1, config=cfg).settings()["mission_risk"] == 0.01
    assert "mission_risk" not in Campaign(runs=1, config=_config()).settings()
    # one process flying both: the open-loop plan of one is not reused for the other
    _, paper_plan, _ = Campaign(runs=1, config=eq14).planned(0)
    _, risk_plan, _ = Campaign(runs=1, config=cfg).planned(0)
    assert risk_plan.cost == pytest.approx(tight.cost) and paper_plan.cost == paper.cost
    assert risk_plan.cost != paper_plan.cost


def test_a_re_plan_over_the_time_budget_is_not_flown(plan):
    """A budget no solve meets: the re-plan at node 50 is late and the open-loop plan's
    impulses are flown to the end (the shared truth flight draws no error here)."""
    cfg = _config(warmstart="previous", time_budget_s=1e-9)
    result = robust.fly(INSTANCE, cfg, seed=0, open_loop=plan)
    assert [(r.node, r.late, r.accepted) for r in result.replans] == [(K_ONE, True, False)]
    np.testing.assert_array_equal(result.dv_applied, plan.trajectory.u)
    assert [seg.start for seg in result.flown] == [0]


def test_the_remaining_problem_starts_from_the_estimate_with_the_domains_of_its_nodes():
    model = linear_model(INSTANCE)
    estimate = INSTANCE.roe0 + np.array([5.0, -20.0, 1.0, 1.0, 0.5, 0.5])
    sub = robust.remaining_instance(INSTANCE, 60, estimate, model.oe[60])
    assert sub.n_nodes == 40 and sub.scenario.n_ae_to_koz == 0
    np.testing.assert_allclose(sub.roe0, estimate, atol=1e-6)
    assert sub.waypoint == INSTANCE.waypoint and sub.uncertainty == INSTANCE.uncertainty
    assert sub.horizon_s == pytest.approx(INSTANCE.horizon_s * 0.4, rel=1e-9)
    assert (
        robust.remaining_instance(INSTANCE, 10, estimate, model.oe[10]).scenario.n_ae_to_koz == 45
    )
    assert robust.replan_nodes(100, 10) == [10, 20, 30, 40, 50, 60, 70, 80, 90]
    assert robust.replan_nodes(100, 99) == []
    with pytest.raises(ValueError, match="needs 0 < k <= N - 2"):
        robust.remaining_instance(INSTANCE, 99, estimate, model.oe[99])


def test_art_replans_from_the_flown_prefix_and_records_the_start_it_used(plan):
    """The learned start: the robust ART model started at node 50 with the flown prefix as
    its context; its guess passes the Eq. 8 check or the TPBVP replaces it (the record's
    ``used`` says which), and passive safety from it is a verified plan that docks. Without
    errors the remaining problem is the plan's own tail, so the closed loop's delta-v stays
    within the bound of the test above."""
    cfg = _config(warmstart="art")
    result = robust.fly(INSTANCE, cfg, seed=0, open_loop=plan)
    (record,) = result.replans
    assert record.warmstart == "art" and record.used in ("art", "tpbvp")
    assert record.accepted and result.success
    tol = cfg.solver.verification
    remaining_s = (INSTANCE.n_nodes - K_ONE) * INSTANCE.horizon_s / INSTANCE.n_nodes
    bound = tol.terminal_velocity_m_s + 2.0 * tol.terminal_position_m / remaining_s
    assert abs(result.fuel - result.open_loop_fuel) <= bound
    assert Campaign(runs=1, config=cfg).settings()["model"] == "default"


#: ``J`` of the remaining TPBVP in the constructed candidates [m/s]: ``R(t_k) = -J``.
J_TPBVP = 1.0


def _guess(value: float) -> Trajectory:
    """A recognizable guess: every state and impulse equals ``value``."""
    return Trajectory(x=np.full((4, 6), value), u=np.full((3, 3), value), p=np.zeros(0))


def _art(cost: float, ctg: float) -> WarmStartResult:
    """What ``ArtWarmStart`` returns for ART's guess of ``sum |u|`` = ``cost`` and ``C`` =
    ``ctg`` conditioned on ``R = -J_TPBVP``, ``C = 0``: the guess (marked 1) when Eq. 8 accepts
    it, the TPBVP (marked 0) otherwise."""
    decision = AcceptanceCheck().evaluate(rtg_desired=-J_TPBVP, ctg_desired=0.0,
                                          rtg_realized=-cost, ctg_realized=ctg)  # fmt: skip
    details = {"rtg0": -J_TPBVP, "ctg0": 0.0, "art_cost": cost, "art_constraint_to_go": ctg}
    if decision.accepted:
        record = WarmStartRecord(source="art", time_s=0.5, cost=cost, constraint_to_go=ctg,
                                 details=details)  # fmt: skip
        return WarmStartResult(_guess(1.0), record)
    record = WarmStartRecord(source="art", time_s=0.5, cost=J_TPBVP, constraint_to_go=4.0,
                             accepted=False, fallback_source="tpbvp", details=details)  # fmt: skip
    return WarmStartResult(_guess(0.0), record)


def _previous(cost: float, ctg: float) -> WarmStartResult:
    """The shifted plan (marked 2) as :func:`previous_candidate` records it."""
    record = WarmStartRecord(source="previous", time_s=0.25, cost=cost, constraint_to_go=ctg)
    return WarmStartResult(_guess(2.0), record)


@pytest.mark.parametrize(
    ("art", "previous", "used", "mark"),
    [
        # an accepted shifted plan beats a rejected ART guess (100 E_R = 20 > 3.5) ...
        ((1.2, 0.0), (1.01, 0.0), "previous", 2.0),
        # ... and an accepted ART guess a rejected shifted plan (E_R, then E_C = 3 > 2)
        ((1.01, 0.0), (1.2, 0.0), "art", 1.0),
        ((1.01, 1.0), (1.0, 3.0), "art", 1.0),
        # both accepted: the fewer violations left, then the cost nearer J
        ((1.0, 1.0), (1.03, 0.0), "previous", 2.0),
        ((1.0, 0.0), (1.03, 0.0), "art", 1.0),
        # neither accepted: the fallback of art, the TPBVP
        ((1.2, 0.0), (1.0, 3.0), "tpbvp", 0.0),
    ],
)
def test_best_starts_from_the_guess_the_post_hoc_check_prefers(art, previous, used, mark):
    """Eq. 8 against the R and C ART was conditioned on: accepted first, then E_C, then
    |E_R|; when neither guess passes, the paper's CVX fallback (the TPBVP)."""
    result = robust.best_guess(_art(*art), _previous(*previous), AcceptanceCheck())
    assert result.record.used == used and result.record.details["best"] == used
    np.testing.assert_array_equal(result.trajectory.x, _guess(mark).x)
    accepted = result.record.details["accepted"]
    assert accepted == {"art": art[0] <= 1.035 and art[1] <= 2.0,
                        "previous": previous[0] <= 1.035 and previous[1] <= 2.0}  # fmt: skip
    assert "art (100 E_R" in result.record.reason and "previous (100 E_R" in result.record.reason
    assert result.record.time_s >= 0.5 + 0.25  # ART's guess and the shifted plan's check


def test_best_without_an_art_guess_starts_from_the_shifted_plan():
    record = WarmStartRecord(source="art", time_s=0.5, cost=float("nan"),
                             constraint_to_go=float("nan"), accepted=False,
                             fallback_source="tpbvp", reason="no R(t_1)")  # fmt: skip
    result = robust.best_guess(WarmStartResult(None, record), _previous(1.0, 0.0),
                               AcceptanceCheck())  # fmt: skip
    assert result.record.used == "previous" and "ART has no guess" in result.record.reason
    np.testing.assert_array_equal(result.trajectory.x, _guess(2.0).x)


@pytest.fixture
def one_thread():
    """One torch thread for the batch-1 ART inference, as the CLI runs it."""
    torch = pytest.importorskip("torch")
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def test_best_replans_from_the_preferred_start_and_times_the_whole_path(plan, one_thread):
    """``best`` at node 50, compared with ``art`` and ``previous`` on the same problem: the
    start it used is the one Eq. 8 prefers (``art``'s own decision on ART's guess, ``tpbvp``
    when neither passes), its plan is the plan of that start, and its wall time holds ART's
    guess (TPBVP and generation), the checks and the passive-safety solve."""
    cfg = _config(warmstart="best", compare=("art", "previous"), model="default")
    result = robust.fly(INSTANCE, cfg, seed=0, open_loop=plan)
    (best,), (art, previous) = result.replans, result.comparisons
    assert best.warmstart == "best" and best.accepted and result.success
    warm = result.flown[-1].plan.extras["warmstart"]
    accepted = warm["details"]["accepted"]
    assert best.used == warm["used"] == warm["details"]["best"]
    assert art.used == ("art" if accepted["art"] else "tpbvp")
    allowed = {(True, True): {"art", "previous"}, (True, False): {"art"},
               (False, True): {"previous"}, (False, False): {"tpbvp"}}  # fmt: skip
    assert best.used in allowed[accepted["art"], accepted["previous"]]
    same = previous if best.used == "previous" else art
    assert best.cost == pytest.approx(same.cost, rel=1e-9)  # same guess, same SCvx*
    details = warm["details"]
    assert warm["time_s"] >= details["generation_s"] + details["convex_s"] > 0.0
    stages = result.flown[-1].plan.extras["stage_wall_s"]
    assert best.wall_s >= warm["time_s"] + stages["passive_safety"]
    assert best.iterations == sum(result.flown[-1].plan.extras["stage_iterations"].values())


def test_the_art_model_goes_with_best():
    assert robust.MPCConfig(warmstart="best", model="run").model == "run"
    assert robust.MPCConfig(compare=("best",), model="run").model == "run"


def test_the_loops_covariance_designs_every_flown_plan_for_fixes_at_the_replans_only(plan):
    """``covariance="loop"``: the open-loop plan and every re-plan design for navigation
    fixes every K nodes (their first node is a re-plan's fix), the flown plans pass the
    family's Monte Carlo drawn the same way, and the campaign records the setting."""
    cfg = _config(warmstart="previous", covariance="loop")
    designed = robust.designed_instance(INSTANCE, cfg)
    assert designed.uncertainty.fix_every == K_ONE
    assert designed.uncertainty.delta == INSTANCE.uncertainty.delta  # the risk is unchanged
    assert robust.designed_instance(INSTANCE, _config(covariance="eq14")) is INSTANCE
    result = robust.fly(INSTANCE, cfg, seed=0, open_loop=robust.open_loop_plan(INSTANCE, cfg))
    assert [r.accepted for r in result.replans] == [True] and result.success
    assert [f.instance.uncertainty.fix_every for f in result.flown] == [K_ONE, K_ONE]
    assert Campaign(runs=1, config=_config()).settings()["covariance"] == "loop"  # default
    assert "covariance" not in Campaign(runs=1, config=_config(covariance="eq14")).settings()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"replan_every": 0}, "replan_every"),
        ({"warmstart": "tscvx"}, "warmstart must be one of cold, previous, art, best"),
        ({"warmstart": "hot"}, "warmstart must be one of cold, previous"),
        ({"model": 3, "warmstart": "art"}, "model must be a path or None"),
        ({"model": "run"}, "model: used with the warm starts art and best only"),
        ({"compare": ("hot",)}, "warmstart must be one of"),
        ({"solver": RobustSolverConfig(safety_mode="deterministic")}, "safety_mode must be"),
        ({"safety_samples": 0}, "safety_samples"),
        ({"mission_risk": 0.0}, "mission_risk must be positive"),
        ({"mission_risk": 1.0}, "mission_risk must be below 1"),
        ({"mission_risk": float("nan")}, "mission_risk"),
        ({"covariance": "eq15"}, "covariance must be one of eq14, loop"),
    ],
)
def test_bad_configuration_is_refused_naming_the_field(kwargs, match):
    with pytest.raises(ValueError, match=match):
        robust.MPCConfig(**kwargs)


def test_runs_csv_has_the_columns_and_resumes(tmp_path, plan):
    cfg = _config(replan_every=INSTANCE.n_nodes)  # no re-plan: the open-loop plan is flown
    flown = []
    rows = run_campaign(Campaign(runs=1, config=cfg), tmp_path, on_run=flown.append)
    assert [r["run"] for r in rows] == ["0"] and len(flown) == 1
    starts = []
    rows = run_campaign(Campaign(runs=2, config=cfg), tmp_path, on_run=flown.append,
                        on_start=lambda done, total: starts.append((done, total)))  # fmt: skip
    assert starts == [(1, 2)] and [f["run"] for f in flown] == [0, 1]
    with (tmp_path / "runs.csv").open(newline="") as fh:
        table = list(csv.DictReader(fh))
    assert tuple(table[0]) == ROBUST_COLUMNS and set(REQUIRED) <= set(table[0])
    assert [r["success"] for r in table] == ["True", "True"]
    with np.load(tmp_path / "run-0001.npz") as data:
        assert data["rtn"].shape == (INSTANCE.n_nodes * 10 + 1, 6)
        assert data["dv_applied"].shape == (INSTANCE.n_nodes, 3)
        assert data["passive_safety_p"].shape == (INSTANCE.n_nodes,)
    with pytest.raises(ValueError, match="other settings \\(warmstart differ\\)"):
        run_campaign(Campaign(runs=2, config=_config(replan_every=100, warmstart="previous")),
                     tmp_path)  # fmt: skip


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--replan-every", "0"], "--replan-every: must be at least 1"),
        (["--runs", "0"], "--runs: must be at least 1"),
        (["--warmstart", "tscvx"], "invalid choice: 'tscvx'"),
        (["--mission-risk", "2"], "mission_risk must be below 1"),
        (["--covariance", "every"], "invalid choice: 'every'"),
    ],
)
def test_the_simulate_command_refuses_bad_input_in_one_line(argv, match, tmp_path, capsys):
    assert main(["simulate", "robust-rendezvous", "--out", str(tmp_path), *argv]) == 2
    err = capsys.readouterr().err
    assert match in err and err.count("\n") == 1


def test_the_parser_choices_are_the_library_ones():
    assert simulate_parser.ROBUST_WARMSTARTS == robust.WARMSTARTS
