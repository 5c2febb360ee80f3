import dataclasses

import numpy as np
import pytest

from scpformer.scp.scvx import (
    Candidate,
    Evaluation,
    SCvxParameters,
    meets_stopping_test,
    solve_scvx,
    stalled,
    update_trust_radius,
)
from scpformer.scp.solution import IterationRecord, Status, Trajectory, Verification

P = SCvxParameters()


@pytest.mark.parametrize(
    "rho, eta_after, accepted",
    [(-0.5, 1.0, False), (0.05, 1.0, True), (0.5, 2.0, True), (0.9, 4.0, True)],
)
def test_trust_region_update_follows_eq_15(rho, eta_after, accepted):
    assert update_trust_radius(2.0, rho, P) == (eta_after, accepted)


def test_trust_radius_stays_within_bounds():
    assert update_trust_radius(P.eta_ub, 0.99, P)[0] == P.eta_ub
    assert update_trust_radius(P.eta_lb, -1.0, P)[0] == P.eta_lb


def test_defaults_are_table_1_except_penalty_weight_and_iteration_cap():
    # lambda 500 -> 10 and iter_max 20 -> 100: see the scvx module docstring
    assert (P.lambda_, P.rho_0, P.rho_1, P.rho_2) == (2.0, 0.0, 0.1, 0.7)
    assert (P.eta_init, P.eta_lb, P.eta_ub, P.iter_max) == (2.0, 1e-3, 10.0, 100)
    assert (P.eps_abs, P.eps_rel, P.feas_tol) == (0.1, 1e-3, 0.5)


def _record(step_norm: float) -> IterationRecord:
    return IterationRecord(
        iteration=1, accepted=True, cost=-2.0, penalty=0.0, J=-2.0, L=-2.0, rho=1.0,
        trust_radius=1.0, virtual_control_norm=0.0, step_norm=step_norm,
        tight_flags=np.zeros(0, dtype=bool), time_discretization=0.0, time_solver=0.0,
        time_total=0.0,
    )  # fmt: skip


def test_small_predicted_decrease_is_stationary_only_with_room_to_move():
    tiny = 0.5 * P.eps_opt * 2.0  # Delta L below eps_opt |J| with |J| = 2
    assert meets_stopping_test(P, _record(0.0), tiny, tiny, -2.0, eta_used=P.eta_stationary)
    assert not meets_stopping_test(P, _record(0.0), tiny, tiny, -2.0, eta_used=0.01)
    assert not meets_stopping_test(P, _record(0.0), 0.0, 0.1, -2.0, eta_used=2.0)


def test_a_small_step_under_a_throttled_trust_region_is_not_convergence():
    # Table 1's step test would stop here; the stationarity test does not
    table1 = SCvxParameters(stopping="table1")
    assert meets_stopping_test(table1, _record(0.01), 1e-3, 0.05, -2.0, eta_used=0.01)
    assert not meets_stopping_test(P, _record(0.01), 1e-3, 0.05, -2.0, eta_used=0.01)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"rho_1": 0.9}, "rho"),
        ({"eta_init": 100.0}, "eta"),
        ({"solver": "gurobi"}, "solver"),
        ({"lambda_": -1.0}, "lambda_"),
        ({"iter_max": 0}, "iter_max"),
        ({"stopping": "step"}, "stopping"),
        ({"eps_opt": 0.0}, "eps_opt"),
        ({"stall_window": -1}, "stall_window"),
        ({"stall_window": 2.5}, "stall_window"),
        ({"stall_decrease": 1.5}, "stall_decrease"),
        ({"stall_penalty": 0.0}, "stall_penalty"),
        ({"polish_penalty": 0.0}, "polish_penalty"),
    ],
)
def test_bad_parameters_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        SCvxParameters(**kwargs)


def test_the_stall_test_fires_only_on_a_flat_penalty_above_its_floor_after_a_full_window():
    w = P.stall_window
    flat = [0.5] * 3 + [0.06] * w  # penalty flat over the last window
    assert not stalled(P, flat[:w])  # not a full window yet
    assert stalled(P, [*flat, 0.0599])
    falling = [0.3 * 0.97**i for i in range(w + 5)]  # 3% per accepted iterate: slow progress
    assert not stalled(P, falling)
    rising_then_flat = [0.05] + [0.2] * w  # a penalty above its value a window ago
    assert stalled(P, rising_then_flat)
    assert not stalled(P, [1e-4] * (w + 2))  # nearly feasible: creeping cost, not a stall
    assert not stalled(SCvxParameters(stall_window=0), flat)


class ScriptedProblem:
    """A ConvexifiedProblem whose subproblem answers are scripted: candidate i has the cost
    ``costs[i]``, the penalty ``penalties[i]`` and the linear prediction ``predictions[i]``."""

    def __init__(self, costs, penalties, predictions):
        self.costs, self.penalties, self.predictions = costs, penalties, predictions
        self.solves = 0

    @staticmethod
    def _z(i: int) -> Trajectory:
        return Trajectory(x=np.full((3, 1), float(i)), u=np.zeros((3, 1)), p=np.zeros(1))

    def evaluate(self, z):
        i = int(z.x[0, 0])
        return Evaluation(
            cost=self.costs[i], penalty=self.penalties[i], max_defect=self.penalties[i],
            tight_flags=np.zeros(0, dtype=bool), linearization=None, time=0.0,
        )  # fmt: skip

    def solve_subproblem(self, z, evaluation, eta, lambda_, solver):
        self.solves += 1
        i = self.solves
        return Candidate(self._z(i), self.predictions[i], 0.0, 0.0, "optimal", 0.0, True)

    def solve_correction(self, z, evaluation, candidate, cand_ev, eta, lambda_, solver):
        raise AssertionError("no correction is needed once z_bar is certified stationary")

    def verify(self, z):
        return Verification(True, {}, 0.0, {}, {})

    def node_times(self, z):
        return np.arange(3.0)

    def step_norm(self, z_new, z_old):
        return 1.0


