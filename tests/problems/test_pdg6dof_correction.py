"""The least-change second-order correction of the 6-DoF problem (slow: solves once)."""

import numpy as np
import pytest

from scpformer.problems.pdg6dof import constraints as con
from scpformer.problems.pdg6dof.correction import LeastChangeCorrection
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.problem import (
    LEAST_CHANGE,
    PDGProblem,
    PDGSolverConfig,
    propagate,
    propellant_gap,
    solve,
)
from scpformer.problems.pdg6dof.sampling import PDGSampleRanges, sample_instances
from scpformer.problems.pdg6dof.subproblem import fixed_terminal_columns
from scpformer.scp.scvx import Candidate, SCvxParameters
from scpformer.scp.solution import Status, Trajectory

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def optimum():
    solution = solve(PDGInstance())
    assert solution.status is Status.CONVERGED, solution.message
    return solution


def _perturbed(z: Trajectory, size: float, seed: int = 0) -> Trajectory:
    """``z`` with its thrust and final time moved by ``size`` of their trust-region scales
    (states unchanged): an iterate whose defects are O(size)."""
    rng = np.random.default_rng(seed)
    u = z.u + size * 0.25 * 5.0 * rng.standard_normal(z.u.shape)
    return Trajectory(x=z.x.copy(), u=u, p=z.p + size * 0.5)


def _values(z: Trajectory) -> np.ndarray:
    return con.constraint_values(PDGInstance(), z.x, z.u)


def _defects(problem: PDGProblem, z: Trajectory) -> np.ndarray:
    return problem.evaluate(z).linearization.defects(z.x)


@pytest.mark.parametrize("size", [1e-2, 3e-3])
def test_one_step_leaves_defects_of_second_order(optimum, size):
    problem = PDGProblem(PDGInstance(), PDGSolverConfig())
    z = _perturbed(optimum.trajectory, size)
    d0 = np.abs(_defects(problem, z)).max()
    correction = LeastChangeCorrection(
        problem.instance, problem.evaluate(z).linearization, z, False, 1e-5
    )
    corrected = correction.step(z, _defects(problem, z), _values(z))
    d1 = np.abs(_defects(problem, corrected)).max()
    # Newton on the defects: the residual is O(d0^2), far below d0 (measured ~1e-3 d0)
    assert d1 < 0.05 * d0, (d0, d1)
    again = correction.step(corrected, _defects(problem, corrected), _values(corrected))
    assert np.abs(_defects(problem, again)).max() < d1


def test_the_boundary_conditions_and_the_held_rows_are_kept(optimum):
    instance = PDGInstance()
    problem = PDGProblem(instance, PDGSolverConfig())
    z = _perturbed(optimum.trajectory, 1e-2)
    held = con.constraint_values(instance, z.x, z.u) >= -1e-5
    correction = LeastChangeCorrection(instance, problem.evaluate(z).linearization, z, False, 1e-5)
    corrected = correction.step(z, _defects(problem, z), _values(z))
    np.testing.assert_allclose(corrected.x[0], z.x[0], atol=1e-12)
    last = fixed_terminal_columns(False)
    np.testing.assert_allclose(corrected.x[-1, last], z.x[-1, last], atol=1e-12)
    before = np.abs(con.constraint_values(instance, z.x, z.u)[held]).max()
    after = np.abs(con.constraint_values(instance, corrected.x, corrected.u)[held]).max()
    assert after < 1e-2 * before, (before, after)  # held at g = 0 up to second order
    assert np.abs(corrected.u - z.u).max() > 1e-6  # the thrust did move


def test_a_correction_that_breaks_a_convex_row_is_refused(optimum):
    instance = PDGInstance()
    problem = PDGProblem(instance, PDGSolverConfig())
    z = optimum.trajectory
    correction = LeastChangeCorrection(instance, problem.evaluate(z).linearization, z, False, 1e-5)
    assert correction.keeps_convex_rows(z, _values(z))
    peak = np.linalg.norm(z.u, axis=1).max()
    too_much = Trajectory(x=z.x, u=z.u * 1.2 * instance.constants.T_max / peak, p=z.p)
    assert not correction.keeps_convex_rows(too_much, _values(too_much))  # thrust above T_max


