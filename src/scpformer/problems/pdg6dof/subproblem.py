"""The SCvx convex subproblem of the 6-DoF problem, compiled once as a parametric cvxpy problem.

Variables: X (N, 14), U (N, 3), sigma = t_f, virtual control nu (N-1, 14) (E = I, Eq. 8) and
virtual buffers s (N,) >= 0 for the linearized thrust lower bound (Eq. 9, 11). Everything that
changes between SCvx iterations *or between instances* is a ``cvxpy.Parameter``: the FOH
matrices, the reference trajectory, the trust radius, the boundary conditions and the constraint
bounds. The problem is therefore canonicalized once per node count N and process (DPP), and an
iteration only writes numbers into parameters before calling the conic solver.

Subproblem (Eq. 7 with Eqs. 10-11):

    min   -m_N + lambda (|nu|_1 + sum s) [+ |W (z - z_bar)|^2, soft trust region, see below]
    s.t.  X_{k+1} = A_k X_k + Bm_k U_k + Bp_k U_{k+1} + S_k sigma + z_k + nu_k       (10)
                                                               (rows r, v, q, omega)
          m_{k+1} <= m_k - sigma_bar alpha dtau I_k(U) + S_k^m sigma + c_k + nu_k^m (4a)
          T_min - d_k . U_k <= s_k,  d_k = U_bar_k / |U_bar_k|                       (11, 6a)
          convex rows of 5a-5d, 6a (upper), 6b at every node
          boundary conditions 3b-3i (terminal attitude: see TerminalAttitude note; with
          fix_roll the final quaternion's vector part is zero and q0 = +-1 follows from the
          unit norm: fixing q0 = 1 as well over-determines the linearized rows, whose q0
          drifts from 1 at second order, and left a virtual control of ~3e-6 that never
          vanished on EmbersArc's scenario)
          tf_min <= sigma <= tf_max                                                   (3a)
          |X - X_bar|_inf, |U - U_bar|_inf, |sigma - sigma_bar| <= eta   (q_tr = inf, Table 1)

The mass row is not linearized (not in the paper; measurements in the README, "The mass row").
The mass rate of Eq. 4a, ``-alpha |u| - beta``, does not depend on the state, so over an
interval ``m_{k+1} = m_k - sigma dtau (alpha I_k + beta)`` with ``I_k`` the mean of ``|u|`` along
the first-order hold -- and RK4 applied to a state-independent rate is Simpson's rule, so the
discretization computes ``I_k`` as the composite Simpson sum over the RK4 stages (points 0,
1/4, 1/2, 3/4, 1 of the interval for the default two steps). ``I_k(U)`` is convex in
``(U_k, U_{k+1})``, so the row above is a convex (second-order cone) constraint that is exact in
the thrust and linear only in ``sigma``; ``c_k`` makes it hold with equality at the reference.
Linearizing ``|u|`` instead tells the subproblem that turning the thrust vector costs no
propellant to first order: every step then turns it as far as the trust region allows, the
burned propellant shows up as mass defects, and the ratio test rejects the step or the cost
creeps. The row is an inequality, so a subproblem may burn more than the engine needs
(a lighter vehicle decelerates harder at full thrust); the nonlinear evaluation charges such
slack as a mass defect in the penalty of Eq. 16, and convergence requires every defect below
``defect_tol``, so a converged solution burns exactly what its thrust burns. (Measured: on the
nominal instances the slack vanishes; on a near-infeasible instance of EmbersArc's scenario
with lambda = 50 SCvx stalled at a trajectory whose only defect was such slack.)

With ``soft=True`` the objective also holds the penalized (soft) trust region of Reynolds,
Szmuk et al.: ``sum_i w_i (z_i - z_bar_i)^2`` with one weight per variable group (position,
velocity, quaternion, rate, mass, thrust, final time), all parameters, so that the SCvx loop
sets them from the trust radius at every iteration (:meth:`PDGSubproblem.solve`). The state is
declared as one variable per group so that each weighted ``sum_squares`` of a bare variable
goes straight into the quadratic objective of the conic problem (no auxiliary rows).
"""

