"""3-DoF powered descent with lossless convexification: a new problem family in one file.

The tutorial ``docs/new-family.md`` walks through this file and runs the whole pipeline on it
(solve, generate, train, warm-start). Import it with ``examples/`` on ``PYTHONPATH``
(``PYTHONPATH=examples python ...``): the dataset engine's worker processes import it by name.

Notation (Acikmese & Ploen 2007, fixed final time; z up)
--------------------------------------------------------
A point mass ``m`` with position ``r``, velocity ``v`` and thrust ``T`` in a uniform gravity
field ``g``; the engine's thrust magnitude is bounded below and above, ``rho_1 <= |T| <=
rho_2`` (nonconvex: the lower bound), and burns propellant at ``m' = -alpha |T|``.

*Lossless convexification*: relax ``|T|`` to a slack ``Gamma`` with ``|T| <= Gamma``,
``rho_1 <= Gamma <= rho_2``, ``m' = -alpha Gamma``. For minimum fuel the relaxed optimum has
``|T| = Gamma`` (their main result), so it solves the nonconvex problem.

*Change of variables*: ``u = T / m``, ``sigma = Gamma / m``, ``z = ln m`` make the dynamics
linear: ``r'' = u + g``, ``z' = -alpha sigma``, ``|u| <= sigma``. The bounds become
``rho_1 e^{-z} <= sigma <= rho_2 e^{-z}``: the lower one is convex (an exponential cone), the
upper one is not, and is replaced by its tangent at a reference ``z_ref``,
``sigma <= rho_2 e^{-z_ref} (1 - (z - z_ref))``, which lies below ``rho_2 e^{-z}`` (the
exponential is convex): every solution is feasible for the true bound. Re-solving with
``z_ref`` = the last solution's ``z`` until it stops moving is a sequential convex program
(a convex-concave procedure: the last solution stays feasible, so the cost does not rise);
the warm start provides the first ``z_ref``, by default Acikmese & Ploen's
``z_ref(t) = ln(m0 - alpha rho_2 t)``.

Discretization: ``u, sigma`` constant on each of the ``N`` intervals, which makes
``r_{k+1} = r_k + dt v_k + dt^2/2 (u_k + g)``, ``v_{k+1} = v_k + dt (u_k + g)``,
``z_{k+1} = z_k - alpha dt sigma_k`` exact. On interval ``k``, ``Gamma(t) = sigma_k m(t)``
decreases from ``sigma_k m_k`` to ``sigma_k m_{k+1}``: the upper bound is imposed at ``z_k``
and the lower at ``z_{k+1}``, so both hold at every instant, not just at the nodes.

The file has four parts: parameters (vehicle, configuration, instance, sampler), the solver
(convex subproblem built once, the SCP loop, verification), the warm start, and the dataset
family (registered as ``pdg3dof`` when the module is imported).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Any, ClassVar

import cvxpy as cp
import numpy as np
from scipy.integrate import solve_ivp

from scpformer.data.family import (
    FamilySpec,
    Field,
    SampleResult,
    dataclass_from_dict,
    package_versions,
    register_family,
)
from scpformer.scp.conic import check_solver, solve_timed, start_cold
from scpformer.scp.solution import Solution, Status, Timing, Trajectory, Verification
from scpformer.warmstart.base import WarmStartRecord, WarmStartResult, as_provider, timed

G0 = 9.80665  # standard gravity [m/s^2] (specific impulse to exhaust velocity)


# ======================================================================================
# parameters
# ======================================================================================
@dataclass(frozen=True, kw_only=True)
class Vehicle:
    """The lander of Acikmese & Ploen's numerical example (Mars), SI units; tf, the
    glideslope angle and the sampled ranges are ours."""

    g: tuple[float, float, float] = (0.0, 0.0, -3.7114)  # gravity [m/s^2], z up
    m_dry: float = 1505.0  # dry mass [kg]
    isp: float = 225.0  # specific impulse [s]; alpha = 1 / (isp g0)
    T_bar: float = 3100.0  # thrust of one of the six engines [N]
    cant_deg: float = 27.0  # engine cant angle [deg]; net thrust 6 T_bar cos(cant)
    throttle: tuple[float, float] = (0.3, 0.8)  # rho_1, rho_2 as fractions of the net thrust
    gamma_gs_deg: float = 30.0  # glideslope: elevation of r >= gamma_gs [deg] (our choice)

    @property
    def alpha(self) -> float:
        """Propellant use per unit thrust, 1 / (isp g0) [s/m]."""
        return 1.0 / (self.isp * G0)

    @property
    def rho(self) -> tuple[float, float]:
        """Thrust magnitude bounds (rho_1, rho_2) [N]."""
        net = 6.0 * self.T_bar * math.cos(math.radians(self.cant_deg))
        return self.throttle[0] * net, self.throttle[1] * net


@dataclass(frozen=True, kw_only=True)
class Config:
    """Vehicle, time grid and SCP settings of the family."""

    vehicle: Vehicle = field(default_factory=Vehicle)
    tf: float = 50.0  # fixed final time [s]
    n_intervals: int = 30  # N, intervals of constant u and sigma
    iter_max: int = 20  # subproblem solves at most
    z_tol: float = 1e-7  # converged when max_k |z_k - z_ref,k| <= z_tol (ln kg)
    lossless_tol: float = 1e-4  # |T| = Gamma to this relative tolerance counts as lossless
    solver: str = "clarabel"  # conic solver (scpformer.scp.conic.SOLVERS)

    def __post_init__(self) -> None:
        if not self.tf > 0.0:
            raise ValueError(f"tf must be positive, got {self.tf!r}")
        if isinstance(self.n_intervals, bool) or int(self.n_intervals) < 2:
            raise ValueError(f"n_intervals must be an integer >= 2, got {self.n_intervals!r}")
        if int(self.iter_max) < 1:
            raise ValueError(f"iter_max must be a positive integer, got {self.iter_max!r}")
        check_solver(self.solver)

    @property
    def dt(self) -> float:
        """Interval length [s]."""
        return self.tf / self.n_intervals

    @property
    def t(self) -> np.ndarray:
        """Node times (N+1,) [s]."""
        return np.linspace(0.0, self.tf, self.n_intervals + 1)


@dataclass(frozen=True, kw_only=True)
class Instance:
    """One landing: initial position [m], velocity [m/s] and mass [kg] (theta)."""

    r0: tuple[float, float, float]
    v0: tuple[float, float, float]
    m0: float

    def __post_init__(self) -> None:
        for name in ("r0", "v0"):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.shape != (3,) or not np.all(np.isfinite(value)):
                raise ValueError(f"{name} must be 3 finite numbers, got {getattr(self, name)!r}")
            object.__setattr__(self, name, tuple(float(c) for c in value))
        if not (math.isfinite(self.m0) and self.m0 > 0.0):
            raise ValueError(f"m0 must be a positive mass, got {self.m0!r}")

    @property
    def theta(self) -> np.ndarray:
        """(r0, v0, m0) as a vector (7,)."""
        return np.array([*self.r0, *self.v0, self.m0])

    @classmethod
    def from_theta(cls, theta: np.ndarray) -> Instance:
        """Inverse of :attr:`theta`."""
        theta = np.asarray(theta, dtype=float)
        return cls(r0=tuple(theta[:3]), v0=tuple(theta[3:6]), m0=float(theta[6]))


@dataclass(frozen=True, kw_only=True)
class Ranges:
    """Uniform ranges of theta (lower, upper) per component, inside the glideslope cone."""

    r0_low: tuple[float, float, float] = (-600.0, -600.0, 1500.0)  # [m]
    r0_high: tuple[float, float, float] = (600.0, 600.0, 2400.0)
    v0_low: tuple[float, float, float] = (-40.0, -40.0, -50.0)  # [m/s]
    v0_high: tuple[float, float, float] = (40.0, 40.0, -20.0)
    m0: tuple[float, float] = (1800.0, 1905.0)  # [kg]


def sample_instance(rng: np.random.Generator, ranges: Ranges | None = None) -> Instance:
    """One instance drawn uniformly from ``ranges``."""
    ranges = ranges or Ranges()
    return Instance(
        r0=tuple(rng.uniform(ranges.r0_low, ranges.r0_high)),
        v0=tuple(rng.uniform(ranges.v0_low, ranges.v0_high)),
        m0=float(rng.uniform(*ranges.m0)),
    )


# ======================================================================================
# the solver: a convex subproblem built once, re-solved with new parameter values
# ======================================================================================
class Subproblem:
    """The convexified problem on a fixed grid, with theta and z_ref as cvxpy Parameters.

    Minimizes the propellant ``sum_k sigma_k dt`` subject to the exact discrete dynamics,
    ``|u_k| <= sigma_k`` (the relaxation), ``rho_1 e^{-z_{k+1}} <= sigma_k`` (exponential
    cone), ``sigma_k <= b_k - a_k z_k`` (the tangent of ``rho_2 e^{-z}`` at ``z_ref,k``:
    ``a = rho_2 e^{-z_ref}``, ``b = a (1 + z_ref)``), the glideslope
    ``tan(gamma_gs) |r_xy| <= r_z``, ``m_N >= m_dry``, and rest at the origin at ``t_f``.
    """

    def __init__(self, config: Config) -> None:
        vehicle, n, dt = config.vehicle, config.n_intervals, config.dt
        g = np.array(vehicle.g)
        self.r0, self.v0 = cp.Parameter(3), cp.Parameter(3)
        self.z0 = cp.Parameter()
        self.a, self.b = cp.Parameter(n, nonneg=True), cp.Parameter(n)
        self.r, self.v = cp.Variable((n + 1, 3)), cp.Variable((n + 1, 3))
        self.z, self.u, self.sigma = cp.Variable(n + 1), cp.Variable((n, 3)), cp.Variable(n)
        r, v, z, u, sigma = self.r, self.v, self.z, self.u, self.sigma
        accel = u + np.tile(g, (n, 1))  # (N, 3)
        constraints = [
            r[1:] == r[:-1] + dt * v[:-1] + 0.5 * dt**2 * accel,
            v[1:] == v[:-1] + dt * accel,
            z[1:] == z[:-1] - vehicle.alpha * dt * sigma,
            cp.norm(u, 2, axis=1) <= sigma,  # |T| <= Gamma
            vehicle.rho[0] * cp.exp(-z[1:]) <= sigma,  # rho_1 <= Gamma at the interval's end
            sigma <= self.b - cp.multiply(self.a, z[:-1]),  # Gamma <= rho_2 at its start
            math.tan(math.radians(vehicle.gamma_gs_deg)) * cp.norm(r[:, :2], 2, axis=1) <= r[:, 2],
            z[n] >= math.log(vehicle.m_dry),
            r[0] == self.r0,
            v[0] == self.v0,
            z[0] == self.z0,
            r[n] == 0.0,
            v[n] == 0.0,
        ]
        self.problem = cp.Problem(cp.Minimize(dt * cp.sum(sigma)), constraints)

    def set_instance(self, instance: Instance) -> None:
        self.r0.value, self.v0.value = np.array(instance.r0), np.array(instance.v0)
        self.z0.value = math.log(instance.m0)

    def set_reference(self, z_ref: np.ndarray, rho_2: float) -> None:
        """Tangent of ``rho_2 e^{-z}`` at ``z_ref`` (N+1,) for the upper bounds."""
        self.a.value = rho_2 * np.exp(-z_ref[:-1])
        self.b.value = self.a.value * (1.0 + z_ref[:-1])


_SUBPROBLEMS: dict[Config, Subproblem] = {}  # built once per configuration and process


def subproblem(config: Config) -> Subproblem:
    """The :class:`Subproblem` of ``config`` (built on first use)."""
    if config not in _SUBPROBLEMS:
        _SUBPROBLEMS[config] = Subproblem(config)
    return _SUBPROBLEMS[config]


@dataclass(frozen=True)
class MinimumMassGuess:
    """Acikmese & Ploen's reference: the mass at full thrust, ``m0 - alpha rho_2 t``."""

    config: Config = field(default_factory=Config)

    def guess(self, instance: Instance) -> WarmStartResult:
        start = time.perf_counter()
        vehicle, t = self.config.vehicle, self.config.t
        m = np.maximum(instance.m0 - vehicle.alpha * vehicle.rho[1] * t, vehicle.m_dry)
        x = np.zeros((t.size, 7))
        x[:, :3] = np.linspace(instance.r0, 0.0, t.size)
        x[:, 3:6] = np.linspace(instance.v0, 0.0, t.size)
        x[:, 6] = m
        trajectory = Trajectory(x=x, u=np.zeros((t.size - 1, 3)), p=np.array([self.config.tf]))
        record = WarmStartRecord(
            source="minimum_mass", time_s=0.0, cost=instance.m0 - m[-1], constraint_to_go=math.nan
        )
        return WarmStartResult(trajectory, timed(record, start))


