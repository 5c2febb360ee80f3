"""The 6-DoF family's former single module, kept for old imports for one release.

Its parts now live in :mod:`.config` (:class:`PDGSolverConfig`), :mod:`.adapter`
(:class:`PDGProblem`), :mod:`.verification`, :mod:`.restart`, :mod:`.api` and
:mod:`.metrics`; the entry point is ``scpformer.pdg6dof.solve``. Nothing inside
:mod:`scpformer.problems` imports this module.
"""

from __future__ import annotations

import warnings
from dataclasses import replace
from typing import Any

import numpy as np

from scpformer.problems.pdg6dof.adapter import (  # noqa: F401
    LEAST_CHANGE,
    LEAST_CHANGE_STEPS,
    PDGProblem,
    candidate,
    conic_solves,
    final_mass_cost,
    penalty,
)
from scpformer.problems.pdg6dof.api import solve as _solve
from scpformer.problems.pdg6dof.config import (  # noqa: F401
    SOFT_BOX_FACTOR,
    PDGSolverConfig,
    PDGVerificationTolerances,
)
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.metrics import (  # noqa: F401
    REFERENCE_EPS_OPT,
    REFERENCE_ITER_MAX,
    propellant_gap,
    reference_config,
    solve_reference,
)
from scpformer.problems.pdg6dof.restart import (  # noqa: F401
    RESTART_DECREASE,
    RESTART_DRY_MARGIN,
    RESTART_MIN_BUDGET,
    RESTART_TF_FACTOR,
    solve_with_restart,
)
from scpformer.problems.pdg6dof.tscvx import TscvxProvider
from scpformer.problems.pdg6dof.verification import propagate, verify_trajectory  # noqa: F401
from scpformer.scp.solution import Solution, Trajectory
from scpformer.validation import check_positive, check_type

VerificationTolerances = PDGVerificationTolerances  # the old name, in the old module


def solve(
    instance: PDGInstance,
    config: PDGSolverConfig | None = None,
    guess: Any = None,
    eta_init: float | None = None,
) -> Solution:
    """Deprecated: ``scpformer.pdg6dof.solve(instance, config, method=..., warmstart=...)``.

    ``guess`` maps onto ``warmstart``; a T-SCvx provider runs ``method="tscvx"`` (the old
    inference from its type); ``eta_init`` overrides the initial trust radius (of
    ``config.scvx``, or of the T-SCvx provider's parameters).
    """
    warnings.warn(
        "scpformer.problems.pdg6dof.problem.solve(instance, config, guess=, eta_init=) is "
        "deprecated; use scpformer.pdg6dof.solve(instance, config, method=..., warmstart=...)",
        DeprecationWarning,
        stacklevel=2,
    )
    config = PDGSolverConfig() if config is None else config
    method = "tscvx" if isinstance(guess, TscvxProvider) else "scvx"
    if eta_init is not None:
        eta_init = check_positive("eta_init", eta_init)
        if method == "tscvx":
            guess = replace(guess, params=replace(guess.params, eta_init=eta_init))
        elif isinstance(config, PDGSolverConfig):
            config = replace(config, scvx=replace(config.scvx, eta_init=eta_init))
    if isinstance(guess, list | tuple | np.ndarray | dict):
        check_type("guess", guess, Trajectory)  # a guess of states alone is refused
    return _solve(instance, config, method=method, warmstart=guess)