from __future__ import annotations

import functools
import math
from typing import Any

import cvxpy as cp
import numpy as np

from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.scp.conic import (
    SubproblemSolution,
    VariableSlices,
    assign,
    batched_matvec,
    compiled,
    solve_timed,
    variable_slices,
)
from scpformer.scp.discretization import FOHDiscretization

STATE_GROUPS: tuple[tuple[str, int, int], ...] = (
    ("r", 0, 3),
    ("v", 3, 6),
    ("q", 6, 10),
    ("omega", 10, 13),
    ("m", 13, 14),
)


# Conic solver settings of this family (scpformer.scp.conic.solve_timed). Clarabel's iterative
# refinement of each KKT solve (by default up to 10 steps, to a relative residual of 1e-13)
# undoes its static regularization of 1e-8, an accuracy these subproblems do not need.
# Measured on the 134 subproblems of 5 feasible-range SCvx runs (seed 7): the same
# interior-point iterations (2,725 against 2,723 in all), objectives equal to a relative 4e-9,
# 28-37% less time in Clarabel (7.8 and 7.4 s -> 4.9 and 5.6 s, two runs). The rendezvous
# families keep the refinement: without it their Problem 3 and SCvx* runs took more
# iterations and failed more often (bench rendezvous --n 40: median SCP iterations 2 -> 4, one
# run at its limit; bench robust-rendezvous --n 10: 1 -> 3 chance runs at max_iterations).
CONIC_SETTINGS: dict[str, dict[str, Any]] = {"clarabel": {"iterative_refinement_enable": False}}
MASS = 13  # column of the mass in the state
MASS_QUADRATURE = (  # points s_j and weights w_j of composite Simpson on [0, 1], two steps
    (0.0, 0.25, 0.5, 0.75, 1.0),
    (1.0 / 12.0, 4.0 / 12.0, 2.0 / 12.0, 4.0 / 12.0, 1.0 / 12.0),
)


def mean_thrust(u: np.ndarray) -> np.ndarray:
    """``sum_j w_j |(1 - s_j) u_k + s_j u_{k+1}|`` per interval (K,): the mean thrust magnitude
    along the first-order hold by :data:`MASS_QUADRATURE`."""
    points, weights = MASS_QUADRATURE
    return sum(
        w * np.linalg.norm((1.0 - s) * u[:-1] + s * u[1:], axis=1)
        for s, w in zip(points, weights, strict=True)
    )


