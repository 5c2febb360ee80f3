"""The least-change second-order correction of the 6-DoF problem (slow: solves once)."""

import numpy as np
import pytest

from scpformer.problems.pdg6dof import constraints as con
from scpformer.problems.pdg6dof.correction import LeastChangeCorrection
from scpformer.problems.pdg6dof.instance import PDGInstance, SampleRanges, sample_instances
from scpformer.problems.pdg6dof.problem import (
    LEAST_CHANGE,
    PDGProblem,
    PDGSolverConfig,
    propellant_gap,
    solve,
)
from scpformer.problems.pdg6dof.subproblem import fixed_terminal_columns
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
    instance = sample_instances(np.random.default_rng(0), 3, SampleRanges.nominal())[2]
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
    # would leave it is refused for the conic one, which keeps the box
    instance = sample_instances(np.random.default_rng(0), 1, SampleRanges.nominal())[0]
    solution = solve(instance, PDGSolverConfig(prox_weight=0.0))
    used = [rec for rec in solution.history if rec.solver_status == LEAST_CHANGE]
    assert used
    assert all(rec.step_norm <= rec.trust_radius * (1.0 + 1e-9) for rec in used)
