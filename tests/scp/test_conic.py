"""The shared conic-solve layer: primal values read from the solver's vector."""

import cvxpy as cp
import numpy as np
import pytest
import scipy.sparse as sp

from scpformer.scp.conic import (
    SOLVERS,
    ConicDataMap,
    assign,
    clarabel_inputs,
    solve_timed,
    variable_slices,
)


def _parametric_problem() -> tuple[cp.Problem, dict[str, cp.Variable], cp.Parameter]:
    """A small DPP problem with a matrix variable, a nonneg variable (which cvxpy replaces by
    a free copy) and a scalar, so that the offsets are not trivial."""
    X = cp.Variable((3, 2), name="X")
    s = cp.Variable(4, nonneg=True, name="s")
    t = cp.Variable(name="t")
    target = cp.Parameter((3, 2), name="target")
    cost = cp.sum_squares(X - target) + cp.sum(s) + t
    constraints = [cp.norm(X[:, 0], 2) <= t, s >= X[0, 0] - X[1:, 1].sum(), t <= 5.0]
    return cp.Problem(cp.Minimize(cost), constraints), {"X": X, "s": s, "t": t}, target


@pytest.mark.parametrize("solver", sorted(SOLVERS))
def test_primal_values_from_the_conic_vector_equal_cvxpys_unpacking(solver):
    problem, variables, target = _parametric_problem()
    slices = variable_slices(problem, solver, variables)
    for seed in range(3):  # the slices hold for every parameter value
        target.value = np.random.default_rng(seed).normal(size=(3, 2))
        unpacked = solve_timed(problem, solver)
        assert unpacked.solved and unpacked.values == {}
        expected = {name: np.array(var.value) for name, var in variables.items()}
        for var in variables.values():
            var.value = None
        direct = solve_timed(problem, solver, primal=slices)
        assert direct.solved
        assert all(var.value is None for var in variables.values())  # nothing unpacked
        assert set(direct.values) == set(variables)
        for name, value in expected.items():
            np.testing.assert_array_equal(direct.values[name], value)


@pytest.mark.parametrize("solver", sorted(SOLVERS))
def test_an_infeasible_problem_reads_no_primal_values(solver):
    x = cp.Variable(2, name="x")
    problem = cp.Problem(cp.Minimize(cp.sum(x)), [x >= 1.0, x <= 0.0])
    call = solve_timed(problem, solver, primal=variable_slices(problem, solver, {"x": x}))
    assert not call.solved and call.values == {}
    if solver != "qoco":  # QOCO has no infeasibility detection: it reports a solver error
        assert call.status.startswith("infeasible")


def test_assign_gives_the_solve_that_cvxpys_setter_gives():
    problem, variables, target = _parametric_problem()
    value = np.random.default_rng(7).normal(size=(3, 2))
    target.value = value
    expected = solve_timed(problem, "clarabel")
    x_set = np.array(variables["X"].value)
    assign(target, value.tolist())  # any array-like; stored as a float array
    assert isinstance(target.value, np.ndarray) and target.value.dtype == float
    assert solve_timed(problem, "clarabel").status == expected.status
    np.testing.assert_array_equal(variables["X"].value, x_set)


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (np.zeros(3), r"'r': shape \(3,\), expected \(\)"),
        (np.nan, "'r': value contains NaN"),
        (-1e-9, "'r' is nonneg"),
    ],
)
def test_assign_rejects_what_the_subproblem_cannot_take_and_keeps_the_old_value(value, message):
    radius = cp.Parameter(nonneg=True, name="r")
    assign(radius, 2.0)
    with pytest.raises(ValueError, match=message):
        assign(radius, value)
    assert radius.value == 2.0


def _problem_with_parameters_everywhere() -> tuple[cp.Problem, list[cp.Parameter]]:
    """Parameters in the quadratic weight (P), in the constraint matrix (A), the offsets (b)
    and the linear cost (c), with a second-order cone."""
    x = cp.Variable(4, name="x")
    t = cp.Variable(name="t")
    w = cp.Parameter(nonneg=True, name="w")
    M = cp.Parameter((2, 4), name="M")
    h = cp.Parameter(2, name="h")
    g = cp.Parameter(4, name="g")
    cost = w * cp.sum_squares(x) + g @ x + t
    constraints = [M @ x == h, cp.norm(x[:3], 2) <= t, x[3] >= -h[0], t <= 10.0]
    return cp.Problem(cp.Minimize(cost), constraints), [w, M, h, g]