class PDGSubproblem:
    """Parametric convex subproblem for ``n_nodes`` nodes; see the module docstring."""

    def __init__(self, n_nodes: int, fix_roll: bool = False, soft: bool = False) -> None:
        if n_nodes < 3:
            raise ValueError(f"n_nodes must be at least 3, got {n_nodes}")
        self.n_nodes = n_nodes
        self.fix_roll = fix_roll
        self.soft = bool(soft)
        n, k = n_nodes, n_nodes - 1
        P = cp.Parameter
        self.A = P((k, 14 * 14), name="A")  # row-major A_k per interval (batched_matvec)
        self.Bm = P((k, 14 * 3), name="Bm")
        self.Bp = P((k, 14 * 3), name="Bp")
        self.S = P((k, 14), name="S")
        self.z = P((k, 14), name="z")
        self.x_ref = P((n, 14), name="x_ref")
        self.u_ref = P((n, 3), name="u_ref")
        self.sigma_ref = P(name="sigma_ref")
        self.thrust_dir = P((n, 3), name="thrust_dir")
        self.eta_x = P(14, nonneg=True, name="eta_x")  # eta * scale per state component
        self.eta_u = P(3, nonneg=True, name="eta_u")
        self.eta_sigma = P(nonneg=True, name="eta_sigma")
        self.lambda_ = P(nonneg=True, name="lambda")
        self.x0 = P(14, name="x0")
        self.r_f = P(3, name="r_f")
        self.v_f = P(3, name="v_f")
        self.m_dry = P(name="m_dry")
        self.tan_gs = P(nonneg=True, name="tan_gamma_gs")
        self.tilt_bound = P(nonneg=True, name="tilt_bound")
        self.omega_max = P(nonneg=True, name="omega_max")
        self.T_min = P(nonneg=True, name="T_min")
        self.T_max = P(nonneg=True, name="T_max")
        self.cos_delta = P(nonneg=True, name="cos_delta_max")
        self.tf_bounds = P(2, name="tf_bounds")
        self.mass_rate = P(nonneg=True, name="sigma_alpha_dtau")  # sigma_bar alpha / (N - 1)
        self.mass_offset = P(k, name="c_mass")  # c_k of the mass row

        self.w_x = P(len(STATE_GROUPS), nonneg=True, name="w_x")  # soft weight per state group
        self.w_u = P(nonneg=True, name="w_u")
        self.w_sigma = P(nonneg=True, name="w_sigma")
        self.wx_ref = P((n, 14), name="wx_ref")  # weight * x_ref (keeps the objective DPP)
        self.wu_ref = P((n, 3), name="wu_ref")
        self.wsigma_ref = P(name="wsigma_ref")
        self.state_groups = [
            cp.Variable((n, stop - start), name=f"X_{name}") for name, start, stop in STATE_GROUPS
        ]
        self.X = cp.hstack(self.state_groups)
        self.U = cp.Variable((n, 3), name="U")
        self.sigma = cp.Variable(name="sigma")
        self.nu = cp.Variable((k, 14), name="nu")
        self.buffers = cp.Variable(n, nonneg=True, name="s")
        self.problem = self._build()
        self._instance: PDGInstance | None = None  # whose values the parameters hold
        self._z_linear: np.ndarray | None = None  # affine term of the current linearization
        self._mass_offset_linear: np.ndarray | None = None  # c_k of the current linearization
        self._alpha_mdot = 0.0  # alpha of Eq. 4a (set_instance)
        self._slices: dict[str, VariableSlices] = {}  # per solver: variable_slices

    def named_variables(self) -> dict[str, cp.Variable]:
        """The decision variables by name: the state groups ``x0, x1, ...``, ``u``, ``sigma``,
        ``nu`` and the buffers ``s``."""
        groups = {f"x{i}": var for i, var in enumerate(self.state_groups)}
        return groups | {"u": self.U, "sigma": self.sigma, "nu": self.nu, "s": self.buffers}

    def primal_slices(self, solver: str) -> VariableSlices:
        """Where :meth:`named_variables` sit in the conic primal vector for ``solver``."""
        if solver not in self._slices:
            self._slices[solver] = variable_slices(self.problem, solver, self.named_variables())
        return self._slices[solver]

    def _build(self) -> cp.Problem:
        X, U, sigma = self.X, self.U, self.sigma
        linearized = (  # Eq. 10, all intervals at once
            batched_matvec(self.A, X[:-1], 14, 14)
            + batched_matvec(self.Bm, U[:-1], 14, 3)
            + batched_matvec(self.Bp, U[1:], 14, 3)
            + self.S * sigma
            + self.z
            + self.nu
        )
        thrust = cp.norm(U, 2, axis=1)  # |U_k|: Eqs. 6a-b and the mass row's end points
        self.mass_row = self._mass_row(thrust)
        dynamics = [X[1:, :MASS] == linearized[:, :MASS], self.mass_row]
        ones = np.ones((self.n_nodes, 1))
        terminal_q, terminal_w = terminal_attitude_columns(self.fix_roll)
        self.inequalities = {  # one (N,) constraint per name of constraints.CONSTRAINT_NAMES
            "mass": X[:, 13] >= self.m_dry,  # 5a
            "glideslope": cp.multiply(self.tan_gs, cp.norm(X[:, 1:3], 2, axis=1)) <= X[:, 0],
            "tilt": cp.norm(X[:, 8:10], 2, axis=1) <= self.tilt_bound,  # 5c
            "omega": cp.norm(X[:, 10:13], 2, axis=1) <= self.omega_max,  # 5d
            "thrust_min": self.T_min - cp.sum(cp.multiply(self.thrust_dir, U), axis=1)
            <= self.buffers,  # 6a lower, linearized about u_ref with the virtual buffer
            "thrust_max": thrust <= self.T_max,  # 6a upper
            "gimbal": cp.multiply(self.cos_delta, thrust) <= U[:, 0],  # 6b
        }
        self.trust_box = [  # the hard trust region (a far safeguard under the soft one)
            X - self.x_ref <= ones @ self.eta_x[None, :],
            self.x_ref - X <= ones @ self.eta_x[None, :],
            U - self.u_ref <= ones @ self.eta_u[None, :],
            self.u_ref - U <= ones @ self.eta_u[None, :],
            sigma - self.sigma_ref <= self.eta_sigma,
            self.sigma_ref - sigma <= self.eta_sigma,
        ]
        constraints = [
            *dynamics,
            X[0] == self.x0,
            X[-1, 0:3] == self.r_f,
            X[-1, 3:6] == self.v_f,
            X[-1, terminal_q] == (np.array([1.0, 0, 0, 0])[[t - 6 for t in terminal_q]]),
            X[-1, terminal_w] == 0.0,
            *self.inequalities.values(),
            sigma >= self.tf_bounds[0],
            sigma <= self.tf_bounds[1],
            *self.trust_box,
        ]
        penalty = cp.sum(cp.abs(self.nu)) + cp.sum(self.buffers)
        cost = -X[-1, 13] + self.lambda_ * penalty
        if self.soft:
            cost = cost + self._deviation_without_constant()
        return cp.Problem(cp.Minimize(cost), constraints)

    def _mass_row(self, thrust: cp.Expression) -> cp.Constraint:
        """``m_{k+1} <= m_k - sigma_bar alpha dtau I_k(U) + S_k^m sigma + c_k + nu_k^m`` (Eq. 4a).

        ``I_k(U) = sum_j w_j |(1 - s_j) U_k + s_j U_{k+1}|``, ``dtau = 1 / (N - 1)``: the
        composite Simpson rule of :data:`MASS_QUADRATURE`, which is what the two-step RK4 of the
        discretization computes for a state-independent rate (module docstring; the numbers
        at the reference come from :func:`mean_thrust`). The end points ``s = 0, 1`` are the
        node norms ``|U_k|`` of Eqs. 6a-b, ``thrust``: one cone per node instead of two per
        interval, 98 fewer second-order cones at N = 50 (the subproblem is the same). The
        reduced subproblem of T-SCvx (:mod:`~scpformer.problems.pdg6dof.reduced`) keeps
        that shared cone, and the interior points' cones, with every row.
        """
        X, U = self.X, self.U
        points, weights = MASS_QUADRATURE
        mean_norm = sum(
            w * (thrust[:-1] if s == 0.0 else thrust[1:] if s == 1.0
                 else cp.norm((1.0 - s) * U[:-1] + s * U[1:], 2, axis=1))
            for s, w in zip(points, weights, strict=True)
        )  # fmt: skip
        return X[1:, MASS] <= (
            X[:-1, MASS]
            - self.mass_rate * mean_norm
            + cp.multiply(self.S[:, MASS], self.sigma)
            + self.mass_offset
            + self.nu[:, MASS]
        )

    def _deviation_without_constant(self) -> cp.Expression:
        """``sum_g w_g |z_g - z_bar_g|^2`` over the variable groups, less its constant part.

        Expanded as ``w |z|^2 - 2 <w z_bar, z>``: cvxpy canonicalizes ``sum_squares`` of a bare
        variable straight into the quadratic objective, whereas ``sum_squares(z - z_bar)``
        gets an auxiliary variable and an equality row per entry (851 of each at N = 50, a
        third of the conic problem). Same minimizer; the constant ``w |z_bar|^2`` is left out
        (the linearized cost ``L`` is computed from the solution, not from the objective).
        """
        X, U, sigma = self.X, self.U, self.sigma
        quadratic = sum(self.w_x[i] * cp.sum_squares(v) for i, v in enumerate(self.state_groups))
        return (
            quadratic
            + self.w_u * cp.sum_squares(U)
            + self.w_sigma * cp.square(sigma)
            - 2.0 * cp.sum(cp.multiply(self.wx_ref, X))
            - 2.0 * cp.sum(cp.multiply(self.wu_ref, U))
            - 2.0 * self.wsigma_ref * sigma
        )

    def set_instance(self, instance: PDGInstance) -> None:
        """Write the boundary conditions and constraint bounds of ``instance``.

        A no-op when they already hold ``instance``, so that the SCvx loop can call it at every
        iteration for free.
        """
        if instance is self._instance:
            return
        self._instance = instance
        c = instance.constants
        assign(self.x0, instance.x0)
        assign(self.r_f, c.r_f)
        assign(self.v_f, c.v_f)
        assign(self.m_dry, c.m_dry)
        assign(self.tan_gs, instance.tan_gamma_gs)
        assign(self.tilt_bound, instance.tilt_bound)
        assign(self.omega_max, math.radians(c.omega_max_deg))
        assign(self.T_min, c.T_min)
        assign(self.T_max, c.T_max)
        assign(self.cos_delta, math.cos(math.radians(c.delta_max_deg)))
        assign(self.tf_bounds, (c.tf_min, c.tf_max))
        self._alpha_mdot = c.model().alpha_mdot
        self.scale_x, self.scale_u, self.scale_sigma = trust_region_scales(instance)

    def set_linearization(
        self, disc: FOHDiscretization, x: np.ndarray, u: np.ndarray, sigma: float
    ) -> None:
        """Write the FOH matrices and the reference trajectory of the current iterate."""
        k = disc.A.shape[0]
        assign(self.A, disc.A.reshape(k, -1))
        assign(self.Bm, disc.Bm.reshape(k, -1))
        assign(self.Bp, disc.Bp.reshape(k, -1))
        assign(self.S, disc.S)
        assign(self.z, disc.z)
        self._z_linear = disc.z
        assign(self.x_ref, x)
        assign(self.u_ref, u)
        assign(self.sigma_ref, sigma)
        norms = np.linalg.norm(u, axis=1, keepdims=True)
        safe = np.where(norms > 0.0, norms, 1.0)
        assign(self.thrust_dir, np.where(norms > 0.0, u / safe, np.array([1.0, 0.0, 0.0])))
        self._set_mass_row(disc, x, u, sigma)

    def _set_mass_row(
        self, disc: FOHDiscretization, x: np.ndarray, u: np.ndarray, sigma: float
    ) -> None:
        """``sigma_bar alpha dtau`` and the offsets ``c_k`` that make the mass row hold with
        equality at the reference: ``c_k = F_k^m - m_k + sigma_bar alpha dtau I_k(u) -
        S_k^m sigma_bar`` (any difference between the discretization's integral and
        :data:`MASS_QUADRATURE`, e.g. for ``n_sub != 2``, goes into ``c_k``)."""
        rate = sigma * self._alpha_mdot / (self.n_nodes - 1)
        assign(self.mass_rate, rate)
        offset = (
            disc.x_next[:, MASS] - x[:-1, MASS] + rate * mean_thrust(u) - disc.S[:, MASS] * sigma
        )
        assign(self.mass_offset, offset)
        self._mass_offset_linear = offset

    def shift_affine_term(self, defects: np.ndarray) -> None:
        """Second-order correction: ``z_k <- z_k - d_k`` with the defects ``d`` (K, 14) of a
        candidate, so that the linearized dynamics aim at the nonlinear flow there (the SOC
        step of SQP, Nocedal & Wright Sec. 15.5); ``set_linearization`` undoes it."""
        assign(self.z, self._z_linear - defects)
        assign(self.mass_offset, self._mass_offset_linear - defects[:, MASS])

    def _set_soft_weights(self, weight: float) -> None:
        """Weights ``weight / scale_g^2`` of the soft trust region and their products with
        the reference (the scales are constant within each group of :data:`STATE_GROUPS`)."""
        w_cols = weight / self.scale_x**2
        w_groups = w_cols[[start for _, start, _ in STATE_GROUPS]]
        w_u, w_sigma = weight / self.scale_u[0] ** 2, weight / self.scale_sigma**2
        assign(self.w_x, w_groups)
        assign(self.w_u, w_u)
        assign(self.w_sigma, w_sigma)
        assign(self.wx_ref, self.x_ref.value * w_cols)
        assign(self.wu_ref, self.u_ref.value * w_u)
        assign(self.wsigma_ref, self.sigma_ref.value * w_sigma)

    def solve(
        self,
        eta: float,
        lambda_: float,
        solver: str = "clarabel",
        box: float | None = None,
        soft_weight: float = 0.0,
    ) -> SubproblemSolution:
        """Solve with trust radius ``eta`` and penalty weight ``lambda_``; failures are statuses.

        The hard trust region is the box of radius ``box`` (default ``eta``) in the units of
        :func:`trust_region_scales`. A soft subproblem also adds
        ``soft_weight sum_i ((z_i - z_bar_i) / scale_i)^2`` to the cost.
        """
        self.set_trust_region(eta, lambda_, box, soft_weight)
        slices = self.primal_slices(solver)
        call = solve_timed(self.problem, solver, reuse=True, settings=CONIC_SETTINGS, primal=slices)
        if not call.solved:
            return SubproblemSolution.failed(call.status, call.wall_time, call.solver_time)
        return self.solution_from(
            call.values, lambda_, call.status, call.solver_time, call.wall_time
        )

    def solution_from(
        self,
        values: dict[str, np.ndarray],
        lambda_: float,
        status: str,
        solve_time: float,
        wall_time: float,
    ) -> SubproblemSolution:
        """The :meth:`solution` of primal ``values`` keyed as :meth:`named_variables`."""
        n_groups = len(self.state_groups)
        x = np.hstack([values[f"x{i}"] for i in range(n_groups)])
        return self.solution(
            x, values["u"], float(values["sigma"]), values["nu"], values["s"], lambda_,
            status, solve_time, wall_time,
        )  # fmt: skip

    def set_trust_region(
        self, eta: float, lambda_: float, box: float | None = None, soft_weight: float = 0.0
    ) -> None:
        """Write the trust region (box radius ``box``, default ``eta``; soft weight) and lambda."""
        box = eta if box is None else box
        assign(self.eta_x, box * self.scale_x)
        assign(self.eta_u, box * self.scale_u)
        assign(self.eta_sigma, box * self.scale_sigma)
        assign(self.lambda_, lambda_)
        if self.soft:
            self._set_soft_weights(soft_weight)

    @staticmethod
    def solution(
        x: np.ndarray,
        u: np.ndarray,
        sigma: float,
        nu: np.ndarray,
        buffers: np.ndarray,
        lambda_: float,
        status: str,
        solve_time: float,
        wall_time: float,
    ) -> SubproblemSolution:
        """A solved subproblem's values with its linearized cost ``L`` (Eq. 13)."""
        buffers = np.maximum(buffers, 0.0)
        linear_cost = -x[-1, 13] + lambda_ * (np.abs(nu).sum() + buffers.sum())
        return SubproblemSolution(
            status=status,
            x=np.array(x, dtype=float),
            u=np.array(u, dtype=float),
            sigma=float(sigma),
            nu=np.array(nu, dtype=float),
            buffers=np.array(buffers, dtype=float),
            cost=float(linear_cost),
            solver_time=solve_time,
            wall_time=wall_time,
        )


