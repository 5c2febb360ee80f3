"""T-SCvx (Algorithm 2 of the T-SCvx paper): SCvx on subproblems reduced to the tight rows.

Given a predictor of the tight rows ``tau = f_2(theta, k)`` and of the solution
``z = f_1(theta)`` (the API of :mod:`scpformer.models.tscvx`, :class:`TscvxPredictor`),
:func:`solve_tscvx` runs the SCvx loop of :func:`scpformer.scp.scvx.solve_scvx` (the same
ratio test, second-order correction and stopping test as cold SCvx, on the full problem) with
three changes:

* step 1: the subproblem of iteration k holds the ``(name, node)`` rows predicted tight,
  ``f_2(theta, k)``, plus the rows that the current iterate violates or nearly violates
  (:func:`near_active_rows`, ``g / scale >= -margin``), plus all equalities, solved on the
  sliced conic data of :mod:`scpformer.problems.pdg6dof.reduced`; by default (not in the
  paper, ``sticky_rows`` of :class:`TscvxParameters`) it also keeps every row kept before in
  the run, and the first one the rows predicted for the first few iterations;
* the penalized cost J is that of the FULL nonlinear problem (Eq. 16): the convex rows left
  out of a subproblem enter J with weight lambda when a candidate violates them, and a
  candidate that violates a left-out row by more than ``violation_tol`` is re-solved with
  those rows added (a repair) before the ratio test sees it;
* the trust radius follows Eq. 22 with the fraction ``tau_r`` of predicted flags that changed
  since the previous iteration (:func:`eq22_update`).

Not in the paper: a reduced solve leaves the virtual control ``nu`` out as well
(``drop_virtual``, :mod:`~scpformer.problems.pdg6dof.reduced`), and with it the safeguard box
of the soft trust region; a solve that turns out to need ``nu`` is solved again with it (and
the next solves keep it until one needs none), so every step is still the optimum of the
subproblem with ``nu``.

Fallbacks: after ``max_repairs`` repairs in one iteration, or ``stall_rejections`` rejected
steps in a row, the loop switches to the full subproblem for the rest of the run
(``extras["tscvx"]["fallback"] = "full"``); a run that still ends unconverged is replaced by
a cold SCvx solve from the default cold start, the cubic profile (``"cold"``; its iterations
and time are added to the run's, and ``extras["warmstart"]["used"]`` names it), so T-SCvx never
reports a trajectory that the full problem's verification rejects. A run that stalls (an
infeasible stationary point, by a stall test over 5 accepted iterates) is reported as
stalled without that fallback: on the draws measured, cold SCvx stalled wherever T-SCvx did
(:class:`TscvxParameters`, ``fallback_after_stall``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from scpformer.problems.pdg6dof import constraints as con
from scpformer.problems.pdg6dof.adapter import LEAST_CHANGE, PDGProblem, candidate
from scpformer.problems.pdg6dof.config import PDGSolverConfig
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.reduced import ReducedSubproblem, cached_layout
from scpformer.problems.pdg6dof.restart import concatenated, solve_with_restart
from scpformer.scp.conic import SubproblemSolution
from scpformer.scp.scvx import Candidate, Evaluation, SCvxParameters, solve_scvx
from scpformer.scp.solution import Solution, Status, Trajectory
from scpformer.validation import check_int, check_positive


class TscvxPredictor(Protocol):
    """What T-SCvx asks of the networks (``scpformer.models.tscvx.TscvxPredictor``)."""

    n_nodes: int

    def predict_tight(self, theta: np.ndarray, k: np.ndarray) -> np.ndarray:
        """Flags (B, 7N) of the rows predicted tight for ``theta`` (B, 16) at SCvx iterations
        ``k`` (B,) (1-based): T-SCvx asks for several iterations of one instance at once."""

    def predict_solution(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """Predicted ``(x (N, 14), u (N, 3), t_f)``."""


@runtime_checkable
class TscvxProvider(Protocol):
    """A warm start that can drive Algorithm 2: its guess under a configuration and the
    predicted tight rows (``scpformer.warmstart.tscvx.TscvxWarmStart``)."""

    params: TscvxParameters

    def guess_for(self, instance: PDGInstance, config: PDGSolverConfig) -> Any:
        """The ``WarmStartResult`` of ``instance`` under ``config``."""

    def tight(self, instance: PDGInstance) -> Any:
        """``k -> flags (7N,)`` of the rows predicted tight at iteration ``k``."""


@dataclass(frozen=True, kw_only=True)
class TscvxParameters:
    """T-SCvx settings (not in the paper, but for Table 1's eta_reduced,init = 0.01).

    ``eta_init = 2`` (cold SCvx's), not Table 1's 0.01: the stopping test shared with cold
    SCvx (:func:`scpformer.scp.scvx.meets_stopping_test`) certifies stationarity only with a
    trust radius of at least ``eta_stationary = 1``, and from a guess at the optimum the steps
    are too small for the ratio test to grow 0.01 to 1 (measured on 4 nominal instances with
    the oracle predictor: 10 to 100 solves at 0.01, with one run stuck at max_iterations,
    against 1 to 2 solves at 1). The soft trust region keeps the first steps short anyway. With
    the networks' guesses (12 + 12 nominal instances, seeds 5 and 6, networks trained on 8,208
    samples) 2 rather than 1 took the median from 12 to 9 and from 13 to 11 solves.

    ``eta_ub = 6``, not Table 1's 10 (which cold SCvx keeps): the paper gives T-SCvx a
    smaller trust region because its guess is already close to the solution, and that is
    where the radius matters here too. From the networks' guesses the cost is within 0.1% of
    the optimum after two solves; what remains is moving the thrust switches along a flat
    valley, where steps of radius 8 to 10 overshoot (ratios of -5 to -100) and each rejected
    step costs a conic solve. A smaller radius also certifies stationarity sooner (the
    predicted decrease of a smaller soft trust region is smaller), which costs optimality:
    that is why 6 and not the fastest value, 4. Chosen on validation draws, never on the test
    sets, with ``thrust_gain = 4``, mean / median ms per run (conic solves), alternating per
    draw; eta_ub 10 against 4, other values after the semicolon:

    * seed 26 rotated, samples 1, 5, 9, ... (100): 123.1 / 106.7 (5.6) against 102.4 / 94.5
      (4.9); 6: 106.8 / 100.4.
    * seed 26 rotated, samples 2, 6, 10, ... (100): 103.2 / 90.8 (5.6) against 85.7 / 77.9
      (4.9); 2: 105.1 / 89.1, 3: 88.2 / 86.7.
    * seed 26 rotated, samples 3, 7, 11, ... (100): 129.0 / 110.9 (5.6) against 105.5 / 95.8
      (4.9); 5: 104.3 / 100.3.
    * seed 28, 60 base draws: 259.6 / 110.4 (7.3) against 218.6 / 93.6 (6.0); 3: 206.2 /
      98.7, 5: 219.9 / 94.4 (the means hold 4 draws that no method solves, each ending in
      the cold fallback).
    * seed 26 rotated, samples 0, 4, 8, ... (100), with the propellant gap to cold SCvx
      (median, 90th percentile and largest, in % of cold SCvx's propellant): 10: 135.9 /
      117.0 ms, gaps -0.005, 0.019, 0.042%; 6: 116.1 / 110.1 ms, gaps 0.006, 0.055, 0.11%;
      4: 114.2 / 107.7 ms, gaps 0.027, 0.090, 0.17%.

    Cold SCvx with a smaller radius gains less and not everywhere: with eta_ub 6 instead of
    10 its mean went from 405.8 to 353.3 ms on 85 of the seed 26 draws, from 442.9 to 420.0
    ms on the 60 of seed 28, and its median on the 20 nominal instances of ``scpformer bench
    pdg6dof`` from 0.207 / 0.214 to 0.220 / 0.222 s; it keeps Table 1's 10.
    ``thrust_gain``: the predicted thrust magnitudes are sharpened towards the bounds
    (:func:`sharpened_magnitudes`). Measured with eta_ub 10, before it was lowered: gains of
    1, 2, 3, 4 and 6 on 140 rotated seed 26 draws (samples 1, 4, 7, ...): 123.5, 114.3, 114.4,
    113.0 ms mean (1 to 4); on samples 2, 5, 8, ...: 113.5 (1), 103.2 (3), 101.1 (4), 107.7
    (6) ms, with 6.04, 5.67, 5.52 and 5.91 conic solves.
    ``sticky_rows``: the paper's subproblem of iteration k holds the rows predicted for k;
    here a row, once kept, stays kept for the rest of the run, and the first subproblem
    holds the rows predicted for any of the first ``lookahead`` iterations (one forward pass,
    :data:`scpformer.warmstart.tscvx.TIGHT_BATCH`). Extra rows are harmless to the solution
    (the left-out rows are those the optimum does not need), and an unchanged row set lets
    Clarabel update its solver in place instead of setting up a new one (about 2.5 ms each):
    2.1 instead of 3.4 set-ups per run. On three slices of 100 rotated seed 26 validation
    draws (samples 0, 4, 8, ...; 1, 5, 9, ...; 3, 7, 11, ...) the mean run went from 113.7,
    125.2 and 112.6 ms to 106.9, 119.5 and 108.0 ms, the medians from 103.6, 115.6 and 104.7
    to 99.2, 117.3 and 101.6 ms, with 4.9-5.0 conic solves either way. (Before ``thrust_gain``
    and ``eta_ub`` shortened the runs it made no difference: 120.8 against 120.2 ms.)
    ``margin``: a row left out of the prediction is still kept when the current iterate has
    ``g / scale >= -margin`` (scales of :func:`row_scales`: 30% of the constraint's range by
    default), so that a step of the trust region's size rarely crosses a left-out row (with
    5%, the repairs of crossed rows cost 10-20% more wall time on the same 24 instances).
    30% rather than 20% since the compiled dynamics made everything around
    the conic solves cheaper. Alternating per draw on the 423 rotated validation samples of
    ``generate pdg6dof --n 60 --seed 26`` (even and odd ones, 212 and 211 draws), 0.3
    against 0.2 took the mean T-SCvx run from 149.9 to 148.4 ms and from 151.3 to 148.8 ms
    (conic solves 6.02 -> 5.97 and 6.07 -> 5.99); 0.1 was 17% slower and 0.6 4% slower on 60
    of them, and on the 60 base draws 0.3 and 0.2 had the same median.
    ``shrink_floor``: Eq. 22 divides the radius by ``alpha^tau_r`` on a poor or rejected step;
    with unchanged predictions (``tau_r = 0``) a rejected step would then be retried with the
    same radius, the same subproblem and the same outcome. The exponent is therefore
    ``max(tau_r, shrink_floor)`` (1: contractions as Eq. 15; 0: Eq. 22 literally).
    ``drop_box``: under the soft trust region the hard box (radius ``SOFT_BOX_FACTOR eta``)
    is a safeguard that never binds in practice; with ``drop_box`` it is left out (and the
    step re-solved with it when it leaves the box). Off by default: the box's rows are few,
    but it bounds every variable, and without it Clarabel needed 28 interior-point
    iterations per reduced subproblem instead of 20 (10 feasible-range instances, seed 5, 83
    solves either way, final masses equal to 6 digits): 65 against 50 ms per solve.
    ``drop_virtual``: leave ``nu`` and the box out of every reduced solve unless the last
    one needed ``nu`` (module docstring). Without ``nu`` and the box a reduced subproblem has
    about half of the rows and columns, Clarabel needs 17-18 interior-point iterations
    instead of 19-20 and 17 ms instead of 25 (3 held-out instances, at the optimum and at the
    cubic guess, setup included); the result agrees with the solve with ``nu`` to Clarabel's
    tolerance (largest difference 8e-6). On 40 held-out draws from the networks' guesses no
    solve needed ``nu`` (252 solves); dropping it only after a solve without it, the first
    solve of each run kept it: 0.188 s against 0.181 s mean per run.
    ``guess_factor``: J (Eq. 16) is a poor measure of a guess's distance to the optimum, as
    its L1 defects grow with any noise on the states: measured on nominal instances, the
    cold optimum with Gaussian noise of 2% of the trust-region scales has about 1.1 times
    the straight line's J, yet SCvx converges from it in 12-14 solves against 47-63 from the
    straight line (and in 24-38 with 20% noise, J about 11 times). Only a prediction with J
    above ``guess_factor`` times the straight line's (e.g. random states: 400 times) is
    replaced.
    ``stall_window`` and ``fallback_after_stall``: a draw with no landing costs T-SCvx its
    own attempt and then, with ``cold_fallback``, a cold SCvx run that stalls too. Measured on
    30 tuning draws of the feasible sampler (seed 90210, never used for training or for the
    test figures): the 5 draws on which T-SCvx stalled were the 5 on which cold SCvx stalled
    (after 26-52 solves), and T-SCvx plus its cold fallback took 2.5-6.8 s on them against
    1.4-4.3 s for cold SCvx alone. The accepted penalties of those T-SCvx runs level off
    after 4-6 accepted iterations at 0.01-0.1 and then fall by under 2% in 5, whereas every
    converging run (25) was below ``stall_penalty`` by its fourth accepted iterate. So T-SCvx
    applies the stall test of :mod:`scpformer.scp.scvx` over 5 accepted iterates instead of
    cold SCvx's 15, and a stalled T-SCvx run is returned as stalled (an infeasible
    stationary point, as cold SCvx would report) without the cold fallback; a run that ends
    otherwise unconverged (the iteration cap, a solver failure) still falls back.
    """

    eta_init: float = 2.0  # initial trust radius (Table 1's eta_reduced,init: 0.01, see above)
    eta_ub: float = 6.0  # largest trust radius (cold SCvx: Table 1's 10, see above)
    margin: float = 0.3  # near-active rows of the iterate are kept (units of row_scales)
    violation_tol: float = 1e-6  # left-out row violated when g > this [nondimensional]
    max_repairs: int = 2  # re-solves per iteration with violated rows added, then full
    stall_rejections: int = 3  # rejected steps in a row before the full subproblem
    shrink_floor: float = 1.0  # least exponent of alpha in Eq. 22's contractions
    drop_box: bool = False  # leave out the safeguard box of the soft trust region
    drop_virtual: bool = True  # leave out nu (and the box) unless the last solve needed nu
    cold_fallback: bool = True  # an unconverged run is replaced by cold SCvx
    fallback_after_stall: bool = False  # ... also one that stalled (see above)
    stall_window: int = 5  # accepted iterates of T-SCvx's stall test (cold SCvx: 15)
    guess_factor: float = 20.0  # a predicted guess with J above this many straight lines' J
    # is replaced by the cubic-profile cold start (TscvxWarmStart)
    thrust_gain: float = 4.0  # slope of the predicted thrust magnitudes' sharpening (1: none)
    sticky_rows: bool = True  # a row kept once stays kept for the rest of the run
    lookahead: int = 8  # with sticky_rows, the first subproblem holds the rows predicted for
    # iterations 1 .. lookahead

    def __post_init__(self) -> None:
        for name in ("eta_init", "eta_ub", "violation_tol", "guess_factor", "thrust_gain"):
            check_positive(name, getattr(self, name))
        if not self.eta_init <= self.eta_ub:
            raise ValueError(
                f"T-SCvx needs eta_init <= eta_ub, got eta_init {self.eta_init} and eta_ub "
                f"{self.eta_ub}"
            )
        if not self.margin >= 0.0:
            raise ValueError(f"margin must be nonnegative, got {self.margin}")
        if not 0.0 <= self.shrink_floor <= 1.0:
            raise ValueError(f"shrink_floor must be in [0, 1], got {self.shrink_floor}")
        for name in ("max_repairs", "stall_rejections", "stall_window"):
            check_int(name, getattr(self, name), least=0)
        check_int("lookahead", self.lookahead, least=1)


def eq22_update(
    eta: float, rho: float, params: SCvxParameters, tau_r: float, shrink_floor: float = 0.0
) -> tuple[float, bool]:
    """Trust radius after a step with ratio ``rho`` and whether it is accepted (Eq. 22).

    ``rho < rho_0``: rejected, ``eta / alpha^e``; ``rho < rho_1``: ``eta / alpha^e``;
    ``rho >= rho_2``: ``beta^(1 - tau_r) eta``; else unchanged; with
    ``e = max(tau_r, shrink_floor)`` and the result clipped to ``[eta_lb, eta_ub]``.
    """
    shrink = params.beta_sh ** max(tau_r, shrink_floor)
    accepted = rho >= params.rho_0
    if rho < params.rho_1:
        eta = eta / shrink
    elif rho >= params.rho_2:
        eta = eta * params.beta_gr ** (1.0 - tau_r)
    return float(np.clip(eta, params.eta_lb, params.eta_ub)), accepted


def row_scales(instance: PDGInstance, n_nodes: int) -> np.ndarray:
    """Range of each ``(name, node)`` row's ``g`` (7N,), flag order: the unit of ``margin``.

    Mass ``m0 - m_dry``; glideslope 1 U_L; tilt ``sin(theta_max / 2)``; rate ``omega_max``;
    the thrust rows ``T_max``.
    """
    c = instance.constants
    per_name = {
        "mass": instance.m0 - c.m_dry,
        "glideslope": 1.0,
        "tilt": max(instance.tilt_bound, 1e-3),
        "omega": math.radians(c.omega_max_deg),
        "thrust_min": c.T_max,
        "thrust_max": c.T_max,
        "gimbal": c.T_max,
    }
    return np.repeat([per_name[name] for name in con.CONSTRAINT_NAMES], n_nodes)


def near_active_rows(
    instance: PDGInstance, z: Trajectory, margin: float, scales: np.ndarray
) -> np.ndarray:
    """Rows with ``g(z) / scale >= -margin`` (violated or nearly so), flag order (7N,)."""
    values = con.constraint_values(instance, z.x, z.u).reshape(-1)
    return values >= -margin * scales


def convex_excess(instance: PDGInstance, z: Trajectory) -> float:
    """``sum max(0, h(z))`` over the convex rows: their term of Eq. 16 (tau_i = 1).

    Zero up to the conic solver's tolerance for a full subproblem's solution, which imposes
    the convex rows exactly; positive when a reduced subproblem left a violated row out.
    """
    values = con.constraint_values(instance, z.x, z.u)
    return float(np.maximum(values[list(con.CONVEX_ROWS)], 0.0).sum())


@dataclass
class TscvxLog:
    """What each subproblem solve of a T-SCvx run did (``Solution.extras["tscvx"]``)."""

    rows_kept: list[int] = field(default_factory=list)  # (name, node) rows per conic solve
    conic_rows: list[int] = field(default_factory=list)  # rows handed to the conic solver
    predicted: list[int] = field(default_factory=list)  # rows predicted tight per iteration
    tau_r: list[float] = field(default_factory=list)  # Eq. 22's changed fraction per iteration
    repairs: list[int] = field(default_factory=list)  # re-solves with violated rows added
    modes: list[str] = field(default_factory=list)  # reduced|full [correction], per solve
    without_virtual: list[bool] = field(default_factory=list)  # solved without nu, per solve
    virtual_retries: int = 0  # solves without nu that had to be repeated with it
    fallback: str | None = None  # None, "full" (switched mid-run) or "cold"
    fallback_reason: str = ""

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


class TscvxProblem(PDGProblem):
    """:class:`PDGProblem` whose subproblems hold the predicted tight rows (Algorithm 2)."""

    def __init__(
        self,
        instance: PDGInstance,
        config: PDGSolverConfig,
        tight: Any,
        params: TscvxParameters,
    ) -> None:
        super().__init__(instance, config)
        self.tight = tight  # k -> (7N,) bool flags predicted tight at iteration k
        self.params = params
        self.reduced = ReducedSubproblem(self.subproblem, cached_layout(self.subproblem))
        self.scales = row_scales(instance, config.n_nodes)
        self.log = TscvxLog()
        self.full_mode = False
        self.tau_r = 0.0
        self._previous_tau: np.ndarray | None = None
        self._keep: np.ndarray | None = None
        self._last_z: Trajectory | None = None
        self._rejections = 0
        self._virtual_free = True  # no solve of the run has needed nu yet (or the last one)

    def evaluate(self, z: Trajectory) -> Evaluation:
        """Eq. 16 on the full problem: the penalty also charges violated convex rows."""
        ev = super().evaluate(z)
        return dataclasses.replace(ev, penalty=ev.penalty + convex_excess(self.instance, z))

    def update_radius(self, eta: float, rho: float, params: SCvxParameters) -> tuple[float, bool]:
        """Eq. 22 with this iteration's ``tau_r`` (the radius update handed to SCvx)."""
        return eq22_update(eta, rho, params, self.tau_r, self.params.shrink_floor)

    def solve_subproblem(
        self, z: Trajectory, evaluation: Evaluation, eta: float, lambda_: float, solver: str
    ) -> Candidate:
        self._track_rejections(z)
        iteration = len(self.log.modes) + 1
        tau = np.asarray(self.tight(iteration), dtype=bool)
        self.tau_r = (
            0.0
            if self._previous_tau is None
            else float(np.abs(tau.astype(int) - self._previous_tau).mean())
        )
        self._previous_tau = tau.astype(int)
        self.log.predicted.append(int(tau.sum()))
        self.log.tau_r.append(self.tau_r)
        if self.full_mode:
            return self._full(super().solve_subproblem(z, evaluation, eta, lambda_, solver))
        self._keep = self._kept_before(iteration) | tau
        self._keep |= near_active_rows(self.instance, z, self.params.margin, self.scales)
        self.subproblem.set_instance(self.instance)
        self.subproblem.set_linearization(evaluation.linearization, z.x, z.u, float(z.p[0]))
        return self._reduced(z, eta, lambda_, solver)

    def least_change(self, *args: Any) -> Candidate | None:
        """:meth:`PDGProblem.least_change`, logged when it alone corrects the candidate."""
        cheap = super().least_change(*args)
        if cheap is not None:  # no conic solve: logged with the rows of the last one
            self._log_solve(LEAST_CHANGE, self.log.rows_kept[-1], 0, 0)
        return cheap

    def conic_correction(
        self, z: Trajectory, candidate: Candidate, ev: Evaluation, eta: float, lambda_: float,
        solver: str,
    ) -> Candidate:  # fmt: skip
        """The correction of :meth:`PDGProblem.conic_correction` on the reduced subproblem (the
        full one in full mode)."""
        if self.full_mode:
            full = super().conic_correction(z, candidate, ev, eta, lambda_, solver)
            return self._full(full, "full correction")
        self.subproblem.shift_affine_term(ev.linearization.defects(candidate.trajectory.x))
        return self._reduced(z, eta, lambda_, solver, "correction")

    def _kept_before(self, iteration: int) -> np.ndarray:
        """Rows this iteration keeps whatever it predicts (``sticky_rows``): those of the last
        reduced solve or, before the first, the rows predicted tight at any of the first
        ``lookahead`` iterations; none without ``sticky_rows``."""
        if not self.params.sticky_rows:
            return np.zeros(len(self.scales), dtype=bool)
        if self._keep is not None:
            return self._keep
        first = range(iteration, iteration + self.params.lookahead)
        return np.logical_or.reduce([np.asarray(self.tight(k), dtype=bool) for k in first])

    def _track_rejections(self, z: Trajectory) -> None:
        """Count rejected steps in a row (SCvx hands back the same iterate after a rejection)."""
        self._rejections = self._rejections + 1 if z is self._last_z else 0
        self._last_z = z
        if not self.full_mode and self._rejections >= self.params.stall_rejections > 0:
            self._switch_to_full(f"{self._rejections} rejected steps in a row")

    def _switch_to_full(self, reason: str) -> None:
        self.full_mode = True
        self.log.fallback, self.log.fallback_reason = "full", reason

    def _full(self, cand: Candidate, mode: str = "full") -> Candidate:
        self.tau_r = 0.0
        self._log_solve(mode, len(self.scales), self.reduced.layout.n_rows, 0)
        return cand

    def _log_solve(
        self, mode: str, rows_kept: int, conic_rows: int, repairs: int, virtual: bool = True
    ) -> None:
        self.log.modes.append(mode)
        self.log.without_virtual.append(not virtual)
        self.log.rows_kept.append(rows_kept)
        self.log.conic_rows.append(conic_rows)
        self.log.repairs.append(repairs)

    def _reduced(
        self, z: Trajectory, eta: float, lambda_: float, solver: str, mode: str = "reduced"
    ) -> Candidate:
        """Solve with ``self._keep``, adding left-out rows the candidate violates; without
        ``nu`` and the box first unless the last solve needed ``nu``."""
        weight, box = self.trust_region(eta)
        keep_virtual = not (self.params.drop_virtual and self._virtual_free and weight > 0.0)
        keep_box = keep_virtual and not (self.params.drop_box and weight > 0.0)
        self.subproblem.set_trust_region(eta, lambda_, box, weight)
        solver_time, repairs = 0.0, 0
        while True:
            sol = self.reduced.solve(self._keep, lambda_, keep_box, keep_virtual)
            solver_time += sol.solver_time
            if not keep_virtual and sol.x is None:  # needs nu (or failed): solve with it
                keep_virtual, keep_box = True, not (self.params.drop_box and weight > 0.0)
                self.log.virtual_retries += 1
                continue
            missing, box_left = self._left_out_violations(sol, z, box, keep_box)
            if not (missing.any() or box_left):
                break
            if repairs >= self.params.max_repairs:
                self._switch_to_full(f"left-out rows still violated after {repairs} repairs")
                full = super()._solve(eta, lambda_, solver)
                cand = dataclasses.replace(full, solver_time=full.solver_time + solver_time)
                return self._full(cand, f"full {mode}" if mode != "reduced" else "full")
            self._keep = self._keep | missing
            keep_box = keep_box or box_left
            repairs += 1
        size = self.reduced.last_size
        rows = size.rows if size is not None else 0
        self._log_solve(mode, int(self._keep.sum()), rows, repairs, keep_virtual)
        self._virtual_free = sol.nu is not None and (
            float(np.abs(sol.nu).sum()) <= self.config.scvx.virtual_tol
        )
        return dataclasses.replace(candidate(sol), solver_time=solver_time)

    def _left_out_violations(
        self, sol: SubproblemSolution, z: Trajectory, box: float, keep_box: bool
    ) -> tuple[np.ndarray, bool]:
        """Left-out rows the solution violates, and whether it left the dropped box."""
        if sol.x is None:
            return np.zeros_like(self._keep), False
        values = con.constraint_values(self.instance, sol.x, sol.u).reshape(-1)
        missing = (values > self.params.violation_tol) & ~self._keep
        if keep_box:
            return missing, False
        step = self.step_norm(Trajectory(x=sol.x, u=sol.u, p=np.array([sol.sigma])), z)
        return missing, step > box


