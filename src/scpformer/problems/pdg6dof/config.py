"""How to pose and solve the 6-DoF problem: :class:`PDGSolverConfig` (T-SCvx paper, Table 1)
and the tolerances of the nonlinear check."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

from scpformer.scp.scvx import SCvxParameters
from scpformer.validation import check_in_range, check_int

SOFT_BOX_FACTOR = 100.0  # hard box radius / eta under the soft trust region (a safeguard only)


@dataclass(frozen=True, kw_only=True)
class PDGVerificationTolerances:
    """Tolerances of the nonlinear check (nondimensional units; not in the paper)."""

    terminal: float = 5e-3  # |propagated - required| of each fixed terminal quantity
    defect: float = 5e-3  # max |propagated node state - solution node state|
    constraint: float = 1e-3  # max constraint violation at the nodes
    rtol: float = 1e-10  # integrator relative tolerance
    atol: float = 1e-12  # integrator absolute tolerance
    samples_per_interval: int = 5  # dense samples between nodes for path violations


MAX_NODES = 1000  # largest N accepted (memory and time; see PDGSolverConfig.__post_init__)
MAX_SUBSTEPS = 1000  # largest n_sub accepted


@dataclass(frozen=True, kw_only=True)
class PDGSolverConfig:
    """How to pose and solve the 6-DoF problem; defaults are Table 1 of the T-SCvx paper.

    ``n_sub`` is the number of RK4 steps per interval of the FOH discretization. Table 1's
    N_sub = 49 (the SCPToolbox count of integration nodes) is far more than the dynamics need:
    on the converged nominal trajectory 2 RK4 steps per interval match an adaptive DOP853
    propagation (rtol 1e-12) to 8e-8, 250 times below ``defect_tol``, and 4 steps to 5e-9.
    The default is 2; the paper's value remains one flag away.

    ``prox_weight`` turns the hard trust region of Algorithm 1 into a soft one (the penalized
    trust region of Reynolds, Szmuk et al.): the subproblem adds
    ``(prox_weight / eta^2) sum_i ((z_i - z_bar_i) / scale_i)^2`` over every node, in the
    units of :func:`~scpformer.problems.pdg6dof.subproblem.trust_region_scales`, and keeps the
    box only as a safeguard at ``SOFT_BOX_FACTOR eta``. Eq. 15 still updates ``eta``, so the
    weight adapts like a Levenberg-Marquardt parameter, and the ratio test still compares the
    nonlinear J with the linear L without the quadratic term. With the hard box every step of
    a linear cost lands on a corner of the box and moves every variable by ``eta``, whose
    nonlinear defects then hold the ratio below ``rho_1``; the soft region lets each variable
    move as far as its own gradient asks (measurements in the README, "A soft trust region").
    ``prox_weight = 0`` is the hard box of Algorithm 1 exactly.

    ``least_change_correction``: SCvx's second-order correction first moves the candidate by
    the least change that cancels its defects along the linearization at the candidate
    (:mod:`~scpformer.problems.pdg6dof.correction`, a few milliseconds), and re-solves the
    conic subproblem only when that falls short of the ratio ``rho_1``. Near a solution
    almost every accepted step of the 6-DoF problem needs a correction: the step is rejected
    for its defects, the correction accepted with a ratio near 1 (the Maratos effect). On the
    bench's 20 nominal instances (seed 0), 54 of 276 conic solves were such corrections; the
    least-change correction replaced 33 of the 51 it was tried on (10 after one chord step,
    21 after two, 2 after three). Conic solves per run: median 13 -> 11, p95 19 -> 17; the
    propellant gap to the reference stayed small (median 0.003% -> 0.005%, max 0.056% ->
    0.116%: the conic correction also re-optimizes the cost, the least change does not).
    """

    n_nodes: int = 50  # N, number of temporal nodes
    n_sub: int = 2  # RK4 steps per interval
    fix_roll: bool = False  # impose q_f = q_id and w_f = 0 literally (see constants docstring)
    prox_weight: float = 1e-2  # soft trust-region weight at eta = 1 (0: hard box, Algorithm 1)
    tight_tol: float = 1e-5  # a row is tight when g >= -tight_tol
    least_change_correction: bool = True  # try the SOC without a conic solve first
    scvx: SCvxParameters = field(default_factory=SCvxParameters)
    verification: PDGVerificationTolerances = field(default_factory=PDGVerificationTolerances)

    def __post_init__(self) -> None:
        # Upper bounds from memory and time, not physics: the compiled subproblem grows by about
        # 17 variables and 300 discretization entries per node (50 in the paper); N = 1000
        # already takes minutes to canonicalize, and N = 1e8 exhausts any machine's memory.
        check_int("n_nodes", self.n_nodes, least=3, most=MAX_NODES)
        check_int("n_sub", self.n_sub, least=1, most=MAX_SUBSTEPS)
        if not 0.0 <= self.prox_weight < math.inf:
            raise ValueError(f"prox_weight must be finite and nonnegative, got {self.prox_weight}")
        # tight_tol compares the nondimensional constraint values g (Eqs. 4-6) with 0: a
        # negative or NaN tolerance would flag no row as tight, silently
        check_in_range("tight_tol", self.tight_tol, 0.0, 1.0)


def __getattr__(name: str) -> Any:
    """``VerificationTolerances``, the old name of :class:`PDGVerificationTolerances`, for one
    release (PEP 562)."""
    if name == "VerificationTolerances":
        warnings.warn(
            "VerificationTolerances of the 6-DoF family is now PDGVerificationTolerances "
            "(scpformer.problems.pdg6dof.config)",
            DeprecationWarning,
            stacklevel=2,
        )
        return PDGVerificationTolerances
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
