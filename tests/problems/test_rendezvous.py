"""Tests of the rendezvous family: scenario, instance, Problems 1-3, SCP, verification, .npz."""

from __future__ import annotations

import dataclasses
import functools
import json
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from scpformer.dynamics.orbits import (
    accel_two_body_j2,
    eci_to_oe,
    j2_secular_rates,
    mean_motion,
    oe_to_eci,
    oe_to_qns,
    qns_to_oe,
    rtn_to_eci,
)
from scpformer.dynamics.roe import oe_to_roe, psi_matrix, roe_to_oe
from scpformer.dynamics.truth import propagate_relative
from scpformer.problems.rendezvous import subproblems
from scpformer.problems.rendezvous.instance import (
    RendezvousInstance,
    SampleRanges,
    sample_instances,
)
from scpformer.problems.rendezvous.io import NPZ_FIELDS, load_solution, save_solution
from scpformer.problems.rendezvous.problem import (
    constraint_index,
    constraint_to_go,
    keep_out_cut,
    linear_model,
    osculating_initial_state,
    replay,
    reward_to_go,
    solve,
    verify_solution,
)
from scpformer.problems.rendezvous.scenario import (
    MAX_HORIZON_ORBITS,
    RendezvousScenario,
    RendezvousSolverConfig,
    SCPParameters,
    TargetOrbit,
    VerificationTolerances,
)
from scpformer.scp.solution import Status

N = 100
KEPLER_CIRCULAR = {"target": TargetOrbit(e=0.0), "scenario": RendezvousScenario(j2=False)}


@pytest.fixture(scope="module")
def nominal():
    """The default instance and its Problem 2 and Problem 3 solutions."""
    instance = RendezvousInstance()
    convex = solve(instance, "convex")
    scp = solve(instance, "scp", convex)
    return instance, convex, scp


# ---------------------------------------------------------------------------------------
# scenario and instance
# ---------------------------------------------------------------------------------------
def test_scenario_defaults_are_table_1():
    sc, target = RendezvousScenario(), TargetOrbit()
    assert sc.n_nodes == 100 and sc.n_waypoint == 90
    assert sc.koz_semi_axes_m == (60.0, 94.0, 123.0)  # (h + 15, l + 20, w + 15)
    np.testing.assert_allclose(sc.waypoint_m, [0.0, 104.0, 0.0])  # dr_dp + 30 n_ac
    assert sc.dock_port_m == (0.0, 74.0, 0.0) and sc.cone_half_angle_deg == 30.0
    assert target.period_s / 3600.0 == pytest.approx(1.548, abs=5e-4)
    scp = SCPParameters()
    assert (scp.K, scp.zeta_1, scp.zeta_K, scp.J_tol) == (20, 200.0, 1.0, 1e-6)
    assert scp.beta == pytest.approx((1.0 / 200.0) ** (1 / 20))


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: TargetOrbit(a_m=6.0e6), "target.a_m: semi-major axis"),
        (lambda: TargetOrbit(e=1.0), "target.e: eccentricity must satisfy 0 <= e < 1"),
        (lambda: TargetOrbit(e=0.3), "target.e: periapsis radius"),
        (lambda: TargetOrbit(i_deg=math.nan), "target.i_deg must be finite"),
        (lambda: TargetOrbit(i_deg=0.0), "target.i_deg: quasi-nonsingular ROE are singular"),
        (lambda: RendezvousInstance(roe0_m=(0, math.nan, 0, 80, 0, 140)), "roe0_m must be finite"),
        (lambda: RendezvousInstance(roe0_m=(0, 50, 0, 80)), "roe0_m must have shape (6,)"),
        (lambda: RendezvousInstance(horizon_orbits=0.5), "horizon_orbits must lie in [1.0, 3.0]"),
        (lambda: RendezvousInstance(horizon_orbits=3.5), "horizon_orbits must lie in [1.0, 3.0]"),
        (lambda: RendezvousInstance(roe0_m=(0, 0, 0, 20, 0, 20)), "lies inside the keep-out zone"),
        (lambda: RendezvousScenario(waypoint_distance_m=5.0), "waypoint_distance_m: the waypoint"),
        (lambda: RendezvousScenario(approach_axis=(0, 2, 0)), "approach_axis must be a unit"),
        (lambda: RendezvousScenario(cone_half_angle_deg=90.0), "cone_half_angle_deg must lie"),
        (lambda: RendezvousScenario(n_nodes=11), "scenario.n_nodes must be >="),
        (lambda: SCPParameters(zeta_K=300.0), "scp.zeta_K (300.0) must not exceed"),
        (lambda: SCPParameters(solver="mosek"), "scp.solver must be one of"),
        (lambda: SCPParameters(K=0), "scp.K must be an integer >= 1"),
        (lambda: VerificationTolerances(keep_out=-1.0), "verification.keep_out must be positive"),
    ],
)
def test_bad_input_raises_a_value_error_naming_the_field(make, message):
    with pytest.raises(ValueError) as err:
        make()
    assert message in str(err.value)


