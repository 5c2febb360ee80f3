"""Tests of the robust (chance-constrained, passively safe) rendezvous family."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import stats

from scpformer.dynamics.orbits import eci_to_rtn, oe_to_eci, propagate_mean_j2, rtn_to_eci
from scpformer.dynamics.roe import propagate_roe_mean, psi_matrix, stm_j2
from scpformer.dynamics.truth import propagate_relative
from scpformer.dynamics.uncertainty import (
    GatesModel,
    NavigationModel,
    ProcessNoise,
    UncertaintyModel,
    chance_margin,
)
from scpformer.problems.robust_rendezvous import (
    MonteCarloConfig,
    RobustInstance,
    RobustScenario,
    constraint_violation_budget,
    monte_carlo,
    sample_instances,
    solve,
    solve_safety,
    solve_tpbvp,
    trajectory_violations,
)
from scpformer.problems.robust_rendezvous.io import NPZ_FIELDS, load_solution, save_solution
from scpformer.problems.robust_rendezvous.montecarlo import propagate_drift_truth
from scpformer.problems.robust_rendezvous.plan_dynamics import linearize_dynamics
from scpformer.problems.robust_rendezvous.problem import replay
from scpformer.problems.robust_rendezvous.safety import (
    _arc_h,
    _sampled_arcs,
    arc_upper_bound,
    covariance_at_tstar,
    drift_geometry,
    evaluate_safety,
    linear_model,
    node_violation_flags,
    plan_safety,
    sample_peaks,
    violation_flags,
)
from scpformer.problems.robust_rendezvous.scenario import RobustSolverConfig
from scpformer.problems.robust_rendezvous.subproblem import ConicResult, SafetySubproblem
from scpformer.scp.solution import Status, Trajectory

INSTANCE = RobustInstance()
SOLVED = RobustInstance(waypoint="-T")  # the three-stage solutions below are of this one


@pytest.fixture(scope="module")
def tpbvp():
    return solve_tpbvp(INSTANCE)


@pytest.fixture(scope="module")
def deterministic_r():
    """The deterministic three-stage solution of the nominal instance with waypoint +R."""
    instance = RobustInstance(waypoint="+R")
    return instance, solve(instance, mode="deterministic")


@pytest.fixture(scope="module")
def solved():
    """Three-stage solutions of the nominal instance (waypoint -T) in both modes."""
    return {mode: solve(SOLVED, mode=mode) for mode in ("deterministic", "chance")}


# -- scenario and instance ------------------------------------------------------------------
def test_defaults_are_robust_tables_1_and_2():
    sc, tgt = INSTANCE.scenario, INSTANCE.target
    assert (sc.n_nodes, sc.horizon_orbits, sc.t_safety_orbits, sc.n_safety) == (100, 1.29, 1, 20)
    assert sc.ae_semi_axes_m == (1000.0,) * 3 and sc.koz_semi_axes_m == (200.0,) * 3
    assert sc.n_ae_to_koz == 55
    assert (tgt.a_m, tgt.e, tgt.i_deg, tgt.raan_deg, tgt.argp_deg, tgt.M_deg) == (
        6738e3, 5.58e-4, 51.64, 301.04, 26.18, 68.23,
    )  # fmt: skip
    assert tgt.period_s / 3600 == pytest.approx(1.528, abs=2e-3)
    assert INSTANCE.x0_rtn == (-4000.0, -17500.0, 0.0, 0.0, 6.849, 0.0)
    assert INSTANCE.uncertainty.q == pytest.approx(3.09, abs=1e-3)


@pytest.mark.parametrize(
    ("waypoint", "expected"),
    [("+T", (0, 750, 0)), ("-T", (0, -750, 0)), ("+R", (750, 0, 0)), ("-R", (-750, 0, 0))],
)
def test_waypoints_are_750_m_on_r_bar_and_v_bar_at_rest(waypoint, expected):
    inst = dataclasses.replace(INSTANCE, waypoint=waypoint)
    np.testing.assert_array_equal(inst.xf_rtn, [*expected, 0, 0, 0])
    model = linear_model(inst)
    x = solve_tpbvp(inst, RobustSolverConfig(dynamics="stm")).trajectory.x  # Psi's waypoint
    np.testing.assert_allclose(model.rtn(x)[-1], inst.xf_rtn, atol=1e-6)
    np.testing.assert_allclose(model.rtn(x)[0], inst.x0_rtn, atol=1e-6)
    u = solve_tpbvp(inst).trajectory.u  # nonlinear: the truth model's waypoint
    assert np.linalg.norm(replay(inst, u).rtn[-1] - inst.xf_rtn) < 1.0


@pytest.mark.parametrize(
    ("build", "field"),
    [
        (lambda: RobustInstance(waypoint="+N"), "waypoint"),
        (lambda: RobustInstance(x0_rtn=(100.0, 0, 0, 0, 0, 0)), "x0_rtn"),
        (lambda: RobustInstance(x0_rtn=(np.nan, 0, 0, 0, 0, 0)), "x0_rtn"),
        (lambda: UncertaintyModel(delta=1.0), "delta"),
        (lambda: UncertaintyModel(delta=0.0), "delta"),
        (lambda: GatesModel(sigma_s=-1e-3), "sigma_s"),
        (lambda: NavigationModel(s1=(-1, 0, 0, 0, 0, 0)), "s1"),
        (lambda: ProcessNoise(Q_roe=np.diag([1, 1, 1, 1, 1, -1.0]).tolist()), "Q_roe"),
        (lambda: ProcessNoise(Q_roe=np.zeros((6, 6)).tolist()), "Q_roe"),
        (lambda: RobustScenario(n_safety=0), "n_safety"),
        (lambda: RobustScenario(t_safety_orbits=-1.0), "t_safety_orbits"),
        (lambda: RobustScenario(t_safety_orbits=0.0), "t_safety_orbits must be positive"),
        (lambda: RobustScenario(koz_semi_axes_m=(200.0, 0.0, 200.0)), "koz_semi_axes_m"),
        (lambda: RobustInstance.from_dict({"x0": [0] * 6}), "x0"),
        (lambda: RobustInstance.from_dict({"uncertainty": {"delta": 2.0}}), "delta"),
        (lambda: solve(INSTANCE, mode="robust"), "mode"),
        (lambda: sample_instances(0, -1), "n"),
        (lambda: sample_instances(0, np.int64(-1)), "n must be an integer >= 0, got -1$"),
    ],
)
def test_bad_input_raises_naming_the_field(build, field):
    with pytest.raises(ValueError, match=field):
        build()


def test_sampler_is_seeded_and_stays_in_the_table_1_ranges():
    a, b = sample_instances(7, 50), sample_instances(np.random.default_rng(7), 50)
    assert [i.to_dict() for i in a] == [i.to_dict() for i in b]
    x0 = np.array([i.x0_rtn for i in a])
    nominal = np.array(INSTANCE.x0_rtn)
    assert np.all(np.abs(x0[:, 0] - nominal[0]) <= 1400.0)
    assert np.all(np.abs(x0[:, 1] - nominal[1]) <= 3000.0)
    assert np.all(np.abs(x0[:, 4] - nominal[4]) <= 1.0)
    np.testing.assert_array_equal(x0[:, [2, 3, 5]], 0.0)
    assert {i.waypoint for i in a} == {"+T", "-T", "+R", "-R"}


def test_instance_round_trips_through_a_dict():
    inst = sample_instances(3, 1)[0]
    assert RobustInstance.from_dict(inst.to_dict()) == inst
    assert "fix_every" not in inst.to_dict()["uncertainty"]  # Eq. 14's files stay as they were
    loop = dataclasses.replace(inst, uncertainty=UncertaintyModel(fix_every=10))
    assert RobustInstance.from_dict(loop.to_dict()) == loop


def test_monte_carlo_errors_between_fixes_have_the_designed_covariance(tpbvp):
    """With fixes every 10 nodes, the Monte Carlo's post-maneuver errors, drawn source by
    source and chained by the STM between the fixes, have the covariance X_i the chance
    constraints design for, at fixes and between them (whitened sample covariance within 5
    standard deviations of Wishart(n, I) / n: tests/dynamics/test_uncertainty.py)."""
    from scpformer.problems.robust_rendezvous.montecarlo import _errors

    x, u = np.asarray(tpbvp.trajectory.x), np.asarray(tpbvp.trajectory.u)
    geo, model = drift_geometry(FIXES_EVERY_10), linear_model(FIXES_EVERY_10)
    X = evaluate_safety(geo, model, x, u, FIXES_EVERY_10, "chance").X
    nodes, n = np.array([0, 1, 9, 10, 14, 55, 99]), 40_000
    e, u_exec = _errors(FIXES_EVERY_10, x, u, nodes, np.random.default_rng(7), n)
    post = e + np.einsum("kij,kmj->kmi", model.B[nodes], u_exec - u[nodes][:, None, :])
    for k, i in enumerate(nodes):
        w = np.linalg.solve(np.linalg.cholesky(X[i]), post[k].T)
        assert np.max(np.abs(w @ w.T / n - np.eye(6))) < 5 * np.sqrt(2 / n), i
    # between fixes the dispersion is not Eq. 14's: the carried error is part of it
    X14 = evaluate_safety(geo, model, x, u, INSTANCE, "chance").X
    assert np.allclose(X[[0, 10, 50]], X14[[0, 10, 50]]) and not np.allclose(X[9], X14[9])


# -- passive safety (Eqs. 14-16) --------------------------------------------------------------
def _brute_force_maps(inst: RobustInstance) -> np.ndarray:
    """``E_i D Psi(t_i + tau_j) Phi(t_i + tau_j, t_i)``, one STM and Psi at a time (N, S, 3, 6)."""
    t = inst.times()
    oe0 = inst.target.oe.to_array()
    tau = np.linspace(0.0, inst.t_safety_s, inst.scenario.n_safety)
    G = np.empty((inst.n_nodes, tau.size, 3, 6))
    for i in range(inst.n_nodes):
        axes = inst.scenario.ae_semi_axes_m if i < 55 else inst.scenario.koz_semi_axes_m
        for j, s in enumerate(tau):
            Phi = stm_j2(propagate_mean_j2(oe0, t[i]), s)
            Psi = psi_matrix(propagate_mean_j2(oe0, t[i] + s))
            G[i, j] = (Psi @ Phi)[:3] / np.asarray(axes)[:, None]
    return G


def test_passive_safety_matches_brute_force_sampling_of_the_drift_arc(tpbvp):
    """STM drift model: the design samples are the brute-force ones; the extra column is the
    arc's worst instant, no better than the worst sample."""
    x, u = tpbvp.trajectory.x, tpbvp.trajectory.u
    model, geo = linear_model(INSTANCE), drift_geometry(INSTANCE, dynamics="stm")
    det = evaluate_safety(geo, model, x, u, INSTANCE, "deterministic")
    chance = evaluate_safety(geo, model, x, u, INSTANCE, "chance")
    y = x[:-1] + np.einsum("ikl,il->ik", model.B, u)
    G = _brute_force_maps(INSTANCE)
    r = np.einsum("ijrl,il->ijr", G, y)
    d = np.linalg.norm(r, axis=-1)
    np.testing.assert_allclose(det.d[:, :20], d, rtol=1e-10)
    np.testing.assert_allclose(det.y, y)
    # deterministic: h is 1 - the minimum separation of the arc (Eq. 16), at least the samples'
    assert np.all(det.h >= 1.0 - d.min(axis=1) - 1e-12)
    assert np.all(det.d[np.arange(100), det.j_star] <= d.min(axis=1) + 1e-12)
    # chance: at least the worst sample of 1 + q sqrt(a^T X a) - d, a = G^T G y / d (Eq. 16)
    a = np.einsum("ijr,ijrl->ijl", r / d[..., None], G)
    beta = chance_margin(chance.X[:, None], a, 1e-3)
    assert np.all(chance.h >= (1.0 + beta - d).max(axis=1) - 1e-12)
    assert np.all(chance.h >= det.h) and np.any(det.h > 0.0)  # the TPBVP is not safe