def test_least_change_corrections_replace_conic_solves_at_the_same_optimum():
    # the third nominal instance of seed 0: the default run needs corrections (bench pdg6dof)
    instance = sample_instances(np.random.default_rng(0), 3, PDGSampleRanges.nominal())[2]
    on = solve(instance)
    off = solve(instance, PDGSolverConfig(least_change_correction=False))
    assert on.status is Status.CONVERGED and off.status is Status.CONVERGED
    used = [rec for rec in on.history if rec.solver_status == LEAST_CHANGE]
    assert used and all(rec.accepted and rec.time_solver == 0.0 for rec in used)
    assert on.iterations - len(used) < off.iterations  # fewer conic solves
    assert abs(propellant_gap(instance, on.cost, off.cost)) < 1e-3


def test_the_dynamics_rows_are_eq10_at_the_candidate(optimum):
    from scpformer.problems.pdg6dof.correction import _dynamics_rows

    problem = PDGProblem(PDGInstance(), PDGSolverConfig())
    disc = problem.evaluate(_perturbed(optimum.trajectory, 1e-2)).linearization
    n = optimum.trajectory.x.shape[0]
    rng = np.random.default_rng(1)
    dx, du, ds = rng.normal(size=(n, 14)), rng.normal(size=(n, 3)), rng.normal()
    change = np.concatenate([dx.ravel(), du.ravel(), [ds]])
    expected = dx[1:] - (
        np.einsum("kij,kj->ki", disc.A, dx[:-1])
        + np.einsum("kij,kj->ki", disc.Bm, du[:-1])
        + np.einsum("kij,kj->ki", disc.Bp, du[1:])
        + disc.S * ds
    )
    rows = _dynamics_rows(disc, optimum.trajectory.x)
    np.testing.assert_allclose((rows @ change).reshape(n - 1, 14), expected, atol=1e-12)


def test_with_the_hard_box_a_least_change_step_stays_inside_the_box():
    # Algorithm 1's hard box (no soft term): its steps end on the box, and a correction that
    # would leave it is refused for the conic one, which keeps the box (polish off: it
    # removes the defects that call for these corrections)
    instance = sample_instances(np.random.default_rng(0), 1, PDGSampleRanges.nominal())[0]
    config = PDGSolverConfig(prox_weight=0.0, scvx=SCvxParameters(polish=False))
    solution = solve(instance, config)
    used = [rec for rec in solution.history if rec.solver_status == LEAST_CHANGE]
    assert used
    assert all(rec.step_norm <= rec.trust_radius * (1.0 + 1e-9) for rec in used)


@pytest.mark.parametrize("size", [3e-3, 1e-3])
def test_polish_moves_an_iterate_onto_the_nonlinear_flow(optimum, size):
    instance = PDGInstance()
    config = PDGSolverConfig()
    problem = PDGProblem(instance, config)
    z0 = optimum.trajectory  # a step of the final time alone: defects O(size), no row broken
    z = Trajectory(x=z0.x.copy(), u=z0.u.copy(), p=z0.p + size * 0.5)
    conic = Candidate(z, -2.0, 0.0, 0.0, "optimal", 0.02, True)
    polished = problem.polish(conic, problem.evaluate(z))
    assert polished is not None and polished.solver_time == 0.0  # no conic solve
    assert polished.linear_cost == conic.linear_cost
    z1 = polished.trajectory
    before = np.abs(problem.flow_defects(z)).max()
    assert np.abs(problem.flow_defects(z1)).max() <= 0.1 * config.scvx.defect_tol < before
    # an independent check: DOP853 from x_0 under z1's controls lands on z1's nodes
    np.testing.assert_allclose(propagate(instance, z1), z1.x, atol=50 * config.scvx.defect_tol)
    np.testing.assert_allclose(z1.x[0], z.x[0], atol=1e-12)
    last = fixed_terminal_columns(False)
    np.testing.assert_allclose(z1.x[-1, last], z.x[-1, last], atol=1e-12)
    values = con.constraint_values(instance, z1.x, z1.u)
    assert values[list(con.CONVEX_ROWS)].max() <= 1e-7


def test_a_polish_that_would_break_a_convex_row_is_refused(optimum):
    # thrust pushed past T_max at most nodes: holding those rows at g = 0 alone is not
    # enough once the step is this large, and polish refuses rather than return it
    problem = PDGProblem(PDGInstance(), PDGSolverConfig())
    z = _perturbed(optimum.trajectory, 0.3, seed=3)
    conic = Candidate(z, -2.0, 0.0, 0.0, "optimal", 0.02, True)
    assert problem.polish(conic, problem.evaluate(z)) is None
