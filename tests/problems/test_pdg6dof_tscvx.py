"""T-SCvx (Algorithm 2): oracle predictions reach the cold optimum; wrong ones fall back."""

import math

import numpy as np
import pytest

from scpformer.problems.pdg6dof.guess import straight_line_trajectory
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.problem import PDGSolverConfig, solve
from scpformer.problems.pdg6dof.tscvx import (
    TscvxParameters,
    TscvxProblem,
    consistent_guess,
    eq22_update,
    gimbal_projected_directions,
    sharpened_magnitudes,
    solve_tscvx,
)
from scpformer.scp.scvx import SCvxParameters
from scpformer.scp.solution import Status
from scpformer.warmstart.tscvx import TscvxWarmStart, penalized_cost

N = 50


class OraclePredictor:
    """The predictor API answering with a cold solve: its flags per iteration, its optimum."""

    n_nodes = N

    def __init__(self, solution, flags=None, guess=None):
        self.solution, self.flags, self.guess = solution, flags, guess

    def predict_tight(self, theta, k):
        history = self.solution.history
        return np.array(
            [
                self.flags
                if self.flags is not None
                else history[min(int(j), len(history)) - 1].tight_flags
                for j in np.atleast_1d(k)
            ]
        )

    def predict_solution(self, theta):
        if self.guess is not None:
            return self.guess
        z = self.solution.trajectory
        return z.x, z.u, float(z.p[0])


@pytest.fixture(scope="module")
def cold():
    return solve(PDGInstance())


def _gap(solution, cold):
    return abs(solution.cost - cold.cost) / (PDGInstance().m0 + cold.cost)


@pytest.mark.slow
def test_oracle_rows_reach_the_cold_optimum_with_reduced_subproblems(cold):
    solution = solve(PDGInstance(), guess=TscvxWarmStart(OraclePredictor(cold)))
    assert solution.status is Status.CONVERGED, solution.message
    assert solution.verification.passed
    assert _gap(solution, cold) <= 5e-3
    log = solution.extras["tscvx"]
    assert log["fallback"] is None
    assert set(log["modes"]) <= {"reduced", "correction"}
    assert max(log["rows_kept"]) < 7 * N and len(log["rows_kept"]) == solution.iterations
    assert solution.extras["warmstart"]["accepted"]


@pytest.mark.slow
def test_tscvx_runs_algorithm_1_exactly_with_the_hard_box_and_no_quadratic_term(cold):
    # prox_weight 0: the conic data has no P matrix; the reduced subproblem must not need one
    scvx = SCvxParameters(
        lambda_=500.0,
        iter_max=20,
        second_order_correction=False,
        polish=False,
        stopping="table1",
    )
    config = PDGSolverConfig(prox_weight=0.0, scvx=scvx)
    solution = solve(PDGInstance(), config, guess=TscvxWarmStart(OraclePredictor(cold)))
    assert solution.status is Status.CONVERGED, solution.message
    assert solution.verification.passed
    assert _gap(solution, cold) <= 5e-3
    assert "reduced" in solution.extras["tscvx"]["modes"]


@pytest.mark.slow
def test_all_rows_dropped_still_converge_to_the_optimum_through_repairs(cold):
    # From a guess away from the optimum the steps cross rows that were neither predicted
    # nor near-active: they are added back (repairs) or the run goes on with the full rows.
    guess = OraclePredictor(cold).predict_solution(None)
    x, u, tf = guess[0].copy(), guess[1] * 1.1, guess[2] * 0.95
    predictor = OraclePredictor(cold, flags=np.zeros(7 * N, dtype=bool), guess=(x, u, tf))
    params = TscvxParameters(margin=0.0)
    solution = solve(PDGInstance(), guess=TscvxWarmStart(predictor, params))
    assert solution.status is Status.CONVERGED, solution.message
    assert _gap(solution, cold) <= 5e-3
    log = solution.extras["tscvx"]
    assert sum(log["repairs"]) > 0 or log["fallback"] is not None


