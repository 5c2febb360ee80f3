"""The entry point of the 6-DoF family: :func:`solve` with SCvx or T-SCvx (Algorithm 2)."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from scpformer.problems.pdg6dof import constraints as con
from scpformer.problems.pdg6dof.adapter import PDGProblem
from scpformer.problems.pdg6dof.config import PDGSolverConfig
from scpformer.problems.pdg6dof.guess import ANALYTIC_GUESSES
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.restart import checked_guess, solve_with_restart
from scpformer.problems.pdg6dof.tscvx import TscvxProvider, solve_tscvx
from scpformer.problems.pdg6dof.warmstart import AnalyticWarmStart
from scpformer.scp.scvx import solve_scvx
from scpformer.scp.solution import Solution, Status, Trajectory
from scpformer.scp.warmstart import (
    WarmStart,
    WarmStartRecord,
    checked_solve_arguments,
    resolve,
)

FAMILY = "pdg6dof"  # key of the learned warm starts in scpformer.scp.warmstart's registry
METHODS = ("scvx", "tscvx")  # SCvx (Algorithm 1) or T-SCvx (Algorithm 2)
DEFAULT_WARMSTART = {"scvx": "cubic_profile", "tscvx": "tscvx"}


def analytic_providers(config: PDGSolverConfig) -> dict[str, Any]:
    """The family's own named warm starts, name -> factory (``cubic_profile`` first)."""
    return {
        profile: lambda profile=profile: AnalyticWarmStart(config.n_nodes, profile)
        for profile in ANALYTIC_GUESSES
    }


def solve(
    instance: PDGInstance,
    config: PDGSolverConfig | None = None,
    *,
    method: str = "scvx",
    warmstart: Any = None,
    verify: bool = True,
) -> Solution:
    """Solve the 6-DoF free-final-time minimum-fuel problem (Eqs. 2-6).

    Parameters
    ----------
    instance
        The problem parameters theta.
    config
        Formulation and algorithm settings (default: Table 1).
    method
        ``"scvx"``: SCvx (Algorithm 1) from the warm start's guess; from the default cold
        start (the cubic profile) it restarts once a run that creeps
        (:func:`~scpformer.problems.pdg6dof.restart.solve_with_restart`). ``"tscvx"``:
        T-SCvx (Algorithm 2, :func:`~scpformer.problems.pdg6dof.tscvx.solve_tscvx`), whose
        predictor is the warm start's: a T-SCvx provider
        (``scpformer.warmstart.tscvx.TscvxWarmStart``, with the networks or a lookup table)
        or a registered learned name (``"tscvx"``, the default: the pretrained networks).
        The algorithm is never inferred from the warm start.
    warmstart
        A provider (``guess(instance) -> WarmStartResult``), its precomputed
        ``WarmStartResult``, a name (``"cubic_profile"``, the default of ``"scvx"``,
        ``"straight_line"``, or a learned name registered by :mod:`scpformer.warmstart`:
        ``"tscvx"``, ``"kdtree"``, ``"interp"``), a :class:`Trajectory` or a ``Solution``.
    verify
        Check the result against the nonlinear model; ``False`` leaves ``verification`` None.

    Returns
    -------
    Solution
        ``extras["warmstart"]``: the warm start's record (``WarmStartRecord.to_dict``; its
        ``used`` names the guess the returned trajectory came from, ``cubic_profile`` after a
        T-SCvx run fell back to cold SCvx). ``Status.INFEASIBLE_INSTANCE`` without solving
        when the initial state already violates a state constraint.

    Raises
    ------
    ValueError
        An unknown method or warm start name, or a warm start the method cannot use
        (``"tscvx"`` with a warm start that has no tight-row predictor).
    """
    config = checked_solve_arguments(
        method, METHODS, instance, PDGInstance, config, PDGSolverConfig
    )
    if warmstart is None:
        warmstart = DEFAULT_WARMSTART[method]
    named = analytic_providers(config)
    if method == "tscvx" and isinstance(warmstart, str) and warmstart in named:
        raise ValueError(_cannot_use(warmstart))
    provider = resolve(warmstart, FAMILY, named, config)
    if method == "tscvx" and not isinstance(provider, TscvxProvider):
        raise ValueError(_cannot_use(type(provider).__name__))
    violated = con.initial_state_violations(instance)
    if violated:
        message = "initial state violates " + ", ".join(violated)
        return _not_solved(message, _source(warmstart, provider))
    if method == "tscvx":
        return _solve_tscvx(instance, config, provider, verify)
    return _solve_scvx(instance, config, provider, verify)


def _cannot_use(warmstart: str) -> str:
    return (
        f"method 'tscvx' cannot use warmstart {warmstart!r}: Algorithm 2 needs a T-SCvx "
        "predictor of the tight rows (warmstart 'tscvx', 'kdtree', 'interp' or a "
        "TscvxWarmStart)"
    )


def _source(warmstart: Any, provider: WarmStart) -> str:
    return warmstart if isinstance(warmstart, str) else type(provider).__name__


def _not_solved(message: str, source: str) -> Solution:
    record = WarmStartRecord(
        source=source, time_s=0.0, cost=math.nan, constraint_to_go=math.nan, accepted=False,
        reason=f"not run: {message}",
    )  # fmt: skip
    return Solution(
        status=Status.INFEASIBLE_INSTANCE,
        trajectory=None,
        t=None,
        cost=np.nan,
        iterations=0,
        message=message,
        extras={"warmstart": record.to_dict()},
    )


def _problem(instance: PDGInstance, config: PDGSolverConfig, verify: bool) -> PDGProblem:
    problem = PDGProblem(instance, config)
    if not verify:
        problem.verify = _not_verified  # type: ignore[method-assign]
    return problem


def _not_verified(z: Trajectory) -> None:
    """The verification of a solve asked not to verify: none (never a passed one)."""
    return None


def _solve_scvx(
    instance: PDGInstance, config: PDGSolverConfig, provider: WarmStart, verify: bool
) -> Solution:
    problem = _problem(instance, config, verify)
    result = provider.guess(instance)
    if result.trajectory is None:
        raise ValueError(
            f"warmstart: the {result.record.source} warm start produced no trajectory "
            f"({result.record.reason})"
        )
    default_start = isinstance(provider, AnalyticWarmStart) and provider.profile == "cubic_profile"
    if default_start:  # the default cold start (built right): restarted once if it creeps
        solution = solve_with_restart(problem, result.trajectory)
    else:
        guess = checked_guess(result.trajectory, problem.initial_guess())
        solution = solve_scvx(problem, guess, config.scvx)
    return replace(solution, extras={**solution.extras, "warmstart": result.record.to_dict()})


def _solve_tscvx(
    instance: PDGInstance, config: PDGSolverConfig, provider: TscvxProvider, verify: bool
) -> Solution:
    result = provider.guess_for(instance, config)
    solution = solve_tscvx(
        instance, config, result.trajectory, provider.tight(instance), provider.params,
        verify=verify,
    )  # fmt: skip
    record = result.record
    if solution.extras["tscvx"]["fallback"] == "cold":  # the path ended in cold SCvx
        record = replace(
            record,
            accepted=False,
            fallback_source="cubic_profile",
            reason=f"{record.reason}; {solution.extras['tscvx']['fallback_reason']}, then cold "
            "SCvx from the cubic profile",
        )
    return replace(solution, extras={**solution.extras, "warmstart": record.to_dict()})