def solve(instance: Instance, config: Config | None = None, warmstart: Any = None) -> Solution:
    """Minimum-fuel landing of ``instance`` by successive convexification of the upper bound.

    Parameters
    ----------
    instance
        The landing (theta).
    config
        Vehicle, grid and SCP settings (default :class:`Config`).
    warmstart
        A provider whose ``guess(instance).trajectory.x[:, 6]`` is the mass profile (N+1,)
        the first subproblem linearizes about, a Trajectory or Solution, or None for
        :class:`MinimumMassGuess`.

    Returns
    -------
    Solution
        ``trajectory.x`` (N+1, 7) = (r, v, m), ``trajectory.u`` (N, 3) = thrust at the start of
        each interval [N], ``cost`` = propellant [kg]; ``extras`` hold ``Gamma`` (N,) at the
        interval starts, ``lossless_gap`` = max_k (Gamma_k - |T_k|) / Gamma_k, the cost after
        each solve (``costs``) and the warm start record.
    """
    config = config or Config()
    start = time.perf_counter()
    named = {"minimum_mass": lambda: MinimumMassGuess(config)}
    provider = MinimumMassGuess(config) if warmstart is None else as_provider(warmstart, named)
    guess = provider.guess(instance)
    extras: dict[str, Any] = {"warmstart": guess.record.to_dict(), "costs": []}
    if guess.trajectory is None:
        return _failed(Status.SOLVER_FAILED, "the warm start gave no trajectory", extras)
    vehicle = config.vehicle
    m_ref = np.clip(np.asarray(guess.trajectory.x)[:, 6], vehicle.m_dry, instance.m0)
    z_ref = np.log(m_ref)
    sub = subproblem(config)
    sub.set_instance(instance)
    start_cold(sub.problem)
    solver_time, status, message = 0.0, Status.MAX_ITERATIONS, "iteration limit reached"
    for iteration in range(1, config.iter_max + 1):
        sub.set_reference(z_ref, vehicle.rho[1])
        call = solve_timed(sub.problem, config.solver, reuse=True)
        solver_time += call.solver_time
        if not call.solved:
            infeasible = call.status.startswith("infeasible")
            status = Status.INFEASIBLE_INSTANCE if infeasible else Status.SOLVER_FAILED
            return _failed(status, f"subproblem {iteration}: {call.status}", extras)
        extras["costs"].append(instance.m0 - math.exp(sub.z.value[-1]))
        step, z_ref = float(np.max(np.abs(sub.z.value - z_ref))), sub.z.value.copy()
        if step <= config.z_tol:
            status, message = Status.CONVERGED, ""
            break
    return _solution(instance, config, sub, status, message, iteration, extras, start, solver_time)


