"""Self-describing ``.npz`` output of a rendezvous solution, replayable without the package.

Fields (N impulses, N + 1 nodes):

* ``t`` (N+1,): node times [s] from ``t_0 = 0``; ``dv[k]`` is applied at ``t[k]``.
* ``roe`` (N+1, 6): scaled mean ROE ``a dalpha`` [m], (a da, a dlambda, a dex, a dey, a dix,
  a diy), before the impulse at that node.
* ``rtn`` (N+1, 6): servicer relative to the target in the target's rotating RTN frame,
  position [m] and velocity as seen in that frame [m/s], ``Psi(t_k) roe[k]`` (Eq. 9).
* ``dv`` (N, 3): impulses in RTN [m/s].
* ``cost``: ``sum |dv|_2`` [m/s]; ``status``: the solution status string.
* ``constraint_to_go`` (N+1,): Eq. 21 on ``rtn``; ``reward_to_go`` (N+1,): Eq. 20 [m/s].
* ``target_oe``: JSON ``{a_m, e, i_deg, raan_deg, argp_deg, M_deg}`` at ``t[0]``: the MEAN
  elements of the model, plus ``"osculating"`` (same keys) and ``"rtn0_osculating"``: the
  osculating target elements and relative state whose orbit average is the model's (use these
  to start a nonlinear replay; see :func:`.problem.osculating_initial_state`).
* ``constants``: JSON of the scenario, with at least ``koz_semi_axes_m`` and ``n_waypoint``
  (0-based index into ``t``), plus the waypoint, cone apex, horizon and the instance.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.dynamics.orbits import R_EARTH
from scpformer.files import save_npz_atomic
from scpformer.problems.rendezvous.constraints import constraint_to_go, reward_to_go
from scpformer.problems.rendezvous.instance import RendezvousInstance
from scpformer.problems.rendezvous.linear_model import linear_model
from scpformer.problems.rendezvous.verification import osculating_initial_state
from scpformer.scp.solution import Solution

NPZ_FIELDS = (
    "t",
    "roe",
    "rtn",
    "dv",
    "cost",
    "status",
    "constraint_to_go",
    "reward_to_go",
    "target_oe",
    "constants",
)


def _oe_record(oe: np.ndarray) -> dict[str, float]:
    a, e, i, raan, argp, M = (float(v) for v in oe)
    deg = np.degrees
    return {
        "a_m": a,
        "e": e,
        "i_deg": float(deg(i)),
        "raan_deg": float(deg(raan)),
        "argp_deg": float(deg(argp)),
        "M_deg": float(deg(M)),
    }


def target_record(instance: RendezvousInstance) -> dict[str, Any]:
    """Mean target elements at ``t_0`` and a consistent osculating initial state.

    Also used for robust instances, which carry the same ``target``, ``roe0`` and ``scenario``
    attributes that :func:`.problem.osculating_initial_state` reads.
    """
    record: dict[str, Any] = {**instance.target.to_dict(), "elements": "mean (first-order J2)"}
    oe_osc, rtn0 = osculating_initial_state(instance)
    record["osculating"] = _oe_record(oe_osc)
    record["rtn0_osculating"] = [float(v) for v in rtn0]
    return record


def constants_record(instance: RendezvousInstance) -> dict[str, Any]:
    """Scenario constants and derived geometry, JSON-ready."""
    sc = instance.scenario
    record = sc.to_dict()
    record.update(
        koz_semi_axes_m=list(sc.koz_semi_axes_m),
        n_waypoint=sc.n_waypoint,
        waypoint_m=sc.waypoint_m.tolist(),
        cone_vertex_m=sc.cone_vertex_m.tolist(),
        horizon_orbits=instance.horizon_orbits,
        horizon_s=instance.horizon_s,
        period_s=instance.target.period_s,
        earth_radius_m=R_EARTH,
        instance=instance.to_dict(),
    )
    return record


def trajectory_arrays(solution: Solution, instance: RendezvousInstance) -> dict[str, Any]:
    """The fields both rendezvous families write: ``t``, ``roe``, ``rtn``, ``dv``, ``cost``,
    ``status``, ``reward_to_go`` and ``target_oe`` (also for a robust instance).

    Raises
    ------
    ValueError
        If the solution has no trajectory or does not match the instance's node count.
    """
    if solution.trajectory is None:
        raise ValueError(f"no trajectory to write: status {solution.status.value}")
    roe = np.asarray(solution.trajectory.x, dtype=float)
    dv = np.asarray(solution.trajectory.u, dtype=float)
    n = instance.n_nodes
    if roe.shape != (n + 1, 6) or dv.shape != (n, 3):
        raise ValueError(
            f"solution shapes {roe.shape}, {dv.shape} do not match N = {n} of the instance"
        )
    return {
        "t": instance.times(),
        "roe": roe,
        "rtn": linear_model(instance).rtn(roe),
        "dv": dv,
        "cost": np.float64(np.linalg.norm(dv, axis=1).sum()),
        "status": np.str_(solution.status.value),
        "reward_to_go": reward_to_go(dv),
        "target_oe": np.str_(json.dumps(target_record(instance))),
    }


def save_solution(path: str | Path, solution: Solution, instance: RendezvousInstance) -> None:
    """Write ``solution`` to ``path`` atomically (temporary name in the folder, then rename).

    Raises
    ------
    ValueError
        If the solution has no trajectory or does not match the instance's node count.
    """
    arrays = trajectory_arrays(solution, instance)
    arrays["constraint_to_go"] = constraint_to_go(arrays["rtn"], instance.scenario)
    arrays["constants"] = np.str_(json.dumps(constants_record(instance)))
    save_npz_atomic(path, arrays)


def load_solution(path: str | Path) -> dict[str, Any]:
    """Read a file written by :func:`save_solution`; JSON fields come back as dicts."""
    with np.load(Path(path), allow_pickle=False) as data:
        out: dict[str, Any] = {k: data[k] for k in data.files}
    for key in ("target_oe", "constants"):
        out[key] = json.loads(str(out[key]))
    out["status"] = str(out["status"])
    out["cost"] = float(out["cost"])
    return out
