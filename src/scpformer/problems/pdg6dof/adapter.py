"""The 6-DoF powered descent family as an SCvx problem (:class:`PDGProblem`).

Decision variables z = (x (N, 14), u (N, 3), p = (t_f,)). Cost ``C(z) = -m_N`` (Eq. 2). The
nonlinear penalty of Eq. 16 is ``P(z) = sum_k |x_{k+1} - F_k(z)|_1 + sum_k max(0, T_min - |u_k|)``:
the convex constraints are imposed exactly in every subproblem, so only the dynamics defects
and the non-convex thrust lower bound can be violated by an iterate.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import replace

import numpy as np

from scpformer.dynamics import powered_descent_kernels as pdk
from scpformer.problems.pdg6dof import constraints as con
from scpformer.problems.pdg6dof.config import SOFT_BOX_FACTOR, PDGSolverConfig
from scpformer.problems.pdg6dof.correction import LeastChangeCorrection
from scpformer.problems.pdg6dof.guess import cubic_profile_trajectory
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.reduced import ReducedSubproblem, cached_layout
from scpformer.problems.pdg6dof.subproblem import (
    SubproblemSolution,
    compiled_subproblem,
    trust_region_scales,
)
from scpformer.problems.pdg6dof.verification import verify_trajectory
from scpformer.scp.conic import SOLVED, start_cold
from scpformer.scp.discretization import FOHDiscretization, foh_discretize, foh_flow
from scpformer.scp.scvx import Candidate, Evaluation
from scpformer.scp.solution import Solution, Trajectory, Verification

LEAST_CHANGE = "least_change"  # solver status of a correction made without a conic solve
LEAST_CHANGE_STEPS = 3  # chord steps of the least-change correction before the conic one


class PDGProblem:
    """One instance posed for SCvx (implements :class:`scpformer.scp.scvx.ConvexifiedProblem`)."""

    def __init__(self, instance: PDGInstance, config: PDGSolverConfig) -> None:
        self.instance = instance
        self.config = config
        self.model = instance.constants.model()
        self.packed_model = pdk.packed_constants(self.model)
        self.subproblem = compiled_subproblem(
            config.n_nodes, config.fix_roll, config.prox_weight, config.scvx.solver
        )
        start_cold(self.subproblem.problem)  # the run's solves reuse one solver object
        self._direct: ReducedSubproblem | None = None  # Clarabel on the data map (_solve)
        self._every_row = np.ones(len(con.CONSTRAINT_NAMES) * config.n_nodes, dtype=bool)

    def dynamics(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Eq. 4 at the points (K, 14), (K, 3): the compiled kernel
        (:mod:`scpformer.dynamics.powered_descent_kernels`)."""
        return pdk.dynamics(self.packed_model, x, u)

    def linearize(self, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Eq. 4 and its Jacobians at the points: the compiled kernel."""
        return pdk.linearize(self.packed_model, x, u)

    def initial_guess(self) -> Trajectory:
        """The default cold start: the cubic-profile guess (:mod:`.guess`)."""
        return cubic_profile_trajectory(self.instance, self.config.n_nodes)

    def node_times(self, z: Trajectory) -> np.ndarray:
        return np.linspace(0.0, float(z.p[0]), self.config.n_nodes)

    def step_norm(self, z_new: Trajectory, z_old: Trajectory) -> float:
        sx, su, ss = trust_region_scales(self.instance)
        return float(
            max(
                (np.abs(z_new.x - z_old.x) / sx).max(),
                (np.abs(z_new.u - z_old.u) / su).max(),
                abs(float(z_new.p[0] - z_old.p[0])) / ss,
            )
        )

    def evaluate(self, z: Trajectory) -> Evaluation:
        """The nonlinear cost, penalty and linearization about ``z``. A candidate far outside
        the region the dynamics were linearized in can make the flow overflow: its defects
        are then inf or nan, quietly, and SCvx rejects it (``J = inf``)."""
        start = time.perf_counter()
        with np.errstate(over="ignore", invalid="ignore"):
            disc = foh_discretize(self.linearize, z.x, z.u, float(z.p[0]), self.config.n_sub)
        defects = disc.defects(z.x)
        values = con.constraint_values(self.instance, z.x, z.u)
        return Evaluation(
            cost=final_mass_cost(z),
            penalty=penalty(defects, values),
            max_defect=float(np.abs(defects).max()),
            tight_flags=con.tight_flags(values, self.config.tight_tol),
            linearization=disc,
            time=time.perf_counter() - start,
        )

    def flow_defects(self, z: Trajectory) -> np.ndarray:
        """The defects ``x_{k+1} - F_k(z)`` (K, 14) of ``z`` without its linearization (inf or
        nan, quietly, where the flow overflows: see :meth:`evaluate`)."""
        with np.errstate(over="ignore", invalid="ignore"):
            flow = foh_flow(self.dynamics, z.x, z.u, float(z.p[0]), self.config.n_sub)
        return z.x[1:] - flow

    def solve_subproblem(
        self, z: Trajectory, evaluation: Evaluation, eta: float, lambda_: float, solver: str
    ) -> Candidate:
        disc = evaluation.linearization
        assert isinstance(disc, FOHDiscretization)
        self.subproblem.set_instance(self.instance)
        self.subproblem.set_linearization(disc, z.x, z.u, float(z.p[0]))
        return self._solve(eta, lambda_, solver)

    def solve_correction(
        self,
        z: Trajectory,
        evaluation: Evaluation,
        candidate: Candidate,
        candidate_evaluation: Evaluation,
        eta: float,
        lambda_: float,
        solver: str,
    ) -> Candidate:
        """The least-change correction when it passes the ratio test, else the subproblem about
        ``z`` with its affine term shifted by the candidate's defects."""
        cheap = self.least_change(z, evaluation, candidate, candidate_evaluation, eta, lambda_)
        if cheap is not None:
            return cheap
        return self.conic_correction(z, candidate, candidate_evaluation, eta, lambda_, solver)

    def conic_correction(
        self, z: Trajectory, candidate: Candidate, ev: Evaluation, eta: float, lambda_: float,
        solver: str,
    ) -> Candidate:  # fmt: skip
        """The subproblem about ``z``, the iterate of the candidate's solve, its affine term
        shifted by the defects of the candidate (whose evaluation is ``ev``)."""
        disc = ev.linearization
        assert isinstance(disc, FOHDiscretization) and candidate.trajectory is not None
        self.subproblem.shift_affine_term(disc.defects(candidate.trajectory.x))
        return self._solve(eta, lambda_, solver)

    def least_change(
        self,
        z_bar: Trajectory,
        evaluation: Evaluation,
        candidate: Candidate,
        candidate_evaluation: Evaluation,
        eta: float,
        lambda_: float,
    ) -> Candidate | None:
        """The candidate moved by :class:`~.correction.LeastChangeCorrection`, if that alone
        gives a ratio (Eq. 14, against the first solve's ``Delta L``) of at least ``rho_1``
        within ``LEAST_CHANGE_STEPS`` chord steps, every convex row kept and the step from
        ``z_bar`` inside the box of the trust region (radius ``eta``).

        ``None`` when the correction is off (``config.least_change_correction``) or falls
        short; the conic correction then runs.
        """
        if not self.config.least_change_correction or candidate.trajectory is None:
            return None
        J_bar = evaluation.cost + lambda_ * evaluation.penalty
        wanted = self.config.scvx.rho_1 * (J_bar - candidate.linear_cost)
        box = self.trust_region(eta)[1] * (1.0 + 1e-9)
        steps = self._chord_steps(candidate.trajectory, candidate_evaluation.linearization)
        for correction, z, defects, values in steps:
            J = final_mass_cost(z) + lambda_ * penalty(defects, values)
            kept = correction.keeps_convex_rows(z, values)
            if J_bar - J >= wanted and kept and self.step_norm(z, z_bar) <= box:
                return replace(candidate, trajectory=z, status=LEAST_CHANGE, solver_time=0.0)
        return None

    def polish(self, candidate: Candidate, evaluation: Evaluation) -> Candidate | None:
        """An accepted candidate moved onto the nonlinear flow without a conic solve.

        Chord steps of :class:`~.correction.LeastChangeCorrection` about the candidate (the
        boundary conditions and the rows tight at the candidate held), at most
        ``LEAST_CHANGE_STEPS``, until its largest defect is below a tenth of ``defect_tol``.
        ``None`` when the first step fails or breaks a convex row (a later one that does so
        ends the steps). SCvx keeps the result only when it lowers J
        (:func:`scpformer.scp.scvx.solve_scvx`, ``polish``).
        """
        if candidate.trajectory is None:
            return None
        polished = None
        steps = self._chord_steps(candidate.trajectory, evaluation.linearization)
        for correction, z, defects, values in steps:
            if not correction.keeps_convex_rows(z, values):
                break
            polished = z
            if np.abs(defects).max() <= 0.1 * self.config.scvx.defect_tol:
                break
        return (
            None if polished is None else replace(candidate, trajectory=polished, solver_time=0.0)
        )

    def _chord_steps(
        self, z: Trajectory, disc: object
    ) -> Iterator[tuple[LeastChangeCorrection, Trajectory, np.ndarray, np.ndarray]]:
        """The chord steps of :class:`~.correction.LeastChangeCorrection` about ``z`` (whose
        linearization is ``disc``): ``(correction, z_k, flow defects, row values)`` for each
        of at most ``LEAST_CHANGE_STEPS``, ending early when the linear algebra fails."""
        assert isinstance(disc, FOHDiscretization)
        correction = LeastChangeCorrection(
            self.instance, disc, z, self.config.fix_roll, self.config.tight_tol
        )
        defects = disc.defects(z.x)
        values = con.constraint_values(self.instance, z.x, z.u)
        for _ in range(LEAST_CHANGE_STEPS):
            z = correction.step(z, defects, values)
            if z is None:
                return
            defects = self.flow_defects(z)
            values = con.constraint_values(self.instance, z.x, z.u)
            yield correction, z, defects, values

    def _solve(self, eta: float, lambda_: float, solver: str) -> Candidate:
        """One conic solve with the trust region of radius ``eta`` (soft or hard, see config).

        With Clarabel the full subproblem is solved on the conic data of the compiled
        problem's parameter map, every row kept (:class:`~.reduced.ReducedSubproblem`), and
        the run's solver object is updated in place; cvxpy's ``get_problem_data`` and its
        Clarabel interface (the same numbers, tested) cost about 1 ms more per solve (40
        validation draws of ``generate pdg6dof --seed 26``: cold SCvx 451 -> 435 ms per run;
        README, "Compiled dynamics, and Clarabel without cvxpy in the loop"). ECOS and QOCO
        go through cvxpy.
        """
        weight, box = self.trust_region(eta)
        if solver != "clarabel":
            sol = self.subproblem.solve(eta, lambda_, solver, box=box, soft_weight=weight)
            return candidate(sol)
        self.subproblem.set_trust_region(eta, lambda_, box, weight)
        if self._direct is None:
            self._direct = ReducedSubproblem(self.subproblem, cached_layout(self.subproblem))
        return candidate(self._direct.solve(self._every_row, lambda_))

    def trust_region(self, eta: float) -> tuple[float, float]:
        """The soft weight and the box radius of the trust region of radius ``eta``: the
        box is ``eta`` itself without the soft term (Algorithm 1), a far safeguard with it."""
        weight = self.config.prox_weight / eta**2
        return weight, SOFT_BOX_FACTOR * eta if weight > 0.0 else eta

    def verify(self, z: Trajectory) -> Verification:
        return verify_trajectory(self.instance, z, self.config)


def conic_solves(solution: Solution) -> int:
    """The records of ``solution.history`` that solved a conic subproblem (every one but the
    least-change corrections)."""
    return sum(record.solver_status != LEAST_CHANGE for record in solution.history)


def final_mass_cost(z: Trajectory) -> float:
    """``C(z) = -m_N`` (Eq. 2)."""
    return float(-z.x[-1, 13])


def penalty(defects: np.ndarray, values: np.ndarray) -> float:
    """``P(z)`` of the module docstring from the defects (K, 14) and the inequality rows
    (:func:`~scpformer.problems.pdg6dof.constraints.constraint_values`) of ``z``."""
    thrust_min = values[con.CONSTRAINT_NAMES.index("thrust_min")]
    return float(np.abs(defects).sum() + np.maximum(thrust_min, 0.0).sum())


def candidate(sol: SubproblemSolution) -> Candidate:
    """The SCvx candidate of a subproblem solution (failed solves keep their status)."""
    if sol.status not in SOLVED or sol.x is None:
        return Candidate(None, np.nan, np.nan, np.nan, sol.status, sol.solver_time, False)
    virtual_max = max(float(np.abs(sol.nu).max()), float(sol.buffers.max()))
    return Candidate(
        trajectory=Trajectory(x=sol.x, u=sol.u, p=np.array([sol.sigma])),
        linear_cost=sol.cost,
        virtual_norm=float(np.abs(sol.nu).sum() + sol.buffers.sum()),
        virtual_max=virtual_max,
        status=sol.status,
        solver_time=sol.solver_time,
        ok=True,
    )