@pytest.mark.parametrize("dynamics", ["stm", "nonlinear"])
def test_worst_instant_is_the_worst_of_a_dense_grid_of_the_arc(tpbvp, dynamics):
    """Continuous-time passive safety: h at the refined t* equals the max of 1 - d over a
    1 s grid of each arc (the 20 design samples alone miss it by up to ~1e-2)."""
    x, u = tpbvp.trajectory.x, tpbvp.trajectory.u
    model, geo = linear_model(INSTANCE), drift_geometry(INSTANCE, dynamics=dynamics)
    det = evaluate_safety(geo, model, x, u, INSTANCE, "deterministic")
    nodes = np.arange(0, 100, 9)
    tau = np.arange(0.0, INSTANCE.t_safety_s, 1.0)
    dense = np.empty((nodes.size, tau.size))
    for k, i in enumerate(nodes):
        for lo in range(0, tau.size, 500):
            taus = tau[lo : lo + 500]
            Psi = geo.rtn_map(geo.t[i] + taus)[:, :3, :]  # Psi, or the osculating map
            if dynamics == "stm":
                states = stm_j2(geo.target_at(geo.t[i]), taus) @ det.y[i]
            else:
                a = INSTANCE.target.oe.a
                states = a * propagate_roe_mean(geo.target_at(geo.t[i]), det.y[i] / a, taus)
            pos = np.einsum("tij,tj->ti", Psi, states)
            dense[k, lo : lo + 500] = np.linalg.norm(pos @ geo.E[i].T, axis=1)
    h_dense = 1.0 - dense.min(axis=1)
    np.testing.assert_allclose(det.h[nodes], h_dense, atol=2e-6)
    sampled = 1.0 - det.d[nodes, :20].min(axis=1)
    assert np.max(h_dense - sampled) > 1e-4  # the samples alone would miss it


