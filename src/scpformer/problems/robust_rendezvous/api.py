"""The entry point of the robust rendezvous: :func:`solve` (robust ART paper, Sec. 5)."""

from __future__ import annotations

import warnings
from dataclasses import replace
from typing import Any

from scpformer.problems.robust_rendezvous.instance import RobustInstance
from scpformer.problems.robust_rendezvous.problem import passive_safety_from, three_stage
from scpformer.problems.robust_rendezvous.scenario import RobustSolverConfig
from scpformer.problems.robust_rendezvous.warmstart import RobustTpbvpWarmStart
from scpformer.scp.solution import Solution
from scpformer.scp.warmstart import (
    GivenWarmStart,
    checked_solve_arguments,
    resolve,
    warmstart_name,
)
from scpformer.validation import check_type

FAMILY = "robust-rendezvous"  # key of the learned warm starts in scpformer.scp.warmstart
METHODS = ("three_stage", "passive_safety")  # the dataset procedure; PS-CVX / PS-ART


def solve(
    instance: RobustInstance,
    config: RobustSolverConfig | None = None,
    *,
    method: str = "three_stage",
    warmstart: Any = None,
    verify: bool = True,
) -> Solution:
    """Solve the passively safe rendezvous (Eq. 1) and keep the final feasible solution.

    Parameters
    ----------
    instance
        The robust rendezvous instance.
    config
        SCvx* parameters (robust Table 1), ``safety_mode`` (``"chance"``: the margin of
        Eq. 16 with the instance's ``Delta``; ``"deterministic"``: ``X = 0``), dynamics,
        conic solver and verification.
    method
        ``"three_stage"``: TPBVP -> collision avoidance -> passive safety, the dataset
        procedure (:func:`~scpformer.problems.robust_rendezvous.problem.three_stage`), which
        makes its own warm starts and takes none. ``"passive_safety"``: SCvx* on passive
        safety straight from the warm start: PS-CVX from ``"tpbvp"`` (its default), PS-ART
        from ``"art"``.
    warmstart
        ``"passive_safety"`` only: a name (``"tpbvp"``, the convex TPBVP; ``"art"``, the
        learned warm start registered by :mod:`scpformer.warmstart`, the pretrained model), a
        provider (``guess(instance) -> WarmStartResult``, e.g. ``ArtWarmStart``) or its
        precomputed ``WarmStartResult``, a ``Solution`` or a ``Trajectory``. The guess only
        starts SCvx*; it is never returned as the solution.
    verify
        Check the final trajectory (``PassiveSafetyProblem.verify``); ``False`` leaves
        ``verification`` None.

    Returns
    -------
    Solution
        ``trajectory.x`` (N+1, 6) [m], ``trajectory.u`` (N, 3) [m/s], ``cost = sum |u|``
        [m/s]; ``status`` is that of the passive-safety problem; ``extras``: ``stage`` (which
        stage produced the trajectory), ``dynamics`` (the model the trajectory obeys),
        ``stage_status``, ``stage_iterations``, ``stage_wall_s``, ``mode``,
        ``retried_from_tpbvp`` (present when stage 3 ran twice), ``violation_budget`` (Eq. 7,
        ``C(t_i)``, (N+1,)), ``warmstart`` (the warm start's record,
        ``WarmStartRecord.to_dict``). A failing conic solve is a status with the solver's
        reason, never an exception.

    Raises
    ------
    ValueError
        An unknown method or warm start name, a warm start given to ``"three_stage"``, or a
        provider whose passive-safety mode differs from ``config.safety_mode``.
    """
    config = checked_solve_arguments(
        method, METHODS, instance, RobustInstance, config, RobustSolverConfig
    )
    if method == "three_stage":
        if warmstart is not None:
            raise ValueError(
                f"method 'three_stage' cannot use warmstart {warmstart_name(warmstart)!r}: the "
                "procedure makes its own (TPBVP, then collision avoidance); use method "
                "'passive_safety'"
            )
        return three_stage(instance, config, RobustTpbvpWarmStart(config).guess(instance), verify)
    warmstart = "tpbvp" if warmstart is None else warmstart
    provider = resolve(warmstart, FAMILY, {"tpbvp": lambda: RobustTpbvpWarmStart(config)}, config)
    mode = getattr(provider, "mode", config.safety_mode)
    if mode != config.safety_mode:
        raise ValueError(
            f"warmstart: the provider's mode {mode!r} differs from the configuration's "
            f"{config.safety_mode!r}"
        )
    result = provider.guess(instance)
    given = isinstance(provider, GivenWarmStart)
    return passive_safety_from(instance, config, result, verify, given=given)


def legacy_solve(
    instance: RobustInstance,
    config: RobustSolverConfig | None = None,
    mode: str = "chance",
    *,
    warmstart: Any = "three_stage",
    verify: bool = True,
) -> Solution:
    """Deprecated: ``scpformer.robust_rendezvous.solve(instance, config, method=...,
    warmstart=...)``. The old signature of ``scpformer.problems.robust_rendezvous.solve``,
    mapped onto :func:`solve` (``mode`` into ``config.safety_mode``, ``"three_stage"`` onto the
    method)."""
    warnings.warn(
        "scpformer.problems.robust_rendezvous.solve(instance, config, mode=, warmstart=) is "
        "deprecated; use scpformer.robust_rendezvous.solve(instance, config, method=..., "
        "warmstart=...) with the mode in config.safety_mode",
        DeprecationWarning,
        stacklevel=2,
    )
    config = RobustSolverConfig() if config is None else config
    check_type("config", config, RobustSolverConfig)
    config = replace(config, safety_mode=mode)
    if isinstance(warmstart, str) and warmstart == "three_stage":
        solution = solve(instance, config, method="three_stage", verify=verify)
    else:
        if isinstance(warmstart, str) and warmstart != "tpbvp":
            raise ValueError(f"warmstart must be one of three_stage, tpbvp, got {warmstart!r}")
        solution = solve(instance, config, method="passive_safety", warmstart=warmstart,
                         verify=verify)  # fmt: skip
    if isinstance(warmstart, str):  # the old record named the procedure asked for
        record = {**solution.extras["warmstart"], "source": warmstart}
        if record["accepted"] or record["fallback_source"] is None:
            record["used"] = warmstart
        solution = replace(solution, extras={**solution.extras, "warmstart": record})
    return solution
