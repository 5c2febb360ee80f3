"""The reduced 6-DoF subproblem: conic rows of each (name, node) row, and the full-rows solve."""

import numpy as np
import pytest
import scipy.sparse as sp

from scpformer.problems.pdg6dof import constraints as con
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.problem import (
    SOFT_BOX_FACTOR,
    PDGProblem,
    PDGSolverConfig,
    solve,
)
from scpformer.problems.pdg6dof.reduced import VIRTUAL_NEEDED, ReducedSubproblem
from scpformer.problems.pdg6dof.subproblem import MASS_QUADRATURE
from scpformer.scp.solution import Trajectory

N = 50


@pytest.fixture(scope="module")
def linearized():
    """A subproblem linearized about a perturbed straight-line guess, trust radius 2."""
    instance = PDGInstance()
    problem = PDGProblem(instance, PDGSolverConfig())
    guess = problem.initial_guess()
    rng = np.random.default_rng(3)
    u = guess.u + rng.normal(scale=0.3, size=guess.u.shape)
    x = guess.x + rng.normal(scale=0.05, size=guess.x.shape)
    x[:, 6:10] /= np.linalg.norm(x[:, 6:10], axis=1, keepdims=True)
    z = Trajectory(x=x, u=u, p=guess.p)
    evaluation = problem.evaluate(z)
    eta, weight = 2.0, problem.config.prox_weight / 4.0
    sub = problem.subproblem
    sub.set_instance(instance)
    sub.set_linearization(evaluation.linearization, z.x, z.u, float(z.p[0]))
    sub.set_trust_region(eta, 10.0, SOFT_BOX_FACTOR * eta, weight)
    return problem, z, evaluation, ReducedSubproblem(sub)


def _conic_point(reduced, data, z):
    """Conic primal vector of (x, u, t_f) with every norm's epigraph variable at its norm."""
    lay = reduced.layout
    point = np.zeros(data["A"].shape[1])
    start = 0
    for i in range(len(reduced.sub.state_groups)):
        offset, shape = lay.variables[f"x{i}"]
        width = shape[1]
        point[offset : offset + z.x.shape[0] * width] = z.x[:, start : start + width].ravel("F")
        start += width
    offset, _ = lay.variables["u"]
    point[offset : offset + z.u.size] = z.u.ravel("F")
    point[lay.variables["sigma"][0]] = z.p[0]
    A = data["A"].tocsr()
    slack = data["b"] - A @ point
    first = lay.n_zero + lay.n_nonneg + np.concatenate([[0], np.cumsum(lay.soc_sizes)])
    for row, size in zip(first[:-1], lay.soc_sizes, strict=True):
        (column,) = A[[row]].indices  # the first row of |v| <= t holds t alone
        point[column] = np.linalg.norm(slack[row + 1 : row + size]) / abs(A[row, column])
    return point


def test_each_name_node_row_maps_to_the_conic_rows_of_that_constraint_at_that_node(linearized):
    # Linearized about z and evaluated at z, the slack b - A x of the nonnegative row of
    # (name, k) is -g(name, k) exactly (thrust_min: the linearization is exact at u_ref).
    problem, z, _, reduced = linearized
    data = reduced.conic_data()
    slack = data["b"] - data["A"].tocsr() @ _conic_point(reduced, data, z)
    lay = reduced.layout
    values = con.constraint_values(problem.instance, z.x, z.u).reshape(-1)
    for flag, (name, node) in enumerate(con.constraint_index(N)):
        rows = lay.rows_of(flag)
        nonneg = rows[(rows >= lay.n_zero) & (rows < lay.n_zero + lay.n_nonneg)]
        assert nonneg.size == 1, (name, node)
        assert slack[nonneg[0]] == pytest.approx(-values[flag], abs=1e-9), (name, node)
        cone_rows = rows.size - 1  # the thrust cone is the mass row's too: owned by no flag
        assert cone_rows == {"glideslope": 3, "tilt": 3, "omega": 4}.get(name, 0)


def test_the_layouts_parameter_map_gives_cvxpys_conic_data_of_the_subproblem(linearized):
    reduced = linearized[3]
    data = reduced.conic_data()
    data_map = reduced.layout.data_map
    P, c, A, b = data_map.values()
    rows = np.ones(data_map.n_rows, dtype=bool)
    columns = np.ones(data_map.n_columns, dtype=bool)
    np.testing.assert_array_equal(c, data["c"])
    np.testing.assert_array_equal(b, data["b"])
    assert (data_map.A.submatrix(A, rows, columns) != sp.csc_array(data["A"])).nnz == 0
    expected_P = sp.triu(sp.csc_array(data["P"])).tocsc()
    assert (data_map.P.submatrix(P, columns, columns) != expected_P).nnz == 0