def terminal_attitude_columns(fix_roll: bool) -> tuple[list[int], list[int]]:
    """State columns of the quaternion and of the rate fixed at the final node (Eqs. 3h-3i).

    The quaternion's vector part only (see the module docstring): ``[q2, q3]`` and
    ``[omega_y, omega_z]``, the roll ``q1`` and ``omega_x`` as well with ``fix_roll``.
    """
    return ([7, 8, 9], [10, 11, 12]) if fix_roll else ([8, 9], [11, 12])


def fixed_terminal_columns(fix_roll: bool) -> list[int]:
    """Every state column the terminal conditions fix: position, velocity and the attitude
    columns of :func:`terminal_attitude_columns`."""
    terminal_q, terminal_w = terminal_attitude_columns(fix_roll)
    return [0, 1, 2, 3, 4, 5, *terminal_q, *terminal_w]


def trust_region_scales(instance: PDGInstance) -> tuple[np.ndarray, np.ndarray, float]:
    """Per-variable scales of the trust region: ``|x_i - x_bar_i| <= eta * scale_i``.

    The paper scales its variables to their ranges (Sec. III.E.1) without listing the scales.
    A unit trust radius here spans position 1 U_L, velocity 0.5 U_L/U_T, quaternion 0.25, rates
    omega_max / 2, mass m0 - m_dry, thrust T_max / 4 and final time 0.5 U_T. These are tighter
    than the variable ranges on the thrust, rate and final-time axes, where the linearization
    error is largest (measured: the steps sat on those faces of the box and were rejected),
    and balanced so that no axis is left effectively unconstrained. Unscaled, the final time,
    ten times larger than the other variables, creeps towards its optimum by eta per iteration.
    """
    c = instance.constants
    scale_x = np.concatenate(
        [
            np.full(3, 1.0),
            np.full(3, 0.5),
            np.full(4, 0.25),
            np.full(3, 0.5 * math.radians(c.omega_max_deg)),
            [instance.m0 - c.m_dry],
        ]
    )
    return scale_x, np.full(3, 0.25 * c.T_max), 0.5