def solve_tscvx(
    instance: PDGInstance,
    config: PDGSolverConfig,
    guess: Trajectory,
    tight: Any,
    params: TscvxParameters | None = None,
    *,
    verify: bool = True,
) -> Solution:
    """Algorithm 2 from ``guess`` with the predicted flags ``tight(k)`` (see module docstring).

    The returned solution's ``extras["tscvx"]`` is the :class:`TscvxLog` of the run (of the
    T-SCvx run, also when the cold fallback replaced its result). After a cold fallback the
    solution covers the whole path: its iterations, history and timing are those of the
    T-SCvx run followed by the cold run (``extras["tscvx_iterations"]``: the T-SCvx run's).
    ``verify=False`` skips the nonlinear check (``verification`` None).
    """
    params = params or TscvxParameters()
    problem = TscvxProblem(instance, config, tight, params)
    scvx = dataclasses.replace(  # T-SCvx's own trust radii: TscvxParameters
        config.scvx,
        eta_init=params.eta_init,
        eta_ub=params.eta_ub,
        eta_lb=min(config.scvx.eta_lb, params.eta_init),
        stall_window=params.stall_window,
    )
    if not verify:
        problem.verify = _not_verified  # type: ignore[method-assign]
    solution = solve_scvx(problem, guess, scvx, radius_update=problem.update_radius)
    log = problem.log
    if needs_cold_fallback(solution, params):
        log.fallback = "cold"
        log.fallback_reason = f"T-SCvx ended {solution.status.value}: {solution.message}"
        cold_problem = PDGProblem(instance, config)
        if not verify:
            cold_problem.verify = _not_verified  # type: ignore[method-assign]
        cold = solve_with_restart(cold_problem, cold_problem.initial_guess())
        extras = {"tscvx": log.to_dict(), "tscvx_iterations": solution.iterations}
        path = concatenated(dataclasses.replace(solution, extras={}), cold)
        return dataclasses.replace(path, extras={**cold.extras, **extras})
    return dataclasses.replace(solution, extras={**solution.extras, "tscvx": log.to_dict()})


