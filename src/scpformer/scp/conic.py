"""The one place that knows which conic solvers scpformer drives and how a solve is timed.

Every convex subproblem in the package is a parametric ``cvxpy.Problem`` built once and
canonicalized once (DESIGN: "build the convex subproblem once, update numbers in the loop").
This module holds what they share:

* :data:`SOLVERS` -- the supported solver names and their cvxpy constants, with
  :func:`check_solver` giving the one error message for an unknown name;
* :func:`canonicalize` -- run cvxpy's parameter-to-data compilation ahead of the first solve
  (the result is what :func:`scpformer.cache.cached_pickle` keeps on disk);
* :func:`solve_timed` -- cvxpy's three stages run by hand (cached parameter map -> conic solver
  -> unpack, or with :func:`variable_slices` the primal values alone), so that the conic
  solver call is timed on its own with the same clock as the wall time around it; a failing
  solve is a status, never a raise. With ``reuse`` the solver object of the previous call is
  updated in place instead of rebuilt (Clarabel keeps its symbolic KKT factorization and
  equilibration; measured 74 -> 69 ms per 6-DoF subproblem);
  :func:`start_cold` makes the next call build a fresh one, so that every SCP run (every
  instance) starts from the same solver state and gives the same bytes in any process;
* :class:`SubproblemSolution` -- what one subproblem solve returns, the same for every family;
* :class:`ConicDataMap` -- the parameter map of a compiled problem as plain arrays (one
  sparse matrix-vector product per matrix), for callers that hand the conic data to the
  solver themselves (the reduced 6-DoF subproblems of T-SCvx);
* :func:`assign` -- write a parameter's value in the SCP loops with the checks that matter
  (shape, NaN, sign) instead of cvxpy's projection test;
* :func:`batched_matvec` -- ``K`` small matrix-vector products as one affine expression,
  vectorized over the horizon.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, TypeVar

import cvxpy as cp
import numpy as np
import scipy.sparse as sp
from cvxpy.cvxcore.python.canonInterface import get_parameter_vector
from cvxpy.reductions.solvers.conic_solvers.clarabel_conif import CLARABEL
from numpy.typing import ArrayLike

from scpformer.cache import cached_pickle

_Sub = TypeVar("_Sub")

ConicSettings = dict[str, dict[str, Any]]  # solver name -> that solver's settings
SOLVERS: dict[str, str] = {"clarabel": cp.CLARABEL, "ecos": cp.ECOS, "qoco": cp.QOCO}
SOLVED = (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)  # statuses with a usable primal solution
# Settings under which a solver accepts in-place data updates (Clarabel refuses them when its
# presolve or the dropping of structural zeros changed the problem). Neither changes results
# here: no constraint row has an infinite bound and the parametric sparsity is fixed.
REUSE_OPTIONS: dict[str, dict[str, bool]] = {
    "clarabel": {"presolve_enable": False, "input_sparse_dropzeros": False}
}


def check_solver(solver: str, what: str = "solver") -> str:
    """Return ``solver`` if scpformer drives it, else raise ``ValueError`` naming the choices."""
    if solver not in SOLVERS:
        raise ValueError(f"{what} must be one of {', '.join(SOLVERS)}, got {solver!r}")
    return solver


def canonicalize(problem: cp.Problem, solver: str) -> None:
    """Compile ``problem`` for ``solver`` now, so that the first solve only maps parameters."""
    problem.get_problem_data(SOLVERS[check_solver(solver)], solver_opts={})


def compiled(key: str, make: Callable[[], _Sub], solver: str, source: str) -> _Sub:
    """A family's subproblem ``make()`` (an object with a cvxpy ``problem``), canonicalized for
    ``solver`` and kept on disk (:func:`scpformer.cache.cached_pickle`) under ``key``, which
    names the structure and the solver; ``source`` (the family module's file) is digested too,
    so that a change of the module builds it again."""
    check_solver(solver)

    def build() -> _Sub:
        sub = make()
        canonicalize(sub.problem, solver)
        return sub

    return cached_pickle(key, build, source=source)


@dataclass(frozen=True)
class ConicCall:
    """Outcome of one :func:`solve_timed` call.

    ``status`` is cvxpy's status string, or ``"solver_error: ..."`` when the solver raised;
    the solution (in the problem's variables, or in ``values`` when the call asked for the
    primal values alone) is there only when ``solved`` is true.
    """

    status: str
    solver_time: float  # s inside the conic solver call (data in, raw solution out)
    wall_time: float  # s from the parameter values to the unpacked solution
    values: dict[str, np.ndarray] = field(default_factory=dict)  # primal values by name

    @property
    def solved(self) -> bool:
        """Optimal or optimal-inaccurate (the caller flags the latter through ``status``)."""
        return self.status in SOLVED


@dataclass(frozen=True, kw_only=True)
class SubproblemSolution:
    """What one solve of a family's convex subproblem returns, in the family's units.

    ``status`` is cvxpy's status string; the arrays are ``None`` when the solve failed (then
    ``cost`` and ``sigma`` are NaN and ``message`` says why). The 6-DoF subproblem fills
    ``sigma``, ``nu`` and ``buffers``; the rendezvous subproblems leave them unset.
    """

    status: str
    x: np.ndarray | None  # states at the nodes (6-DoF: (N, 14); rendezvous: (N+1, 6) [m])
    u: np.ndarray | None  # (N, 3) controls (6-DoF: thrust; rendezvous: impulses, RTN [m/s])
    cost: float  # objective: 6-DoF the linearized cost L^k (Eq. 13); rendezvous sum_k |u_k|_2
    solver_time: float  # s inside the conic solver call (data in, raw solution out)
    wall_time: float  # s from the parameter values to the unpacked solution
    sigma: float = math.nan  # 6-DoF: time dilation (final time)
    nu: np.ndarray | None = None  # 6-DoF: (N-1, 14) virtual control
    buffers: np.ndarray | None = None  # 6-DoF: (N,) virtual buffers of the thrust lower bound
    message: str = ""

    @property
    def ok(self) -> bool:
        """A usable solution: optimal, or optimal_inaccurate (flagged by ``status``)."""
        return self.status in SOLVED and self.x is not None

    @classmethod
    def failed(cls, status: str, wall_time: float, solver_time: float) -> SubproblemSolution:
        """A solve that returned no solution: no arrays, NaN cost, ``status`` as the message."""
        return cls(
            status=status,
            x=None,
            u=None,
            cost=math.nan,
            solver_time=solver_time,
            wall_time=wall_time,
            message=status,
        )


VariableSlices = Mapping[str, tuple[int, tuple[int, ...]]]  # name -> (offset, shape)


def solve_timed(
    problem: cp.Problem,
    solver: str,
    reuse: bool = False,
    settings: ConicSettings | None = None,
    primal: VariableSlices | None = None,
) -> ConicCall:
    """Solve ``problem`` with its current parameter values and time the solver call alone.

    ``reuse`` updates the solver object of the previous call in place where the solver
    supports it (:data:`REUSE_OPTIONS`); cvxpy rebuilds it when the update is refused.
    ``settings`` maps a solver name to the settings a problem family gives it.

    Without ``primal`` the solution is unpacked into the problem's variables (and duals) as
    ``problem.solve`` does. With the :func:`variable_slices` of ``problem`` only the primal
    values of those variables are read from the solver's vector into ``ConicCall.values``;
    cvxpy's unpacking (the inverse of every reduction, the duals of every constraint) costs
    about 1 ms per 6-DoF subproblem, 2-3% of a solve, and the loops need none of it.
    """
    name = SOLVERS[check_solver(solver)]
    in_place = reuse and solver in REUSE_OPTIONS
    options = solver_options(solver, in_place, settings)
    start = time.perf_counter()
    solver_time = 0.0
    values: dict[str, np.ndarray] = {}
    try:
        with warnings.catch_warnings():  # "inaccurate" is reported as a status instead
            warnings.simplefilter("ignore", UserWarning)
            data, chain, inverse = problem.get_problem_data(name, solver_opts=options)
            t0 = time.perf_counter()
            raw = chain.solve_via_data(problem, data, in_place, False, options)
            solver_time = time.perf_counter() - t0
            if primal is None:
                problem.unpack_results(raw, chain, inverse)
                status = str(problem.status)
            else:
                status, x = primal_solution(chain.solver, raw, inverse[-1])
                if status in SOLVED:
                    values = {key: primal_value(x, primal, key) for key in primal}
    except cp.SolverError as err:
        return ConicCall(f"solver_error: {err}", solver_time, time.perf_counter() - start)
    return ConicCall(status, solver_time, time.perf_counter() - start, values)


def variable_slices(
    problem: cp.Problem, solver: str, variables: Mapping[str, cp.Variable]
) -> VariableSlices:
    """Where each of ``variables`` sits in the primal vector of ``problem``'s conic form.

    Read from cvxpy's matrix stuffing (its ``var_offsets``); matched by variable name because
    cvxpy replaces a variable with attributes (``nonneg``) by a free copy of the same name.
    The names must be unique within the problem.
    """
    _, _, inverse = problem.get_problem_data(SOLVERS[check_solver(solver)], solver_opts={})
    stuffing = next(d for d in inverse if hasattr(d, "var_offsets") and hasattr(d, "minimize"))
    offsets = {var.name(): stuffing.var_offsets[vid] for vid, var in stuffing.id2var.items()}
    return {key: (offsets[var.name()], var.shape) for key, var in variables.items()}


def primal_solution(solver: Any, raw: Any, inverse_data: Any) -> tuple[str, np.ndarray | None]:
    """cvxpy's status and the stuffed primal vector of a raw solver result, nothing else.

    For Clarabel they are read from its result (``status``, ``x``) through cvxpy's own status
    map; cvxpy's ``invert`` would also split ``z`` into a dual value per constraint, about
    0.5 ms per 6-DoF subproblem that no loop uses. Other solvers go through ``invert``.
    """
    if solver.name() == cp.CLARABEL:
        return clarabel_status(raw), raw.x
    solution = solver.invert(raw, inverse_data)
    if solution.status not in SOLVED:
        return str(solution.status), None
    (x,) = solution.primal_vars.values()
    return str(solution.status), x


def clarabel_status(result: Any) -> str:
    """cvxpy's status string for a Clarabel result (``SOLVER_ERROR`` for an unknown one)."""
    return CLARABEL.STATUS_MAP.get(str(result.status), cp.SOLVER_ERROR)