#: The nominal instance with navigation fixes every 10 nodes only (a closed loop's covariance).
FIXES_EVERY_10 = dataclasses.replace(INSTANCE, uncertainty=UncertaintyModel(fix_every=10))


@pytest.mark.parametrize(
    ("mode", "instance"),
    [("deterministic", INSTANCE), ("chance", INSTANCE), ("chance", FIXES_EVERY_10)],
    ids=["deterministic", "chance", "chance-fixes-every-10"],
)
def test_subproblem_rows_are_the_exact_linearization_of_h(tpbvp, mode, instance):
    """Finite differences of h_ij (margin included) w.r.t. x_i and u_i, at four nodes (with
    fixes every 10 nodes: two at a fix, two between fixes, whose covariance carries that of
    the earlier nodes and depends on the node's own (x_i, u_i) through its maneuver only)."""
    x, u = tpbvp.trajectory.x, tpbvp.trajectory.u
    geo, model = drift_geometry(instance), linear_model(instance)
    ev = evaluate_safety(geo, model, x, u, instance, mode, n_rows=3)
    a_x, a_u, c = ev.subproblem_rows(x, u)
    for i in (5, 30, 45, 90):
        j = ev.rows[i, 0]

        def h(xx, uu, i=i, j=j):
            e = evaluate_safety(geo, model, xx, uu, instance, mode, n_rows=20)
            return 1.0 + e.beta_rows[i, list(e.rows[i]).index(j)] - e.d[i, j]

        for k, step in [(k, 1e-2) for k in range(6)]:
            dx = np.zeros_like(x)
            dx[i, k] = step
            fd = (h(x + dx, u) - h(x - dx, u)) / (2 * step)
            assert fd == pytest.approx(-a_x[i, 0, k], rel=1e-3, abs=1e-6)
        for k in range(3):
            du = np.zeros_like(u)
            du[i, k] = 1e-3  # t* is located to 0.5 s: h jitters by ~1e-7 with it
            fd = (h(x, u + du) - h(x, u - du)) / 2e-3
            assert fd == pytest.approx(-a_u[i, 0, k], rel=3e-3, abs=2e-4)
        # the row reproduces h at the reference
        assert c[i, 0] - a_x[i, 0] @ x[i] - a_u[i, 0] @ u[i] == pytest.approx(ev.h[i], abs=1e-9)
    if mode == "deterministic":
        np.testing.assert_allclose(a_u, np.einsum("ikl,ijk->ijl", model.B, ev.a_rows))