def _solution(
    instance: Instance,
    config: Config,
    sub: Subproblem,
    status: Status,
    message: str,
    iterations: int,
    extras: dict[str, Any],
    start: float,
    solver_time: float,
) -> Solution:
    m = np.exp(sub.z.value)  # (N+1,)
    x = np.column_stack([sub.r.value, sub.v.value, m])  # (N+1, 7)
    thrust = sub.u.value * m[:-1, None]  # (N, 3) T = u m at the interval starts
    Gamma = sub.sigma.value * m[:-1]  # (N,)
    extras["Gamma"] = Gamma
    extras["lossless_gap"] = float(np.max((Gamma - np.linalg.norm(thrust, axis=1)) / Gamma))
    verify_start = time.perf_counter()
    verification = verify(instance, config, x, sub.u.value, sub.sigma.value)
    if status is Status.CONVERGED and not verification.passed:
        status, message = Status.VERIFICATION_FAILED, verification.message
    if status is Status.CONVERGED and extras["lossless_gap"] > config.lossless_tol:
        status = Status.VERIFICATION_FAILED
        message = f"not lossless: |T| < Gamma by {extras['lossless_gap']:.2g} (relative)"
    end = time.perf_counter()
    return Solution(
        status=status,
        trajectory=Trajectory(x=x, u=thrust, p=np.array([config.tf])),
        t=config.t,
        cost=instance.m0 - float(m[-1]),
        iterations=iterations,
        verification=verification,
        timing=Timing(end - start, 0.0, solver_time, end - verify_start),
        message=message,
        extras=extras,
    )