@dataclass(frozen=True)
class ClarabelCsc:
    """A CSC matrix as Clarabel's Python binding reads it, with Python lists for its arrays.

    The binding (Clarabel 0.11) copies ``data``, ``indices`` and ``indptr`` of the matrix it
    is given into Rust vectors through Python's sequence protocol, one element at a time;
    from a numpy array each element is first boxed as a numpy scalar, from a list it is
    read directly. For a reduced 6-DoF subproblem (2,055 x 1,201, 16,316 nonzeros) a new
    solver took 3.25 ms (the conversion to lists included) instead of 3.99 ms, with the same
    iterates to the last bit (README, "Compiled dynamics, and Clarabel without cvxpy in the
    loop").
    """

    data: list[float]
    indices: list[int]
    indptr: list[int]
    nnz: int
    shape: tuple[int, int]
    has_canonical_format: bool = True  # sorted indices, no duplicates (CSC from scipy/the map)
    has_sorted_indices: bool = True

    @classmethod
    def of(cls, M: sp.csc_array | sp.csc_matrix) -> ClarabelCsc:
        """The lists of a canonical CSC matrix (scipy's own, or one built by the data map)."""
        return cls(M.data.tolist(), M.indices.tolist(), M.indptr.tolist(), int(M.nnz), M.shape)