def needs_cold_fallback(solution: Solution, params: TscvxParameters) -> bool:
    """Whether an ended T-SCvx run is replaced by cold SCvx: unconverged, with
    ``cold_fallback``, and not stalled unless ``fallback_after_stall``
    (:class:`TscvxParameters`)."""
    if solution.converged or not params.cold_fallback:
        return False
    return solution.status is not Status.STALLED or params.fallback_after_stall


def _not_verified(z: Trajectory) -> None:
    """The verification of a solve asked not to verify: none (never a passed one)."""
    return None


def consistent_guess(
    instance: PDGInstance,
    x: np.ndarray,
    u: np.ndarray,
    tf: float,
    n_nodes: int,
    thrust_gain: float = 1.0,
) -> Trajectory:
    """A predicted ``(x, u, t_f)`` made consistent where cheap.

    ``x_0`` is the instance's initial state, quaternions are normalized, the mass is clipped
    to ``[m_dry, m0]`` and made nonincreasing, thrust directions are brought into the gimbal
    cone (:func:`gimbal_projected_directions`), thrust magnitudes are clipped to
    ``[T_min, T_max]`` and sharpened with ``thrust_gain`` (:func:`sharpened_magnitudes`; 1
    leaves them), and the final time is clipped to ``[tf_min, tf_max]``. Raises
    ``ValueError`` on a wrong shape or a non-finite value.
    """
    c = instance.constants
    x = np.array(x, dtype=float)
    u = np.array(u, dtype=float)
    tf = float(tf)
    if x.shape != (n_nodes, 14) or u.shape != (n_nodes, 3):
        raise ValueError(f"predicted x {x.shape}, u {u.shape}: expected ({n_nodes}, 14), (.., 3)")
    if not (np.isfinite(x).all() and np.isfinite(u).all() and math.isfinite(tf)):
        raise ValueError("the predicted solution holds NaN or infinity")
    x[0] = instance.x0
    norms = np.linalg.norm(x[:, 6:10], axis=1, keepdims=True)
    x[:, 6:10] = np.where(norms > 1e-9, x[:, 6:10] / np.maximum(norms, 1e-9), [1.0, 0, 0, 0])
    x[:, 13] = np.minimum.accumulate(np.clip(x[:, 13], c.m_dry, instance.m0))
    thrust = np.linalg.norm(u, axis=1, keepdims=True)
    safe = np.where(thrust > 1e-9, thrust, 1.0)
    direction = np.where(thrust > 1e-9, u / safe, [1.0, 0.0, 0.0])
    direction = gimbal_projected_directions(direction, c.delta_max_deg)
    u = direction * sharpened_magnitudes(thrust, c.T_min, c.T_max, thrust_gain)
    tf = float(np.clip(tf, c.tf_min, c.tf_max))
    return Trajectory(x=x, u=u, p=np.array([tf]))