def test_margin_is_q_sqrt_of_the_linearized_variance_eq_16(tpbvp):
    x, u = tpbvp.trajectory.x, tpbvp.trajectory.u
    geo = drift_geometry(INSTANCE)
    ev = evaluate_safety(geo, linear_model(INSTANCE), x, u, INSTANCE, "chance")
    np.testing.assert_allclose(ev.beta, chance_margin(ev.X, ev.a_hat, 1e-3), rtol=1e-12)
    # Same variance seen at t*: g^T X(t*) g with g the gradient w.r.t. the state at t*.
    X_star = covariance_at_tstar(ev)
    Phi = ev.Phi_star
    g = np.linalg.solve(np.swapaxes(Phi, 1, 2), ev.a_hat[..., None])[..., 0]
    np.testing.assert_allclose(ev.beta, 3.0902 * np.sqrt(np.einsum("ik,ikl,il->i", g, X_star, g)),
                               rtol=1e-4)  # fmt: skip


def test_propagated_covariance_at_tstar_matches_monte_carlo_on_the_linear_model(tpbvp):
    x, u = tpbvp.trajectory.x, tpbvp.trajectory.u
    geo = drift_geometry(INSTANCE)
    ev = evaluate_safety(geo, linear_model(INSTANCE), x, u, INSTANCE, "chance")
    i, n = 20, 50_000
    rng = np.random.default_rng(0)
    e = rng.standard_normal((n, 6)) @ np.linalg.cholesky(ev.X[i]).T
    drifted = e @ ev.Phi_star[i].T
    L = np.linalg.cholesky(covariance_at_tstar(ev)[i])
    w = np.linalg.solve(L, drifted.T)
    assert np.max(np.abs(w @ w.T / n - np.eye(6))) < 5 * np.sqrt(2 / n)


