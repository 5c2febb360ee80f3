"""What every family's closed loop shares: the check of the open-loop plan it starts from, the
time budget of a re-plan, and what it keeps of its re-plans (the ``runs.csv`` statistics and
the per-re-plan tables of ``run-NNNN.npz``).

A family's re-plan record is a frozen dataclass with at least ``accepted`` (bool),
``iterations`` (int) and ``wall_s`` (float, the wall time of the whole re-plan: warm start,
solve and verification); :func:`record_table` turns a list of them into one array per field.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import numpy as np

from scpformer.scp.solution import Solution

#: A family's re-plan record (a frozen dataclass with ``accepted``, ``wall_s``, ``late`` and
#: ``message``).
R = TypeVar("R")
#: numpy dtype of a record field by its annotation (fields of other types are left out).
_DTYPES = {"int": int, "float": float, "bool": bool, "str": str}
#: Fields kept out of the npz tables (free text, read from the logs instead).
_UNTABLED = ("message",)


def flyable_plan(sol: Solution, accepted: Callable[[Solution], bool]) -> Solution:
    """``sol``, the open-loop plan a closed loop starts from, when the family's ``accepted``
    says it may be flown.

    Raises
    ------
    ValueError
        When it may not (the plan failed): there is nothing to fly.
    """
    if not accepted(sol):
        raise ValueError(f"the open-loop plan failed ({sol.status.value}): {sol.message}")
    return sol


def within_budget(record: R, budget_s: float | None) -> R:
    """``record`` as the loop takes it under a re-plan time budget.

    A re-plan whose wall time (``record.wall_s``: warm start, solve and verification) exceeds
    ``budget_s`` [s] is late: its plan would reach the actuators after the vehicle has moved
    on, so it is not accepted and the last accepted plan keeps being flown. The returned
    record then has ``accepted`` False, ``late`` True and a message saying by how much.
    ``budget_s`` None is no budget (the default of every loop: wall times depend on the
    machine, so a budget makes a run's outcome depend on it too).
    """
    if budget_s is None or record.wall_s <= budget_s:
        return record
    late = f"late: {record.wall_s:.3g} s against a budget of {budget_s:.3g} s"
    return dataclasses.replace(record, accepted=False, late=True,
                               message=f"{late}; {record.message}")  # fmt: skip


def check_budget(budget_s: Any) -> float | None:
    """``time_budget_s`` of a loop's configuration: None or a positive finite number of
    seconds; ``ValueError`` naming the field otherwise."""
    if budget_s is None:
        return None
    if isinstance(budget_s, bool) or not isinstance(budget_s, int | float):
        raise ValueError(f"time_budget_s must be a number of seconds or None, got "
                         f"{type(budget_s).__name__}")  # fmt: skip
    if not (math.isfinite(budget_s) and budget_s > 0.0):
        raise ValueError(f"time_budget_s must be positive and finite, got {budget_s}")
    return float(budget_s)


def replan_statistics(replans: Sequence[Any]) -> dict[str, float | int]:
    """The re-plan columns of a run's ``runs.csv`` row: count, failures (not accepted), the
    median and 99th percentile of the wall time [s] and the median SCP iterations (NaN
    without a re-plan)."""
    times = np.array([r.wall_s for r in replans], dtype=float)
    iterations = np.array([r.iterations for r in replans], dtype=float)
    some = times.size > 0
    return {
        "replans": len(replans),
        "replans_failed": sum(not r.accepted for r in replans),
        "replan_time_median_s": float(np.median(times)) if some else math.nan,
        "replan_time_p99_s": float(np.percentile(times, 99)) if some else math.nan,
        "replan_iterations_median": float(np.median(iterations)) if some else math.nan,
    }


def record_table(records: Sequence[Any], record_type: type) -> dict[str, np.ndarray]:
    """One array per field of the dataclass ``record_type`` (its annotated int, float, bool
    and str fields but ``message``), over ``records``; empty arrays of the right dtype when
    there are none."""
    return {
        f.name: np.array([getattr(r, f.name) for r in records], dtype=_DTYPES[str(f.type)])
        for f in dataclasses.fields(record_type)
        if str(f.type) in _DTYPES and f.name not in _UNTABLED
    }


def replan_tables(
    replans: Sequence[Any], comparisons: Sequence[Any], record_type: type
) -> dict[str, np.ndarray]:
    """The npz tables of a run: :func:`record_table` of the flown re-plans (``replan_*``) and
    of the comparison solves of the same re-plan problems (``compare_*``)."""
    tables = {f"replan_{k}": v for k, v in record_table(replans, record_type).items()}
    return tables | {f"compare_{k}": v for k, v in record_table(comparisons, record_type).items()}