@pytest.mark.slow
def test_a_garbage_solution_guess_falls_back_to_the_cubic_profile(cold):
    rng = np.random.default_rng(0)
    garbage = (rng.normal(size=(N, 14)) * 5, rng.normal(size=(N, 3)) * 5, 30.0)
    predictor = OraclePredictor(cold, flags=np.zeros(7 * N, dtype=bool), guess=garbage)
    solution = solve(PDGInstance(), guess=TscvxWarmStart(predictor))
    record = solution.extras["warmstart"]
    assert not record["accepted"] and record["used"] == "cubic_profile"
    assert solution.status is Status.CONVERGED, solution.message
    assert _gap(solution, cold) <= 5e-3


def test_a_nan_prediction_is_replaced_by_the_cubic_profile():
    nan = (np.full((N, 14), np.nan), np.zeros((N, 3)), 5.0)
    predictor = OraclePredictor(None, guess=nan)
    result = TscvxWarmStart(predictor).guess(PDGInstance())
    assert not result.record.accepted and "NaN" in result.record.reason
    assert np.isfinite(result.trajectory.x).all()


def test_consistent_guess_normalizes_quaternions_and_clips_to_the_bounds():
    instance = PDGInstance()
    c = instance.constants
    rng = np.random.default_rng(1)
    x = rng.normal(size=(N, 14))
    x[:, 13] = np.linspace(4.0, 1.0, N)
    u = rng.normal(size=(N, 3)) * 10
    z = consistent_guess(instance, x, u, 100.0, N)
    np.testing.assert_allclose(np.linalg.norm(z.x[:, 6:10], axis=1), 1.0)
    np.testing.assert_array_equal(z.x[0], instance.x0)
    assert z.x[:, 13].min() >= c.m_dry and z.x[:, 13].max() <= instance.m0
    assert np.all(np.diff(z.x[:, 13]) <= 0.0)
    thrust = np.linalg.norm(z.u, axis=1)
    assert thrust.min() >= c.T_min - 1e-12 and thrust.max() <= c.T_max + 1e-12
    gimbal = math.cos(math.radians(c.delta_max_deg)) * thrust - z.u[:, 0]
    assert gimbal.max() <= 1e-12  # Eq. 6b at every node
    assert z.p[0] == c.tf_max
    with pytest.raises(ValueError, match="expected"):
        consistent_guess(instance, x[:10], u, 5.0, N)


def test_gimbal_projection_keeps_inside_turns_to_the_edge_and_resets_backwards():
    delta = 20.0
    inside = [math.cos(0.1), math.sin(0.1), 0.0]
    outside = [math.cos(1.0), 0.0, -math.sin(1.0)]  # 57 deg off e1, pointing -z
    backwards = [-0.9, 0.3, math.sqrt(1 - 0.9**2 - 0.3**2)]
    d = gimbal_projected_directions(np.array([inside, outside, backwards]), delta)
    np.testing.assert_allclose(d[0], inside)
    edge = [math.cos(math.radians(delta)), 0.0, -math.sin(math.radians(delta))]
    np.testing.assert_allclose(d[1], edge, atol=1e-15)
    np.testing.assert_allclose(d[2], [1.0, 0.0, 0.0])
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)


@pytest.mark.parametrize(
    ("rho", "tau_r", "expected", "accepted"),
    [
        (0.9, 0.0, 2.0, True),  # rho >= rho_2: beta^(1 - tau_r)
        (0.9, 0.5, 2.0**0.5, True),
        (0.5, 0.3, 1.0, True),  # rho_1 <= rho < rho_2: unchanged
        (0.05, 0.5, 2.0**-0.5, True),  # rho < rho_1: alpha^-tau_r (floor 0)
        (-1.0, 0.25, 2.0**-0.25, False),  # rejected
    ],
)
def test_eq22_scales_growth_and_contraction_by_the_changed_fraction(rho, tau_r, expected, accepted):
    eta, ok = eq22_update(1.0, rho, SCvxParameters(), tau_r, shrink_floor=0.0)
    assert eta == pytest.approx(expected)
    assert ok is accepted


