"""``scpformer solve robust-rendezvous`` and ``scpformer bench robust-rendezvous`` (robust ART)."""

from __future__ import annotations

import argparse
import dataclasses
import math
import re
import time
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.cli.argtypes import count, positive
from scpformer.cli.commands import command_help
from scpformer.cli.dataclass_args import add_dataclass_arguments, overrides, with_overrides
from scpformer.cli.outputs import check_solve_outputs, write_csv
from scpformer.cli.rendezvous import print_rows
from scpformer.cli.warmstart import (
    add_warmstart_arguments,
    art_provider,
    comparison_rows,
    warmstart_line,
)
from scpformer.files import check_output_file
from scpformer.problems.rendezvous.scenario import TargetOrbit
from scpformer.problems.robust_rendezvous.instance import RobustInstance, sample_instances
from scpformer.problems.robust_rendezvous.problem import (
    WARMSTARTS,
    solve,
    solve_safety,
    solve_tpbvp,
)
from scpformer.problems.robust_rendezvous.scenario import (
    MODES,
    WAYPOINTS,
    RobustScenario,
    RobustSolverConfig,
    RobustVerification,
    robust_target,
)
from scpformer.scp.scvx_star import SCvxStarParameters
from scpformer.scp.solution import Solution, Status


# ======================================================================================
# shared flags
# ======================================================================================
def add_config_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags for every solver setting and scenario constant (robust Tables 1-2 defaults).

    The waypoints ``-T`` and ``-R`` are values (``--waypoint -T``, ``--range-waypoints +T -T``),
    not options: ``parser`` reads them as it reads negative numbers.
    """
    parser._negative_number_matcher = re.compile(r"^-(\d+\.?\d*|\.\d+|[A-Z])$")
    add_dataclass_arguments(parser, RobustSolverConfig, title="formulation")
    add_dataclass_arguments(parser, SCvxStarParameters, prefix="scvx", title="SCvx* (Table 1)")
    add_dataclass_arguments(parser, RobustVerification, prefix="verify", title="verification")
    add_dataclass_arguments(parser, RobustScenario, prefix="scenario", title="OCP (Table 1)")
    add_dataclass_arguments(parser, TargetOrbit, prefix="target", title="target orbit (Table 1)")
    parser.add_argument("--delta", type=float, help="Delta: chance-constraint level (1e-3)")


def config_from_args(args: argparse.Namespace) -> RobustSolverConfig:
    """The solver configuration with the command-line overrides applied."""
    return RobustSolverConfig(
        scvx=SCvxStarParameters(**overrides(args, SCvxStarParameters, "scvx")),
        verification=RobustVerification(**overrides(args, RobustVerification, "verify")),
        **overrides(args, RobustSolverConfig),
    )


def common_from_args(args: argparse.Namespace, base: RobustInstance | None) -> dict[str, Any]:
    """Scenario, target and uncertainty (of ``base`` or the tables) with the overrides."""
    scenario = with_overrides(base.scenario if base else RobustScenario(), args, RobustScenario,
                       "scenario")  # fmt: skip
    target = with_overrides(base.target if base else robust_target(), args, TargetOrbit, "target")
    unc = base.uncertainty if base else RobustInstance().uncertainty
    if getattr(args, "delta", None) is not None:
        unc = dataclasses.replace(unc, delta=args.delta)
    return {"scenario": scenario, "target": target, "uncertainty": unc}


# ======================================================================================
# solve
# ======================================================================================
def add_solve_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "robust-rendezvous",
        help=command_help("solve", "robust-rendezvous"),
        description="Solve the passively safe rendezvous of the robust ART paper (Table 1) "
        "with the three-stage procedure (convex TPBVP -> deterministic collision avoidance -> "
        "passive safety, deterministic or chance-constrained) and SCvx*; optionally verify "
        "the chance constraint by Monte Carlo through a two-body + J2 propagator.",
    )
    parser.add_argument("--mode", choices=MODES, default="chance", help="(default: chance)")
    parser.add_argument(
        "--waypoint", help=f"pre-docking state: {', '.join(WAYPOINTS)} (default: instance's)"
    )
    add_warmstart_arguments(
        parser, WARMSTARTS, "three_stage", "three_stage (dataset procedure), tpbvp (PS-CVX)"
    )
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--instance", type=Path, help="instance JSON (x0_rtn, waypoint, ...)")
    source.add_argument("--seed", type=count, help="sample the instance (Table 1) with this seed")
    parser.add_argument("--out", type=Path, help="write the solution to this .npz file")
    parser.add_argument(
        "--plot", type=Path, help="write Figs. 7-8 style plots to this .png, .pdf or .svg"
    )
    parser.add_argument(
        "--monte-carlo", type=count, default=0, metavar="N",
        help="Monte Carlo draws per node through the two-body + J2 propagator (0: skip)",
    )  # fmt: skip
    parser.add_argument("--mc-seed", type=count, default=0, help="Monte Carlo seed (0)")
    add_config_arguments(parser)
    parser.set_defaults(handler=run_solve)


def instance_from_args(args: argparse.Namespace) -> RobustInstance:
    """``--instance FILE``, ``--seed S`` or Table 1's nominal instance, with overrides."""
    base = RobustInstance.from_json(args.instance) if args.instance else None
    common = common_from_args(args, base)
    if base is None and args.seed is not None:
        base = sample_instances(args.seed, 1, **common)[0]
    changes: dict[str, Any] = dict(common)
    if args.waypoint is not None:
        changes["waypoint"] = args.waypoint
    if base is None:
        return RobustInstance(**changes)
    return dataclasses.replace(base, **changes)


