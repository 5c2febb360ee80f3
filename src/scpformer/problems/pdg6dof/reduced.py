"""The 6-DoF subproblem reduced to chosen inequality rows, solved on sliced conic data.

T-SCvx (Algorithm 2, step 1 of the T-SCvx paper) solves each convex subproblem with only the
inequality rows predicted tight. cvxpy compiles the parametric subproblem once
(:func:`~scpformer.problems.pdg6dof.subproblem.compiled_subproblem`); at every iteration it
maps the parameter values to the conic data ``(P, c, A, b, cones)`` of Clarabel. This module
keeps, once per compiled problem, a :class:`ConicLayout`: which conic rows and second-order
cones belong to each ``(name, node)`` row of
:func:`~scpformer.problems.pdg6dof.constraints.constraint_index`, and where each variable
sits in the conic solution vector. A reduced solve then

1. writes the full conic data from the current parameters with the layout's
   :class:`~scpformer.scp.conic.ConicDataMap` (cvxpy's parameter tensors times the parameter
   vector, no canonicalization and no scipy matrix assembly),
2. selects the entries of the kept rows and columns: it drops the rows and cones of the
   left-out ``(name, node)`` rows and the columns that no kept row, quadratic or linear cost
   term touches any more (the epigraph variable of a dropped norm),
3. calls Clarabel on the smaller problem and maps its primal solution back to ``(x, u,
   sigma, nu, buffers)``.

With every row kept this is the full subproblem, and cold SCvx solves its subproblems this way
too (:meth:`~scpformer.problems.pdg6dof.problem.PDGProblem._solve`): the same numbers as
cvxpy's ``get_problem_data`` and Clarabel interface, without their per-solve cost.

What a ``(name, node)`` row owns in the conic problem (cvxpy 1.9 canonicalization, checked
by the layout tests against :func:`~scpformer.problems.pdg6dof.constraints.constraint_values`):
mass and thrust_min one nonnegative row; glideslope, tilt and omega one nonnegative row and
the second-order cone of their norm's epigraph variable; thrust_max and gimbal one
nonnegative row each. The cone of the thrust norm ``|U_k|`` that they share is also the end
point of the mass row's quadrature (Eq. 4a), so no flag owns it: like the equalities, the
virtual-control rows, the final-time bounds and the trust region it is always kept; with
``drop_box`` the safeguard box of the soft trust region is left out too (the caller checks
the solution against it, see :meth:`ReducedSubproblem.solve`).

With ``keep_virtual=False`` the virtual control ``nu`` is fixed at zero: its columns, the
nonnegative rows of its ``|nu|`` epigraph and the epigraph's columns are left out (a third of
the rows and half of the columns at N = 50). The result is the optimum of the subproblem with
``nu`` exactly when that optimum has ``nu = 0``: Eq. 16's L1 penalty is exact for the
subproblem (Nocedal & Wright, Thm. 17.3) once every multiplier ``y`` of a dynamics row is
below its weight, ``|A_nu^T y| <= lambda`` column by column, which
:meth:`ReducedSubproblem.solve` checks on Clarabel's dual solution. A subproblem whose
linearized dynamics cannot be met without ``nu`` is infeasible and is reported so; either way
the caller solves again with ``nu``.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass

import clarabel
import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from scpformer.problems.pdg6dof import constraints as con
from scpformer.problems.pdg6dof.subproblem import (
    CONIC_SETTINGS,
    PDGSubproblem,
    SubproblemSolution,
)
from scpformer.scp.conic import (
    SOLVED,
    SOLVERS,
    ConicDataMap,
    VariableSlices,
    clarabel_inputs,
    clarabel_status,
    primal_value,
    solver_options,
)

ALWAYS = -1  # owner of a conic row kept in every reduced problem
BOX = -2  # owner of a row of the safeguard trust-region box
VIRTUAL_NEEDED = "virtual_needed"  # status: the optimum without nu is not the one with nu


@dataclass(frozen=True)
class ConicLayout:
    """Where the ``(name, node)`` rows and the variables sit in the compiled conic problem.

    Row ``i`` of ``A`` belongs to ``owner_a[i]`` and ``owner_b[i]``: flag indices (name-major,
    as the tight-flag vector), :data:`ALWAYS` or :data:`BOX`; a row is kept when either owner
    is kept (the two differ only on the thrust cone shared by thrust_max and gimbal).
    """

    n_zero: int  # equality rows (first in A)
    n_nonneg: int  # nonnegative rows (next)
    soc_sizes: np.ndarray  # (n_cones,) dimensions of the second-order cones (last)
    owner_a: np.ndarray  # (m,) int
    owner_b: np.ndarray  # (m,) int
    variables: VariableSlices  # name -> (column offset, shape), PDGSubproblem.named_variables
    virtual_rows: np.ndarray  # (m,) bool: the nonnegative rows of the |nu| epigraph
    virtual_columns: np.ndarray  # (n,) bool: nu and its epigraph variables
    nu_columns: np.ndarray  # (n,) bool: nu alone
    data_map: ConicDataMap  # the parameter map of the compiled problem, as plain arrays

    @property
    def n_rows(self) -> int:
        """Rows of the full conic problem."""
        return self.owner_a.size

    def rows_of(self, flag: int) -> np.ndarray:
        """Conic rows owned by the ``(name, node)`` row with index ``flag``."""
        return np.flatnonzero((self.owner_a == flag) | (self.owner_b == flag))

    def kept_rows(self, keep: np.ndarray, keep_box: bool = True) -> np.ndarray:
        """Boolean mask of the conic rows kept for the flag mask ``keep`` (R,)."""
        lookup = np.concatenate([np.asarray(keep, dtype=bool), [keep_box, True]])
        return lookup[self.owner_a] | lookup[self.owner_b]  # ALWAYS = -1, BOX = -2


def conic_layout(sub: PDGSubproblem) -> ConicLayout:
    """Map the compiled Clarabel problem of ``sub`` (see the module docstring)."""
    data, _, inverse = sub.problem.get_problem_data(SOLVERS["clarabel"], solver_opts={})
    solver_data = inverse[-1].inverse_data
    ordered = [*solver_data["eq_constr"], *solver_data["other_constr"]]
    dims = data["dims"]
    n_nodes = sub.n_nodes
    flag_of = {
        sub.inequalities[name].id: i * n_nodes for i, name in enumerate(con.CONSTRAINT_NAMES)
    }
    box_ids = {c.id for c in sub.trust_box}
    norm_owners = _norm_owners(ordered, flag_of)
    owner_a, owner_b = [], []
    for constraint in ordered:
        rows = _rows_per_node(constraint, dims)
        if constraint.id in flag_of:
            base = flag_of[constraint.id]
            a = b = base + np.repeat(np.arange(n_nodes), rows // n_nodes)
        elif isinstance(constraint, cp.constraints.SOC) and _epigraph_id(constraint) in norm_owners:
            bases = norm_owners[_epigraph_id(constraint)]
            nodes = np.repeat(np.arange(n_nodes), rows // n_nodes)
            a, b = bases[0] + nodes, bases[-1] + nodes
        else:
            a = b = np.full(rows, BOX if constraint.id in box_ids else ALWAYS)
        owner_a.append(a)
        owner_b.append(b)
    variables = sub.primal_slices("clarabel")
    virtual_rows, virtual_columns, nu_columns = _virtual_parts(data["A"], int(dims.zero), variables)
    layout = ConicLayout(
        n_zero=int(dims.zero),
        n_nonneg=int(dims.nonneg),
        soc_sizes=np.asarray(dims.soc, dtype=int),
        owner_a=np.concatenate(owner_a).astype(int),
        owner_b=np.concatenate(owner_b).astype(int),
        variables=variables,
        virtual_rows=virtual_rows,
        virtual_columns=virtual_columns,
        nu_columns=nu_columns,
        data_map=ConicDataMap(sub.problem),
    )
    if layout.n_rows != data["A"].shape[0]:
        raise RuntimeError(f"conic layout maps {layout.n_rows} rows, A has {data['A'].shape[0]}")
    return layout


@functools.lru_cache(maxsize=8)
def cached_layout(sub: PDGSubproblem) -> ConicLayout:
    """The conic layout of a process-wide compiled subproblem (computed once per process)."""
    return conic_layout(sub)


def _virtual_parts(
    A: sp.spmatrix, n_zero: int, variables: VariableSlices
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rows of the ``|nu|`` epigraph, the columns of ``nu`` and its epigraph, and those
    of ``nu`` alone (see the module docstring): the inequality rows with two entries, one in
    ``nu`` (``t -+ nu >= 0``; the mass rows of Eq. 4a, inequalities that also hold ``nu``,
    stay), and the columns that only those rows touch."""
    A = sp.csr_array(A)
    offset, shape = variables["nu"]
    nu_columns = np.zeros(A.shape[1], dtype=bool)
    nu_columns[offset : offset + int(np.prod(shape))] = True
    touches_nu = np.diff(sp.csr_array(A[:, nu_columns]).indptr) > 0
    two_entries = np.diff(A.indptr) == 2
    virtual_rows = touches_nu & two_entries & (np.arange(A.shape[0]) >= n_zero)
    in_virtual = np.zeros(A.shape[1], dtype=bool)
    in_virtual[A[virtual_rows].indices] = True
    elsewhere = np.zeros(A.shape[1], dtype=bool)
    elsewhere[A[~virtual_rows].indices] = True
    epigraph = in_virtual & ~nu_columns & ~elsewhere
    if epigraph.sum() != nu_columns.sum() or virtual_rows.sum() != 2 * nu_columns.sum():
        raise RuntimeError("the |nu| epigraph is not the one the reduced solve expects")
    return virtual_rows, nu_columns | epigraph, nu_columns


