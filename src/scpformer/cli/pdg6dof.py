"""``scpformer solve pdg6dof`` and ``scpformer bench pdg6dof``: the handlers; the flags are in
:mod:`scpformer.cli.parsers.pdg6dof`."""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from scpformer.cli.dataclass_args import nested_overrides, overrides
from scpformer.cli.outputs import check_solve_outputs, print_rows, timing_rows, write_csv
from scpformer.files import check_output_file
from scpformer.pdg6dof import solve
from scpformer.problems.pdg6dof.adapter import conic_solves
from scpformer.problems.pdg6dof.config import PDGSolverConfig
from scpformer.problems.pdg6dof.constants import VehicleConstants
from scpformer.problems.pdg6dof.instance import PDGInstance, constants_from_dict
from scpformer.problems.pdg6dof.metrics import propellant_gap, solve_reference
from scpformer.problems.pdg6dof.sampling import PDGSampleRanges, sample_instances
from scpformer.scp.solution import Solution, Status


def config_from_args(args: argparse.Namespace) -> PDGSolverConfig:
    """The solver configuration with the command-line overrides applied."""
    return nested_overrides(args, PDGSolverConfig, {"scvx": "scvx"})


def instance_from_args(args: argparse.Namespace) -> PDGInstance:
    """The nominal instance, or ``--instance FILE``, with constant overrides applied."""
    instance = PDGInstance.from_json(args.instance) if args.instance else PDGInstance()
    const = overrides(args, VehicleConstants, "const")
    if const:
        merged = {**dataclasses.asdict(instance.constants), **const}
        instance = dataclasses.replace(instance, constants=constants_from_dict(merged))
    return instance


def warmstart_from_args(args: argparse.Namespace) -> object:
    """An analytic guess's name or the T-SCvx provider of ``--warmstart tscvx|kdtree|interp
    [--model RUN]`` (tscvx without ``--model``, or with ``default``: the shipped,
    checksum-verified networks; the lookup tables need their run folder)."""
    if args.warmstart in ("cubic_profile", "straight_line"):
        if args.model is not None:
            raise ValueError("--model: used with --warmstart tscvx, kdtree or interp only")
        return args.warmstart
    from scpformer.models.capabilities import single_thread_inference
    from scpformer.models.predictors import load_predictor
    from scpformer.pretrained import resolve_model
    from scpformer.warmstart.tscvx import TscvxWarmStart

    if args.warmstart == "tscvx":
        single_thread_inference()
        return TscvxWarmStart.from_checkpoint(resolve_model(args.model, "pdg6dof"))
    if args.model is None:
        raise ValueError(f"--warmstart {args.warmstart} needs --model RUN "
                         f"(made by `scpformer train {args.warmstart}`)")  # fmt: skip
    return TscvxWarmStart(load_predictor(args.model, args.warmstart))


def print_summary(solution: Solution, instance: PDGInstance) -> None:
    """A human-readable table of the solution."""
    rows = [
        ("status", solution.status.value),
        ("iterations", str(solution.iterations)),
        ("  conic solves", str(conic_solves(solution))),
    ]
    if solution.message:
        rows.append(("message", solution.message))
    if "tscvx" in solution.extras:
        rows += tscvx_rows(solution.extras)
    if solution.trajectory is not None:
        x, tf = solution.trajectory.x, float(solution.trajectory.p[0])
        rows += [
            ("final time t_f", f"{tf:.4f} U_T"),
            ("final mass m(t_f)", f"{x[-1, 13]:.5f} U_M"),
            ("fuel used", f"{instance.m0 - x[-1, 13]:.5f} U_M"),
        ]
    if solution.verification is not None:
        ver = solution.verification
        rows.append(("verified", "yes" if ver.passed else f"no ({ver.message})"))
        for name, value in ver.terminal_error.items():
            rows.append((f"terminal {name} error", f"{value:.2e}"))
        rows.append(("max node defect (propagated)", f"{ver.max_defect:.2e}"))
        worst = max(ver.path_violations.items(), key=lambda kv: kv[1], default=("-", 0.0))
        rows.append(("worst path violation", f"{worst[0]} {worst[1]:.2e}"))
    elif solution.trajectory is not None:
        rows.append(("verified", "not verified"))
    if solution.timing is not None:
        rows += timing_rows(solution.timing, "discretization")
    print_rows(rows)