def test_horizons_beyond_max_horizon_orbits_are_refused_naming_the_bound():
    from scpformer.problems.robust_rendezvous.scenario import RobustScenario

    edge = (1.0, MAX_HORIZON_ORBITS)
    assert RendezvousScenario(horizon_range_orbits=edge).horizon_range_orbits == edge
    assert SampleRanges(horizon_orbits=edge).horizon_orbits == edge
    assert RobustScenario(horizon_orbits=MAX_HORIZON_ORBITS).horizon_orbits == MAX_HORIZON_ORBITS
    cases = {
        "scenario.horizon_range_orbits": lambda h: RendezvousScenario(horizon_range_orbits=(1, h)),
        "ranges.horizon_orbits": lambda h: SampleRanges(horizon_orbits=(1.0, h)),
        "scenario.horizon_orbits": lambda h: RobustScenario(horizon_orbits=h),
        "scenario.t_safety_orbits": lambda h: RobustScenario(t_safety_orbits=h),
    }
    for name, make in cases.items():
        for horizon in (MAX_HORIZON_ORBITS + 1.0, 1e6):
            with pytest.raises(ValueError, match=rf"{name} must be at most 200 orbits"):
                make(horizon)


@pytest.mark.parametrize(
    "data, message",
    [
        ({"roe0": [0, 50, 0, 80, 0, 140]}, "unknown instance field(s): roe0"),
        ({"target": {"a": 7e6}}, "unknown target field(s): a"),
        ({"scenario": {"N": 50}}, "unknown scenario field(s): N"),
        ({"target": {"a_m": 6.0e6}}, "target.a_m"),
        ({"target": [1, 2]}, "target must be a JSON object"),
        ([1, 2], "instance must be a JSON object"),
    ],
)
def test_from_dict_rejects_unknown_keys_and_bad_values(data, message):
    with pytest.raises(ValueError) as err:
        RendezvousInstance.from_dict(data)
    assert message in str(err.value)


def test_instance_round_trips_through_json(tmp_path):
    instance = RendezvousInstance(
        roe0_m=(1.0, 60.0, 3.0, 80.0, -2.0, 140.0),
        horizon_orbits=2.5,
        scenario=RendezvousScenario(cone_half_angle_deg=25.0),
    )
    path = tmp_path / "instance.json"
    path.write_text(json.dumps(instance.to_dict()))
    assert RendezvousInstance.from_json(path) == instance
    with pytest.raises(ValueError, match="instance file not found"):
        RendezvousInstance.from_json(tmp_path / "missing.json")
    path.write_text("{oops")
    with pytest.raises(ValueError, match="malformed JSON"):
        RendezvousInstance.from_json(path)


def test_sampler_is_seeded_and_draws_passively_safe_orbits_over_table_1():
    a = sample_instances(np.random.default_rng(3), 40)
    b = sample_instances(np.random.default_rng(3), 40)
    assert a == b
    assert a != sample_instances(np.random.default_rng(4), 40)
    r_r, _, r_n = RendezvousScenario().koz_semi_axes_m
    ranges = SampleRanges()
    for inst in a:
        da, dl, dex, dey, dix, diy = inst.roe0
        assert 1.0 <= inst.horizon_orbits <= 3.0
        assert -5.0 <= da <= 5.0 and -100.0 <= dl <= 100.0
        assert r_r + 5.0 <= math.hypot(dex, dey) <= r_r + 30.0
        assert r_n + 5.0 <= math.hypot(dix, diy) <= r_n + 30.0
        phi, theta = math.degrees(math.atan2(dey, dex)), math.degrees(math.atan2(diy, dix))
        assert ranges.phi_deg[0] <= phi <= ranges.phi_deg[1]
        assert abs(phi - theta) <= 10.0  # e/i vectors nearly parallel: passive safety
        assert inst.scenario.koz_metric(inst.rtn0_linear[:3]) >= 1.0


