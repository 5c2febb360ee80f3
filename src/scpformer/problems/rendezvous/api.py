"""The entry point of the rendezvous family: :func:`solve` (ART paper, Problems 1-3)."""

from __future__ import annotations

import math
import time
from dataclasses import replace
from functools import partial
from typing import Any

from scpformer.problems.rendezvous.instance import RendezvousInstance
from scpformer.problems.rendezvous.scenario import RendezvousSolverConfig
from scpformer.problems.rendezvous.scp import setup, solve_convex, solve_scp
from scpformer.problems.rendezvous.warmstart import RENDEZVOUS_CONVEX, RendezvousConvexWarmStart
from scpformer.scp.solution import Solution
from scpformer.scp.warmstart import (
    WarmStartRecord,
    checked_solve_arguments,
    resolve,
    warmstart_name,
)

FAMILY = "rendezvous"  # key of the learned warm starts in scpformer.scp.warmstart's registry
METHODS = ("tpbvp", "convex", "scp")  # Problems 1, 2 and 3 (the SCP of Section 4)


def solve(
    instance: RendezvousInstance,
    config: RendezvousSolverConfig | None = None,
    *,
    method: str = "scp",
    warmstart: Any = None,
    verify: bool = True,
) -> Solution:
    """Solve Problem 1 (``method="tpbvp"``), 2 (``"convex"``) or 3 (``"scp"``) of the ART paper.

    Parameters
    ----------
    instance
        The rendezvous instance.
    config
        SCP constants, conic solver and verification tolerances (default: Table 1).
    method
        ``"tpbvp"`` and ``"convex"`` are convex problems solved in one conic solve, from no
        warm start; ``"scp"`` is the SCP of Section 4 on Problem 3 (keep-out zone).
    warmstart
        ``"scp"`` only: the initial reference, a name (``"convex"``, the default, or
        ``"tpbvp"``: the convex Problem 2 or 1, solved here; ``"art"``: the learned warm
        start registered by :mod:`scpformer.warmstart`, the pretrained model), a provider
        (``guess(instance) -> WarmStartResult``, e.g. ``ArtWarmStart``) or its precomputed
        ``WarmStartResult``, a ``Solution`` (e.g. of Problem 2, to time the SCP alone), a
        ``Trajectory`` or ROE states (N+1, 6) [m]. ``J_0`` of Eq. 19 is the warm start's cost
        when it carries impulses. The guess only starts the SCP; it is never the solution.
    verify
        Replay the impulses through the nonlinear propagator
        (:func:`~scpformer.problems.rendezvous.verification.verify_solution`); ``False``
        leaves ``verification`` None.

    Returns
    -------
    Solution
        ``trajectory.x`` (N+1, 6) ROE [m], ``trajectory.u`` (N, 3) impulses [m/s],
        ``trajectory.p`` empty; ``t`` (N+1,) [s]; ``cost`` = ``sum |dv|_2`` [m/s];
        ``extras["warmstart"]``: the warm start's record (``WarmStartRecord.to_dict``; source
        ``"none"`` for the convex problems). A failing conic solve is a status
        (``INFEASIBLE_INSTANCE`` for a certified infeasible convex problem, else
        ``SOLVER_FAILED``), never an exception.

    Raises
    ------
    ValueError
        An unknown method or warm start name, or a warm start given to a convex problem.
    """
    config = checked_solve_arguments(
        method, METHODS, instance, RendezvousInstance, config, RendezvousSolverConfig
    )
    if method != "scp":
        if warmstart is not None:
            raise ValueError(
                f"method {method!r} cannot use warmstart {warmstart_name(warmstart)!r}: it is a "
                "convex problem solved from no guess (warm starts start method 'scp')"
            )
        solution = solve_convex(instance, method, config, verify)
        record = WarmStartRecord(
            source="none", time_s=0.0, cost=math.nan, constraint_to_go=math.nan,
            reason=f"method {method!r} is solved without a warm start",
        )  # fmt: skip
        return replace(solution, extras={**solution.extras, "warmstart": record.to_dict()})
    warmstart = "convex" if warmstart is None else warmstart
    named = {kind: partial(RendezvousConvexWarmStart, kind, config) for kind in RENDEZVOUS_CONVEX}
    provider = resolve(warmstart, FAMILY, named, config)
    start = time.perf_counter()
    prepared = setup(instance, config)
    result = provider.guess(instance)
    warm = result.solution
    own = isinstance(warmstart, str) and warmstart in named  # its convex solve is counted
    warm_solver = warm.timing.solver if own and warm is not None and warm.timing else 0.0
    solution = solve_scp(prepared, result, verify, start, warm_solver)
    return replace(solution, extras={**solution.extras, "warmstart": result.record.to_dict()})