def tscvx_rows(extras: dict) -> list[tuple[str, str]]:
    """What the T-SCvx run did: guess, rows kept, repairs, fallback."""
    log, record = extras["tscvx"], extras.get("warmstart", {})
    kept = log["rows_kept"]
    rows = [
        ("T-SCvx guess", f"{record.get('used', '-')} ({record.get('reason', '')})"),
        ("T-SCvx rows kept", f"median {np.median(kept):.0f} per solve" if kept else "-"),
        ("T-SCvx repairs", str(sum(log["repairs"]))),
    ]
    if log["fallback"]:
        rows.append(("T-SCvx fallback", f"{log['fallback']} ({log['fallback_reason']})"))
    return rows


def history_plot_path(plot: Path) -> Path:
    """Where the SCvx history figure goes next to ``--plot`` (same format)."""
    return plot.with_name(f"{plot.stem}_history{plot.suffix}")


def run_solve(args: argparse.Namespace) -> int:
    instance = instance_from_args(args)
    config = config_from_args(args)
    history = history_plot_path(args.plot) if args.plot else None
    check_solve_outputs(args.out, args.plot, history)
    method = "scvx" if args.warmstart in ("cubic_profile", "straight_line") else "tscvx"
    solution = solve(instance, config, method=method, warmstart=warmstart_from_args(args))
    if solution.status is Status.INFEASIBLE_INSTANCE and solution.iterations == 0:
        # refused before any solve (the initial state already violates a constraint): bad
        # input, said as such, not a solver outcome
        raise ValueError(f"the instance cannot be flown: {solution.message}")
    print_summary(solution, instance)
    if solution.trajectory is not None:
        if args.out:
            from scpformer.problems.pdg6dof.io import save_solution

            save_solution(args.out, solution, instance)
            print(f"wrote {args.out}")
        if args.plot:
            write_figures(args.plot, solution, instance)
            print(f"wrote {args.plot} and {history}")
    return 0 if solution.converged else 1


def write_figures(plot: Path, solution: Solution, instance: PDGInstance) -> None:
    """The trajectory figure at ``plot`` and the SCvx history beside it
    (:func:`history_plot_path`)."""
    from scpformer.plotting.pdg6dof import plot_history, plot_trajectory
    from scpformer.problems.pdg6dof.io import constants_record

    x, u = solution.trajectory.x, solution.trajectory.u
    plot_trajectory(solution.t, x, u, constants_record(instance), path=plot)
    restart_after = solution.extras.get("restart", {}).get("after")
    rows = [rec.summary() for rec in solution.history]
    plot_history(rows, path=history_plot_path(plot), restart_after=restart_after)


BENCH_FIELDS = (
    "set",
    "index",
    "status",
    "iterations",
    "conic_solves",
    "wall_s",
    "discretization_s",
    "solver_s",
    "verification_s",
    "other_s",
    "cost",
    "tf",
    "reference_status",
    "reference_cost",
    "gap",
)


def _bench_row(name: str, index: int, solution: Solution, wall: float) -> dict[str, object]:
    tm = solution.timing
    return {
        "set": name,
        "index": index,
        "status": solution.status.value,
        "iterations": solution.iterations,
        "conic_solves": conic_solves(solution),
        "wall_s": wall,
        "discretization_s": tm.discretization if tm else 0.0,
        "solver_s": tm.solver if tm else 0.0,
        "verification_s": tm.verification if tm else 0.0,
        "other_s": tm.other if tm else 0.0,
        "cost": solution.cost,
        "tf": float(solution.trajectory.p[0]) if solution.trajectory is not None else np.nan,
        "reference_status": "",
        "reference_cost": np.nan,
        "gap": np.nan,
    }


def _add_reference(
    row: dict[str, object], instance: PDGInstance, solution: Solution, config: PDGSolverConfig
) -> None:
    """The reference run's status, cost and the propellant gap of ``solution`` to it."""
    if solution.trajectory is None:
        return
    reference = solve_reference(instance, config, solution)
    row["reference_status"] = reference.status.value
    row["reference_cost"] = reference.cost
    row["gap"] = propellant_gap(instance, solution.cost, reference.cost)