def _failed(status: Status, message: str, extras: dict[str, Any]) -> Solution:
    return Solution(
        status, None, None, math.nan, len(extras["costs"]), message=message, extras=extras
    )


def verify(
    instance: Instance, config: Config, x: np.ndarray, u: np.ndarray, sigma: np.ndarray
) -> Verification:
    """Propagate ``r'' = T/m + g``, ``m' = -alpha Gamma`` with ``T = u_k m``, ``Gamma = sigma_k
    m`` on each interval (DOP853) and compare with the nodes; check the bounds on ``Gamma``
    at both ends of each interval, the glideslope and the final rest state."""
    vehicle, dt, g = config.vehicle, config.dt, np.array(config.vehicle.g)
    state, defects = np.array([*instance.r0, *instance.v0, instance.m0]), []
    for k in range(config.n_intervals):

        def rhs(t: float, s: np.ndarray, k: int = k) -> np.ndarray:
            thrust, gamma = u[k] * s[6], sigma[k] * s[6]  # T(t), Gamma(t) [N]
            return np.concatenate([s[3:6], thrust / s[6] + g, [-vehicle.alpha * gamma]])

        state = solve_ivp(rhs, (0.0, dt), state, method="DOP853", rtol=1e-10, atol=1e-8).y[:, -1]
        defects.append(np.max(np.abs(state - x[k + 1])))
    m = x[:, 6]
    rho_1, rho_2 = vehicle.rho
    gamma_low, gamma_high = sigma * m[1:], sigma * m[:-1]  # Gamma(t) at interval end and start
    tan_gs = math.tan(math.radians(vehicle.gamma_gs_deg))
    violations = {
        "thrust_lower": max(0.0, float(np.max(rho_1 - gamma_low)) / rho_1),
        "thrust_upper": max(0.0, float(np.max(gamma_high - rho_2)) / rho_2),
        "glideslope": max(0.0, float(np.max(tan_gs * np.linalg.norm(x[:, :2], axis=1) - x[:, 2]))),
        "dry_mass": max(0.0, vehicle.m_dry - float(m[-1])),
    }
    terminal = {
        "position_m": float(np.linalg.norm(state[:3])),
        "velocity_m_s": float(np.linalg.norm(state[3:6])),
    }
    max_defect = float(max(defects))
    failed = [k for k, v in violations.items() if v > 1e-6]
    failed += [k for k, v in terminal.items() if v > 1e-3]
    failed += ["defect"] if max_defect > 1e-4 else []
    message = f"verification failed: {', '.join(failed)}" if failed else ""
    return Verification(not failed, terminal, max_defect, violations, {}, message)