def clarabel_inputs(
    P: sp.csc_array, q: np.ndarray, A: sp.csc_array, b: np.ndarray
) -> tuple[ClarabelCsc, list[float], ClarabelCsc, list[float]]:
    """``(P, q, A, b)`` as lists for ``clarabel.DefaultSolver`` and its ``update``
    (:class:`ClarabelCsc`)."""
    return ClarabelCsc.of(P), q.tolist(), ClarabelCsc.of(A), b.tolist()


def primal_value(x: np.ndarray, slices: VariableSlices, key: str) -> np.ndarray:
    """The variable ``key`` read from a conic primal vector ``x`` (cvxpy's column-major order)."""
    offset, shape = slices[key]
    size = int(np.prod(shape))
    return np.asarray(x[offset : offset + size]).reshape(shape, order="F")


def solver_options(
    solver: str, in_place: bool = False, settings: ConicSettings | None = None
) -> dict[str, Any]:
    """``settings[solver]`` (a family's own), with :data:`REUSE_OPTIONS` when the solver
    object is to be updated in place."""
    options = dict((settings or {}).get(solver, {}))
    return (options | REUSE_OPTIONS.get(solver, {})) if in_place else options


def start_cold(problem: cp.Problem) -> None:
    """Make the next :func:`solve_timed` of ``problem`` build a fresh solver object.

    cvxpy keeps the solver object of a parametric problem in ``Problem._solver_cache``. An
    updated solver could carry state from earlier data (Clarabel reuses its KKT structure and
    scaling); no difference was measured, but clearing it at the start of each SCP run
    guarantees that a run does not depend on what the process solved before.
    """
    problem._solver_cache.clear()