_DYNAMICS_LABEL = {
    "nonlinear": "nonlinear mean elements (secular J2 flow, exact impulses)",
    "stm": "linear J2 STM about the target (Koenig 2017)",
}


def summary_rows(solution: Solution) -> list[tuple[str, str]]:
    """Human-readable (key, value) rows of a solution."""
    ex = solution.extras
    rows = [
        ("status", solution.status.value),
        ("trajectory from stage", str(ex.get("stage"))),
        ("dynamics model", _DYNAMICS_LABEL.get(ex.get("dynamics"), str(ex.get("dynamics")))),
        ("stages", ", ".join(f"{k}: {v}" for k, v in ex.get("stage_status", {}).items())),
        ("SCvx* iterations", str(solution.iterations)),
    ]
    if solution.message:
        rows.append(("message", solution.message))
    if solution.trajectory is not None:
        rows.append(("cost sum |dv|", f"{solution.cost:.4f} m/s"))
    rows += replay_rows(solution)
    ctg = math.nan
    if "violation_budget" in ex:
        ctg = int(ex["violation_budget"][0])
        rows.append(("violation budget C(t_0)", str(ctg)))
    if "warmstart" in ex:
        rows += comparison_rows(ex["warmstart"], solution, ctg)
    if solution.timing is not None:
        tm = solution.timing
        rows += [
            ("wall time (last stage)", f"{tm.total:.3f} s"),
            ("  conic solver", f"{tm.solver:.3f} s"),
            ("  linearization", f"{tm.discretization:.3f} s"),
        ]
    return rows


def replay_rows(solution: Solution) -> list[tuple[str, str]]:
    """The truth replay's miss of the waypoint, when the verification replayed the plan."""
    ver = solution.verification
    if ver is None or "position_m" not in ver.terminal_error:
        return []
    miss = ver.terminal_error
    text = f"{miss['position_m']:.3f} m, {miss['velocity_m_s'] * 1e3:.3f} mm/s"
    return [("truth replay miss", f"{text} ({'passed' if ver.passed else 'failed'})")]