def compiled_subproblem(
    n_nodes: int, fix_roll: bool = False, prox_weight: float = 0.0, solver: str = "clarabel"
) -> PDGSubproblem:
    """The process-wide subproblem of a configuration: soft trust region iff ``prox_weight > 0``.

    ``prox_weight`` only selects the structure (its value is applied per solve), so every
    positive weight shares one compiled problem.
    """
    return _compiled_subproblem(n_nodes, fix_roll, prox_weight > 0.0, solver)


@functools.lru_cache(maxsize=8)
def _compiled_subproblem(n_nodes: int, fix_roll: bool, soft: bool, solver: str) -> PDGSubproblem:
    """The process-wide subproblem per structure, canonicalized for ``solver``.

    cvxpy's parametric canonicalization of this problem takes about 7 s for Clarabel and
    1.5 s for QOCO at N = 50 (measured). The canonicalized problem is therefore kept on disk (see
    :func:`scpformer.cache.cached_pickle`), keyed by the structure, the solver, the cvxpy and
    scpformer versions and this module's source, so that it is built once per machine rather
    than once per process.
    """
    key = f"pdg6dof-subproblem-N{n_nodes}-roll{int(fix_roll)}-soft{int(soft)}-{solver}"
    return compiled(key, lambda: PDGSubproblem(n_nodes, fix_roll, soft), solver, __file__)
