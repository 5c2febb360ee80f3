"""End-to-end SCvx solves of the 6-DoF problem (slow: compiles the subproblem once)."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from scpformer.dynamics import powered_descent as pd
from scpformer.dynamics import quaternion as quat
from scpformer.problems.pdg6dof import constraints as con
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.problem import propagate, solve
from scpformer.scp.solution import Status

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def nominal():
    return solve(PDGInstance())


def test_nominal_instance_converges_to_a_verified_trajectory(nominal):
    assert nominal.status is Status.CONVERGED, nominal.message
    ver = nominal.verification
    assert ver.passed
    assert max(ver.terminal_error.values()) < 5e-3
    x = nominal.trajectory.x
    assert 2.0 <= x[-1, 13] < 3.0  # fuel was used, dry mass respected
    assert nominal.cost == pytest.approx(-x[-1, 13])


def test_history_records_every_iteration_with_flags_and_timing(nominal):
    assert len(nominal.history) == nominal.iterations
    n_rows = 7 * 50
    for rec in nominal.history:
        assert rec.tight_flags.shape == (n_rows,)
        assert rec.time_solver > 0.0 and rec.time_discretization > 0.0
    # the returned iterate is the last accepted one (a run certified stationary may end on
    # a solve whose candidate it rejects)
    last_accepted = [rec for rec in nominal.history if rec.accepted][-1]
    assert nominal.cost == last_accepted.cost
    assert nominal.timing.solver <= nominal.timing.total


def test_the_truth_propagation_agrees_with_an_independent_tight_integration(nominal):
    # one solve_ivp (Radau, rtol 1e-12) of the vectorized model over each interval, against
    # the verification's DOP853 that carries its step size from interval to interval
    instance, z = PDGInstance(), nominal.trajectory
    model = instance.constants.model()
    n, m = z.x.shape[0], 3
    dt = float(z.p[0]) / (n - 1)
    states = propagate(instance, z, samples_per_interval=m)
    expected = [instance.x0]
    for k in range(n - 1):

        def rhs(t, x, k=k):
            return pd.dynamics(model, x, z.u[k] + (t / dt) * (z.u[k + 1] - z.u[k]))

        times = np.linspace(0.0, dt, m + 1)[1:]
        result = solve_ivp(rhs, (0.0, dt), expected[-1], "Radau", times, rtol=1e-12, atol=1e-13)
        expected.extend(result.y.T)
    assert states.shape == ((n - 1) * m + 1, 14)
    np.testing.assert_allclose(states, np.array(expected), rtol=0.0, atol=1e-6)
    np.testing.assert_allclose(states[::m], z.x, atol=5e-3)  # and the solution is dynamical


def _tight(instance: PDGInstance, solution, tol: float) -> np.ndarray:
    values = con.constraint_values(instance, solution.trajectory.x, solution.trajectory.u)
    return con.tight_flags(values, tol).ravel()


def test_rotating_the_instance_about_up_rotates_the_solution(nominal):
    # The two runs stop at different iterates of the same local optimum: the stationarity test
    # (eps_opt = 1e-4 |J|) leaves about 0.1% of the propellant, and the iterates a few 1e-2 of
    # U_L, between a stationary point and the optimum.
    angle = math.radians(90.0)
    instance = PDGInstance().rotated_about_up(angle)
    rotated = solve(instance)
    assert rotated.status is Status.CONVERGED
    q_rot = quat.from_axis_angle([1.0, 0.0, 0.0], angle)
    expected_r = quat.rotate(q_rot, nominal.trajectory.x[:, 0:3])
    np.testing.assert_allclose(rotated.trajectory.x[:, 0:3], expected_r, atol=5e-2)
    assert rotated.trajectory.p[0] == pytest.approx(nominal.trajectory.p[0], abs=2e-2)
    propellant = PDGInstance().m0 + nominal.cost
    assert rotated.cost == pytest.approx(nominal.cost, abs=2e-3 * propellant)
    # The same tight rows, up to the distance between the two stopping points: of ~50 tight
    # rows at most one differs, the thrust bound at a node where the thrust switches from its
    # maximum (a direction in which the cost is nearly flat)
    strict = _tight(PDGInstance(), nominal, 1e-5), _tight(instance, rotated, 1e-5)
    loose = _tight(PDGInstance(), nominal, 5e-2), _tight(instance, rotated, 5e-2)
    assert strict[0].sum() >= 5  # the nominal solution rides its thrust and gimbal bounds
    differing = np.flatnonzero((strict[0] & ~loose[1]) | (strict[1] & ~loose[0]))
    assert len(differing) <= 1
    index = con.constraint_index(50)
    assert all(index[i][0] == "thrust_max" for i in differing)


def test_instance_violating_a_state_constraint_is_a_status_not_a_crash():
    sol = solve(PDGInstance(omega0_deg=(95.0, 0.0, 0.0)))
    assert sol.status is Status.INFEASIBLE_INSTANCE
    assert "omega" in sol.message


def test_infeasible_subproblem_is_a_solver_failed_status_with_the_reason():
    from scpformer.problems.pdg6dof.constants import VehicleConstants

    # a landing target off the glideslope cone's axis at zero altitude: Eq. 5b cannot hold there
    instance = PDGInstance(constants=VehicleConstants(r_f=(0.0, 1.0, 0.0)))
    sol = solve(instance)
    assert sol.status is Status.SOLVER_FAILED
    assert "infeasible" in sol.message


@pytest.mark.parametrize("solver", ["ecos", "qoco"])
def test_every_conic_solver_reaches_the_same_trajectory(nominal, solver):
    from scpformer.problems.pdg6dof.problem import PDGSolverConfig
    from scpformer.scp.scvx import SCvxParameters

    params = SCvxParameters(solver=solver)
    other = solve(PDGInstance(), PDGSolverConfig(scvx=params))
    assert other.status is Status.CONVERGED
    # How close two runs can be is set by what stops them, not by the conic solver. SCvx
    # stops at the first iterate whose predicted decrease Delta L (Eq. 13) is below
    # eps = eps_opt max(1, |J|). The decrease still ahead is the sum of the predicted
    # decreases of the iterations not taken; near the optimum each accepted step at least
    # halves Delta L (rho <= 1), so it is at most eps (1 + 1/2 + ...) = 2 eps: both penalized
    # costs J lie in [J*, J* + 2 eps] and differ by at most 2 eps. (Measured on this instance
    # with a run to eps_opt = 1e-6 as J*: the gap was 1.0-1.7 eps for Clarabel and ECOS at
    # eps_opt 1e-4 and 1e-5.) The cost C = J - lambda P adds lambda times the larger
    # penalty P of the two returned iterates; the conic solvers' own duality gaps (1e-8
    # relative for Clarabel and ECOS, 1e-7 for QOCO) add 2e-7 |J|. Which iterate a run stops
    # at depends on the solver's rounding (here ECOS's virtual control is 1.3e-6, over
    # virtual_tol, so it skips a polish Clarabel makes), hence on the CPU and BLAS.
    runs = [_returned_record(sol) for sol in (nominal, other)]
    eps = params.eps_opt * max(1.0, abs(runs[0].J))
    tolerance = 2 * eps + params.lambda_ * max(r.penalty for r in runs) + 2e-7 * abs(runs[0].J)
    assert abs(runs[1].J - runs[0].J) <= 2 * eps + 2e-7 * abs(runs[0].J)
    assert other.cost == pytest.approx(nominal.cost, abs=tolerance)
    # The final time is free, so the optimal cost is flat in it to first order: a cost within
    # 2 eps of the optimum fixes t_f only to sqrt(2 * 2 eps / kappa), kappa the curvature of
    # the optimal cost in t_f, about 14 per s^2 here (the 1e-4 runs of both solvers against
    # their 1e-6 runs: cost gaps 2.5e-4 and 3.1e-4 at t_f 6.0e-3 and 6.7e-3 s short; 13 used).
    assert other.trajectory.p[0] == pytest.approx(
        nominal.trajectory.p[0], abs=math.sqrt(4 * eps / 13.0)
    )


def _returned_record(sol):
    """The history record of the iterate ``sol`` returns: the accepted one of lowest J."""
    record = min((r for r in sol.history if r.accepted), key=lambda r: r.J)
    assert record.cost == pytest.approx(sol.cost, abs=1e-12)
    return record


def test_a_solve_does_not_depend_on_what_the_process_solved_before(nominal):
    # The subproblem and its solver object are shared by every solve in a process (updated in
    # place, scpformer.scp.conic): results must not depend on the process's history, or a
    # dataset would differ with the number of workers.
    solve(PDGInstance(m0=2.2))
    again = solve(PDGInstance())
    np.testing.assert_array_equal(again.trajectory.x, nominal.trajectory.x)
    np.testing.assert_array_equal(again.trajectory.u, nominal.trajectory.u)


def test_default_solutions_are_within_half_a_percent_of_propellant_of_the_reference():
    from scpformer.problems.pdg6dof.problem import (
        PDGSolverConfig,
        propellant_gap,
        solve_reference,
    )
    from scpformer.problems.pdg6dof.sampling import PDGSampleRanges, sample_instances

    instances = sample_instances(np.random.default_rng(0), 3, PDGSampleRanges.nominal())
    for instance in instances:
        default = solve(instance)
        assert default.status is Status.CONVERGED, default.message
        reference = solve_reference(instance, PDGSolverConfig(), default)
        assert reference.verification.passed
        gap = propellant_gap(instance, default.cost, reference.cost)
        assert gap < 5e-3, (gap, default.cost, reference.cost)


def test_a_run_stopped_by_the_iteration_cap_says_so_and_returns_its_verified_iterate():
    from scpformer.problems.pdg6dof.problem import PDGSolverConfig
    from scpformer.scp.scvx import SCvxParameters

    capped = solve(PDGInstance(), PDGSolverConfig(scvx=SCvxParameters(iter_max=6)))
    assert capped.status is Status.MAX_ITERATIONS
    accepted = [rec for rec in capped.history if rec.accepted]
    assert capped.cost == pytest.approx(accepted[-1].cost)
    assert capped.verification is not None


def test_prox_weight_zero_solves_the_hard_box_subproblem_of_algorithm_1():
    from scpformer.problems.pdg6dof.subproblem import compiled_subproblem

    hard = compiled_subproblem(50, False, 0.0)
    soft = compiled_subproblem(50, False, 0.01)
    assert not hard.soft and soft.soft

    def objective_parameters(sub):
        return {p.name() for p in sub.problem.objective.parameters()}

    assert objective_parameters(hard) == {"lambda"}  # -m_N + lambda (|nu|_1 + sum s), Eq. 7
    assert {"w_x", "w_u", "w_sigma"} <= objective_parameters(soft)


def test_an_instance_out_of_propellant_stalls_early_without_a_restart():
    # m0 = 2.05 leaves 0.05 U_M of propellant: far too little to land from the nominal state
    sol = solve(PDGInstance(m0=2.05))
    assert sol.status is Status.STALLED
    assert "stalled out of propellant" in sol.message and "lacks the propellant" in sol.message
    assert sol.iterations < 40  # not the 100 of the iteration cap
    assert sol.trajectory is not None and not sol.verification.passed
    assert sol.trajectory.x[-1, 13] == pytest.approx(2.0, abs=1e-6)  # burned to m_dry
    assert "restart" not in sol.extras  # a longer flight would only burn more


def _scripted_first_run(nominal, penalties, iterations):
    """``nominal`` dressed as a first run stopped by the restart's looser stall test: its
    accepted records carry ``penalties``, it used ``iterations`` solves."""
    from dataclasses import replace

    template = next(rec for rec in nominal.history if rec.accepted)
    history = [
        replace(template, iteration=i + 1, accepted=True, penalty=p)
        for i, p in enumerate(penalties)
    ]
    return replace(
        nominal, status=Status.STALLED, message="stalled after", history=history,
        iterations=iterations,
    )  # fmt: skip


def _script_solve_scvx(monkeypatch, first, then):
    """Make the restart logic's ``solve_scvx`` return ``first``, then ``then``; the returned
    list collects each call's ``(guess, params, prior_penalties)``."""
    from scpformer.problems.pdg6dof import restart as pdg

    calls = []

    def scripted(problem, guess, params, eta_init=None, prior_penalties=()):
        calls.append((guess, params, list(prior_penalties)))
        return first if len(calls) == 1 else then

    monkeypatch.setattr(pdg, "solve_scvx", scripted)
    return calls