def test_margin_vanishes_with_zero_covariance(tpbvp):
    x, u = tpbvp.trajectory.x, tpbvp.trajectory.u
    geo, model = drift_geometry(INSTANCE), linear_model(INSTANCE)
    det = evaluate_safety(geo, model, x, u, INSTANCE, "deterministic")
    assert det.X is None and np.all(det.beta == 0.0)
    np.testing.assert_array_equal(det.h, det.h_mean)
    quiet = UncertaintyModel(
        navigation=NavigationModel(s1=(0.0,) * 6, s2=(0.0,) * 6),
        actuation=GatesModel(sigma_s=0.0, sigma_p=0.0, sigma_r=0.0, sigma_a=0.0),
        process_noise=ProcessNoise(Q_roe=(np.eye(6) * 1e-30).tolist()),
    )
    chance = evaluate_safety(geo, model, x, u, dataclasses.replace(INSTANCE, uncertainty=quiet),
                             "chance")  # fmt: skip
    assert np.max(chance.beta) < 1e-12
    np.testing.assert_allclose(chance.h, det.h, atol=1e-12)


def test_collision_avoidance_is_the_zero_drift_case(tpbvp):
    x, u = tpbvp.trajectory.x, tpbvp.trajectory.u
    model = linear_model(INSTANCE)
    geo = drift_geometry(INSTANCE, 0.0, dynamics="stm")  # Psi: the model's RTN
    ev = evaluate_safety(geo, model, x, u, INSTANCE, "deterministic")
    E = INSTANCE.scenario.ellipsoid_E()[:-1]
    d = np.linalg.norm(np.einsum("irs,is->ir", E, model.rtn(x)[:-1, :3]), axis=1)
    np.testing.assert_allclose(1.0 - ev.h, d, rtol=1e-6)


def test_violation_budget_counts_violated_nodes_to_go_eq_7(tpbvp):
    h = np.array([0.5, -1.0, 2e-3, 1e-3, 2.0])  # 1e-3: within the solver tolerance
    np.testing.assert_array_equal(constraint_violation_budget(h), [3, 2, 2, 1, 1, 0])
    C = trajectory_violations(INSTANCE, tpbvp.trajectory.x, tpbvp.trajectory.u, "chance")
    assert C.shape == (101,) and C[0] > 0 and C[-1] == 0 and np.all(np.diff(C) <= 0)


# -- SCvx* on Eq. 17 and the three-stage solve ----------------------------------------------
def test_subproblem_is_dpp():
    assert SafetySubproblem(6).problem.is_dpp()


def test_three_stage_solve_is_passively_safe_with_margin(solved):
    for mode, sol in solved.items():
        assert sol.status is Status.CONVERGED, (mode, sol.message)
        assert sol.extras["stage"] == "passive_safety" and sol.extras["mode"] == mode
        assert set(sol.extras["stage_status"]) == {"tpbvp", "collision_avoidance", "passive_safety"}
        x, u = sol.trajectory.x, sol.trajectory.u
        assert trajectory_violations(SOLVED, x, u, mode, tol=1e-3)[0] == 0
        assert sol.verification.passed and sol.extras["violation_budget"][0] == 0
    assert sol.extras["dynamics"] == "nonlinear"