def test_a_stationary_iterate_is_returned_when_its_subproblem_finds_no_descent():
    # guess 0 (infeasible), candidate 1 accepted and feasible; the subproblem about 1 predicts
    # a decrease below eps_opt |J|, but its candidate 2 is worse on the nonlinear problem
    # (defects): 1 is a stationary point and is returned, without a correction solve
    tiny = 0.1 * P.eps_opt
    problem = ScriptedProblem(
        costs=[0.0, -2.0, -2.0 - tiny], penalties=[1.0, 0.0, 1e-3],
        predictions=[None, -2.0, -2.0 - tiny],
    )  # fmt: skip
    solution = solve_scvx(problem, ScriptedProblem._z(0), P)
    assert solution.status is Status.CONVERGED
    assert solution.iterations == 2 and problem.solves == 2
    assert solution.cost == -2.0  # the certified iterate, not the rejected candidate
    assert [r.accepted for r in solution.history] == [True, False]


def test_a_predicted_decrease_is_no_certificate_under_a_small_radius():
    tiny = 0.1 * P.eps_opt
    problem = ScriptedProblem(
        costs=[0.0, -2.0, -2.0 - tiny, -2.0 - tiny], penalties=[1.0, 0.0, 0.0, 0.0],
        predictions=[None, -2.0, -2.0 - tiny, -2.0 - tiny],
    )  # fmt: skip
    small = SCvxParameters(eta_init=0.5, eta_ub=0.5, iter_max=3)
    solution = solve_scvx(problem, ScriptedProblem._z(0), small)
    assert solution.status is Status.MAX_ITERATIONS


def test_a_candidate_whose_nonlinear_penalty_is_not_finite_is_rejected():
    # candidate 1's flow overflowed (penalty nan): it must count as infinitely bad, not as a
    # step whose ratio is undefined (which SCvx accepts as "no predicted change")
    problem = ScriptedProblem(
        costs=[0.0, -3.0, -2.0], penalties=[1.0, np.nan, 0.0], predictions=[None, -3.0, -2.0]
    )
    params = SCvxParameters(iter_max=2, second_order_correction=False)
    solution = solve_scvx(problem, ScriptedProblem._z(0), params)
    first = solution.history[0]
    assert not first.accepted and first.J == np.inf
    assert first.trust_radius == params.eta_init and solution.history[1].trust_radius < 2.0
    assert solution.history[1].accepted and solution.cost == -2.0


class PolishingProblem(ScriptedProblem):
    """A ScriptedProblem whose ``polish`` maps candidate ``i`` to the trajectory
    ``polished[i]`` (``None`` when absent), recording what it was asked and what each
    subproblem was built about."""

    def __init__(self, costs, penalties, predictions, polished):
        super().__init__(costs, penalties, predictions)
        self.polished, self.asked, self.built_about = polished, [], []

    def polish(self, candidate, evaluation):
        i = int(candidate.trajectory.x[0, 0])
        self.asked.append(i)
        j = self.polished.get(i)
        return None if j is None else dataclasses.replace(candidate, trajectory=self._z(j))

    def solve_subproblem(self, z, evaluation, eta, lambda_, solver):
        self.built_about.append(int(z.x[0, 0]))
        return super().solve_subproblem(z, evaluation, eta, lambda_, solver)


def _polishing(penalty_1: float, penalty_polished: float) -> PolishingProblem:
    """Guess 0; candidate 1 (cost -2, accepted) with ``penalty_1``; its polished version 3
    (cost -2) with ``penalty_polished``; candidate 2 anything."""
    return PolishingProblem(
        costs=[0.0, -2.0, -2.0, -2.0], penalties=[1.0, penalty_1, 0.0, penalty_polished],
        predictions=[None, -2.0, -2.0, None], polished={1: 3},
    )  # fmt: skip


def test_an_accepted_step_in_the_tail_is_polished_and_the_next_subproblem_built_about_it():
    problem = _polishing(penalty_1=5e-3, penalty_polished=0.0)
    solution = solve_scvx(problem, ScriptedProblem._z(0), SCvxParameters(iter_max=2))
    assert problem.asked == [1]
    assert problem.built_about == [0, 3]
    first = solution.history[0]  # the accepted step's record holds the polished iterate
    assert first.accepted and first.penalty == 0.0 and first.J == -2.0 and first.polished


def test_a_polish_that_raises_j_is_discarded():
    problem = _polishing(penalty_1=5e-3, penalty_polished=8e-3)
    solution = solve_scvx(problem, ScriptedProblem._z(0), SCvxParameters(iter_max=2))
    assert problem.asked == [1] and problem.built_about == [0, 1]
    assert not solution.history[0].polished and solution.history[0].penalty == 5e-3


@pytest.mark.parametrize(
    "params",
    [SCvxParameters(iter_max=2, polish=False), SCvxParameters(iter_max=2, polish_penalty=1e-3)],
)
def test_no_polish_when_off_or_above_the_tail(params):
    problem = _polishing(penalty_1=5e-3, penalty_polished=0.0)
    solve_scvx(problem, ScriptedProblem._z(0), params)
    assert problem.asked == [] and problem.built_about == [0, 1]