@dataclass(frozen=True)
class TensorEntries:
    """The structural nonzeros of one conic data matrix as a linear map of the parameters.

    ``values = tensor @ parameter_vector`` are the entries in CSC order (by column, rows
    ascending within a column); ``rows`` and ``columns`` say where each one sits.
    """

    tensor: sp.csr_array  # (nnz, parameters + 1)
    rows: np.ndarray  # (nnz,) int
    columns: np.ndarray  # (nnz,) int

    @classmethod
    def of(cls, reduced: Any) -> TensorEntries:
        """From cvxpy's condensed map (``ReducedMat``) of a matrix (an offset column, if the
        map holds one, is its last column)."""
        reduced.cache()
        indices, indptr, _ = reduced.problem_data_index
        columns = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
        rows = np.asarray(indices, dtype=np.int64)
        order = np.lexsort((rows, columns))  # canonical CSC, whatever cvxpy's order
        tensor = sp.csr_array(reduced.reduced_mat)[order]
        return cls(tensor, rows[order], columns[order])

    def restricted(self, keep: np.ndarray) -> TensorEntries:
        """The entries of the boolean mask ``keep`` (nnz,) alone, in the same order."""
        return TensorEntries(self.tensor[keep], self.rows[keep], self.columns[keep])

    def submatrix(
        self, values: np.ndarray, kept_rows: np.ndarray, kept_columns: np.ndarray
    ) -> sp.csc_array:
        """The CSC matrix of the entries ``values`` (in this order) on the rows and columns
        kept (boolean masks), renumbered in order."""
        select = kept_rows[self.rows] & kept_columns[self.columns]
        row_index = np.cumsum(kept_rows) - 1
        column_index = np.cumsum(kept_columns) - 1
        n_columns = int(kept_columns.sum())
        indptr = np.zeros(n_columns + 1, dtype=np.int64)
        counts = np.bincount(column_index[self.columns[select]], minlength=n_columns)
        np.cumsum(counts, out=indptr[1:])
        shape = (int(kept_rows.sum()), n_columns)
        return sp.csc_array((values[select], row_index[self.rows[select]], indptr), shape=shape)