def test_a_deterministic_plan_violates_the_chance_margin(deterministic_r):
    """+R: the deterministic plan touches the approach ellipsoid, so the margin matters."""
    instance, sol = deterministic_r
    x, u = sol.trajectory.x, sol.trajectory.u
    assert sol.converged and trajectory_violations(instance, x, u, "deterministic")[0] == 0
    assert trajectory_violations(instance, x, u, "chance", tol=1e-3)[0] > 0


def test_a_given_warm_start_goes_straight_to_passive_safety(tpbvp):
    sol = solve(INSTANCE, mode="deterministic", warmstart=tpbvp.trajectory)
    assert sol.converged and set(sol.extras["stage_status"]) == {"passive_safety"}
    bad = Trajectory(x=np.zeros((100, 6)), u=np.zeros((100, 3)), p=np.zeros(0))
    with pytest.raises(ValueError, match="warm start"):
        solve(INSTANCE, warmstart=bad)
    with pytest.raises(ValueError, match="warmstart must be one of"):
        solve(INSTANCE, warmstart="art")


def test_conic_solver_failure_is_a_status_with_the_reason(tpbvp, monkeypatch):
    def fail(self, solver="clarabel"):
        return ConicResult("infeasible_inaccurate", None, None, None, float("nan"), 0.0)

    monkeypatch.setattr(SafetySubproblem, "solve", fail)
    sol = solve_safety(INSTANCE, tpbvp, mode="chance")
    assert sol.status is Status.SOLVER_FAILED and "infeasible_inaccurate" in sol.message
    full = solve(INSTANCE, mode="chance")
    assert full.status is Status.SOLVER_FAILED and full.extras["stage"] == "tpbvp"


def test_npz_holds_rendezvous_fields_covariances_and_safety_values(solved, tmp_path):
    path = tmp_path / "s.npz"
    save_solution(path, solved["chance"], SOLVED, "chance")
    data = load_solution(path)
    assert set(NPZ_FIELDS) <= set(data)
    assert data["covariance"].shape == data["covariance_tstar"].shape == (100, 6, 6)
    assert np.all(data["safety"] >= data["safety_mean"]) and np.all(data["safety"] <= 1e-3)
    assert data["constants"]["stage"] == "passive_safety" and data["constraint_to_go"][0] == 0


# -- Monte Carlo verification -----------------------------------------------------------------
def test_rk4_drift_matches_the_adaptive_truth_propagator():
    oe = INSTANCE.target.oe.to_array()
    rtn0 = np.array([-300.0, 2000.0, 50.0, 0.1, 0.4, -0.05])
    tau = np.linspace(0.0, INSTANCE.target.period_s, 11)
    ref = propagate_relative(oe, rtn0, [0.0], t_out=tau).rtn
    r_c, v_c = oe_to_eci(oe)
    r_d, v_d = rtn_to_eci(r_c, v_c, rtn0)
    out = propagate_drift_truth(np.r_[r_c, v_c][None], np.r_[r_d, v_d][None, None], tau, 20.0)
    np.testing.assert_allclose(out[0, 0], ref, atol=1e-2)
    np.testing.assert_allclose(eci_to_rtn(r_c, v_c, r_d, v_d), rtn0, atol=1e-9)


def test_chance_solution_passes_the_monte_carlo_check_at_the_design_level(solved, deterministic_r):
    """Design model at all nodes; a deterministic plan fails the same check."""
    cfg = MonteCarloConfig(n_samples=2000, propagator="linear", dense_step_s=1e9, seed=1)
    results = {}
    for mode, (instance, sol) in {"chance": (SOLVED, solved["chance"]),
                                  "deterministic": deterministic_r}.items():  # fmt: skip
        results[mode] = monte_carlo(instance, sol.trajectory.x, sol.trajectory.u, cfg)
    assert results["chance"].passes()
    assert results["chance"].p_design.mean() < SOLVED.uncertainty.delta
    deterministic = results["deterministic"]
    assert not deterministic.passes()  # its arcs touch the ellipsoid at t*
    # ... and not by a chance of the sampling: even for the worst of its K nodes, the one-sided
    # Clopper-Pearson lower bound of the violation probability at confidence 1 - 1e-4 / K
    # (Bonferroni over the nodes the worst was picked from) lies above Delta. The count it
    # needs follows from the sample size: 13 of 2000 draws for K = 100 (16 on an AVX2 EPYC).
    k, n = int(deterministic.counts().max()), deterministic.n_samples
    lower = stats.beta.ppf(1e-4 / deterministic.nodes.size, k, n - k + 1)  # Clopper-Pearson
    assert lower > SOLVED.uncertainty.delta


