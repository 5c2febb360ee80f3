"""Closed-loop guidance of the 6-DoF landing (``scpformer.guidance.pdg6dof_mpc``) and
``scpformer simulate pdg6dof``."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from scpformer.cli.main import main
from scpformer.cli.parsers import simulate as simulate_parser
from scpformer.guidance import pdg6dof_mpc as mpc
from scpformer.guidance.campaign import PDG_COLUMNS, Campaign, run_campaign, summarize
from scpformer.pdg6dof import PDGInstance, PDGSolverConfig
from scpformer.rendezvous import RendezvousInstance

INSTANCE = PDGInstance()
TOL = PDGSolverConfig().verification
NO_REPLAN = 1000  # K beyond the plan's N - 1 intervals: the open-loop plan is flown
#: The plan's own thrust flown open loop between re-plans, with the full thrust set.
UNTRACKED = {"tracking": None, "thrust_margin": 0.0, "gimbal_margin_deg": 0.0}


@pytest.fixture(scope="module")
def plan():
    return mpc.open_loop_plan(INSTANCE)


def test_with_no_error_and_no_replan_the_loop_flies_the_open_loop_plan(plan):
    """The truth replays the plan exactly as the verification does (same integrator and
    tolerances, interval by interval): the touchdown state is the verification's, to far
    below its tolerance, and the propellant the plan's, to its node defect tolerance."""
    cfg = mpc.MPCConfig(replan_every=NO_REPLAN, errors=mpc.ErrorModels.none(), **UNTRACKED)
    result = mpc.fly(INSTANCE, cfg, seed=0, open_loop=plan)
    assert result.replans == []
    assert abs(result.fuel - result.open_loop_fuel) <= TOL.defect
    xf, c = result.x[-1], INSTANCE.constants
    replay = plan.verification.terminal_error
    assert abs(np.abs(xf[0:3] - c.r_f).max() - replay["position"]) <= 1e-3 * TOL.terminal
    assert abs(np.abs(xf[3:6] - c.v_f).max() - replay["velocity"]) <= 1e-3 * TOL.terminal
    assert result.t[-1] == pytest.approx(float(plan.trajectory.p[0]))
    np.testing.assert_allclose(result.x[:: mpc.SAMPLES_PER_INTERVAL], plan.trajectory.x,
                               atol=TOL.defect)  # fmt: skip
    assert result.success and result.path_violations()["count"] == 0


def test_re_plans_over_the_time_budget_are_not_flown(plan):
    """A budget no solve can meet: every re-plan is late and the loop flies the open-loop
    plan to touchdown, as the no-re-plan flight does."""
    cfg = mpc.MPCConfig(replan_every=10, errors=mpc.ErrorModels.none(), time_budget_s=1e-9,
                        **UNTRACKED)  # fmt: skip
    result = mpc.fly(INSTANCE, cfg, seed=0, open_loop=plan)
    assert result.replans and all(r.late and not r.accepted for r in result.replans)
    assert result.t[-1] == pytest.approx(float(plan.trajectory.p[0]))
    np.testing.assert_allclose(result.x[:: mpc.SAMPLES_PER_INTERVAL], plan.trajectory.x,
                               atol=TOL.defect)  # fmt: skip
    assert Campaign(runs=1, config=cfg).settings()["time_budget_s"] == 1e-9


def test_with_no_error_the_previous_plan_replans_keep_the_propellant(plan):
    """Re-planned from the true state with the shifted plan as the start, every re-plan
    finds the same optimum (Bellman): measured 14 re-plans of 2 iterations each, propellant
    0.55048 against the open loop's 0.55051 U_M."""
    cfg = mpc.MPCConfig(warmstart="previous", errors=mpc.ErrorModels.none(), **UNTRACKED)
    result = mpc.fly(INSTANCE, cfg, seed=0, open_loop=plan)
    assert len(result.replans) >= 10 and all(r.accepted for r in result.replans)
    np.testing.assert_allclose(result.estimates, result.truths)
    assert abs(result.fuel - result.open_loop_fuel) <= 1e-3 * result.open_loop_fuel
    assert result.terminal_position_error <= TOL.terminal
    assert result.success


