"""``tscvx-solve-time`` (T-SCvx paper Fig. 2): cold SCvx and T-SCvx on the same test instances."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from scpformer.experiments import report as rep
from scpformer.experiments.runner import RunOptions, column, require_n, select_test_instances
from scpformer.experiments.tscvx.common import (
    COLD,
    comparison_rows,
    method_stats,
    open_tscvx_study,
    paired_section,
    pct,
    solve_rows,
    start_report,
    stats_table,
)


def run_solve_time(options: RunOptions, *, command: str = "", name: str) -> Path:
    """Fig. 2: cold SCvx vs T-SCvx on ``--n`` test instances (rotations included)."""
    study = open_tscvx_study(options).only("tscvx")
    positions = select_test_instances(study.data, require_n(options), options.seed)
    report = start_report(options, study, name, command, "Fig. 2", n=int(positions.size))
    rows = solve_rows(study, options, positions)
    methods = [COLD, *study.runs]
    report.comparisons = solve_time_comparisons(rows) if rows else []
    report.sections.append(
        ("Solve times", _finished(rows, positions) + "\n\n" + stats_table(rows, methods))
    )
    report.sections.append(("Instance by instance", paired_section(rows, methods)))
    figure = plot_solve_times(rows, methods, options.out / "fig2_solve_times.png")
    report.figures.append((figure, "Fig. 2: solve times of cold SCvx and T-SCvx"))
    return report.write(options.out)


def _finished(rows: Sequence[dict], positions: np.ndarray) -> str:
    return (
        f"{len(rows)} of {positions.size} selected test instances finished (failed or "
        f"missing: {positions.size - len(rows)}). Times are wall seconds of the whole solve "
        "call (predictor inference, guess and T-SCvx's fallbacks included), one torch thread."
    )


def plot_solve_times(rows: Sequence[dict[str, str]], methods: Sequence[str], path: Path) -> str:
    """Fig. 2: box plots of the solve times of each method."""
    figure, ax = rep.new_figure(ncols=1, width=6.0, height=4.0)
    data = [column(rows, f"{m}_time_s") for m in methods]
    ax.boxplot(data, tick_labels=[_label(m) for m in methods], showmeans=True)
    ax.set_ylabel("solve time [s] (wall, inference included)")
    ax.set_title(f"{len(rows)} held-out test instances")
    ax.grid(axis="y", alpha=0.3)
    return rep.save_figure(figure, path)


def _label(method: str) -> str:
    return {COLD: "SCvx (cold)", "tscvx": "T-SCvx (networks)"}.get(method, f"T-SCvx ({method})")


def solve_time_comparisons(rows: Sequence[dict[str, str]]) -> list[rep.Comparison]:
    """Fig. 2's numbers beside ours."""
    cold, warm = method_stats(rows, COLD), method_stats(rows, "tscvx")
    cut_mean = 1.0 - warm["mean_s"] / cold["mean_s"]
    cut_median = 1.0 - warm["median_s"] / cold["median_s"]
    converged = f"{cold['converged']:.1%} / {warm['converged']:.1%}"
    return comparison_rows(
        [
            ("test instances", "545", str(len(rows))),
            ("SCvx mean solve time", "14.61 s", f"{rep.fmt(cold['mean_s'])} s"),
            ("T-SCvx mean solve-time reduction", "66%", f"{100 * cut_mean:.3g}%",
             "issue goal: >= 3x (67%)"),
            ("T-SCvx median solve-time reduction", "70%", f"{100 * cut_median:.3g}%",
             "issue goal: >= 3x"),
            ("T-SCvx std of solve time", "5.24 s", f"{rep.fmt(warm['std_s'])} s"),
            ("converged rate SCvx / T-SCvx", "n/a", converged),
            ("max propellant gap of T-SCvx to cold SCvx", "n/a", pct(warm["gap_max"]),
             "issue goal: <= 0.5%"),
        ]
    )  # fmt: skip
