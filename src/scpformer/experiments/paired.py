"""Per-draw comparison of a method with a baseline on the same draws: what a user pays.

Every learned-vs-classical comparison of the experiments reports, beside the medians, how
each draw came out: solved by both, by one or by neither (a failure is a draw, not a
missing row); wall time of the whole path (guess, every solve, fallbacks) faster, tied or
slower; iterations fewer, equal or more; and, where both solved, cost lower, tied or
higher. :func:`paired_table` writes that as one Markdown table.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scpformer.experiments.report import fmt, markdown_table

#: Relative wall-time difference below which two paths tie: timings on a shared machine
#: scatter by a few percent run to run.
TIME_TIE = 0.05


@dataclass(frozen=True)
class Outcomes:
    """One method's result on each of ``n`` draws, in the draws' order.

    Attributes
    ----------
    time
        Wall time of the whole path [s] (guess, solves, fallbacks, verification).
    iterations
        Iterations (SCP iterations or conic solves, as the experiment counts them).
    solved
        Whether the draw ended with an accepted solution (converged and verified).
    cost
        Cost of the solution (NaN without one).
    """

    time: np.ndarray
    iterations: np.ndarray
    solved: np.ndarray
    cost: np.ndarray

    def __post_init__(self) -> None:
        arrays = {name: np.asarray(getattr(self, name), dtype=float if name != "solved" else bool)
                  for name in ("time", "iterations", "solved", "cost")}  # fmt: skip
        sizes = {a.shape for a in arrays.values()}
        if len(sizes) != 1 or len(next(iter(sizes))) != 1:
            raise ValueError(f"Outcomes arrays must be 1-D of one length, got shapes "
                             f"{ {k: a.shape for k, a in arrays.items()} }")  # fmt: skip
        for name, value in arrays.items():
            object.__setattr__(self, name, value)

    @property
    def n(self) -> int:
        return int(self.time.size)


def exact_sign_test(a: int, b: int) -> float:
    """Two-sided exact sign test of a split ``a`` / ``b`` of discordant pairs (McNemar's
    exact test on paired binary outcomes): ``p = min(1, 2 P(X <= min(a, b)))`` for
    ``X ~ Binomial(a + b, 1/2)``, the chance of a split at least this uneven if neither method
    were better; ``p = 1`` without discordant pairs."""
    if a < 0 or b < 0:
        raise ValueError(f"counts of discordant pairs must be >= 0, got {a} and {b}")
    n = a + b
    tail = sum(math.comb(n, k) for k in range(min(a, b) + 1)) / 2.0**n
    return min(1.0, 2.0 * tail)


def _counts(delta: np.ndarray, tie: np.ndarray | float) -> tuple[int, int, int]:
    """``(below, tie, above)``: how many of ``delta`` lie below ``-tie``, within, above."""
    return (int((delta < -tie).sum()), int((np.abs(delta) <= tie).sum()),
            int((delta > tie).sum()))  # fmt: skip


def paired_rows(
    ours: Outcomes, base: Outcomes, *, cost_tie: float, time_tie: float = TIME_TIE
) -> list[tuple[str, str, str]]:
    """The rows of :func:`paired_table`: ``(quantity, ours, baseline)``."""
    if ours.n != base.n:
        raise ValueError(f"the two methods must be compared on the same draws, got {ours.n} "
                         f"and {base.n}")  # fmt: skip
    both, only_ours = ours.solved & base.solved, ours.solved & ~base.solved
    only_base, neither = base.solved & ~ours.solved, ~(ours.solved | base.solved)
    faster, t_tie, slower = _counts(ours.time - base.time, time_tie * base.time)
    fewer, same, more = _counts(ours.iterations - base.iterations, 0.0)
    rows = [
        ("draws (all, failures included)", str(ours.n), str(base.n)),
        ("solved", f"{int(ours.solved.sum())}", f"{int(base.solved.sum())}"),
        ("solved by both / only this / only the baseline / neither",
         f"{int(both.sum())} / {int(only_ours.sum())} / {int(only_base.sum())} / "
         f"{int(neither.sum())}", ""),
        (f"wall time per draw: faster / tie (within {100 * time_tie:g}%) / slower",
         f"{faster} / {t_tie} / {slower}", ""),
        ("wall time median / mean [s]", f"{fmt(np.median(ours.time))} / "
         f"{fmt(ours.time.mean())}", f"{fmt(np.median(base.time))} / {fmt(base.time.mean())}"),
        ("speed-up: baseline over this, per-draw median / of the totals",
         f"{fmt(float(np.median(base.time / ours.time)))}x / "
         f"{fmt(base.time.sum() / ours.time.sum())}x", ""),
        ("iterations per draw: fewer / same / more", f"{fewer} / {same} / {more}", ""),
        ("iterations median / mean", f"{fmt(np.median(ours.iterations))} / "
         f"{fmt(ours.iterations.mean())}",
         f"{fmt(np.median(base.iterations))} / {fmt(base.iterations.mean())}"),
    ]  # fmt: skip
    if both.any():
        lower, c_tie, higher = _counts(ours.cost[both] - base.cost[both], cost_tie)
        rows.append((f"cost where both solved: lower / tie (within {cost_tie:g}) / higher",
                     f"{lower} / {c_tie} / {higher}", ""))  # fmt: skip
    return rows


def paired_table(
    name: str, ours: Outcomes, baseline: str, base: Outcomes, *, cost_tie: float,
    time_tie: float = TIME_TIE,
) -> str:  # fmt: skip
    """Markdown table of ``name`` against ``baseline`` draw by draw (module docstring)."""
    if not ours.n:
        return f"No draw to compare {name} with {baseline} on."
    rows = paired_rows(ours, base, cost_tie=cost_tie, time_tie=time_tie)
    return markdown_table(("quantity", name, baseline), rows)