def test_with_no_error_the_tracking_law_leaves_the_plan_alone(plan):
    """Without errors the estimate is the truth, which follows the plan to the truth replay's
    defects: the LQR corrections are of that size, and the propellant is the plan's to the
    defect tolerance; with the planning margins the plan flown is the margin plan, a little
    costlier than the optimum and still a landing."""
    cfg = mpc.MPCConfig(replan_every=NO_REPLAN, errors=mpc.ErrorModels.none(),
                        thrust_margin=0.0, gimbal_margin_deg=0.0)  # fmt: skip
    result = mpc.fly(INSTANCE, cfg, seed=0, open_loop=plan)
    assert abs(result.fuel - result.open_loop_fuel) <= TOL.defect
    nodes = result.u_cmd[:: mpc.SAMPLES_PER_INTERVAL]
    assert np.abs(nodes[:-1] - plan.trajectory.u[:-1]).max() <= 10 * TOL.defect
    margin = mpc.fly(INSTANCE, mpc.MPCConfig(replan_every=NO_REPLAN,
                                             errors=mpc.ErrorModels.none()),
                     seed=0, open_loop=plan)  # fmt: skip
    assert result.open_loop_fuel < margin.fuel <= 1.05 * result.open_loop_fuel
    thrust = np.linalg.norm(margin.u_cmd, axis=1)
    c, m = INSTANCE.constants, mpc.MPCConfig().thrust_margin
    assert thrust.max() <= c.T_max * (1 - m) + 10 * TOL.defect
    assert margin.success and result.success


def test_tracking_corrects_what_the_open_loop_flight_does_not(plan):
    """Same vehicle, same errors, no re-plan: the tracked flight lands within the tolerance
    and closer than the plan flown open loop (measured 0.02 against 0.3 U_L)."""
    tracked = mpc.fly(INSTANCE, mpc.MPCConfig(replan_every=NO_REPLAN), seed=3, open_loop=plan)
    untracked = mpc.fly(INSTANCE, mpc.MPCConfig(replan_every=NO_REPLAN, **UNTRACKED), seed=3,
                        open_loop=plan)  # fmt: skip
    assert tracked.terminal_position_error < untracked.terminal_position_error
    assert tracked.terminal_position_error <= tracked.tolerance.position
    assert tracked.terminal_velocity_error <= tracked.tolerance.velocity


@pytest.mark.parametrize("seed", [0])
def test_seeded_runs_with_errors_land(plan, seed):
    cfg = mpc.MPCConfig(warmstart="previous", replan_every=10)
    result = mpc.fly(INSTANCE, cfg, seed=seed, open_loop=plan)
    assert result.replans, "the loop re-planned"
    assert result.success, result.summary()
    # the same seed flies the same vehicle and the same errors up to the first re-plan
    again = mpc.fly(INSTANCE, mpc.MPCConfig(replan_every=NO_REPLAN), seed=seed, open_loop=plan)
    first = 10 * mpc.SAMPLES_PER_INTERVAL + 1
    np.testing.assert_array_equal(result.x[:first], again.x[:first])
    assert result.truth_constants == again.truth_constants


def test_best_keeps_the_shifted_optimum_over_the_networks_guess(plan):
    """Without errors the shifted plan is the optimum's own tail (Bellman), dynamically
    consistent to the replay's defects: its penalized cost J (Eq. 16) is the cost of a
    feasible landing, and ``best`` keeps it over the networks' prediction, whose J is higher
    (measured: the shipped networks' guess at node 10 of the default descent)."""
    from scpformer.warmstart.tscvx import penalized_cost

    config = PDGSolverConfig()
    x = plan.trajectory.x[10]
    sub = mpc.remaining_instance(INSTANCE, x)
    used, warm = mpc.best_start(sub, plan, 10, x, mpc.MPCConfig(solver=config))
    shifted = mpc.shifted_plan(plan, 10, x).guess(sub).trajectory
    j_shifted = penalized_cost(sub, config, shifted)
    guess = mpc._tscvx_provider(config).guess_for(sub, config)
    assert used == "previous" and warm.guess(sub).trajectory.p[0] == shifted.p[0]
    assert j_shifted < guess.record.details["J_prediction"]
    flown = mpc.fly(INSTANCE, mpc.MPCConfig(warmstart="best", replan_every=20,
                                            errors=mpc.ErrorModels.none(), **UNTRACKED),
                    seed=0, open_loop=plan)  # fmt: skip
    assert flown.replans and all(r.used in ("previous", "tscvx") for r in flown.replans)
    assert all(r.warmstart == "best" and r.accepted for r in flown.replans)