# ---------------------------------------------------------------------------------------
# linear model
# ---------------------------------------------------------------------------------------
def test_linear_model_rollout_reproduces_the_solution_states(nominal):
    instance, _, scp = nominal
    model = linear_model(instance)
    assert model.Phi.shape == (N, 6, 6) and model.B.shape == (N, 6, 3)
    assert model.Psi.shape == (N + 1, 6, 6)
    x = model.rollout(instance.roe0, scp.trajectory.u)
    np.testing.assert_allclose(x, scp.trajectory.x, atol=1e-6)
    assert model.residual(scp.trajectory.x, scp.trajectory.u) < 1e-6


# ---------------------------------------------------------------------------------------
# convex problems against closed forms (circular Keplerian model: e = 0, no J2)
# ---------------------------------------------------------------------------------------
def _drift_start(da_m: float, end_m: float) -> float:
    """a dlambda(t_0) such that tangential burns of -n a da / 4 at nodes 10 and 60 (half an
    orbit apart, horizon one orbit) stop the along-track drift exactly at ``end_m``."""
    P = TargetOrbit(e=0.0).period_s
    t = np.linspace(0.0, P, N + 1)
    n = 2.0 * math.pi / P
    return end_m + 1.5 * n * da_m * t[10] + 1.5 * n * (da_m / 2.0) * (t[60] - t[10])


@pytest.mark.parametrize("da_m", [30.0, 40.0])
def test_tpbvp_matches_the_closed_form_cost_of_stopping_an_along_track_drift(da_m):
    """Only a tangential impulse changes a da (by 2 dv_T / n for e = 0), so any plan removing
    a da costs at least n |a da| / 2; two burns half an orbit apart reach it (their relative
    eccentricity kicks cancel), with the start chosen so the drift ends at the docking port."""
    instance = RendezvousInstance(
        roe0_m=(da_m, _drift_start(da_m, 74.0), 0, 0, 0, 0), horizon_orbits=1.0, **KEPLER_CIRCULAR
    )
    sol = solve(instance, "tpbvp")
    assert sol.status is Status.CONVERGED
    n = mean_motion(instance.target.a_m)
    assert sol.cost == pytest.approx(n * da_m / 2.0, rel=1e-5)


def test_tpbvp_matches_the_closed_form_cost_of_a_cross_track_correction():
    """A normal impulse changes a di by (cos u, sin u) dv_N / n, so removing a di costs at least
    n a |di|, reached by one burn where the argument of latitude points along -di (node 25)."""
    target = KEPLER_CIRCULAR["target"]
    P, d = target.period_s, 150.0
    u25 = math.radians(target.argp_deg + target.M_deg) + 2 * math.pi * 25 / N
    roe0 = (0.0, 74.0, 0.0, 0.0, -d * math.cos(u25), -d * math.sin(u25))
    instance = RendezvousInstance(roe0_m=roe0, horizon_orbits=1.0, **KEPLER_CIRCULAR)
    sol = solve(instance, "tpbvp")
    assert sol.cost == pytest.approx(2 * math.pi / P * d, rel=1e-5)


def test_convex_cost_grows_with_the_initial_drift_at_the_closed_form_rate():
    """The waypoint fixes the whole state at N_wp, so Problem 2 splits into a drift stop at the
    waypoint (closed form n |a da| / 2) plus a final approach that does not depend on a da."""
    costs = []
    for da_m in (30.0, 40.0):
        roe0 = (da_m, _drift_start(da_m, 104.0), 0, 0, 0, 0)
        instance = RendezvousInstance(roe0_m=roe0, horizon_orbits=1.0, **KEPLER_CIRCULAR)
        sol = solve(instance, "convex", verify=False)
        assert sol.status is Status.CONVERGED
        costs.append(sol.cost)
    n = mean_motion(TargetOrbit().a_m)
    assert costs[1] - costs[0] == pytest.approx(n * 10.0 / 2.0, rel=1e-5)


