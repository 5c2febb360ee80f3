"""Self-describing ``.npz`` output of a robust rendezvous solution.

The rendezvous family's fields (:mod:`scpformer.problems.rendezvous.io`; N impulses, N + 1
nodes): ``t``, ``roe``, ``rtn``, ``dv``, ``cost``, ``status``, ``constraint_to_go`` (here the
Eq. 7 constraint-violation budget of the solved mode, (N+1,)), ``reward_to_go`` (Eq. 9),
``target_oe`` (JSON: mean elements, consistent osculating elements and relative state) and
``constants`` (JSON: scenario, instance, mode, stage, dynamics). Plus, for nodes ``0 .. N-1``:

* ``covariance`` (N, 6, 6): ``X(t_i)`` of Eq. 14 [m^2] (zeros in deterministic mode);
* ``covariance_tstar`` (N, 6, 6): ``X(t*)``, propagated to the minimum-separation instant;
* ``t_star`` (N,): ``t*`` [s] of each free-drift arc;
* ``safety`` / ``safety_mean`` (N,): the normalized constraint ``h`` with and without the
  margin (``<= 0`` is safe, :mod:`.safety`);
* ``eq15`` / ``eq15_mean`` (N,): the left-hand side of Eq. 15 with and without ``beta``
  (Fig. 8 of the paper);
* ``beta`` (N,): the normalized margin ``beta / b_ps``.

Files are read back with the rendezvous family's :func:`load_solution` (re-exported here).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.files import save_npz_atomic
from scpformer.problems.rendezvous.io import load_solution, trajectory_arrays
from scpformer.problems.robust_rendezvous.instance import RobustInstance
from scpformer.problems.robust_rendezvous.safety import (
    constraint_violation_budget,
    covariance_at_tstar,
    linear_model,
    plan_safety,
)
from scpformer.scp.solution import Solution

NPZ_FIELDS = (
    "t", "roe", "rtn", "dv", "cost", "status", "constraint_to_go", "reward_to_go", "target_oe",
    "constants", "covariance", "covariance_tstar", "t_star", "safety", "safety_mean", "eq15",
    "eq15_mean", "beta",
)  # fmt: skip


def safety_record(
    instance: RobustInstance, x: np.ndarray, u: np.ndarray, dynamics: str = "nonlinear"
) -> dict[str, Any]:
    """Covariances and safety values of the chance-constrained evaluation of ``(x, u)`` in the
    plan model ``dynamics``."""
    model = linear_model(instance)
    ev = plan_safety(instance, x, u, "chance", dynamics)
    return {
        "covariance": ev.X,
        "covariance_tstar": covariance_at_tstar(ev),
        "t_star": model.t[:-1] + ev.tau_star,
        "safety": ev.h,
        "safety_mean": ev.h_mean,
        "eq15": ev.eq15,
        "eq15_mean": ev.eq15_mean,
        "beta": ev.beta,
    }


def save_solution(
    path: str | Path, solution: Solution, instance: RobustInstance, mode: str = "chance"
) -> None:
    """Write ``solution`` to ``path`` atomically; the safety fields use the chance margin.

    ``constraint_to_go`` is the Eq. 7 budget in ``mode`` (deterministic: ``beta = 0``).
    """
    arrays = trajectory_arrays(solution, instance)  # type: ignore[arg-type]
    x, u = arrays["roe"], arrays["dv"]
    safety = safety_record(instance, x, u, solution.extras.get("dynamics", "nonlinear"))
    h = safety["safety"] if mode == "chance" else safety["safety_mean"]
    constants = {
        "scenario": instance.scenario.to_dict(),
        "instance": instance.to_dict(),
        "mode": mode,
        "stage": solution.extras.get("stage"),
        "dynamics": solution.extras.get("dynamics"),
        "period_s": instance.target.period_s,
        "t_safety_s": instance.t_safety_s,
        "q": instance.uncertainty.q,
    }
    arrays["constraint_to_go"] = constraint_violation_budget(h)
    arrays["constants"] = np.str_(json.dumps(constants))
    arrays.update(safety)
    save_npz_atomic(path, arrays)


__all__ = ["NPZ_FIELDS", "load_solution", "safety_record", "save_solution"]
