"""The rendezvous family's former single module, kept for old imports for one release.

Its parts now live in :mod:`.linear_model` (Eqs. 9-10, boundary data), :mod:`.constraints`
(keep-out, cone, reward- and constraint-to-go), :mod:`.verification` (nonlinear replay),
:mod:`.scp` (Problems 1-3) and :mod:`.api`; the entry point is
``scpformer.rendezvous.solve``. Nothing inside :mod:`scpformer.problems` imports this module.
"""

from __future__ import annotations

import warnings
from typing import Any

from scpformer.problems.rendezvous.api import solve as _solve
from scpformer.problems.rendezvous.constraints import (  # noqa: F401
    CTG_TOL,
    cone_slack,
    constraint_index,
    constraint_to_go,
    keep_out_cut,
    keep_out_slack,
    reward_to_go,
    tight_flags,
)
from scpformer.problems.rendezvous.instance import RendezvousInstance
from scpformer.problems.rendezvous.linear_model import (  # noqa: F401
    BoundaryData,
    LinearModel,
    boundary_data,
    linear_model,
)
from scpformer.problems.rendezvous.scenario import RendezvousSolverConfig
from scpformer.problems.rendezvous.scp import PROBLEMS, SCPState, run_scp  # noqa: F401
from scpformer.problems.rendezvous.verification import (  # noqa: F401
    osculating_initial_state,
    replay,
    verify_solution,
)
from scpformer.problems.rendezvous.warmstart import RENDEZVOUS_CONVEX as WARMSTARTS  # noqa: F401
from scpformer.scp.solution import Solution


def solve(
    instance: RendezvousInstance,
    problem: str = "scp",
    warmstart: Any = "convex",
    config: RendezvousSolverConfig | None = None,
    *,
    verify: bool = True,
) -> Solution:
    """Deprecated: ``scpformer.rendezvous.solve(instance, config, method=..., warmstart=...)``.

    ``problem`` maps onto ``method``; as before, ``warmstart`` is ignored when ``problem`` is
    not ``"scp"``.
    """
    warnings.warn(
        "scpformer.problems.rendezvous.solve(instance, problem=, warmstart=, config=) is "
        "deprecated; use scpformer.rendezvous.solve(instance, config, method=..., "
        "warmstart=...)",
        DeprecationWarning,
        stacklevel=2,
    )
    if problem not in PROBLEMS:  # the old message, naming the old argument
        raise ValueError(f"problem must be one of {PROBLEMS}, got {problem!r}")
    warmstart = warmstart if problem == "scp" else None
    return _solve(instance, config, method=problem, warmstart=warmstart, verify=verify)