def test_convex_solution_meets_waypoint_cone_and_docking_in_the_linear_model(nominal):
    instance, convex, _ = nominal
    sc = instance.scenario
    rtn = linear_model(instance).rtn(convex.trajectory.x)
    np.testing.assert_allclose(rtn[sc.n_waypoint], np.r_[sc.waypoint_m, 0, 0, 0], atol=1e-6)
    np.testing.assert_allclose(rtn[N], np.r_[sc.dock_port_m, 0, 0, 0], atol=1e-6)
    d = rtn[sc.n_waypoint : N, :3] - sc.cone_vertex_m
    cos_angle = d[:, 1] / np.linalg.norm(d, axis=1)
    assert np.all(cos_angle >= math.cos(math.radians(30.0)) - 1e-7)
    assert solve(instance, "tpbvp", verify=False).cost <= convex.cost  # Problem 1 relaxes 2


# ---------------------------------------------------------------------------------------
# keep-out linearization (Eqs. 15-16)
# ---------------------------------------------------------------------------------------
def test_keep_out_linearization_is_a_conservative_tangent_cut():
    instance = RendezvousInstance()
    sc = instance.scenario
    Psi = linear_model(instance).Psi[:91]
    rng = np.random.default_rng(0)
    x_ref = rng.normal(scale=80.0, size=(91, 6))
    a, b = keep_out_cut(Psi, sc, x_ref)
    r_ref = np.einsum("kij,kj->ki", Psi[:, :3], x_ref)
    # The cut touches the ellipsoid at the radial projection of the reference ...
    x_touch = x_ref / sc.koz_metric(r_ref)[:, None]
    np.testing.assert_allclose(np.einsum("kj,kj->k", a, x_touch), b, rtol=1e-12)
    np.testing.assert_allclose(sc.koz_metric(r_ref / sc.koz_metric(r_ref)[:, None]), 1.0)
    # ... and every point it admits lies outside the ellipsoid (samples near the boundary).
    x = x_touch[:, None, :] + rng.normal(scale=40.0, size=(91, 400, 6))
    admitted = np.einsum("kj,ksj->ks", a, x) >= b[:, None]
    r = np.einsum("kij,ksj->ksi", Psi[:, :3], x)
    assert admitted.sum() > 5000  # the test exercises the cut
    assert sc.koz_metric(r[admitted]).min() >= 1.0 - 1e-12
    # it cuts away the reference itself when the reference is inside the zone
    inside = sc.koz_metric(r_ref) < 1.0
    assert inside.any()
    assert np.all(np.einsum("kj,kj->k", a, x_ref)[inside] < b[inside])


# ---------------------------------------------------------------------------------------
# SCP (Problem 3)
# ---------------------------------------------------------------------------------------
def test_scp_solution_is_feasible_under_the_nonlinear_replay(nominal):
    """Stated tolerance: the defaults of VerificationTolerances (2 m / 2 mm/s terminal miss,
    keep-out depth 2 % of a semi-axis, 0.5 m cone); measured on this instance: 0.45 m,
    0.23 mm/s, 1e-4, 0."""
    instance, convex, scp = nominal
    assert scp.status is Status.CONVERGED and scp.converged
    ver = scp.verification
    assert ver.passed, ver.message
    assert ver.terminal_error["position_m"] < 2.0 and ver.terminal_error["velocity_m_s"] < 2e-3
    assert ver.node_violations["keep_out"] < 0.02 and ver.node_violations["cone_m"] < 0.5
    assert ver.max_defect < 2.0  # linear (mean ROE) vs truth (osculating) gap [m]
    # Problem 2 violated the keep-out zone; Problem 3 does not, at a higher cost.
    model = linear_model(instance)
    assert constraint_to_go(model.rtn(convex.trajectory.x), instance.scenario)[0] > 0
    assert constraint_to_go(model.rtn(scp.trajectory.x), instance.scenario)[0] == 0
    assert scp.cost >= convex.cost - 1e-9