def summarize(rows: list[dict[str, object]]) -> list[str]:
    """Median/mean/p95 wall time, iterations, converged rate, time shares per set."""
    lines = [
        f"{'set':<8} {'n':>3} {'conv':>6} {'med s':>7} {'mean s':>7} {'p95 s':>7} "
        f"{'med it':>6} {'solves':>6} {'solver':>7} {'discr':>6} {'verif':>6} {'other':>6}"
    ]
    for name in dict.fromkeys(r["set"] for r in rows):
        sel = [r for r in rows if r["set"] == name]
        wall = np.array([r["wall_s"] for r in sel], dtype=float)
        total = wall.sum() or 1.0
        share = {
            k: sum(float(r[k]) for r in sel) / total
            for k in ("solver_s", "discretization_s", "verification_s", "other_s")
        }
        conv = np.mean([r["status"] == "converged" for r in sel])
        its = np.median([r["iterations"] for r in sel])
        solves = np.median([r["conic_solves"] for r in sel])
        gaps = np.array([r["gap"] for r in sel], dtype=float)
        gaps = gaps[np.isfinite(gaps)]
        lines.append(
            f"{name:<8} {len(sel):>3} {conv:>6.0%} {np.median(wall):>7.3f} {wall.mean():>7.3f} "
            f"{np.percentile(wall, 95):>7.3f} {its:>6.1f} {solves:>6.1f} {share['solver_s']:>7.0%} "
            f"{share['discretization_s']:>6.0%} {share['verification_s']:>6.0%} "
            f"{share['other_s']:>6.0%}"
        )
        if gaps.size:
            lines.append(
                f"{'':<8} propellant gap to the reference: median {np.median(gaps):.3%}, "
                f"max {gaps.max():.3%}; iterations p95 "
                f"{np.percentile([r['iterations'] for r in sel], 95):.0f}, conic solves p95 "
                f"{np.percentile([r['conic_solves'] for r in sel], 95):.0f}"
            )
    return lines


def per_instance_lines(rows: list[dict[str, object]]) -> list[str]:
    """One line per solve: set, index, status, iterations, wall time and its split."""
    lines = [
        f"{'set':<8} {'#':>3} {'status':<20} {'it':>3} {'cs':>3} {'wall s':>7} {'solver':>7} "
        f"{'discr':>7} {'cost':>8} {'tf':>6} {'gap':>8}"
    ]
    for r in rows:
        lines.append(
            f"{r['set']:<8} {r['index']:>3} {r['status']:<20} {r['iterations']:>3} "
            f"{r['conic_solves']:>3} "
            f"{r['wall_s']:>7.3f} {r['solver_s']:>7.3f} {r['discretization_s']:>7.3f} "
            f"{r['cost']:>8.4f} {r['tf']:>6.3f} {r['gap']:>8.3%}"
        )
    return lines


def run_bench(args: argparse.Namespace) -> int:
    if args.n_nominal + args.n_table2 == 0:
        raise ValueError("--n-nominal and --n-table2 are both 0: nothing to benchmark")
    config = config_from_args(args)
    check_output_file(args.csv, "--csv")
    rng = np.random.default_rng(args.seed)
    sets = [
        ("nominal", sample_instances(rng, args.n_nominal, PDGSampleRanges.nominal())),
        ("table2", sample_instances(rng, args.n_table2, PDGSampleRanges.table2())),
    ]
    start = time.perf_counter()
    solve(PDGInstance(), config)  # canonicalize the parametric subproblem once, untimed
    print(f"compiled the subproblem (N = {config.n_nodes}) in {time.perf_counter() - start:.1f} s")
    rows = []
    total = sum(len(insts) for _, insts in sets)
    from tqdm import tqdm  # only the benchmark needs it

    with tqdm(total=total, desc="pdg6dof", unit="solve") as bar:
        for name, instances in sets:
            for index, instance in enumerate(instances):
                t0 = time.perf_counter()
                solution = solve(instance, config)
                rows.append(_bench_row(name, index, solution, time.perf_counter() - t0))
                if args.optimality:
                    _add_reference(rows[-1], instance, solution, config)
                bar.set_postfix(status=solution.status.value, it=solution.iterations)
                bar.update()
    write_csv(args.csv, BENCH_FIELDS, rows)
    print("\n".join(per_instance_lines(rows)))
    print("\n".join(summarize(rows)))
    print(f"wrote {args.csv}")
    return 0