def test_the_thrust_cone_shared_with_the_mass_row_is_kept_with_no_flag(linearized):
    # cvxpy canonicalizes |U_k| once for thrust_max, gimbal and the end points of Eq. 4a's
    # quadrature: without that cone the mass row's epigraph variable would be free, so it
    # belongs to no (name, node) row and stays in every reduced problem.
    lay = linearized[3].layout
    first = lay.n_zero + lay.n_nonneg + np.concatenate([[0], np.cumsum(lay.soc_sizes)])
    A = linearized[3].conic_data()["A"].tocsr()
    u_offset, _ = lay.variables["u"]
    u_columns = set(range(u_offset, u_offset + 3 * N))
    thrust_cones = [
        row
        for row, size in zip(first[:-1], lay.soc_sizes, strict=True)
        if size == 4
        and set(A[row + 1 : row + 4].indices) <= u_columns
        and len(set(A[row + 1 : row + 4].indices)) == 3
    ]  # |v| <= t with v = U_k itself (one column per row), not a quadrature point
    assert len(thrust_cones) == N
    kept = lay.kept_rows(np.zeros(7 * N, dtype=bool), keep_box=False)
    assert all(kept[row : row + 4].all() for row in thrust_cones)


def test_reduced_solve_with_every_row_equals_the_full_subproblem(linearized):
    problem, z, evaluation, reduced = linearized
    full = problem.solve_subproblem(z, evaluation, 2.0, 10.0, "clarabel")
    sol = reduced.solve(np.ones(7 * N, dtype=bool), 10.0, keep_box=True)
    assert sol.status == "optimal"
    np.testing.assert_allclose(sol.x, full.trajectory.x, atol=1e-6)
    np.testing.assert_allclose(sol.u, full.trajectory.u, atol=1e-6)
    assert sol.sigma == pytest.approx(full.trajectory.p[0], abs=1e-6)
    assert sol.cost == pytest.approx(full.linear_cost, abs=1e-6)
    assert reduced.last_size.rows == reduced.layout.n_rows


def test_leaving_rows_out_gives_fewer_rows_cones_and_columns(linearized):
    reduced = linearized[3]
    reduced.solve(np.ones(7 * N, dtype=bool), 10.0)
    full = reduced.last_size
    keep = np.zeros(7 * N, dtype=bool)
    keep[:N] = True  # the mass rows only
    sol = reduced.solve(keep, 10.0, keep_box=False)
    assert sol.status == "optimal"
    small = reduced.last_size
    interior = len(MASS_QUADRATURE[0]) - 2  # Eq. 4a's norms between the nodes, per interval
    mass_row_cones = interior * (N - 1) + N  # and |U_k| at the nodes, kept in every solve
    assert small.cones == mass_row_cones < full.cones
    assert small.rows < full.rows - 6 * N - 700  # rows, cones and the safeguard box
    assert small.columns == full.columns - 3 * N  # the other three norms' epigraph variables


@pytest.fixture(scope="module")
def at_optimum():
    """The subproblem about a converged solution (its virtual control vanishes), radius 5."""
    instance = PDGInstance()
    problem = PDGProblem(instance, PDGSolverConfig())
    z = solve(instance).trajectory
    evaluation = problem.evaluate(z)
    eta = 5.0
    weight, box = problem.trust_region(eta)
    sub = problem.subproblem

    def linearized(lambda_: float) -> ReducedSubproblem:
        sub.set_instance(instance)
        sub.set_linearization(evaluation.linearization, z.x, z.u, float(z.p[0]))
        sub.set_trust_region(eta, lambda_, box, weight)
        return reduced

    reduced = ReducedSubproblem(sub)
    return linearized


@pytest.mark.slow
def test_without_nu_the_solve_matches_the_one_with_nu_on_half_the_columns(at_optimum):
    reduced = at_optimum(2.0)
    keep = np.ones(7 * N, dtype=bool)
    with_nu = reduced.solve(keep, 2.0)
    full_size = reduced.last_size
    without = reduced.solve(keep, 2.0, keep_box=False, keep_virtual=False)
    small = reduced.last_size
    assert with_nu.status == without.status == "optimal"
    assert np.abs(with_nu.nu).sum() < 1e-6  # nu = 0 is the optimum: the two must agree
    np.testing.assert_allclose(without.x, with_nu.x, atol=1e-4)
    np.testing.assert_allclose(without.u, with_nu.u, atol=1e-4)
    assert without.cost == pytest.approx(with_nu.cost, abs=1e-6)
    assert not without.nu.any()
    n_nu = 14 * (N - 1)
    assert small.columns == full_size.columns - 2 * n_nu  # nu and its |nu| epigraph
    assert small.rows < full_size.rows - 2 * n_nu  # the epigraph rows (and the box)


@pytest.mark.slow
def test_without_nu_a_penalty_below_the_multipliers_asks_for_nu(at_optimum):
    # The dynamics multipliers are about 1 (the final-mass row's); with lambda = 0.3 the
    # penalty is not exact and the optimum with nu uses it, so the solve without nu must
    # not pass for it.
    reduced = at_optimum(0.3)
    keep = np.ones(7 * N, dtype=bool)
    assert np.abs(reduced.solve(keep, 0.3).nu).sum() > 1.0
    without = reduced.solve(keep, 0.3, keep_box=False, keep_virtual=False)
    assert without.status == VIRTUAL_NEEDED and without.x is None