def sharpened_magnitudes(thrust: np.ndarray, T_min: float, T_max: float, gain: float) -> np.ndarray:
    """Thrust magnitudes pushed towards the bound they are nearer: ``T_min + s (T_max -
    T_min)`` with ``s = clip(1/2 + gain (t - 1/2), 0, 1)``, ``t`` the magnitude's place in
    ``[T_min, T_max]`` (clipped). ``gain = 1`` only clips; the midpoint stays where it is.

    Why: the minimum-fuel thrust of powered descent is bang-bang, at ``T_max`` or ``T_min``
    with a switch within a node or two (maximum principle; Acikmese & Ploen 2007 for the
    3-DoF problem, and the 6-DoF optima of our datasets), whereas the solution network,
    trained with MSE, predicts the switches as ramps over five or six nodes. Sharpening the
    ramps about their midpoints, where the optimum's switch most likely lies, gives SCvx a
    guess with the optimum's thrust structure: with the optimum's own thrust magnitudes in
    the predicted guess, T-SCvx needed 4.6 conic solves instead of 6.0 (30 validation draws
    of ``generate pdg6dof --n 60 --seed 26``, rotated). On those 30 draws gains of 2, 3 and 5
    gave 5.6, 5.5 and 5.5 solves, a hard switch (infinite gain) 5.9.
    """
    unit = np.clip((np.asarray(thrust) - T_min) / (T_max - T_min), 0.0, 1.0)
    return T_min + np.clip(0.5 + gain * (unit - 0.5), 0.0, 1.0) * (T_max - T_min)