# ======================================================================================
# the dataset family (scpformer.data.family.DatasetFamily), registered as "pdg3dof"
# ======================================================================================
@dataclass(frozen=True, kw_only=True)
class FamilyConfig:
    """What a ``pdg3dof`` dataset samples and how it solves."""

    ranges: Ranges = field(default_factory=Ranges)
    solver: Config = field(default_factory=Config)


@dataclass(frozen=True)
class PDG3DoFFamily:
    """The 3-DoF landing as the dataset engine sees it (picklable: config only)."""

    config: FamilyConfig = field(default_factory=FamilyConfig)
    name: ClassVar[str] = "pdg3dof"
    success_statuses: ClassVar[frozenset[str]] = frozenset({Status.CONVERGED.value})

    def config_dict(self) -> dict[str, Any]:
        return asdict(self.config)

    def schema(self) -> tuple[Field, ...]:
        n = self.config.solver.n_intervals
        return (
            Field(name="theta", dtype="float64", shape=(7,), normalize=True, doc="r0, v0, m0"),
            Field(name="cost", dtype="float64", doc="propellant m0 - m(t_f) [kg]"),
            Field(name="iterations", dtype="int64", doc="subproblem solves"),
            Field(name="x", dtype="float64", shape=(n + 1, 7), doc="r [m], v [m/s], m [kg]"),
            Field(name="m", dtype="float64", shape=(n + 1,), normalize=True, doc="mass [kg]"),
            Field(name="thrust", dtype="float64", shape=(n, 3), doc="T at interval starts [N]"),
            Field(name="Gamma", dtype="float64", shape=(n,), doc="thrust slack [N]"),
            Field(name="lossless_gap", dtype="float64", doc="max (Gamma - |T|) / Gamma"),
            Field(name="solve_time", dtype="float64", deterministic=False, doc="s in solve()"),
        )

    def versions(self) -> dict[str, str]:
        return package_versions(["numpy", "scipy", "cvxpy", "clarabel"])

    def warm_up(self) -> None:
        subproblem(self.config.solver)

    def sample(self, rng: np.random.Generator) -> Instance:
        return sample_instance(rng, self.config.ranges)

    def encode_instance(self, instance: Instance) -> dict[str, Any]:
        return {"theta": instance.theta}

    def solve(self, instance: Instance) -> SampleResult:
        solution = solve(instance, self.config.solver)
        fields: dict[str, Any] = {"theta": instance.theta, "iterations": solution.iterations}
        if solution.trajectory is not None:
            x = solution.trajectory.x
            fields |= {
                "cost": solution.cost,
                "x": x,
                "m": x[:, 6],
                "thrust": solution.trajectory.u,
                "Gamma": solution.extras["Gamma"],
                "lossless_gap": solution.extras["lossless_gap"],
            }
        fields["solve_time"] = solution.timing.total if solution.timing else math.nan
        solver_time = solution.timing.solver if solution.timing else 0.0
        return SampleResult(solution.status.value, solution.message, fields, solver_time)


def _build(config: dict | None) -> PDG3DoFFamily:
    return PDG3DoFFamily(dataclass_from_dict(FamilyConfig, config) if config else FamilyConfig())


SPEC = register_family(
    FamilySpec(
        name="pdg3dof", summary="3-DoF powered descent, lossless convexification", build=_build
    ),
    replace=True,
)