def run_solve(args: argparse.Namespace) -> int:
    instance = instance_from_args(args)
    config = config_from_args(args)
    check_solve_outputs(args.out, args.plot)
    provider = art_provider(args, "robust-rendezvous", config=config, mode=args.mode)
    warmstart: Any = args.warmstart
    if provider is not None:  # PS-ART: the guess first, then SCvx* always runs
        warmstart = provider.guess(instance)
        print(warmstart_line(warmstart.record))
    solution = solve(instance, config, args.mode, warmstart=warmstart)
    print_rows(summary_rows(solution))
    if solution.trajectory is not None:
        x, u = solution.trajectory.x, solution.trajectory.u
        if args.monte_carlo:
            _monte_carlo(instance, x, u, args.monte_carlo, args.mc_seed)
        if args.out:
            from scpformer.problems.robust_rendezvous.io import save_solution

            save_solution(args.out, solution, instance, args.mode)
            print(f"wrote {args.out}")
        if args.plot:
            from scpformer.plotting.robust_rendezvous import plot_solution

            plot_solution(instance, x, u, args.plot)
            print(f"wrote {args.plot}")
    return 0 if solution.converged else 1


def _monte_carlo(instance: RobustInstance, x: np.ndarray, u: np.ndarray, n: int, seed: int):
    from scpformer.problems.robust_rendezvous.montecarlo import MonteCarloConfig, monte_carlo

    res = monte_carlo(instance, x, u, MonteCarloConfig(n_samples=n, seed=seed))
    worst = int(np.argmax(res.p_design))
    print_rows([
        ("Monte Carlo", f"{n} draws x {res.nodes.size} nodes, truth model, {res.wall_s:.1f} s"),
        ("design level Delta", f"{res.delta:g}"),
        ("max P(violation) at t_j", f"{res.p_design[worst]:.4f} (node {res.nodes[worst]})"),
        ("max P(violation) dense", f"{res.p_dense.max():.4f} "
                                   f"(node {res.nodes[int(np.argmax(res.p_dense))]})"),
        ("nodes above Delta (t_j)", str(int(np.sum(res.p_design > res.delta)))),
        ("passes at Delta (t_j)", "yes" if res.passes() else "no"),
    ])  # fmt: skip


# ======================================================================================
# bench
# ======================================================================================
def add_bench_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "robust-rendezvous",
        help=command_help("bench", "robust-rendezvous"),
        description="On a seeded set of Table 1 instances, solve the convex TPBVP and, from "
        "it, the passive-safety problem with SCvx* in both modes (PS-CVX-D, PS-CVX-C); report "
        "wall time (median, p95), iterations, infeasibility rate (not converged) and the share "
        "of time in the conic solver. Wall times exclude the final verification.",
    )
    parser.add_argument("--n", type=positive, default=20, help="number of instances (20)")
    parser.add_argument("--seed", type=count, default=0, help="sampling seed (0)")
    parser.add_argument(
        "--csv", type=Path, default=Path("bench_robust_rendezvous.csv"),
        help="per-instance CSV (bench_robust_rendezvous.csv)",
    )  # fmt: skip
    add_config_arguments(parser)
    parser.set_defaults(handler=run_bench)


BENCH_FIELDS = (
    "index", "waypoint", "cvx_status", "cvx_wall_s", "cvx_cost", "C_cvx_t1",
    *(f"{m}_{k}" for m in ("det", "cc")
      for k in ("status", "iterations", "wall_s", "solver_s", "cost")),
)  # fmt: skip


def _wall(solution: Solution) -> float:
    tm = solution.timing
    return tm.total - tm.verification if tm else float("nan")


