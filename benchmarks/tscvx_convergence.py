"""How close to the optimum T-SCvx and cold SCvx are after each conic solve.

The test instances are those of ``scpformer experiment run tscvx-solve-time``
(:func:`~scpformer.experiments.runner.select_test_instances` of ``--data``'s test split with
``--seed``). Each is solved by cold SCvx and by T-SCvx with the networks of ``--model``, in
alternating order, one process, one torch thread. After every conic solve of a run, the run's
current iterate (its last accepted one; a least-change correction is no conic solve) is
*within* a tolerance ``tol`` when

* its nonlinear penalty (Eq. 16's defects and thrust lower-bound excess) is at most
  ``--penalty`` (default 1e-3: nearly feasible), and
* its propellant exceeds that of cold SCvx's converged optimum by at most ``tol`` of that
  propellant (:func:`~scpformer.problems.pdg6dof.problem.propellant_gap`).

Every run then goes on until the stopping test of :mod:`scpformer.scp.scvx` certifies a
stationary point (``converged``). The gap between the two counts is what the certificate
costs: the tail in which the iterate moves along the flat valley of bang-bang thrust arcs by
less than the tolerance, which a learned guess shortens only by starting closer.

Prints, per method, the mean and median conic solves until within each ``--tolerances``
value and until converged; writes ``convergence.csv`` (one row per instance and method) and
``convergence_profile.png`` (share of instances within each tolerance, and converged, against
conic solves) into ``--out``.

Usage (the held-out set of the tscvx-solve-time experiment, about 10 minutes on one core)::

    PYTHONPATH=src python benchmarks/tscvx_convergence.py --data r8 --n 688 --out conv
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.cli.argtypes import count, positive
from scpformer.scp.solution import Solution

METHODS = ("cold", "tscvx")
STYLES = {"cold": "tab:gray", "tscvx": "tab:blue"}
LABELS = {"cold": "SCvx (cold)", "tscvx": "T-SCvx (networks)"}


def solves_until_within(
    solution: Solution, instance: Any, reference_cost: float, tol: float, penalty: float
) -> float:
    """Conic solves of ``solution.history`` until its current iterate is within ``tol``
    (module docstring); ``inf`` if it never is."""
    from scpformer.problems.pdg6dof.problem import LEAST_CHANGE, propellant_gap

    solves = 0
    for record in solution.history:
        solves += record.solver_status != LEAST_CHANGE
        if not record.accepted:
            continue
        gap = propellant_gap(instance, record.cost, reference_cost)
        if record.penalty <= penalty and gap <= tol:
            return float(solves)
    return math.inf


def conic_solves_to_converge(solution: Solution) -> float:
    """All conic solves of a converged run (``inf`` for a run that did not converge)."""
    from scpformer.problems.pdg6dof.problem import conic_solves

    return float(conic_solves(solution)) if solution.converged else math.inf


def instance_rows(
    index: int, instance: Any, solutions: dict[str, tuple[Solution, float]], args: Any
) -> list[dict[str, Any]]:
    """One row per method: solves until within each tolerance, until converged, wall time."""
    reference = solutions["cold"][0].cost
    rows = []
    for method in METHODS:
        solution, wall = solutions[method]
        row: dict[str, Any] = {"index": index, "method": method, "wall_s": wall}
        for tol in args.tolerances:
            row[tolerance_column(tol)] = solves_until_within(
                solution, instance, reference, tol, args.penalty
            )
        row["solves_converged"] = conic_solves_to_converge(solution)
        rows.append(row)
    return rows


def tolerance_column(tol: float) -> str:
    return f"solves_within_{100 * tol:g}pct"


def run(args: Any) -> list[dict[str, Any]]:
    """Solve the selected instances with both methods (the tscvx-solve-time experiment's
    :class:`~scpformer.experiments.tscvx.common.SolveTimeSolver`); the rows of
    :func:`instance_rows`."""
    from scpformer.data.storage import read_manifest
    from scpformer.experiments.runner import select_test_instances, theta_tasks
    from scpformer.experiments.tscvx.common import SolveTimeSolver
    from scpformer.pretrained import default_model

    model = default_model("pdg6dof") if args.model == "default" else Path(args.model)
    solver = SolveTimeSolver({"tscvx": model}, read_manifest(args.data).config)
    solver.warm_up()  # one torch thread, the networks traced, the subproblem compiled
    tasks = theta_tasks(args.data, select_test_instances(args.data, args.n, args.seed))
    rows: list[dict[str, Any]] = []
    for done, task in enumerate(tasks):
        instance, solutions = solver.solutions(task)
        if not solutions["cold"][0].converged:
            print(f"instance {task.index}: cold SCvx did not converge, left out", file=sys.stderr)
            continue
        rows.extend(instance_rows(task.index, instance, solutions, args))
        print(f"\r{done + 1}/{len(tasks)} instances", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    return rows


def summary(rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> str:
    """Mean and median solves per method and column, with the share of runs that got there."""
    lines = []
    for method in METHODS:
        mine = [r for r in rows if r["method"] == method]
        walls = np.array([r["wall_s"] for r in mine])
        parts = [
            f"{LABELS[method]:18s} wall mean {walls.mean():.3f} s, median {np.median(walls):.3f} s"
        ]
        for name in columns:
            values = np.array([r[name] for r in mine], dtype=float)
            reached = values[np.isfinite(values)]
            if not reached.size:
                parts.append(f"  {name:22s} reached by none of {values.size}")
                continue
            parts.append(
                f"  {name:22s} mean {reached.mean():5.2f}  median {np.median(reached):4.1f}"
                f"  reached {reached.size}/{values.size}"
            )
        lines.append("\n".join(parts))
    return "\n".join(lines)


def plot_profile(rows: Sequence[dict[str, Any]], columns: Sequence[str], path: Path) -> None:
    """Share of instances within each tolerance (and converged) against conic solves."""
    from scpformer.experiments.report import new_figure, save_figure

    figure, ax = new_figure(ncols=1, width=7.0, height=4.2)
    finite = [r[c] for r in rows for c in columns if math.isfinite(r[c])]
    grid = np.arange(0, int(np.percentile(finite, 99.5)) + 3)  # the long tail left out
    dashes = ["-", "--", ":", "-."]
    for method in METHODS:
        mine = [r for r in rows if r["method"] == method]
        for name, dash in zip(columns, dashes, strict=False):
            values = np.array([r[name] for r in mine], dtype=float)
            share = (values[None, :] <= grid[:, None]).mean(axis=1)
            label = f"{LABELS[method]}: {column_label(name)}"
            ax.step(grid, share, where="post", color=STYLES[method], linestyle=dash, label=label)
    ax.set_xlabel("conic solves")
    ax.set_ylabel("share of instances")
    ax.set_title(f"{len(rows) // len(METHODS)} held-out instances: how close after k solves")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    save_figure(figure, path)


def column_label(name: str) -> str:
    """``solves_within_0.5pct`` -> ``within 0.5%``; ``solves_converged`` -> ``converged``."""
    return name.removeprefix("solves_").replace("_", " ").replace("pct", "%")


def write_csv(rows: Sequence[dict[str, Any]], path: Path) -> None:
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def fraction(text: str) -> float:
    """An argparse type for a tolerance or penalty in (0, 1)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f"must be in (0, 1), got {text}")
    return value