@pytest.mark.parametrize("velocity_error", [0.01, -0.01])
def test_best_runs_algorithm_2_from_the_shifted_plan_to_the_optimum_scvx_reaches(
    plan, velocity_error
):
    """From the shifted plan ``best`` runs T-SCvx's Algorithm 2 with the networks' predicted
    tight rows: a smaller subproblem, not another answer. From an estimate off the plan by
    two sigma of navigation velocity error, it converges to the cost SCvx reaches from the
    same guess with every constraint, within the stationarity tolerance eps_opt."""
    from scpformer.pdg6dof import solve

    config = mpc.MPCConfig(solver=PDGSolverConfig())
    x = plan.trajectory.x[10].copy()
    x[3:6] += velocity_error
    sub = mpc.remaining_instance(INSTANCE, x)
    used, warm = mpc.best_start(sub, plan, 10, x, config)
    assert used == "previous" and isinstance(warm, mpc.PredictedRowsFrom)
    reduced = solve(sub, config.replan_solver, method="tscvx", warmstart=warm)
    full = solve(sub, config.replan_solver, warmstart=mpc.shifted_plan(plan, 10, x))
    assert reduced.converged and full.converged
    assert reduced.extras["tscvx"]["fallback"] is None  # it solved the reduced subproblems
    eps = config.replan_solver.scvx.eps_opt
    assert abs(reduced.cost - full.cost) <= eps * abs(full.cost)


@pytest.mark.parametrize("warmstart", ["previous", "tscvx"])
def test_capped_re_plans_stop_at_the_cap_without_a_cold_fallback(plan, warmstart):
    """``replan_iter_max``: every re-plan ends within the cap, a T-SCvx re-plan without the
    cold-SCvx run after it; the first plan is the uncapped one; the cap is a setting."""
    cfg = mpc.MPCConfig(warmstart=warmstart, replan_every=20, replan_iter_max=2,
                        errors=mpc.ErrorModels.none(), **UNTRACKED)  # fmt: skip
    flown = mpc.fly(INSTANCE, cfg, seed=0, open_loop=plan)
    assert flown.replans
    assert all(0 < r.iterations <= 2 and not r.fallback for r in flown.replans), flown.replans
    assert cfg.replan_solver.scvx.iter_max == 2 and cfg.solver.scvx.iter_max > 2
    assert Campaign(runs=1, config=cfg).settings()["replan_iter_max"] == 2
    assert "replan_iter_max" not in Campaign(runs=1, config=mpc.MPCConfig()).settings()
    with pytest.raises(ValueError, match="replan_iter_max"):
        mpc.MPCConfig(replan_iter_max=0)