def test_eq22_contraction_exponent_has_a_floor():
    eta, ok = eq22_update(1.0, -1.0, SCvxParameters(), 0.0, shrink_floor=1.0)
    assert eta == pytest.approx(0.5) and not ok


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("margin", -1.0),
        ("shrink_floor", 2.0),
        ("max_repairs", 1.5),
        ("thrust_gain", 0.0),
        ("eta_ub", -1.0),
        ("eta_ub", 1.0),  # below eta_init = 2
    ],
)
def test_bad_tscvx_parameters_are_refused_by_name(field, value):
    with pytest.raises(ValueError, match=field):
        TscvxParameters(**{field: value})


@pytest.mark.slow
def test_a_noisy_prediction_is_kept_although_its_j_exceeds_the_straight_lines(cold):
    # Noise on the states inflates the L1 defects of J, not the distance to the optimum.
    rng = np.random.default_rng(0)
    z = cold.trajectory
    guess = (z.x + 0.02 * rng.normal(size=z.x.shape), z.u, float(z.p[0]))
    record = TscvxWarmStart(OraclePredictor(cold, guess=guess)).guess(PDGInstance()).record
    assert record.accepted, record.reason
    straight = penalized_cost(PDGInstance(), PDGSolverConfig(), straight_line_trajectory(
        PDGInstance(), N))  # fmt: skip
    assert record.details["J_prediction"] > straight


@pytest.mark.slow
def test_solves_without_nu_take_the_steps_of_the_solves_with_nu(cold):
    # After a solve that needed no virtual control the next ones leave nu out; the optimum
    # has nu = 0 anyway (lambda = 2 is above the multipliers), so no step may change.
    guess = OraclePredictor(cold).predict_solution(None)
    predictor = OraclePredictor(cold, guess=(guess[0], guess[1] * 1.05, guess[2] * 0.97))
    config = PDGSolverConfig(scvx=SCvxParameters(iter_max=4))
    runs = [
        solve(PDGInstance(), config, guess=TscvxWarmStart(predictor, TscvxParameters(
            drop_virtual=drop, cold_fallback=False)))
        for drop in (False, True)
    ]  # fmt: skip
    costs = [[r.cost for r in run.history] for run in runs]
    np.testing.assert_allclose(costs[1], costs[0], atol=1e-6)
    logs = [run.extras["tscvx"] for run in runs]
    assert not any(logs[0]["without_virtual"])
    assert any(logs[1]["without_virtual"]) and logs[1]["virtual_retries"] == 0


@pytest.mark.slow
def test_a_solve_without_nu_that_needs_nu_is_repeated_with_it(cold):
    # lambda = 0.3 is below the dynamics multipliers (about 1): the optimum uses nu, so the
    # attempt without it must be refused and the step be the one of the solve with nu.
    config = PDGSolverConfig(scvx=SCvxParameters(lambda_=0.3))
    z = cold.trajectory
    flags = np.ones(7 * N, dtype=bool)
    steps = []
    for drop in (False, True):
        problem = TscvxProblem(PDGInstance(), config, lambda k: flags, TscvxParameters(
            drop_virtual=drop))  # fmt: skip
        problem._virtual_free = True  # as after a solve that needed no virtual control
        steps.append(problem.solve_subproblem(z, problem.evaluate(z), 5.0, 0.3, "clarabel"))
        assert problem.log.virtual_retries == int(drop)
    assert steps[1].virtual_norm > 1.0
    np.testing.assert_allclose(steps[1].trajectory.x, steps[0].trajectory.x, atol=1e-6)