def parse_args(argv: Sequence[str] | None = None) -> Any:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, required=True, help="a split pdg6dof dataset")
    parser.add_argument("--n", type=positive, default=100, help="test instances (default 100)")
    parser.add_argument("--seed", type=count, default=0, help="selection seed (default 0)")
    parser.add_argument("--model", default="default", help="T-SCvx run folder or 'default'")
    parser.add_argument("--tolerances", type=fraction, nargs="+", default=[0.005, 0.001])
    parser.add_argument("--penalty", type=fraction, default=1e-3, help="nearly feasible below")
    parser.add_argument("--out", type=Path, required=True, help="folder for the CSV and PNG")
    args = parser.parse_args(argv)
    if not (args.data / "manifest.json").is_file():
        parser.error(f"--data {args.data}: not a dataset folder (no manifest.json)")
    return args


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        rows = run(args)
    except (ValueError, OSError) as err:  # no test split, an unreadable model or dataset
        print(f"tscvx_convergence.py: error: {err}", file=sys.stderr)
        return 2
    if not rows:
        print("no instance on which cold SCvx converged", file=sys.stderr)
        return 1
    args.out.mkdir(parents=True, exist_ok=True)
    columns = [*map(tolerance_column, args.tolerances), "solves_converged"]
    write_csv(rows, args.out / "convergence.csv")
    plot_profile(rows, columns, args.out / "convergence_profile.png")
    print(summary(rows, columns))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