def test_a_tscvx_run_folder_given_as_model_is_the_networks_of_the_re_plans(plan):
    """``--model RUN`` loads that run's networks (here the shipped mid-flight folder, by its
    path) and they predict the same guess as the default ones; the open-loop networks are
    another model."""
    from scpformer.pretrained import default_model

    cfg = mpc.MPCConfig(warmstart="tscvx", model=str(default_model("pdg6dof", guidance=True)))
    sub = mpc.remaining_instance(INSTANCE, plan.trajectory.x[10])
    by_path = mpc._tscvx_provider(cfg.solver, cfg.model).guess_for(sub, cfg.solver)
    shipped = mpc._tscvx_provider(cfg.solver).guess_for(sub, cfg.solver)
    np.testing.assert_array_equal(by_path.trajectory.x, shipped.trajectory.x)
    by_path_settings = Campaign(runs=1, config=cfg).settings()
    default_settings = Campaign(runs=1, config=mpc.MPCConfig(warmstart="tscvx")).settings()
    assert (by_path_settings["model"], default_settings["model"]) == (cfg.model, "default")
    # the same weights are the same model, however they were named
    assert by_path_settings["model_sha256"] == default_settings["model_sha256"]
    open_loop = mpc.MPCConfig(warmstart="tscvx", model=str(default_model("pdg6dof")))
    assert (
        Campaign(runs=1, config=open_loop).settings()["model_sha256"]
        != by_path_settings["model_sha256"]
    )
    assert "model" not in Campaign(runs=1, config=mpc.MPCConfig(warmstart="previous")).settings()


def test_the_networks_load_once_per_model_and_configuration():
    """Re-plans reuse the loaded networks: the provider is built once, not per re-plan."""
    cfg = mpc.MPCConfig(warmstart="tscvx")
    assert cfg.tscvx_provider() is cfg.tscvx_provider()
    other = mpc.MPCConfig(warmstart="tscvx", replan_iter_max=12)  # no cold fallback
    assert other.tscvx_provider() is not cfg.tscvx_provider()


def test_the_shifted_plan_is_the_rest_of_the_plan_retimed(plan):
    z = plan.trajectory
    n = z.x.shape[0]
    warm = mpc.shifted_plan(plan, 10).guess(INSTANCE).trajectory
    dt = float(z.p[0]) / (n - 1)
    assert warm.x.shape == z.x.shape and warm.u.shape == z.u.shape
    assert warm.p[0] == pytest.approx((n - 11) * dt)
    np.testing.assert_allclose(warm.x[0], z.x[10])
    np.testing.assert_allclose(warm.x[-1], z.x[-1])
    np.testing.assert_allclose(np.linalg.norm(warm.x[:, 6:10], axis=1), 1.0)
    with pytest.raises(ValueError, match="node must lie in"):
        mpc.shifted_plan(plan, n - 1)


def test_the_derived_tolerance_is_written_down(plan):
    tol = mpc.LandingTolerance.derive(mpc.ErrorModels(), mpc.MPCConfig(), INSTANCE, plan)
    assert tol.position == pytest.approx(0.064, abs=1e-3)
    assert tol.velocity == pytest.approx(0.047, abs=1e-3)
    none = mpc.LandingTolerance.derive(mpc.ErrorModels.none(), mpc.MPCConfig(), INSTANCE, plan)
    assert none.position == pytest.approx(np.sqrt(3) * TOL.terminal)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"replan_every": 0}, "replan_every"),
        ({"replan_every": 2.5}, "replan_every"),
        ({"warmstart": "art"}, "must be one of cold, previous, tscvx, best"),
        ({"compare": ("nope",)}, "must be one of"),
        ({"min_remaining_time": 0.1}, "tf_min"),
        ({"errors": "none"}, "errors must be an ErrorModels"),
        ({"accept_unconverged": 1}, "accept_unconverged"),
        ({"tracking": "lqr"}, "tracking must be a TrackingWeights"),
        ({"thrust_margin": -0.1}, "thrust_margin"),
        ({"thrust_margin": 0.5}, "leaves no thrust range"),
        ({"gimbal_margin_deg": 25.0}, "gimbal_margin_deg"),
        ({"model": 3}, "model must be a path string"),
    ],
)
def test_bad_configuration_is_refused_naming_the_field(kwargs, match):
    with pytest.raises(ValueError, match=match):
        mpc.MPCConfig(**kwargs)