def test_sharpening_pushes_magnitudes_to_the_nearer_bound_about_a_fixed_midpoint():
    T_min, T_max = 0.3, 5.0
    unit = np.array([-0.2, 0.0, 0.1, 0.4, 0.5, 0.55, 0.6, 0.9, 1.0, 1.3])
    thrust = T_min + unit * (T_max - T_min)
    clipped = T_min + np.clip(unit, 0.0, 1.0) * (T_max - T_min)
    np.testing.assert_allclose(sharpened_magnitudes(thrust, T_min, T_max, 1.0), clipped)
    sharp = (sharpened_magnitudes(thrust, T_min, T_max, 4.0) - T_min) / (T_max - T_min)
    np.testing.assert_allclose(sharp, [0, 0, 0, 0.1, 0.5, 0.7, 0.9, 1, 1, 1], atol=1e-12)
    assert np.all(np.diff(sharp) >= 0.0)


def test_consistent_guess_sharpens_thrust_magnitudes_and_keeps_their_directions():
    instance = PDGInstance()
    c = instance.constants
    rng = np.random.default_rng(3)
    direction = gimbal_projected_directions(
        np.column_stack([np.ones(N), 0.1 * rng.normal(size=(N, 2))]), c.delta_max_deg
    )
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    u = direction * rng.uniform(c.T_min, c.T_max, size=(N, 1))
    x = np.tile(instance.x0, (N, 1))
    z = consistent_guess(instance, x, u, 5.0, N, thrust_gain=3.0)
    norms = np.linalg.norm(z.u, axis=1)
    np.testing.assert_allclose(z.u / norms[:, None], direction, atol=1e-12)
    expected = sharpened_magnitudes(np.linalg.norm(u, axis=1), c.T_min, c.T_max, 3.0)
    np.testing.assert_allclose(norms, expected, atol=1e-12)


@pytest.mark.slow
def test_tscvx_trust_radius_stays_below_its_own_bound_and_reaches_the_optimum(cold):
    # From a perturbed guess the ratio test would grow the radius towards Table 1's 10.
    guess = OraclePredictor(cold).predict_solution(None)
    predictor = OraclePredictor(cold, guess=(guess[0], guess[1] * 1.05, guess[2] * 0.97))
    params = TscvxParameters(eta_ub=3.0, cold_fallback=False)
    ws = TscvxWarmStart(predictor, params)
    z = ws.guess(PDGInstance()).trajectory
    solution = solve_tscvx(PDGInstance(), PDGSolverConfig(), z, ws.tight(PDGInstance()), params)
    assert solution.status is Status.CONVERGED, solution.message
    radii = [record.trust_radius for record in solution.history]
    assert max(radii) <= 3.0 and max(radii) > params.eta_init
    assert _gap(solution, cold) <= 5e-3


@pytest.mark.slow
def test_sticky_rows_keep_the_lookahead_predictions_and_every_row_kept_before(cold):
    # Iteration k predicts the mass row of node k alone; those rows are far from active at
    # the optimum (the mass is well above m_dry early on), so only the predictions keep them.
    def tight(k):
        return np.arange(7 * N) == k

    z = cold.trajectory
    kept = {}
    for sticky in (True, False):
        params = TscvxParameters(lookahead=3, sticky_rows=sticky, margin=0.0)
        problem = TscvxProblem(PDGInstance(), PDGSolverConfig(), tight, params)
        evaluation = problem.evaluate(z)
        kept[sticky] = []
        for _ in range(2):
            problem.solve_subproblem(z, evaluation, 2.0, 2.0, "clarabel")
            kept[sticky].append(problem._keep.copy())
    first, second = kept[True]
    assert first[[1, 2, 3]].all() and not first[4]
    assert (second | ~first).all()
    first, second = kept[False]
    assert first[1] and not first[[2, 3]].any()
    assert second[2] and not second[1]
