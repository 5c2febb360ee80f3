"""Tests of SCvx* (scpformer.scp.scvx_star) on a small non-convex problem with a known optimum.

The problem
-----------
``min f0(z) = z_1`` over ``z in R^2`` subject to

* ``g(z) = |z|^2 - 4 = 0``                (stay on the circle of radius 2, non-convex), and
* ``h(z) = 1 - |z - c|^2 <= 0``, ``c = (-2, 0)`` (keep out of the unit disc at ``c``).

Without the keep-out zone the optimum is ``(-2, 0)``, which lies inside it; the optimum is
therefore where the circle leaves the disc: ``x^2 + y^2 = 4`` and ``(x + 2)^2 + y^2 = 1`` give
``4 + 4x + 4 = 1``, ``x = -7/4``, ``y = +-sqrt(15)/4``; from the upper half plane the solution
is ``z* = (-7/4, sqrt(15)/4)`` with ``f0* = -7/4``. The KKT conditions
``grad f0 + lambda grad g + mu grad h = 0`` read ``1 - 3.5 lambda - 0.5 mu = 0`` and
``sqrt(15)/2 (lambda - mu) = 0``, so ``lambda* = mu* = 1/4`` (``mu* >= 0``: both constraints
active). SCvx* must reach z* from an infeasible guess, with multipliers tending to 1/4.
"""

from __future__ import annotations

import dataclasses
import itertools
import time
from dataclasses import replace

import cvxpy as cp
import numpy as np
import pytest

from scpformer.scp.scvx_star import (
    NonlinearEvaluation,
    PenaltyTerm,
    SCvxStar,
    SCvxStarParameters,
    SubproblemResult,
    feasibility,
    next_delta,
    penalty,
    update_multipliers,
    update_trust_radius,
)
from scpformer.scp.solution import Status, Trajectory, Verification

Z_STAR = np.array([-1.75, np.sqrt(15.0) / 4.0])
CENTER = np.array([-2.0, 0.0])
GUESS = np.array([0.5, 2.5])  # infeasible: |z| = 2.55, outside the circle
# Table 1 except r^(0), which is in ROE metres; Oguri's trust-region rule, as published
PARAMS = SCvxStarParameters(r_init=0.5, shrink_from_step=False)


def _point(z: np.ndarray) -> Trajectory:
    return Trajectory(x=np.asarray(z, dtype=float).reshape(1, 2), u=np.zeros((1, 0)), p=np.zeros(0))


class CircleProblem:
    """The problem of the module docstring; its subproblem is compiled once (DPP)."""

    def __init__(self, contradictory: bool = False) -> None:
        self.term = PenaltyTerm(n_g=1, n_h=1)
        self.z = cp.Variable(2, name="z")
        self.z_ref = cp.Parameter(2, name="z_ref")
        self.G, self.g0 = cp.Parameter(2, name="G"), cp.Parameter(1, name="g0")
        self.H, self.h0 = cp.Parameter(2, name="H"), cp.Parameter(1, name="h0")
        constraints = [
            self.g0 + self.G @ self.z == self.term.xi,  # g_bar + G (z - z_bar), g0 absorbs G z_bar
            self.h0 + self.H @ self.z <= self.term.zeta,
            cp.norm(self.z - self.z_ref, "inf") <= self.term.r,
        ]
        if contradictory:  # a convex constraint set Z that is empty: the conic solve fails
            constraints += [self.z[0] >= 5.0, self.z[0] <= 3.0]
        self.problem = cp.Problem(cp.Minimize(self.z[0] + self.term.expression), constraints)
        self.solves = 0

    def evaluate(self, z: Trajectory) -> NonlinearEvaluation:
        t0, p = time.perf_counter(), z.x[0]
        g, h = np.array([p @ p - 4.0]), np.array([1.0 - (p - CENTER) @ (p - CENTER)])
        grads = (2.0 * p, -2.0 * (p - CENTER))
        return NonlinearEvaluation(float(p[0]), g, h, grads, time=time.perf_counter() - t0)

    def solve_subproblem(self, z, evaluation, *, lambda_, mu, w, r, solver):
        p, (G, H) = z.x[0], evaluation.linearization
        self.z_ref.value, self.G.value, self.H.value = p, G, H
        self.g0.value, self.h0.value = evaluation.g - G @ p, evaluation.h - H @ p
        self.term.assign(lambda_=lambda_, mu=mu, w=w, r=r)
        self.problem.solve(solver=solver.upper())
        self.solves += 1
        stats = self.problem.solver_stats
        if self.problem.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE):
            return SubproblemResult(False, self.problem.status, None, np.nan, None, None, np.nan, 0)
        xi, zeta = self.term.buffers()
        return SubproblemResult(
            ok=True,
            status=self.problem.status,
            z=_point(self.z.value),
            cost=float(self.z.value[0]),
            xi=xi,
            zeta=zeta,
            step_norm=float(np.max(np.abs(self.z.value - p))),
            solver_time=stats.solve_time or 0.0,
        )

    def verify(self, z: Trajectory) -> Verification:
        ev = self.evaluate(z)
        chi = ev.chi
        return Verification(
            passed=chi <= 1e-3,
            terminal_error={},
            max_defect=float(abs(ev.g[0])),
            node_violations={"keep_out": float(ev.h_plus[0])},
            path_violations={},
        )

    def node_times(self, z: Trajectory) -> None:
        return None