def test_every_scp_iterate_stays_out_of_the_keep_out_zone(nominal):
    _, _, scp = nominal
    assert len(scp.history) == scp.iterations >= 2
    assert all(rec.accepted and rec.penalty == 0.0 for rec in scp.history)
    assert scp.cost == min(rec.cost for rec in scp.history)
    flags = scp.tight_flags()
    assert flags.shape == (len(constraint_index(RendezvousScenario())),) and flags.any()


def test_trust_region_shrinks_exponentially_and_the_literal_stop_test_runs_K_iterations():
    config = RendezvousSolverConfig(scp=SCPParameters(K=6, stop_test="radius"))
    sol = solve(RendezvousInstance(), "scp", config=config, verify=False)
    radii = np.array([rec.trust_radius for rec in sol.history])
    assert sol.status is Status.MAX_ITERATIONS and sol.iterations == 6
    np.testing.assert_allclose(radii, 200.0 * config.scp.beta ** np.arange(6))
    assert sol.trajectory is not None  # every iterate satisfies Problem 3 in the model


def test_scp_from_a_keep_out_feasible_convex_solution_stops_at_the_first_iteration():
    instance = sample_instances(np.random.default_rng(0), 2)[1]
    convex = solve(instance, "convex", verify=False)
    rtn = linear_model(instance).rtn(convex.trajectory.x)
    assert constraint_to_go(rtn, instance.scenario)[0] == 0  # C_CVX(t_1) = 0
    sol = solve(instance, "scp", convex, verify=False)
    assert sol.status is Status.CONVERGED and sol.iterations == 1
    assert sol.cost == pytest.approx(convex.cost, rel=1e-6)


def test_warm_starts_by_name_trajectory_or_array_reach_a_feasible_solution(nominal):
    instance, convex, scp = nominal
    from_array = solve(instance, "scp", convex.trajectory.x, verify=False)
    assert from_array.status is Status.CONVERGED
    assert from_array.cost == pytest.approx(scp.cost, rel=1e-4)
    sampled = sample_instances(np.random.default_rng(0), 1)[0]
    from_tpbvp = solve(sampled, "scp", "tpbvp", verify=False)
    from_convex = solve(sampled, "scp", "convex", verify=False)
    assert from_tpbvp.status is from_convex.status is Status.CONVERGED
    assert from_tpbvp.cost == pytest.approx(from_convex.cost, rel=1e-4)
    with pytest.raises(ValueError, match=r"states must have shape \(101, 6\), got \(50, 6\)"):
        solve(instance, "scp", np.zeros((50, 6)))
    with pytest.raises(ValueError, match="warmstart must be one of"):
        solve(instance, "scp", "no-such-start")
    with pytest.raises(ValueError, match="problem must be one of"):
        solve(instance, "problem4")


# ---------------------------------------------------------------------------------------
# failures are statuses
# ---------------------------------------------------------------------------------------
def test_infeasible_instance_is_a_status_not_an_exception():
    """With the cone apex at the docking port the last coast arc leaves the cone (see the
    RendezvousScenario note): Problem 2, hence Problem 3, is infeasible."""
    instance = RendezvousInstance(scenario=RendezvousScenario(cone_vertex_setback_m=0.0))
    convex = solve(instance, "convex")
    assert convex.status is Status.INFEASIBLE_INSTANCE and convex.trajectory is None
    assert "infeasible" in convex.message
    scp = solve(instance, "scp")
    assert scp.status is Status.INFEASIBLE_INSTANCE and "warm start failed" in scp.message


def test_infeasible_scp_subproblem_is_reported_as_solver_failed():
    """From the Problem 1 solution of the nominal instance, which dives into the keep-out zone
    before the waypoint, the cut at node N_wp - 1 excludes the only position from which the
    waypoint is reached at rest (the backward coast of the waypoint state): the first
    subproblem is infeasible, as the paper reports for some CVX-TPBVP warm starts."""
    sol = solve(RendezvousInstance(), "scp", "tpbvp")
    assert sol.status is Status.SOLVER_FAILED and sol.trajectory is None
    assert sol.message.startswith("subproblem 1: infeasible")
    assert sol.iterations == 1 and not sol.history[0].accepted