class ConicDataMap:
    """cvxpy's parameter map of a problem compiled for Clarabel, as plain arrays.

    cvxpy's ``get_problem_data`` multiplies its parameter tensors by the parameter vector and
    then assembles, slices and converts scipy matrices (1.6 ms per 6-DoF subproblem, measured
    on 60 T-SCvx solves). This map keeps the tensors with the structural nonzeros of ``P``
    (upper triangle, as Clarabel takes it), ``A`` and the offset column ``b`` in canonical CSC
    order, so that :meth:`values` is four sparse matrix-vector products; a caller that solves
    a sub-block of the problem selects the entries it keeps by row and column. The numbers are
    Clarabel's data exactly as cvxpy hands them over (``A`` negated: ``b - A x`` in the cones),
    which a test checks against ``get_problem_data``.
    """

    def __init__(self, problem: cp.Problem) -> None:
        data, _, _ = problem.get_problem_data(SOLVERS["clarabel"], solver_opts={})
        prog = data["param_prob"]
        self._prog = prog
        n = int(prog.x.size)
        self.n_rows, self.n_columns = int(data["A"].shape[0]), n
        entries = TensorEntries.of(prog.reduced_A)  # A, then the offset column b
        in_A = entries.columns < n
        A = entries.restricted(in_A)
        self.A = TensorEntries(-A.tensor, A.rows, A.columns)  # Clarabel's sign: b - A x
        self._b_tensor = entries.tensor[~in_A]
        self._b_rows = entries.rows[~in_A]
        self.P: TensorEntries | None = None
        if prog.P is not None:
            full = TensorEntries.of(prog.reduced_P)
            self.P = full.restricted(full.rows <= full.columns)  # the upper triangle
        self._q_tensor = sp.csr_array(prog.q)

    def parameter_vector(self) -> np.ndarray:
        """The current parameter values stacked as cvxpy stacks them (last entry: 1).

        Raises
        ------
        ValueError
            Naming a parameter that has no value yet.
        """
        prog = self._prog

        def value(pid: int) -> np.ndarray:
            parameter = prog.id_to_param[pid]
            if parameter.value is None:
                raise ValueError(f"parameter {parameter.name()!r} has no value")
            return np.asarray(parameter.value, dtype=float)

        return get_parameter_vector(
            prog.total_param_size, prog.param_id_to_col, prog.param_id_to_size, value
        )

    def values(self) -> tuple[np.ndarray | None, np.ndarray, np.ndarray, np.ndarray]:
        """``(P entries or None, c, A entries, b)`` at the current parameter values."""
        vec = self.parameter_vector()
        b = np.zeros(self.n_rows)
        b[self._b_rows] = self._b_tensor @ vec
        c = np.asarray(self._q_tensor @ vec).ravel()[: self.n_columns]
        P = None if self.P is None else self.P.tensor @ vec
        return P, c, self.A.tensor @ vec, b


def assign(parameter: cp.Parameter, value: ArrayLike) -> None:
    """``parameter.value = value`` for the SCP loops, with the checks that matter here.

    cvxpy's setter tests every value against a projection onto the parameter's attributes
    (``np.allclose`` of the difference), about 60 us per assignment and some 5 ms per 6-DoF
    SCvx run. This checks what that test would catch in these loops -- the shape, NaN (which
    cvxpy rejects too) and the sign of a ``nonneg`` parameter -- and stores the float array.

    Raises
    ------
    ValueError
        Naming the parameter, for a wrong shape, a NaN or a negative value of a ``nonneg``
        parameter.
    """
    array = np.asarray(value, dtype=float)
    if array.shape != parameter.shape:
        raise ValueError(
            f"parameter {parameter.name()!r}: shape {array.shape}, expected {parameter.shape}"
        )
    if np.isnan(array).any():
        raise ValueError(f"parameter {parameter.name()!r}: value contains NaN")
    if parameter.attributes["nonneg"] and (array < 0.0).any():
        raise ValueError(f"parameter {parameter.name()!r} is nonneg, got a negative value")
    parameter.save_value(array)


def batched_matvec(M: cp.Expression, V: cp.Expression, rows: int, cols: int) -> cp.Expression:
    """``out[k, r] = sum_j M[k, r*cols + j] V[k, j]`` for all k at once.

    ``M`` is a parameter of shape (K, rows*cols) holding row-major (rows, cols) matrices, ``V``
    an affine expression of shape (K, cols); the result has shape (K, rows). It is built from
    ``cols`` elementwise products, which cvxpy canonicalizes far faster than ``K`` separate
    ``M_k @ v_k`` terms.
    """
    out = None
    for j in range(cols):
        term = cp.multiply(M[:, j::cols], V[:, j : j + 1])  # (K, rows) * (K, 1) broadcast
        out = term if out is None else out + term
    return out