def test_the_conic_data_map_writes_the_numbers_cvxpys_parameter_map_writes():
    problem, parameters = _problem_with_parameters_everywhere()
    rng = np.random.default_rng(0)
    data_map = None
    for _ in range(3):  # one map, several parameter values
        for p in parameters:
            p.value = (
                np.abs(rng.normal(size=p.shape)) if p.is_nonneg() else rng.normal(size=p.shape)
            )
        data, _, _ = problem.get_problem_data(cp.CLARABEL, solver_opts={})
        data_map = data_map or ConicDataMap(problem)
        P, c, A, b = data_map.values()
        every_row = np.ones(data_map.n_rows, dtype=bool)
        every_column = np.ones(data_map.n_columns, dtype=bool)
        np.testing.assert_array_equal(c, data["c"])
        np.testing.assert_array_equal(b, data["b"])
        expected_A = sp.csc_array(data["A"]).toarray()
        np.testing.assert_array_equal(
            data_map.A.submatrix(A, every_row, every_column).toarray(), expected_A
        )
        expected_P = sp.triu(sp.csc_array(data["P"])).toarray()
        np.testing.assert_array_equal(
            data_map.P.submatrix(P, every_column, every_column).toarray(), expected_P
        )


def test_a_submatrix_of_the_map_equals_scipys_slice():
    problem, parameters = _problem_with_parameters_everywhere()
    rng = np.random.default_rng(1)
    for p in parameters:
        p.value = np.abs(rng.normal(size=p.shape)) if p.is_nonneg() else rng.normal(size=p.shape)
    data, _, _ = problem.get_problem_data(cp.CLARABEL, solver_opts={})
    data_map = ConicDataMap(problem)
    _, _, A, _ = data_map.values()
    rows = rng.random(data_map.n_rows) < 0.6
    columns = rng.random(data_map.n_columns) < 0.6
    sub = data_map.A.submatrix(A, rows, columns)
    expected = sp.csc_array(data["A"]).toarray()[rows][:, columns]
    assert sub.shape == expected.shape and sub.has_sorted_indices
    np.testing.assert_array_equal(sub.toarray(), expected)


def test_the_conic_data_map_names_a_parameter_without_a_value():
    problem, parameters = _problem_with_parameters_everywhere()
    for p in parameters:
        p.value = np.ones(p.shape)
    data_map = ConicDataMap(problem)
    parameters[2].value = None  # h
    with pytest.raises(ValueError, match="parameter 'h' has no value"):
        data_map.values()


def test_clarabel_reads_the_list_inputs_as_the_scipy_ones_in_setup_and_update():
    """:func:`clarabel_inputs` hands Clarabel the same problem: the same iterates to the
    last bit, whether a solver is built from them or updated with them."""
    import clarabel

    problem, parameters = _problem_with_parameters_everywhere()
    rng = np.random.default_rng(2)
    data_map = None
    results = []
    for _ in range(2):
        for p in parameters:
            p.value = (
                np.abs(rng.normal(size=p.shape)) if p.is_nonneg() else rng.normal(size=p.shape)
            )
        data, _, _ = problem.get_problem_data(cp.CLARABEL, solver_opts={})
        data_map = data_map or ConicDataMap(problem)
        dims = data["dims"]
        cones = [clarabel.ZeroConeT(dims.zero), clarabel.NonnegativeConeT(dims.nonneg)]
        cones += [clarabel.SecondOrderConeT(int(size)) for size in dims.soc]
        P = sp.triu(sp.csc_array(data["P"])).tocsc()
        scipy_inputs = (P, data["c"], sp.csc_array(data["A"]), data["b"])
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        built = [
            clarabel.DefaultSolver(*inputs, cones, settings)
            for inputs in (scipy_inputs, clarabel_inputs(*scipy_inputs))
        ]
        results.append([solver.solve() for solver in built])
        if len(results) == 1:
            first = built
        else:  # the solvers of the first values, updated with the second's
            first[0].update(P=P, q=data["c"], A=scipy_inputs[2], b=data["b"])
            as_lists = clarabel_inputs(*scipy_inputs)
            first[1].update(P=as_lists[0], q=as_lists[1], A=as_lists[2], b=as_lists[3])
            results.append([solver.solve() for solver in first])
    for from_scipy, from_lists in results:
        assert str(from_scipy.status) == str(from_lists.status) == "Solved"
        assert from_scipy.iterations == from_lists.iterations
        np.testing.assert_array_equal(np.asarray(from_scipy.x), np.asarray(from_lists.x))
    updated, fresh = np.asarray(results[2][0].x), np.asarray(results[1][0].x)
    np.testing.assert_allclose(updated, fresh, rtol=1e-5, atol=1e-6)  # the update took
    assert np.abs(updated - np.asarray(results[0][0].x)).max() > 1e-2