def _patched_status(monkeypatch, status: str) -> None:
    original = subproblems.RendezvousSubproblem.solve

    def solve_with_status(self, solver="clarabel", settings=None):
        sol = original(self, solver, settings)
        if status == subproblems.INACCURATE:
            return dataclasses.replace(sol, status=status)
        return subproblems.SubproblemSolution.failed(status, sol.wall_time, sol.solver_time)

    monkeypatch.setattr(subproblems.RendezvousSubproblem, "solve", solve_with_status)


def test_an_inaccurate_conic_solution_is_accepted_and_flagged(monkeypatch):
    _patched_status(monkeypatch, "optimal_inaccurate")
    convex = solve(RendezvousInstance(), "convex", verify=False)
    assert convex.status is Status.CONVERGED and "accepted optimal_inaccurate" in convex.message
    sol = solve(RendezvousInstance(), "scp", convex)
    assert sol.status is Status.CONVERGED and "accepted optimal_inaccurate at" in sol.message
    assert {rec.solver_status for rec in sol.history} == {"optimal_inaccurate"}
    assert sol.verification.node_violations["model_residual_m"] < 1e-6


def test_a_conic_solver_error_is_a_status(monkeypatch):
    _patched_status(monkeypatch, "solver_error: numerical trouble")
    for problem in ("tpbvp", "convex", "scp"):
        sol = solve(RendezvousInstance(), problem)
        assert sol.status is Status.SOLVER_FAILED and sol.trajectory is None
        assert "solver_error" in sol.message


# ---------------------------------------------------------------------------------------
# verification
# ---------------------------------------------------------------------------------------
def test_verification_fails_a_plan_that_violates_the_checked_constraints(nominal):
    instance, convex, scp = nominal
    model = linear_model(instance)
    x, dv = convex.trajectory.x, convex.trajectory.u
    as_problem_3 = verify_solution(instance, model, x, dv, "scp")
    assert not as_problem_3.passed and "keep_out" in as_problem_3.message
    assert verify_solution(instance, model, x, dv, "convex").passed
    dropped = scp.trajectory.u.copy()
    dropped[np.argmax(np.linalg.norm(dropped, axis=1))] = 0.0  # skip the largest burn
    broken = verify_solution(instance, model, scp.trajectory.x, dropped, "scp")
    assert not broken.passed and broken.terminal_error["position_m"] > 2.0


def _replay_and_verify(monkeypatch, method, instance, x, dv):
    """Replay and verification of ``dv`` with the truth propagation ``method``, cold cache."""
    from scpformer.dynamics import truth
    from scpformer.problems.rendezvous import verification as problem_module

    propagate = functools.partial(truth.propagate_relative, method=method)
    monkeypatch.setattr(problem_module, "propagate_relative", propagate)
    problem_module._osculating_initial_state.cache_clear()
    ver = verify_solution(instance, linear_model(instance), x, dv, "scp")
    return replay(instance, dv), ver


def _assert_same_check(monkeypatch, instance, x, dv):
    (fixed, v_fixed), (adaptive, v_adaptive) = (
        _replay_and_verify(monkeypatch, method, instance, x, dv) for method in ("fixed", "adaptive")
    )
    np.testing.assert_allclose(fixed.rtn[:, :3], adaptive.rtn[:, :3], rtol=0, atol=1e-5)
    np.testing.assert_allclose(fixed.rtn[:, 3:], adaptive.rtn[:, 3:], rtol=0, atol=1e-8)
    assert v_fixed.passed == v_adaptive.passed
    for key, value in v_adaptive.terminal_error.items():
        assert v_fixed.terminal_error[key] == pytest.approx(value, abs=1e-5)
    for key, value in v_adaptive.node_violations.items():
        assert v_fixed.node_violations[key] == pytest.approx(value, abs=1e-5)
    return v_fixed


@pytest.mark.slow
def test_fixed_step_replay_check_agrees_with_the_adaptive_one_on_sampled_instances(monkeypatch):
    """The default checked fixed-step propagation reaches the verdict and the numbers of the
    previous ``solve_ivp`` replay (measured agreement < 1e-6 m, 1e-9 m/s)."""
    for instance in sample_instances(np.random.default_rng(11), 3):
        sol = solve(instance, "scp", verify=False)
        assert sol.trajectory is not None
        _assert_same_check(monkeypatch, instance, sol.trajectory.x, sol.trajectory.u)