def _rows_per_node(constraint: cp.Constraint, dims: object) -> int:
    """Conic rows of one canonical constraint (an SOC of K cones: K times its cone size)."""
    if isinstance(constraint, cp.constraints.SOC):
        return int(sum(constraint.cone_sizes()))
    return int(constraint.size)


def _epigraph_id(cone: cp.constraints.SOC) -> int | None:
    """Id of the variable ``t`` of ``|v| <= t`` (None when ``t`` is not a bare variable)."""
    variables = cone.args[0].variables()
    return variables[0].id if len(variables) == 1 else None


def _norm_owners(ordered: list[cp.Constraint], flag_of: dict[int, int]) -> dict[int, list[int]]:
    """Epigraph variable id -> flag bases of the named constraints that bound it.

    An epigraph that a constraint outside the named rows also uses (the thrust norm, which
    the mass row of Eq. 4a shares with thrust_max and gimbal) has no owner: its cone is kept
    in every reduced problem.
    """
    owners: dict[int, list[int]] = {}
    shared: set[int] = set()
    for constraint in ordered:
        if isinstance(constraint, cp.constraints.SOC):
            continue
        for var in constraint.variables():
            if constraint.id in flag_of:
                owners.setdefault(var.id, []).append(flag_of[constraint.id])
            else:
                shared.add(var.id)
    epigraphs = {_epigraph_id(c) for c in ordered if isinstance(c, cp.constraints.SOC)} - {None}
    return {vid: bases for vid, bases in owners.items() if vid in epigraphs - shared}