@pytest.fixture(scope="module")
def solved():
    problem = CircleProblem()
    return problem, SCvxStar(PARAMS).solve(problem, _point(GUESS))


def test_subproblem_is_dpp_and_compiled_once(solved):
    problem, result = solved
    assert problem.problem.is_dpp()
    assert problem.solves == result.solution.iterations > 1  # one Problem object, re-solved


def test_converges_to_the_analytic_optimum_from_an_infeasible_guess(solved):
    _, result = solved
    sol = result.solution
    assert sol.status is Status.CONVERGED and sol.converged
    np.testing.assert_allclose(sol.trajectory.x[0], Z_STAR, atol=1e-4)
    assert sol.cost == pytest.approx(-1.75, abs=1e-4)
    assert sol.verification.passed and sol.timing.total > 0.0


@pytest.mark.parametrize("r_init", [0.5, 1.0])
def test_the_step_length_contraction_reaches_the_same_analytic_optimum(r_init):
    """The default rule (a rejected step shrinks r from its own length) on the same problem:
    29 solves from r^(0) = 0.5, 8 from 1 (Oguri's rule: 15 and 8)."""
    params = dataclasses.replace(PARAMS, r_init=r_init, shrink_from_step=True, iter_max=40)
    sol = SCvxStar(params).solve(CircleProblem(), _point(GUESS)).solution
    assert sol.converged
    np.testing.assert_allclose(sol.trajectory.x[0], Z_STAR, atol=1e-4)


def test_multiplier_estimate_at_the_solution_is_the_kkt_multipliers(solved):
    """The first-order estimate lambda + w g, max(0, mu + w h) at z* is (1/4, 1/4)."""
    _, result = solved
    st = result.state
    lam, mu = update_multipliers(st.lambda_, st.mu, st.w, st.evaluation.g, st.evaluation.h)
    np.testing.assert_allclose([lam[0], mu[0]], [0.25, 0.25], atol=2e-3)


def test_stops_at_the_first_iteration_meeting_both_tolerances(solved):
    _, result = solved
    met = [abs(s.delta_J) <= PARAMS.eps_opt and s.chi <= PARAMS.eps_feas for s in result.records]
    assert met[-1] and not any(met[:-1])
    assert len(result.records) == len(result.solution.history) == result.solution.iterations


def test_weight_and_delta_change_only_after_a_multiplier_update(solved):
    _, result = solved
    recs = result.records
    assert recs[0].w == PARAMS.w_init and np.isinf(recs[0].delta)
    assert sum(r.multipliers_updated for r in recs) >= 2
    for before, after in itertools.pairwise(recs):
        if before.multipliers_updated:
            assert after.w == min(PARAMS.beta * before.w, PARAMS.w_max)
            expected = abs(before.delta_J) if np.isinf(before.delta) else 0.9 * before.delta
            assert after.delta == pytest.approx(expected)
        else:
            assert (after.w, after.delta) == (before.w, before.delta)


def test_multipliers_are_updated_only_on_accepted_stationary_steps(solved):
    _, result = solved
    for rec, it in zip(result.records, result.solution.history, strict=True):
        if rec.multipliers_updated:
            assert it.accepted and abs(rec.delta_J) < rec.delta


def test_no_multiplier_update_while_the_step_is_not_stationary():
    problem, algorithm = CircleProblem(), SCvxStar(PARAMS)
    state = replace(algorithm.init(problem, _point(GUESS)), delta=1e-9)
    out = algorithm.step(problem, state)
    assert out.record.accepted and abs(out.star.delta_J) > 1e-9
    assert not out.star.multipliers_updated
    assert (out.state.w, out.state.delta) == (PARAMS.w_init, 1e-9)
    assert not np.any(out.state.lambda_) and not np.any(out.state.mu)


def test_feasibility_is_reached_although_the_guess_is_infeasible(solved):
    _, result = solved
    chi = [r.chi for r in result.records]
    assert feasibility(np.array([GUESS @ GUESS - 4.0]), np.zeros(1)) > 0.5
    assert chi[-1] <= PARAMS.eps_feas < chi[0]