def bench_row(index: int, instance: RobustInstance, cvx: Solution, runs: dict) -> dict:
    """One CSV row: the TPBVP and SCvx* in both modes on one instance."""
    from scpformer.problems.robust_rendezvous.safety import trajectory_violations

    row: dict[str, Any] = {
        "index": index, "waypoint": instance.waypoint, "cvx_status": cvx.status.value,
        "cvx_wall_s": _wall(cvx), "cvx_cost": cvx.cost, "C_cvx_t1": -1,
    }  # fmt: skip
    if cvx.trajectory is not None:
        x, u = cvx.trajectory.x, cvx.trajectory.u
        row["C_cvx_t1"] = int(trajectory_violations(instance, x, u, "chance")[0])
    for key, sol in runs.items():
        row.update({
            f"{key}_status": sol.status.value, f"{key}_iterations": sol.iterations,
            f"{key}_wall_s": _wall(sol), f"{key}_solver_s": sol.timing.solver,
            f"{key}_cost": sol.cost,
        })  # fmt: skip
    return row


def summarize(rows: list[dict[str, Any]]) -> list[str]:
    """Median/p95 wall time, iterations, infeasibility rate and conic-solver share per mode."""
    lines = [f"{'SCvx* from CVX':<18} {'n':>3} {'infeas':>7} {'med s':>7} {'p95 s':>7} "
             f"{'mean s':>7} {'it med':>6} {'it p95':>6} {'solver':>7}"]  # fmt: skip
    for label, key in (("PS-CVX-D (det.)", "det"), ("PS-CVX-C (chance)", "cc")):
        wall = np.array([r[f"{key}_wall_s"] for r in rows], dtype=float)
        solver = np.array([r[f"{key}_solver_s"] for r in rows], dtype=float)
        its = np.array([r[f"{key}_iterations"] for r in rows], dtype=float)
        failed = np.mean([r[f"{key}_status"] != Status.CONVERGED.value for r in rows])
        lines.append(
            f"{label:<18} {len(rows):>3} {failed:>7.0%} {np.median(wall):>7.3f} "
            f"{np.percentile(wall, 95):>7.3f} {wall.mean():>7.3f} {np.median(its):>6.0f} "
            f"{np.percentile(its, 95):>6.0f} {solver.sum() / max(wall.sum(), 1e-12):>7.0%}"
        )
    cvx = np.array([r["cvx_wall_s"] for r in rows], dtype=float)
    ctg = np.array([r["C_cvx_t1"] for r in rows], dtype=float)
    lines += [
        f"convex TPBVP: median {np.median(cvx):.3f} s, p95 {np.percentile(cvx, 95):.3f} s",
        f"C_CVX(t_1) (chance): > 0 for {np.mean(ctg > 0):.0%}, median {np.median(ctg):.0f}",
    ]
    return lines


def run_bench(args: argparse.Namespace) -> int:
    config = config_from_args(args)
    check_output_file(args.csv, "--csv")
    instances = sample_instances(args.seed, args.n, **common_from_args(args, None))
    start = time.perf_counter()
    warm = solve_tpbvp(instances[0], config)  # compile or load the subproblems, untimed
    solve_safety(instances[0], warm, config, "chance", verify=False)
    print(f"compiled or loaded the subproblems in {time.perf_counter() - start:.1f} s")
    rows = []
    from tqdm import tqdm  # only the benchmark needs it

    with tqdm(total=len(instances), desc="robust-rendezvous", unit="instance") as bar:
        for index, instance in enumerate(instances):
            cvx = solve_tpbvp(instance, config)
            runs = {}
            if cvx.trajectory is not None:
                for key, mode in (("det", "deterministic"), ("cc", "chance")):
                    runs[key] = solve_safety(instance, cvx, config, mode)
            else:
                runs = {"det": cvx, "cc": cvx}
            rows.append(bench_row(index, instance, cvx, runs))
            bar.set_postfix(det=runs["det"].status.value, cc=runs["cc"].status.value)
            bar.update()
    write_csv(args.csv, BENCH_FIELDS, rows)
    print("\n".join(summarize(rows)))
    print(f"wrote {args.csv}")
    return 0