@dataclass(frozen=True)
class ReducedSize:
    """Size of the conic problem handed to Clarabel, and its interior-point iterations."""

    rows: int
    columns: int
    cones: int  # second-order cones
    flags_kept: int  # (name, node) rows kept
    iterations: int  # Clarabel's interior-point iterations on it


class ReducedSubproblem:
    """Solve the compiled subproblem of ``sub`` with a subset of its ``(name, node)`` rows.

    The parameters of ``sub`` (instance, linearization, trust region) are set by the caller
    exactly as for a full solve; :meth:`solve` reads them through cvxpy's parameter map.
    """

    def __init__(self, sub: PDGSubproblem, layout: ConicLayout | None = None) -> None:
        self.sub = sub
        self.layout = layout or conic_layout(sub)
        self.last_size: ReducedSize | None = None
        self._solver: object | None = None  # the Clarabel solver of the last solve
        self._solver_key: tuple | None = None  # its kept rows and columns
        self._cone_count = 0

    def conic_data(self) -> dict[str, object]:
        """The full conic data of the current parameter values, through cvxpy's own map (the
        reference that :class:`~scpformer.scp.conic.ConicDataMap` is tested against)."""
        data, _, _ = self.sub.problem.get_problem_data(SOLVERS["clarabel"], solver_opts={})
        return data

    def solve(
        self, keep: np.ndarray, lambda_: float, keep_box: bool = True, keep_virtual: bool = True
    ) -> SubproblemSolution:
        """Solve with the ``(name, node)`` rows of ``keep`` (R,) and every other row.

        ``keep_box = False`` leaves out the safeguard box of the trust region (only sound
        with a soft trust region; the caller re-solves with it if the step leaves the box).
        ``keep_virtual = False`` fixes ``nu`` at zero (module docstring); a solution whose
        dynamics multipliers exceed the penalty weight is returned with status
        :data:`VIRTUAL_NEEDED`, an infeasible one with Clarabel's status: the caller solves
        again with ``nu``. ``solve_time`` is the Clarabel call alone (setup or update, and
        solve); ``wall_time`` includes the parameter map, the selection and the unpacking.
        """
        start = time.perf_counter()
        lay, data = self.layout, self.layout.data_map
        P_values, c, A_values, b = data.values()
        rows = lay.kept_rows(keep, keep_box)
        if not keep_virtual:
            rows &= ~lay.virtual_rows
        cols = self._used_columns(rows, c)
        if not keep_virtual:
            cols &= ~lay.virtual_columns
        A = data.A.submatrix(A_values, rows, cols)
        P = (
            data.P.submatrix(P_values, cols, cols)
            if data.P is not None
            else sp.csc_array((int(cols.sum()), int(cols.sum())))
        )
        t0 = time.perf_counter()
        try:
            solver = self._clarabel((rows.tobytes(), cols.tobytes()), P, c[cols], A, b[rows])
            result = solver.solve()
        except Exception as err:  # a solver failure is a status (conic.py)
            return SubproblemSolution.failed(
                f"solver_error: {err}", time.perf_counter() - start, 0.0
            )
        solve_time = time.perf_counter() - t0
        self.last_size = ReducedSize(
            rows=int(rows.sum()),
            columns=int(cols.sum()),
            cones=int(self._cone_count),
            flags_kept=int(np.count_nonzero(keep)),
            iterations=int(result.iterations),
        )
        status = clarabel_status(result)
        if status in SOLVED and not keep_virtual:
            multipliers = self._nu_multipliers(A_values, rows, np.asarray(result.z))
            status = status if multipliers.max(initial=0.0) <= lambda_ else VIRTUAL_NEEDED
        if status not in SOLVED:
            return SubproblemSolution.failed(status, time.perf_counter() - start, solve_time)
        full = np.zeros(cols.size)
        full[cols] = np.asarray(result.x)
        return self._unpack(full, lambda_, status, solve_time, start)

    def _used_columns(self, rows: np.ndarray, c: np.ndarray) -> np.ndarray:
        """Columns that a kept row of ``A``, the quadratic term or the linear cost touches."""
        data = self.layout.data_map
        used = c != 0.0
        used[data.A.columns[rows[data.A.rows]]] = True
        if data.P is not None:
            used[data.P.rows] = True
            used[data.P.columns] = True
        return used

    def _nu_multipliers(self, A_values: np.ndarray, rows: np.ndarray, z: np.ndarray) -> np.ndarray:
        """``|A_nu^T y|`` per column of ``nu``: the dual ``z`` of the kept rows against the
        entries of the ``nu`` columns in those rows (the exactness test of the docstring)."""
        entries = self.layout.data_map.A
        select = rows[entries.rows] & self.layout.nu_columns[entries.columns]
        row_index = np.cumsum(rows) - 1
        weights = A_values[select] * z[row_index[entries.rows[select]]]
        sums = np.bincount(entries.columns[select], weights, minlength=self.layout.nu_columns.size)
        return np.abs(sums[self.layout.nu_columns])

    def _clarabel(
        self, key: tuple, P: sp.csc_array, q: np.ndarray, A: sp.csc_array, b: np.ndarray
    ) -> object:
        """A Clarabel solver holding this data: the previous one updated in place when the
        kept rows and columns are the same (it keeps its symbolic factorization, as cvxpy's
        ``reuse`` path does, :func:`scpformer.scp.conic.solver_options`), else a new one."""
        P_in, q_in, A_in, b_in = clarabel_inputs(P, q, A, b)
        if self._solver is not None and self._solver_key == key:
            try:
                self._solver.update(P=P_in, q=q_in, A=A_in, b=b_in)
                return self._solver
            except Exception:  # a changed sparsity pattern: build a new solver
                pass
        rows = np.frombuffer(key[0], dtype=bool)
        cones = self._cones(rows)
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        for name, value in solver_options("clarabel", True, CONIC_SETTINGS).items():
            setattr(settings, name, value)
        self._solver = clarabel.DefaultSolver(P_in, q_in, A_in, b_in, cones, settings)
        self._solver_key, self._cone_count = key, len(cones) - 2
        return self._solver

    def _cones(self, rows: np.ndarray) -> list[object]:
        lay = self.layout
        first_rows = lay.n_zero + lay.n_nonneg + np.concatenate([[0], np.cumsum(lay.soc_sizes)])
        kept_socs = [
            clarabel.SecondOrderConeT(int(size))
            for size, first in zip(lay.soc_sizes, first_rows[:-1], strict=True)
            if rows[first]
        ]
        n_nonneg = int(rows[lay.n_zero : lay.n_zero + lay.n_nonneg].sum())
        return [clarabel.ZeroConeT(lay.n_zero), clarabel.NonnegativeConeT(n_nonneg), *kept_socs]

    def _unpack(
        self, solution: np.ndarray, lambda_: float, status: str, solve_time: float, start: float
    ) -> SubproblemSolution:
        values = {
            key: primal_value(solution, self.layout.variables, key) for key in self.layout.variables
        }
        return self.sub.solution_from(
            values, lambda_, status, solve_time, time.perf_counter() - start
        )