def gimbal_projected_directions(direction: np.ndarray, delta_max_deg: float) -> np.ndarray:
    """Unit thrust directions (N, 3) brought into the gimbal cone of Eq. 6b.

    A direction within ``delta_max`` of the body axis ``e1`` is kept; one beyond it but in
    front of the body (``e1 . d > 0``) is turned onto the cone's edge about its own azimuth
    (the nearest direction of the cone); one that points backwards (``e1 . d <= 0``) becomes
    ``e1``. Why it matters: the solution network regresses the thrust, and across the switch
    from maximum to minimum thrust it predicts a vector near zero whose direction is noise
    (up to 178 deg off ``e1`` on validation draws). The first subproblem linearizes the thrust
    lower bound about that direction (Eq. 11, ``d_k . U_k >= T_min``), which no thrust inside
    the gimbal cone can meet when ``d_k`` points backwards: the solve pays virtual buffers and
    zeroes the thrust there, and SCvx needs one more solve to undo it (on 53 validation draws,
    ``generate pdg6dof --n 60 --seed 26``: 5.91 against 6.25 conic solves per T-SCvx run; the
    cone's edge for every direction outside it, backwards ones included, gave 6.15).
    """
    cos_max = math.cos(math.radians(delta_max_deg))
    sin_max = math.sin(math.radians(delta_max_deg))
    lateral = direction[:, 1:]
    lateral_norm = np.linalg.norm(lateral, axis=1, keepdims=True)
    azimuth = np.where(lateral_norm > 1e-12, lateral / np.maximum(lateral_norm, 1e-12), [1.0, 0.0])
    edge = np.column_stack([np.full(len(direction), cos_max), sin_max * azimuth])
    outside = direction[:, 0] < cos_max
    backwards = direction[:, 0] <= 0.0
    projected = np.where(outside[:, None], edge, direction)
    return np.where(backwards[:, None], [1.0, 0.0, 0.0], projected)
