"""The shared conic-solve layer: primal values read from the solver's vector."""

import cvxpy as cp
import numpy as np
import pytest

from scpformer.scp.conic import SOLVERS, assign, solve_timed, variable_slices


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