@pytest.mark.parametrize(
    ("fall", "continued"), [(0.1, True), (0.01, False)], ids=["creeping", "stalled"]
)
def test_a_stopped_first_run_without_budget_for_a_restart(nominal, monkeypatch, fall, continued):
    """Fewer than RESTART_MIN_BUDGET solves left: a run that fell by 10% over the window
    (stopped by the looser test of the first run) continues from its last iterate with the
    solves left; one that fell by 1% (stalled by the configured test) is returned as it is."""
    from scpformer.problems.pdg6dof import restart as pdg
    from scpformer.scp.scvx import SCvxParameters

    window = SCvxParameters().stall_window
    penalties = list(0.2 * (1.0 - fall) ** (np.arange(window + 1) / window))
    iter_max = SCvxParameters().iter_max
    first = _scripted_first_run(nominal, penalties, iter_max - pdg.RESTART_MIN_BUDGET + 1)
    calls = _script_solve_scvx(monkeypatch, first, nominal)
    sol = solve(PDGInstance())
    assert calls[0][1].stall_decrease == pdg.RESTART_DECREASE  # the first run's looser test
    if not continued:
        assert len(calls) == 1  # the first run returned as it is (with its warm-start record)
        assert sol.status is first.status and sol.trajectory is first.trajectory
        assert sol.history is first.history and sol.iterations == first.iterations
        return
    guess, params, prior = calls[1]
    assert guess is first.trajectory  # not a new cubic profile
    assert prior == penalties  # the configured stall test sees the first run's iterations
    assert params.iter_max == pdg.RESTART_MIN_BUDGET - 1
    assert params.stall_decrease == SCvxParameters().stall_decrease  # the configured test
    assert sol.iterations == first.iterations + nominal.iterations
    assert sol.extras["restart"]["tf_guess"] is None


def test_a_creeping_first_run_restarts_from_a_longer_final_time(nominal, monkeypatch):
    from scpformer.problems.pdg6dof import restart as pdg

    penalties = list(np.linspace(0.2, 0.19, 16))  # 5% over the window: slow, not stalled
    first = _scripted_first_run(nominal, penalties, 30)
    calls = _script_solve_scvx(monkeypatch, first, nominal)
    sol = solve(PDGInstance())
    guess, params, _ = calls[1]
    tf_first = float(first.trajectory.p[0])
    assert float(guess.p[0]) == pytest.approx(pdg.RESTART_TF_FACTOR * tf_first)
    assert params.iter_max == 100 - 30
    assert sol.status is nominal.status and sol.extras["restart"]["after"] == 30
