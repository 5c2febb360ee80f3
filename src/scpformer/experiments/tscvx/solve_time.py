"""``tscvx-solve-time`` (T-SCvx paper Fig. 2): cold SCvx and T-SCvx on the same test instances."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from scpformer.experiments.runner import (
    RunOptions,
    require_n,
    select_test_instances,
)
from scpformer.experiments.tscvx.common import (
    COLD,
    PAPER,
    TscvxStudy,
    new_report,
    open_tscvx_study,
    paired_section,
    plot_solve_times,
    solve_rows,
    solve_time_comparisons,
    stats_table,
    study_settings,
)


def run_solve_time(options: RunOptions, *, command: str = "", name: str) -> Path:
    """Fig. 2: cold SCvx vs T-SCvx on ``--n`` test instances (rotations included)."""
    study = open_tscvx_study(options)
    study = TscvxStudy(study.data, study.config, {"tscvx": study.runs["tscvx"]})
    positions = select_test_instances(study.data, require_n(options), options.seed)
    settings = study_settings(options, study, name, n=int(positions.size))
    rows = solve_rows(study, options, positions, settings)
    methods = [COLD, "tscvx"]
    report = new_report(name, f"{PAPER} Fig. 2", command, settings, study)
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