def test_chance_solution_passes_monte_carlo_in_the_truth_model_at_its_active_nodes(solved):
    """Every 5 s of the drift arcs (continuous-time passive safety), truth propagation."""
    sol = solved["chance"]
    x, u = sol.trajectory.x, sol.trajectory.u
    ev = plan_safety(SOLVED, x, u, "chance")
    active = np.argsort(ev.h)[-4:]
    cfg = MonteCarloConfig(n_samples=1000, propagator="truth", seed=2)
    res = monte_carlo(SOLVED, x, u, cfg, nodes=active)
    assert res.passes(dense=True) and res.min_distance.shape == (4, 1000)


# -- the plan's dynamics ------------------------------------------------------------------------
def test_plan_dynamics_jacobians_match_finite_differences(tpbvp):
    x, u = tpbvp.trajectory.x, tpbvp.trajectory.u
    model = linear_model(INSTANCE)
    lin = linearize_dynamics(INSTANCE, model, x, u, "nonlinear")

    def nxt(xx, uu):  # F(G(x_i, u_i)) for every node
        return xx[1:] - linearize_dynamics(INSTANCE, model, xx, uu, "nonlinear").defect

    for i in (0, 40, 99):
        for k in range(6):
            dx = np.zeros_like(x)
            dx[i, k] = 1.0
            fd = (nxt(x + dx, u)[i] - nxt(x - dx, u)[i]) / 2.0
            np.testing.assert_allclose(fd, lin.Phi[i, :, k], atol=1e-5)
        for k in range(3):
            du = np.zeros_like(u)
            du[i, k] = 1e-3
            fd = (nxt(x, u + du)[i] - nxt(x, u - du)[i]) / 2e-3
            np.testing.assert_allclose(fd, lin.Gamma[i, :, k], rtol=1e-4, atol=1e-2)
    stm = linearize_dynamics(INSTANCE, model, x, u, "stm")
    assert np.max(np.abs(lin.defect)) < 1e-3  # the TPBVP obeys the nonlinear mean dynamics
    assert np.max(np.abs(stm.defect)) > 0.1  # which the STM misses by decimetres per step


def test_chance_plan_reaches_the_waypoint_in_the_truth_model(solved):
    """Replayed through two-body + J2 from the consistent osculating start (the STM plans of
    the same instances missed by up to ~100 m)."""
    for sol in solved.values():
        truth = replay(SOLVED, sol.trajectory.u)
        assert np.linalg.norm(truth.rtn[-1, :3] - SOLVED.xf_rtn[:3]) < 1.0
        assert sol.extras["dynamics"] == "nonlinear"


def test_the_papers_stm_model_remains_available_and_is_reported(tpbvp):
    config = RobustSolverConfig(dynamics="stm")
    sol = solve_safety(INSTANCE, tpbvp, config, "deterministic")
    assert sol.extras["dynamics"] == "stm" and sol.verification.node_violations is not None
    assert sol.verification.node_violations["model_residual_m"] < 1e-3  # obeys the STM
    with pytest.raises(ValueError, match="dynamics must be one of"):
        RobustSolverConfig(dynamics="exact")


def test_sample_peaks_ranks_local_maxima_and_pads_with_the_highest():
    h = np.array([[0.0, 2.0, 1.0, 3.0, 0.5, 0.6], [5.0, 4.0, 3.0, 2.0, 1.0, 0.0]])
    np.testing.assert_array_equal(sample_peaks(h, 3), [[3, 1, 5], [0, 0, 0]])
    # fewer samples per arc than peaks asked for (N_safety = 2)
    np.testing.assert_array_equal(sample_peaks(h[:, :2], 3), [[1, 1, 1], [0, 0, 0]])


def test_every_dip_of_an_arc_between_samples_is_refined(tpbvp):
    """A second dip deeper than every sample is found: h is the max of a 2 s grid of each arc
    (the chance margin included), whichever local maximum of the samples it sits next to."""
    x, u = tpbvp.trajectory.x, tpbvp.trajectory.u
    model, geo = linear_model(INSTANCE), drift_geometry(INSTANCE)
    ev = evaluate_safety(geo, model, x, u, INSTANCE, "chance")
    tau = np.arange(0.0, INSTANCE.t_safety_s, 2.0)
    dense = np.stack(
        [_arc_h(geo, ev.y, np.full(ev.y.shape[0], t), ev.X, INSTANCE.uncertainty.q) for t in tau]
    ).max(axis=0)
    np.testing.assert_allclose(ev.h, dense, atol=1e-5)


