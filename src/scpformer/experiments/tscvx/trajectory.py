"""``tscvx-trajectory`` (T-SCvx paper Fig. 3): one T-SCvx solution with its predicted and
true tight rows."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from scpformer.experiments import report as rep
from scpformer.experiments.runner import RunOptions, select_test_instances, theta_tasks
from scpformer.experiments.tscvx.common import (
    comparison_rows,
    open_tscvx_study,
    pct,
    solver_config,
    start_report,
)


def run_trajectory(options: RunOptions, *, command: str = "", name: str) -> Path:
    """Fig. 3: a T-SCvx solution and its predicted against its true tight rows."""
    from scpformer.data.pdg6dof_family import instance_from_theta
    from scpformer.models.predictors import load_predictor
    from scpformer.pdg6dof import solve
    from scpformer.warmstart.tscvx import TscvxWarmStart

    study = open_tscvx_study(options)
    report = start_report(options, study, name, command, "Fig. 3")
    (position,) = select_test_instances(study.data, 1, options.seed)
    (task,) = theta_tasks(study.data, [int(position)])
    config = solver_config(study.config)
    instance = instance_from_theta(task.theta, config.constants)
    predictor = load_predictor(study.runs["tscvx"], "tscvx")
    cold = solve(instance, config.solver, method="scvx")
    solution = solve(instance, config.solver, method="tscvx", warmstart=TscvxWarmStart(predictor))
    report.figures += trajectory_figures(
        instance, solution, cold, predictor, options.out, config.solver.tight_tol
    )
    report.sections.append(("Instance", trajectory_summary(int(position), solution, cold)))
    report.comparisons = trajectory_comparisons(instance, solution, cold)
    return report.write(options.out)


def trajectory_comparisons(instance: Any, solution: Any, cold: Any) -> list[rep.Comparison]:
    """Fig. 3 has no numbers; ours: the instance's solves and propellant gap to cold SCvx."""
    from scpformer.problems.pdg6dof.problem import propellant_gap

    gap = propellant_gap(instance, solution.cost, cold.cost)
    solves = f"{cold.iterations} / {solution.iterations}"
    return comparison_rows(
        [
            ("subproblem solves, cold SCvx / T-SCvx", "n/a (figure only)", solves),
            ("T-SCvx propellant beyond cold SCvx's", "n/a (figure only)", pct(gap)),
        ]
    )


def trajectory_figures(
    instance, solution, cold, predictor, out: Path, tight_tol: float
) -> list[tuple[str, str]]:
    """The trajectory figure and the predicted-vs-true tight rows figure."""
    from scpformer.data.pdg6dof_family import theta_vector
    from scpformer.plotting.pdg6dof import plot_trajectory
    from scpformer.problems.pdg6dof.constraints import (
        CONSTRAINT_NAMES,
        constraint_values,
        tight_flags,
    )

    z = solution.trajectory
    t = np.linspace(0.0, float(z.p[0]), z.x.shape[0])
    constants = {
        **instance.constants.__dict__,
        "theta_max_deg": instance.theta_max_deg,
        "gamma_gs_deg": instance.gamma_gs_deg,
    }
    plot_trajectory(t, z.x, z.u, constants, out / "fig3_trajectory.png", title="T-SCvx solution")
    theta = theta_vector(instance)
    panels = {
        "predicted tight, k = 1": predictor.predict_tight(theta, 1),
        "tight at cold SCvx's first solve": cold.history[0].tight_flags,
        f"predicted tight, k = {cold.iterations}": predictor.predict_tight(theta, cold.iterations),
        "tight at cold SCvx's optimum": tight_flags(  # the returned iterate's, not the last
            # solve's: a run certified stationary ends on a solve whose candidate it rejects
            constraint_values(instance, cold.trajectory.x, cold.trajectory.u),
            tight_tol,
        ).ravel(),
    }
    figure, axes = rep.new_figure(ncols=len(panels), width=16.0, height=3.2)
    n = len(CONSTRAINT_NAMES)
    for ax, (title, flags) in zip(axes, panels.items(), strict=True):
        ax.imshow(
            np.asarray(flags, bool).reshape(n, -1),
            aspect="auto",
            cmap="Greys",
            interpolation="nearest",
        )
        ax.set_yticks(range(n), CONSTRAINT_NAMES)
        ax.set_xlabel("node")
        ax.set_title(title, fontsize=9)
    rows = rep.save_figure(figure, out / "fig3_tight_rows.png")
    return [
        ("fig3_trajectory.png", "Fig. 3: the T-SCvx solution (thrust vectors)"),
        (rows, "Fig. 3: tight rows predicted by f2 and tight in cold SCvx (black)"),
    ]


def trajectory_summary(position: int, solution: Any, cold: Any) -> str:
    """Status, solves, final mass of both solves of the instance."""
    rows = [
        (label, s.status.value, s.iterations, rep.fmt(-s.cost, 6))
        for label, s in (("cold SCvx", cold), ("T-SCvx", solution))
    ]
    table = rep.markdown_table(("solver", "status", "solves", "final mass [U_M]"), rows)
    return f"Test sample {position}.\n\n{table}"