def test_bad_errors_and_inputs_are_refused(plan):
    with pytest.raises(ValueError, match=r"errors\.thrust_magnitude"):
        mpc.ErrorModels(thrust_magnitude=-0.01)
    with pytest.raises(ValueError, match=r"below 0\.5"):
        mpc.ErrorModels(aero_fraction=0.9)
    with pytest.raises(ValueError, match=r"navigation\.position"):
        mpc.NavigationErrors(position=float("nan"))
    with pytest.raises(ValueError, match=r"errors\.navigation must be a NavigationErrors"):
        mpc.ErrorModels(navigation=0.01)
    with pytest.raises(ValueError, match="seed"):
        mpc.fly(INSTANCE, mpc.MPCConfig(), seed=-1, open_loop=plan)
    with pytest.raises(ValueError, match="instance must be a PDGInstance"):
        mpc.fly(RendezvousInstance(), mpc.MPCConfig(), seed=0, open_loop=plan)
    with pytest.raises(ValueError, match="config must be an MPCConfig"):
        Campaign(runs=1, config=mpc.ErrorModels())


def test_the_campaign_disperses_the_initial_state_per_run_with_common_draws():
    cfg = mpc.MPCConfig()
    a, b = Campaign(runs=2, config=cfg), Campaign(runs=2, config=cfg)
    assert a.family == "pdg6dof" and a.instance(0) == b.instance(0)
    assert a.instance(0) != a.instance(1) and a.instance(0).r0 != INSTANCE.r0
    none = Campaign(runs=1, config=mpc.MPCConfig(errors=mpc.ErrorModels.none()))
    assert none.instance(0) == INSTANCE
    assert a.settings()["family"] == "pdg6dof"


def test_the_simulate_command_writes_runs_npz_and_figure(tmp_path, capsys):
    out = tmp_path / "sim"
    argv = ["simulate", "pdg6dof", "--runs", "1", "--replan-every", "1000", "--errors",
            "none", "--tracking", "none", "--out", str(out), "--quiet"]  # fmt: skip
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "1 runs, warm start cold: success 100%" in printed
    assert "propellant median" in printed
    with (out / "runs.csv").open(newline="") as fh:
        (row,) = list(csv.DictReader(fh))
    assert tuple(row) == PDG_COLUMNS
    for column in ("run", "warmstart", "success", "terminal_position_error",
                   "terminal_velocity_error", "fuel", "open_loop_fuel", "replans",
                   "replans_failed", "replan_time_median_s", "replan_time_p99_s",
                   "replan_period_s", "violations"):  # fmt: skip
        assert column in row
    assert float(row["fuel"]) == pytest.approx(float(row["open_loop_fuel"]), abs=TOL.defect)
    with np.load(out / "run-0000.npz") as data:
        n = data["open_loop_x"].shape[0]
        assert data["x"].shape == ((n - 1) * mpc.SAMPLES_PER_INTERVAL + 1, 14)
    assert (out / "simulate.png").stat().st_size > 0
    # a rerun resumes; other settings are refused
    rows = run_campaign(
        Campaign(runs=1, config=mpc.MPCConfig(replan_every=1000, tracking=None,
                                              errors=mpc.ErrorModels.none())), out)  # fmt: skip
    assert summarize(rows, out, "pdg6dof")["runs"] == 1
    with pytest.raises(ValueError, match="other settings"):
        run_campaign(Campaign(runs=1, config=mpc.MPCConfig(replan_every=1000)), out)


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--replan-every", "0"], "--replan-every: must be at least 1"),
        (["--runs", "0"], "--runs: must be at least 1"),
        (["--warmstart", "art"], "invalid choice: 'art'"),
        (["--errors", "table2"], "invalid choice: 'table2'"),
        (["--tracking", "pid"], "invalid choice: 'pid'"),
        (["--warmstart", "tscvx", "--model", "no-such-run"], "no-such-run"),
    ],
)
def test_the_simulate_command_refuses_bad_input_in_one_line(argv, match, tmp_path, capsys):
    assert main(["simulate", "pdg6dof", "--out", str(tmp_path), *argv]) == 2
    err = capsys.readouterr().err
    assert match in err and err.count("\n") == 1


def test_the_parser_choices_are_the_library_ones():
    assert simulate_parser.PDG_WARMSTARTS == mpc.WARMSTARTS