def _perturbed(tpbvp, scale: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The TPBVP's states and impulses with Gaussian noise of ``scale`` m/s on the impulses."""
    u = tpbvp.trajectory.u + np.random.default_rng(seed).normal(
        0.0, scale, tpbvp.trajectory.u.shape
    )
    return tpbvp.trajectory.x, u


@pytest.mark.parametrize("scale", [0.0, 0.02])
def test_the_sampled_bound_of_an_arc_is_above_its_dense_maximum(tpbvp, scale):
    """``arc_upper_bound`` of the design samples is at least the arc's maximum on a 2 s grid,
    margin included, at every node (the TPBVP and a noisy copy of it)."""
    x, u = _perturbed(tpbvp, scale, 3)
    model, geo = linear_model(INSTANCE), drift_geometry(INSTANCE)
    arcs = _sampled_arcs(geo, model, x, u, INSTANCE, "chance", None)
    bound = arc_upper_bound(arcs.h)
    tau = np.arange(0.0, INSTANCE.t_safety_s, 2.0)
    dense = np.stack([_arc_h(geo, arcs.y, np.full(arcs.y.shape[0], t), arcs.X,
                             INSTANCE.uncertainty.q) for t in tau]).max(axis=0)  # fmt: skip
    assert np.all(bound >= dense)
    assert np.all(np.isinf(arc_upper_bound(np.zeros((4, 2)))))  # two samples bound nothing


@pytest.mark.parametrize("mode", ["chance", "deterministic"])
def test_node_violation_flags_equal_those_of_the_full_evaluation(tpbvp, mode):
    """The flags decided from the samples where they can be are those of ``evaluate_safety``,
    for whole trajectories and node by node (as the ART rollout asks), on the TPBVP and on
    noisy copies of it with violations."""
    from scpformer.warmstart.families import _node

    model, geo = linear_model(INSTANCE), drift_geometry(INSTANCE)
    for scale, seed in ((0.0, 0), (0.01, 1), (0.05, 2)):
        x, u = _perturbed(tpbvp, scale, seed)
        full = violation_flags(
            evaluate_safety(geo, model, x, u, INSTANCE, mode, margin_gradient=False).h
        )
        np.testing.assert_array_equal(node_violation_flags(geo, model, x, u, INSTANCE, mode), full)
        for k in range(0, u.shape[0], 7):
            node = dataclasses.replace(model, Phi=model.Phi[k : k + 1], B=model.B[k : k + 1],
                                       Psi=model.Psi[k : k + 1])  # fmt: skip
            flag = node_violation_flags(_node(geo, k), node, x[k : k + 1], u[k : k + 1],
                                        INSTANCE, mode)  # fmt: skip
            assert flag.tolist() == [full[k]]
    assert 0 < full.sum() < full.size  # the noisiest copy violates some nodes, not all


@pytest.mark.parametrize("expand", [True, False])
def test_a_guess_far_from_the_boundary_state_grows_the_trust_radius_instead_of_failing(
    tpbvp, expand
):
    """A guess whose interior misses the dynamics by 3 km (a learned warm start) makes the
    first subproblem infeasible at r = 100 m; SCvx* then grows r by alpha_2 and goes on."""
    far = Trajectory(x=tpbvp.trajectory.x.copy(), u=tpbvp.trajectory.u, p=np.zeros(0))
    far.x[1:-1, 1] += 3000.0  # a*dlambda of every interior node
    params = dataclasses.replace(RobustSolverConfig().scvx, expand_on_infeasible=expand)
    sol = solve_safety(INSTANCE, far, RobustSolverConfig(scvx=params), "deterministic")
    if expand:
        first = sol.history[0]
        assert first.solver_status == "infeasible" and not first.accepted
        assert sol.history[1].trust_radius == pytest.approx(3.0 * first.trust_radius)
        assert sol.status is not Status.SOLVER_FAILED
    else:
        assert sol.status is Status.SOLVER_FAILED and "infeasible" in sol.message