def test_iteration_limit_is_a_status():
    result = SCvxStar(SCvxStarParameters(r_init=0.5, iter_max=2)).solve(
        CircleProblem(), _point(GUESS)
    )
    assert result.solution.status is Status.MAX_ITERATIONS
    assert result.solution.iterations == 2 and "2 iterations" in result.solution.message


def test_conic_solver_failure_is_a_status_with_the_reason():
    strict = replace(PARAMS, expand_on_infeasible=False)
    result = SCvxStar(strict).solve(CircleProblem(contradictory=True), _point(GUESS))
    assert result.solution.status is Status.SOLVER_FAILED
    assert "infeasible" in result.solution.message and result.solution.iterations == 0


def test_an_infeasible_subproblem_grows_the_radius_to_r_max_before_failing():
    """Each infeasible solve is a rejected iteration with r grown by alpha_2; a problem that
    stays infeasible at r_max ends as a solver failure with the reason."""
    result = SCvxStar(PARAMS).solve(CircleProblem(contradictory=True), _point(GUESS))
    radii = [r.trust_radius for r in result.solution.history]
    assert result.solution.status is Status.SOLVER_FAILED
    assert "infeasible" in result.solution.message
    assert radii[0] == PARAMS.r_init and not any(r.accepted for r in result.solution.history)
    expected = [min(PARAMS.r_init * PARAMS.alpha_2**k, PARAMS.r_max) for k in range(len(radii))]
    assert radii == pytest.approx(expected) and radii[-1] < PARAMS.r_max


# ----------------------------------------------------------------------------------------
# update rules and parameters
# ----------------------------------------------------------------------------------------
def test_penalty_is_the_augmented_lagrangian_form():
    y, s = np.array([1.0, -2.0]), np.array([0.5])
    value = penalty(y, s, np.array([0.1, 0.2]), np.array([3.0]), 4.0)
    assert value == pytest.approx(0.1 - 0.4 + 1.5 + 2.0 * (5.0 + 0.25))


def test_inequality_multiplier_stays_nonnegative():
    lam, mu = update_multipliers(
        np.array([1.0]), np.array([0.3, 0.3]), 10.0, np.array([-0.5]), np.array([-1.0, 0.02])
    )
    np.testing.assert_allclose(lam, [-4.0])
    np.testing.assert_allclose(mu, [0.0, 0.5])


@pytest.mark.parametrize(
    "rho, r_after, accepted",
    [(-0.5, 0.5, False), (0.1, 0.5, True), (0.5, 1.0, True), (0.7, 3.0, True)],
)
def test_trust_region_update(rho, r_after, accepted):
    assert update_trust_radius(1.0, rho, SCvxStarParameters()) == (r_after, accepted)


def test_a_rejected_step_inside_the_region_shrinks_the_radius_from_its_length():
    p = SCvxStarParameters()
    assert update_trust_radius(100.0, -1.0, p, step_norm=3.0) == (1.5, False)
    assert update_trust_radius(100.0, -1.0, p, step_norm=300.0) == (50.0, False)  # at the edge
    assert update_trust_radius(100.0, 0.1, p, step_norm=3.0) == (50.0, True)  # accepted: Oguri
    oguri = SCvxStarParameters(shrink_from_step=False)
    assert update_trust_radius(100.0, -1.0, oguri, step_norm=3.0) == (50.0, False)


def test_trust_radius_stays_within_bounds():
    p = SCvxStarParameters()
    assert update_trust_radius(p.r_max, 0.99, p)[0] == p.r_max
    assert update_trust_radius(p.r_min, -1.0, p)[0] == p.r_min


def test_delta_starts_at_the_first_improvement_then_decays():
    assert next_delta(np.inf, -0.4, 0.9) == 0.4
    assert next_delta(0.4, 0.01, 0.9) == pytest.approx(0.36)


def test_defaults_are_table_1():
    p = SCvxStarParameters()
    assert (p.eps_opt, p.eps_feas, p.alpha_1, p.alpha_2, p.beta, p.gamma) == (
        1e-3,
        1e-3,
        2.0,
        3.0,
        2.0,
        0.9,
    )
    assert (p.r_min, p.r_max, p.r_init, p.w_init, p.iter_max) == (1e-6, 5e3, 100.0, 10.0, 20)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"eps_opt": 0.0}, "eps_opt"),
        ({"alpha_1": 1.0}, "alpha_1"),
        ({"beta": 0.5}, "beta"),
        ({"gamma": 1.0}, "gamma"),
        ({"rho_1": 0.9}, "rho"),
        ({"r_init": 1e4}, "r_init"),
        ({"w_init": 1e9}, "w_init"),
        ({"iter_max": 0}, "iter_max"),
        ({"solver": "gurobi"}, "solver"),
    ],
)
def test_bad_parameters_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        SCvxStarParameters(**kwargs)
