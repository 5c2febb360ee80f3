"""Self-describing ``.npz`` output of a 6-DoF solution, checkable without the package.

Fields: ``t`` (N,), ``x`` (N, 14) in the order of Eq. 24 (r, v, q scalar first, omega [rad/U_T],
m), ``u`` (N, 3) body-frame thrust, ``tf``, ``status``, ``constants`` (a JSON string of every
model constant and instance parameter used), ``history`` (a JSON list of per-iteration scalars)
and ``tight_flags`` (iterations, rows) with ``constraint_rows`` naming each row ``name:node``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.files import save_npz_atomic
from scpformer.problems.pdg6dof.constraints import constraint_index
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.scp.solution import Solution


def constants_record(instance: PDGInstance) -> dict[str, Any]:
    """Every model constant and instance parameter, JSON-ready."""
    record = instance.constants.to_dict()
    params = instance.to_dict()
    params.pop("constants")
    record.update(params)
    record["omega_max_rad"] = float(np.radians(instance.constants.omega_max_deg))
    record["tilt_bound"] = instance.tilt_bound
    return record


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serializable: {type(value).__name__}")


def save_solution(path: str | Path, solution: Solution, instance: PDGInstance) -> None:
    """Write ``solution`` to ``path`` atomically (temporary name, then rename)."""
    if solution.trajectory is None:
        raise ValueError(f"no trajectory to write: status {solution.status.value}")
    path = Path(path)
    flags = np.array([rec.tight_flags for rec in solution.history], dtype=bool)
    n_nodes = solution.trajectory.x.shape[0]
    arrays = {
        "t": solution.t,
        "x": solution.trajectory.x,
        "u": solution.trajectory.u,
        "tf": np.float64(solution.trajectory.p[0]),
        "status": np.str_(solution.status.value),
        "constants": np.str_(json.dumps(constants_record(instance), default=_json_default)),
        "history": np.str_(
            json.dumps([rec.summary() for rec in solution.history], default=_json_default)
        ),
        "tight_flags": flags.reshape(len(solution.history), -1),
        "constraint_rows": np.array([f"{n}:{k}" for n, k in constraint_index(n_nodes)]),
    }
    if solution.verification is not None:
        arrays["verification"] = np.str_(
            json.dumps(solution.verification.__dict__, default=_json_default)
        )
    save_npz_atomic(path, arrays)
