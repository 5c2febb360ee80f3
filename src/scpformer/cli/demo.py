"""``scpformer demo``: the papers' learned warm starts beside the classical ones, in a minute.

Three problems, each solved with the classical warm start and the learned one (the
pretrained models of :mod:`scpformer.pretrained`):

* the ISS rendezvous (ART paper, Problem 3): SCP from the convex solution (CVX) and from
  ART (Algorithm 2, R(t_1) = -J_CVX, C(t_1) = 0);
* the chance-constrained, passively safe rendezvous (robust ART paper): SCvx* from the
  convex TPBVP (PS-CVX) and from ART after the post hoc check of Eq. 8 (PS-ART);
* the 6-DoF Mars landing (T-SCvx paper): SCvx from the cubic-profile guess and T-SCvx
  (Algorithm 2) from the networks' solution and tight constraints.

It prints one table (problem, warm start, cost, iterations, wall time of warm start plus
solve, verified by the nonlinear replay) and writes one figure per solve into ``--out``.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.cli.commands import command_help
from scpformer.files import check_output_folder

# The instances shown, sampled from each family's Table 1 ranges. Rendezvous seed 4: its
# convex guess violates the keep-out and cone constraints at 15 nodes (C = 15), and so does
# the shipped ART's (9,000 training instances; the model shipped before, trained on 3,000,
# violated none), yet the SCP from ART converges in 3 iterations instead of 6, at the same
# cost. On seeds 0-11 the shipped ART takes fewer iterations on 4 and more on 7, mostly where
# SCP from the convex guess stops after one; every first subproblem from its guesses is
# solved (docs/RESULTS.md has the test-set statistics). Robust seed 0: the shipped robust
# ART's guess fails the Eq. 8 check, so PS-ART falls back to the TPBVP, as the check is meant
# to. Of seeds 0-39 its guess passes on 5 (8, 11, 22, 29, 30); the robust model shipped
# before (1,200 training instances, RTN) passed on none.
RENDEZVOUS_SEED = 4
ROBUST_SEED = 0


@dataclass(frozen=True)
class DemoRow:
    """One line of the comparison table."""

    problem: str
    warmstart: str
    cost: str
    iterations: int
    seconds: float  # warm start + solve (+ verification) wall time
    verified: bool
    figure: Path


def _row(
    problem: str, warmstart: str, cost: str, solution: Any, seconds: float, figure: Path
) -> DemoRow:
    return DemoRow(
        problem, warmstart, cost, solution.iterations, seconds, bool(solution.converged), figure
    )


def add_demo_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "demo",
        help=command_help("", "demo"),
        description=__doc__.split("\n\n")[0] + " See `scpformer demo --help`.",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("scpformer-demo"),
        help="folder for the figures (default: ./scpformer-demo)",
    )
    parser.set_defaults(handler=run_demo)


def run_demo(args: argparse.Namespace) -> int:
    out = check_output_folder(args.out, "--out")  # a file or a read-only place, named as such
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ValueError(f"--out {out}: cannot create the folder ({err.strerror})") from None
    from scpformer.cli.warmstart import single_thread_inference

    single_thread_inference()
    start = time.perf_counter()
    rows = []
    for section in (rendezvous_rows, robust_rows, landing_rows):
        rows += section(out)
    print_table(rows)
    figures = sorted(path.name for path in out.glob("*.png"))
    print(f"figures in {out}/: {', '.join(figures)}")
    print(
        f"total {time.perf_counter() - start:.1f} s; one instance per problem (statistics "
        "over test sets: docs/RESULTS.md)"
    )
    return 0 if all(row.verified for row in rows) else 1


def print_table(rows: list[DemoRow]) -> None:
    """The comparison table, one line per solve."""
    header = ("problem", "warm start", "cost", "iterations", "time [s]", "verified")
    cells = [header] + [
        (
            r.problem,
            r.warmstart,
            r.cost,
            str(r.iterations),
            f"{r.seconds:.2f}",
            "yes" if r.verified else "no",
        )
        for r in rows
    ]
    widths = [max(len(row[i]) for row in cells) for i in range(len(header))]
    for number, row in enumerate(cells):
        print("  ".join(cell.ljust(width) for cell, width in zip(row, widths, strict=True)))
        if number == 0:
            print("  ".join("-" * width for width in widths))


def _timed(solve: Callable[[], Any]) -> tuple[Any, float]:
    start = time.perf_counter()
    result = solve()
    return result, time.perf_counter() - start


def rendezvous_rows(out: Path) -> list[DemoRow]:
    """The ISS rendezvous from CVX and from ART (pretrained), with their figures."""
    from scpformer.cli.rendezvous import write_figure
    from scpformer.pretrained import default_model
    from scpformer.problems.rendezvous import RendezvousSolverConfig, sample_instances, solve
    from scpformer.warmstart import ArtWarmStart, RendezvousConvexWarmStart

    instance = sample_instances(np.random.default_rng(RENDEZVOUS_SEED), 1)[0]
    config = RendezvousSolverConfig()
    providers = {
        "CVX": lambda: RendezvousConvexWarmStart("convex", config),
        "ART": lambda: ArtWarmStart.from_checkpoint(
            default_model("rendezvous"), family="rendezvous", config=config
        ),
    }
    rows = []
    for label, provider in providers.items():
        model = provider()  # loading the network is not part of the solve time

        def run(model=model) -> tuple[Any, Any]:
            warm = model.guess(instance)
            return warm, solve(instance, "scp", warm, config=config)

        (warm, solution), seconds = _timed(run)
        figure = out / f"rendezvous_{label.lower()}.png"
        write_figure(figure, solution, instance, warm)
        cost = f"{1e3 * solution.cost:.1f} mm/s"
        rows.append(_row("rendezvous (ISS, Problem 3)", label, cost, solution, seconds, figure))
    return rows


def robust_rows(out: Path) -> list[DemoRow]:
    """The chance-constrained rendezvous from the TPBVP (PS-CVX) and from ART (PS-ART)."""
    from scpformer.plotting.robust_rendezvous import plot_solution
    from scpformer.pretrained import default_model
    from scpformer.problems.robust_rendezvous.instance import sample_instances
    from scpformer.problems.robust_rendezvous.problem import solve
    from scpformer.problems.robust_rendezvous.scenario import RobustSolverConfig
    from scpformer.warmstart import ArtWarmStart

    instance = sample_instances(ROBUST_SEED, 1)[0]
    config = RobustSolverConfig()
    art = ArtWarmStart.from_checkpoint(
        default_model("robust-rendezvous"), family="robust-rendezvous", config=config, mode="chance"
    )
    rows = []
    for label in ("PS-CVX", "PS-ART"):

        def run(label=label) -> tuple[Any, Any]:
            warm = art.guess(instance) if label == "PS-ART" else "tpbvp"
            return warm, solve(instance, config, "chance", warmstart=warm)

        (warm, solution), seconds = _timed(run)
        name = "TPBVP"
        if label == "PS-ART":
            record = warm.record
            name = "ART, check passed" if record.accepted else f"ART rejected -> {record.used}"
        figure = out / f"robust_{label.lower().replace('-', '_')}.png"
        if solution.trajectory is not None:
            plot_solution(instance, solution.trajectory.x, solution.trajectory.u, figure)
        cost = f"{1e3 * solution.cost:.1f} mm/s"
        rows.append(
            _row("robust rendezvous (chance, Eq. 8)", name, cost, solution, seconds, figure)
        )
    return rows


def landing_rows(out: Path) -> list[DemoRow]:
    """The nominal 6-DoF landing with SCvx (cubic-profile guess) and T-SCvx (pretrained)."""
    from scpformer.cli.pdg6dof import write_figures
    from scpformer.pretrained import default_model
    from scpformer.problems.pdg6dof.instance import PDGInstance
    from scpformer.problems.pdg6dof.problem import PDGSolverConfig, solve
    from scpformer.warmstart.tscvx import TscvxWarmStart

    instance, config = PDGInstance(), PDGSolverConfig()
    tscvx = TscvxWarmStart.from_run(default_model("pdg6dof"))
    rows = []
    guesses = {"cubic profile": "cubic_profile", "T-SCvx networks": tscvx}
    for label, guess in guesses.items():
        solution, seconds = _timed(lambda guess=guess: solve(instance, config, guess=guess))
        figure = out / ("landing_scvx.png" if guess == "cubic_profile" else "landing_t_scvx.png")
        fuel = math.nan
        if solution.trajectory is not None:
            write_figures(figure, solution, instance)
            fuel = instance.m0 - solution.trajectory.x[-1, 13]
        cost = f"{fuel:.4f} U_M fuel"
        rows.append(_row("6-DoF Mars landing (nominal)", label, cost, solution, seconds, figure))
    return rows