def test_fixed_step_replay_check_still_rejects_a_corrupted_plan(monkeypatch, nominal):
    instance, _, scp = nominal
    assert _assert_same_check(monkeypatch, instance, scp.trajectory.x, scp.trajectory.u).passed
    dropped = scp.trajectory.u.copy()
    dropped[np.argmax(np.linalg.norm(dropped, axis=1))] = 0.0  # skip the largest burn
    broken = _assert_same_check(monkeypatch, instance, scp.trajectory.x, dropped)
    assert not broken.passed and "terminal_position_m" in broken.message
    assert broken.terminal_error["position_m"] > 2.0


def test_consistent_osculating_initial_state_shrinks_the_linear_vs_truth_gap(nominal):
    """Mean elements used as osculating offset the relative semi-major axis by its
    short-period J2 term, which drifts into metres; the consistent state removes it."""
    instance, _, scp = nominal
    model = linear_model(instance)
    lin = model.rtn(scp.trajectory.x)
    gaps = []
    for consistent in (True, False):
        tol = VerificationTolerances(consistent_initial_state=consistent)
        truth = replay(instance, scp.trajectory.u, tol)
        gaps.append(np.linalg.norm(truth.rtn[:: tol.samples_per_interval, :3] - lin[:, :3], axis=1))
    assert gaps[0].max() < 1.0 < 3.0 < gaps[1].max()


def _independent_mean_qns(x0: np.ndarray, oe_mean: np.ndarray, samples: int = 360) -> np.ndarray:
    """Mean quasi-nonsingular elements of one spacecraft by an independent numerical average:
    its own DOP853 integration of ``accel_two_body_j2`` over its own draconitic period (from
    the mean elements the state should have), 360 samples, secular drift removed."""
    raan_dot, argp_dot, M_dot = j2_secular_rates(oe_mean)
    period = 2.0 * math.pi / (argp_dot + M_dot)
    t = np.arange(samples) * period / samples
    sol = solve_ivp(lambda _t, s: np.r_[s[3:], accel_two_body_j2(s[:3])], (0.0, period), x0,
                    method="DOP853", t_eval=t, rtol=1e-12, atol=1e-6)  # fmt: skip
    q = oe_to_qns(eci_to_oe(sol.y[:3].T, sol.y[3:].T))
    q[:, 1] = np.unwrap(q[:, 1]) - (argp_dot + M_dot) * t
    q[:, 5] = np.unwrap(q[:, 5]) - raan_dot * t
    return q.mean(axis=0)


@pytest.mark.parametrize("a_da_m", [0.0, -1000.0, -5000.0])
def test_osculating_start_averages_to_the_mean_roe_at_kilometre_separations(a_da_m):
    """Each spacecraft's osculating start, averaged over its own period by an independent
    propagator, gives back the model's mean ROE to centimetres (averaging both over the
    target's period biased a da by 6.7 m at -5 km)."""
    from scpformer.problems.robust_rendezvous.instance import RobustInstance

    target = RobustInstance().target.oe
    roe_m = np.array([a_da_m, 3000.0, 200.0, 300.0, 100.0, 200.0])
    instance = RobustInstance(x0_rtn=tuple(psi_matrix(target) @ roe_m))
    oe_c, rtn0 = osculating_initial_state(instance)  # type: ignore[arg-type]
    r_c, v_c = oe_to_eci(oe_c)
    r_d, v_d = rtn_to_eci(r_c, v_c, rtn0)
    mean_c = target.to_array()
    mean_d = roe_to_oe(mean_c, instance.roe0 / mean_c[0])
    averaged = [
        qns_to_oe(_independent_mean_qns(np.r_[r, v], oe))
        for (r, v), oe in (((r_c, v_c), mean_c), ((r_d, v_d), mean_d))
    ]
    got = oe_to_roe(*averaged) * mean_c[0]
    np.testing.assert_allclose(got, instance.roe0, atol=0.03)


# ---------------------------------------------------------------------------------------
# reward-to-go and constraint-to-go (Eqs. 20-21)
# ---------------------------------------------------------------------------------------
def test_reward_to_go_is_minus_the_remaining_fuel():
    dv = np.zeros((N, 3))
    dv[0], dv[50], dv[99] = [0.0, 0.003, 0.004], [0.01, 0.0, 0.0], [0.0, 0.0, -0.002]
    rtg = reward_to_go(dv)
    assert rtg.shape == (N + 1,)
    assert rtg[0] == pytest.approx(-0.017) and rtg[1] == pytest.approx(-0.012)
    assert rtg[51] == pytest.approx(-0.002) and rtg[N] == 0.0


