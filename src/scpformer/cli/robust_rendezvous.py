"""``scpformer solve robust-rendezvous`` and ``scpformer bench robust-rendezvous`` (robust ART):
the handlers; the flags are in :mod:`scpformer.cli.parsers.robust_rendezvous`."""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from typing import Any

import numpy as np

from scpformer.cli.dataclass_args import nested_overrides, with_overrides
from scpformer.cli.outputs import check_solve_outputs, print_rows, write_csv
from scpformer.cli.warmstart import (
    art_provider,
    comparison_rows,
    warmstart_line,
)
from scpformer.files import check_output_file
from scpformer.problems.rendezvous.scenario import TargetOrbit
from scpformer.problems.robust_rendezvous.api import solve
from scpformer.problems.robust_rendezvous.instance import RobustInstance, sample_instances
from scpformer.problems.robust_rendezvous.scenario import (
    RobustScenario,
    RobustSolverConfig,
    robust_target,
)
from scpformer.problems.robust_rendezvous.tpbvp import solve_tpbvp
from scpformer.scp.solution import Solution, Status


# ======================================================================================
# configuration from the flags
# ======================================================================================
def config_from_args(args: argparse.Namespace) -> RobustSolverConfig:
    """The solver configuration with the command-line overrides applied."""
    sections = {"scvx": "scvx-star", "verification": "verify"}
    return nested_overrides(args, RobustSolverConfig, sections)


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
    ver = solution.verification
    if solution.trajectory is not None:
        verified = "not verified" if ver is None else "yes" if ver.passed else f"no ({ver.message})"
        rows.append(("verified", verified))
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
    config = dataclasses.replace(config_from_args(args), safety_mode=args.mode)
    check_solve_outputs(args.out, args.plot)
    if args.monte_carlo:  # its bounds are checked before the solve, not after it
        from scpformer.problems.robust_rendezvous.montecarlo import MonteCarloConfig

        MonteCarloConfig(n_samples=args.monte_carlo, seed=args.mc_seed)
    provider = art_provider(args, "robust-rendezvous", config=config, mode=args.mode)
    if args.warmstart == "three_stage":
        solution = solve(instance, config, method="three_stage")
    else:
        warmstart: Any = "tpbvp"
        if provider is not None:  # PS-ART: the guess first, then SCvx* always runs
            warmstart = provider.guess(instance)
            print(warmstart_line(warmstart.record))
        solution = solve(instance, config, method="passive_safety", warmstart=warmstart)
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


def _passive_safety(
    instance: RobustInstance,
    cvx: Solution,
    config: RobustSolverConfig,
    mode: str,
    verify: bool = True,
) -> Solution:
    """PS-CVX in ``mode`` from the TPBVP solution ``cvx`` (one TPBVP for both modes)."""
    config = dataclasses.replace(config, safety_mode=mode)
    return solve(instance, config, method="passive_safety", warmstart=cvx, verify=verify)


def run_bench(args: argparse.Namespace) -> int:
    config = config_from_args(args)
    check_output_file(args.csv, "--csv")
    instances = sample_instances(args.seed, args.n, **common_from_args(args, None))
    start = time.perf_counter()
    warm = solve_tpbvp(instances[0], config)  # compile or load the subproblems, untimed
    _passive_safety(instances[0], warm, config, "chance", verify=False)
    print(f"compiled or loaded the subproblems in {time.perf_counter() - start:.1f} s")
    rows = []
    from tqdm import tqdm  # only the benchmark needs it

    with tqdm(total=len(instances), desc="robust-rendezvous", unit="instance") as bar:
        for index, instance in enumerate(instances):
            cvx = solve_tpbvp(instance, config)
            runs = {}
            if cvx.trajectory is not None:
                for key, mode in (("det", "deterministic"), ("cc", "chance")):
                    runs[key] = _passive_safety(instance, cvx, config, mode)
            else:
                runs = {"det": cvx, "cc": cvx}
            rows.append(bench_row(index, instance, cvx, runs))
            bar.set_postfix(det=runs["det"].status.value, cc=runs["cc"].status.value)
            bar.update()
    write_csv(args.csv, BENCH_FIELDS, rows)
    print("\n".join(summarize(rows)))
    print(f"wrote {args.csv}")
    return 0