def test_constraint_to_go_counts_keep_out_violations_up_to_the_waypoint_only():
    sc = RendezvousScenario()
    rtn = np.zeros((N + 1, 6))
    rtn[:, 1] = 200.0  # far outside
    rtn[[3, 40, 90], 1] = 50.0  # inside, at or before the waypoint node 90
    rtn[95, 1] = 50.0  # inside, after the waypoint: not constrained
    rtn[60, 1] = 94.0 * (1.0 - 1e-9)  # on the boundary within the tolerance
    ctg = constraint_to_go(rtn, sc)
    assert ctg.shape == (N + 1,) and ctg.dtype.kind == "i"
    assert list(ctg[[0, 3, 4, 40, 41, 90, 91, N]]) == [3, 3, 2, 2, 1, 1, 0, 0]


# ---------------------------------------------------------------------------------------
# .npz output
# ---------------------------------------------------------------------------------------
def test_npz_holds_exactly_the_documented_fields_and_replays_without_the_model(nominal, tmp_path):
    instance, _, scp = nominal
    path = tmp_path / "out" / "rdv.npz"
    save_solution(path, scp, instance)
    assert [p.name for p in path.parent.iterdir()] == ["rdv.npz"]  # no temporary file left
    with np.load(path, allow_pickle=False) as raw:
        assert set(raw.files) == set(NPZ_FIELDS)
    data = load_solution(path)
    assert data["t"].shape == (N + 1,) and data["roe"].shape == (N + 1, 6)
    assert data["rtn"].shape == (N + 1, 6) and data["dv"].shape == (N, 3)
    assert data["constraint_to_go"].shape == (N + 1,) and data["status"] == "converged"
    assert data["cost"] == pytest.approx(np.linalg.norm(data["dv"], axis=1).sum())
    assert data["t"][-1] == pytest.approx(instance.horizon_s)
    oe = data["target_oe"]
    assert {"a_m", "e", "i_deg", "raan_deg", "argp_deg", "M_deg"} <= set(oe)
    assert oe["a_m"] == instance.target.a_m
    assert data["constants"]["koz_semi_axes_m"] == [60.0, 94.0, 123.0]
    assert data["constants"]["n_waypoint"] == 90
    np.testing.assert_allclose(data["rtn"][N], [0.0, 74.0, 0.0, 0.0, 0.0, 0.0], atol=1e-6)
    # A replay from the file's fields alone docks within the verification tolerance.
    osc = oe["osculating"]
    oe0 = [osc["a_m"], osc["e"]] + [
        math.radians(osc[k]) for k in ("i_deg", "raan_deg", "argp_deg", "M_deg")
    ]
    kicks = np.where(np.linalg.norm(data["dv"], axis=1, keepdims=True) < 1e-9, 0.0, data["dv"])
    truth = propagate_relative(oe0, oe["rtn0_osculating"], data["t"][:-1], kicks, data["t"])
    assert np.linalg.norm(truth.rtn[N, :3] - [0.0, 74.0, 0.0]) < 2.0


def test_npz_writer_refuses_a_solution_without_trajectory(tmp_path):
    failed = solve(RendezvousInstance(scenario=RendezvousScenario(cone_vertex_setback_m=0.0)))
    with pytest.raises(ValueError, match="no trajectory to write"):
        save_solution(tmp_path / "x.npz", failed, RendezvousInstance())
    assert not list(tmp_path.iterdir())


# ---------------------------------------------------------------------------------------
# conic solvers
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("solver", ["ecos", "qoco"])
def test_other_conic_solvers_agree_with_clarabel_on_the_convex_problem(solver, nominal):
    instance, convex, _ = nominal
    config = RendezvousSolverConfig(scp=SCPParameters(solver=solver))
    other = solve(instance, "convex", config=config, verify=False)
    assert other.status is Status.CONVERGED
    assert other.cost == pytest.approx(convex.cost, rel=1e-4)
