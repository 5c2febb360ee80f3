"""``scpformer solve rendezvous`` and ``scpformer bench rendezvous`` (ART paper, Sec. 4-5): the
handlers; the flags are in :mod:`scpformer.cli.parsers.rendezvous`."""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.cli.dataclass_args import nested_overrides, with_overrides
from scpformer.cli.outputs import check_solve_outputs, print_rows, timing_rows, write_csv
from scpformer.cli.warmstart import (
    art_provider,
    comparison_rows,
    warmstart_line,
)
from scpformer.files import check_output_file
from scpformer.problems.rendezvous.api import METHODS, solve
from scpformer.problems.rendezvous.constraints import constraint_to_go
from scpformer.problems.rendezvous.instance import RendezvousInstance, sample_instances
from scpformer.problems.rendezvous.linear_model import linear_model
from scpformer.problems.rendezvous.scenario import (
    RendezvousScenario,
    RendezvousSolverConfig,
    TargetOrbit,
)
from scpformer.scp.solution import Solution, Status
from scpformer.warmstart import RendezvousConvexWarmStart, WarmStartResult


# ======================================================================================
# configuration from the flags
# ======================================================================================
def config_from_args(args: argparse.Namespace) -> RendezvousSolverConfig:
    """The solver configuration with the command-line overrides applied."""
    return nested_overrides(args, RendezvousSolverConfig, {"scp": "scp", "verification": "verify"})


def scenario_from_args(
    args: argparse.Namespace, base: RendezvousInstance | None = None
) -> tuple[RendezvousScenario, TargetOrbit]:
    """Scenario and target orbit (of ``base`` or Table 1) with the command-line overrides."""
    scenario = with_overrides(
        base.scenario if base else RendezvousScenario(), args, RendezvousScenario, "scenario"
    )
    target = with_overrides(base.target if base else TargetOrbit(), args, TargetOrbit, "target")
    return scenario, target


# ======================================================================================
# solve
# ======================================================================================
def instance_from_args(args: argparse.Namespace) -> RendezvousInstance:
    """``--instance FILE``, ``--seed S`` or the default instance, with overrides applied."""
    base = RendezvousInstance.from_json(args.instance) if args.instance else None
    scenario, target = scenario_from_args(args, base)
    if base is None and args.seed is not None:
        rng = np.random.default_rng(args.seed)
        base = sample_instances(rng, 1, scenario=scenario, target=target)[0]
    changes: dict[str, Any] = {"scenario": scenario, "target": target}
    if args.roe0 is not None:
        changes["roe0_m"] = tuple(args.roe0)
    if args.horizon_orbits is not None:
        changes["horizon_orbits"] = args.horizon_orbits
    if base is None:
        return RendezvousInstance(**changes)
    return dataclasses.replace(base, **changes)


def summary_rows(solution: Solution, instance: RendezvousInstance) -> list[tuple[str, str]]:
    """Human-readable (key, value) rows of a solution."""
    rows = [("status", solution.status.value), ("iterations", str(solution.iterations))]
    if solution.message:
        rows.append(("message", solution.message))
    ctg = math.nan
    if solution.trajectory is not None:
        rtn = linear_model(instance).rtn(solution.trajectory.x)
        ctg = int(constraint_to_go(rtn, instance.scenario)[0])
        rows += [
            ("cost sum |dv|", f"{1e3 * solution.cost:.3f} mm/s"),
            ("constraint-to-go C(t_0)", str(ctg)),
        ]
    if "warmstart" in solution.extras:
        record = solution.extras["warmstart"]
        rows += comparison_rows(record, solution, ctg, cost_scale=1e3, cost_unit="mm/s", digits=3)
    ver = solution.verification
    if ver is not None:
        te = ver.terminal_error
        rows.append(("verified (replay)", "yes" if ver.passed else f"no ({ver.message})"))
        if te:  # empty when the replay itself failed (the message says why)
            rows += [
                ("terminal miss", f"{te['position_m']:.3f} m, {1e3 * te['velocity_m_s']:.3f} mm/s"),
                ("  RTN position", f"({te['r_m']:.3f}, {te['t_m']:.3f}, {te['n_m']:.3f}) m"),
                ("max linear-vs-truth gap", f"{ver.max_defect:.3f} m"),
            ]
        rows += [(f"node {k}", f"{v:.3g}") for k, v in ver.node_violations.items()]
    elif solution.trajectory is not None:
        rows.append(("verified (replay)", "not verified"))
    if solution.timing is not None:
        rows += timing_rows(solution.timing, "model + linearization")
    return rows


def run_solve(args: argparse.Namespace) -> int:
    instance = instance_from_args(args)
    config = config_from_args(args)
    check_solve_outputs(args.out, args.plot)
    verify = not args.no_verify
    if args.problem != "scp" and args.warmstart == "art":
        raise ValueError("--warmstart art applies to --problem scp only")
    provider = art_provider(args, "rendezvous", config=config)
    warm = None
    if args.problem == "scp":
        provider = provider or RendezvousConvexWarmStart(args.warmstart, config)
        warm = provider.guess(instance)  # the SCP always runs after it
        print(warmstart_line(warm.record, warm.solution))
        solution = solve(instance, config, method="scp", warmstart=warm, verify=verify)
    else:
        solution = solve(instance, config, method=args.problem, verify=verify)
    print_rows(summary_rows(solution, instance))
    if solution.trajectory is not None:
        if args.out:
            from scpformer.problems.rendezvous.io import save_solution

            save_solution(args.out, solution, instance)
            print(f"wrote {args.out}")
        if args.plot:
            write_figure(args.plot, solution, instance, warm)
            print(f"wrote {args.plot}")
    return 0 if solution.converged else 1


def write_figure(
    path: Path,
    solution: Solution,
    instance: RendezvousInstance,
    warm: WarmStartResult | None,
) -> None:
    """The trajectory figure of ``solution`` (RTN, keep-out zone, ROE, impulses) with the
    warm start's trajectory drawn beside it."""
    from scpformer.plotting.rendezvous import plot_trajectory
    from scpformer.problems.rendezvous.io import constants_record

    model = linear_model(instance)
    reference = None
    if warm is not None and warm.trajectory is not None:
        x = warm.trajectory.x
        reference = {"rtn": model.rtn(x), "roe": x, "label": f"warm start ({warm.record.used})"}
    x = solution.trajectory.x
    constants = constants_record(instance)
    constants["period_s"] = instance.target.period_s
    path.parent.mkdir(parents=True, exist_ok=True)
    plot_trajectory(
        model.t, x, model.rtn(x), solution.trajectory.u, constants, path=path, reference=reference
    )


# ======================================================================================
# bench
# ======================================================================================
BENCH_FIELDS = (
    "index",
    "horizon_orbits",
    "C_cvx_t1",
    *(f"{p}_{k}" for p in ("p1", "p2") for k in ("status", "wall_s", "solver_s", "cost")),
    "p3_status",
    "p3_iterations",
    "p3_wall_s",
    "p3_solver_s",
    "p3_ws_plus_scp_s",
    "p3_cost",
    "p3_terminal_miss_m",
    "p3_terminal_miss_m_s",
    "p3_max_gap_m",
    "p3_keep_out",
    "verification_s",
)
FAILED = {
    Status.SOLVER_FAILED.value,
    Status.INFEASIBLE_INSTANCE.value,
    Status.VERIFICATION_FAILED.value,
}


def _wall(solution: Solution) -> float:
    """Solve time without the verification replay [s]."""
    tm = solution.timing
    return tm.total - tm.verification if tm else float("nan")


def bench_row(
    index: int,
    instance: RendezvousInstance,
    p1: Solution,
    p2: Solution,
    p3: Solution,
    warm: Solution,
) -> dict[str, Any]:
    """One CSV row: the three problems on one instance."""
    row: dict[str, Any] = {"index": index, "horizon_orbits": instance.horizon_orbits}
    model = linear_model(instance)
    row["C_cvx_t1"] = (
        int(constraint_to_go(model.rtn(p2.trajectory.x), instance.scenario)[0])
        if p2.trajectory is not None
        else -1
    )
    for name, sol in (("p1", p1), ("p2", p2)):
        row.update(
            {
                f"{name}_status": sol.status.value,
                f"{name}_wall_s": _wall(sol),
                f"{name}_solver_s": sol.timing.solver,
                f"{name}_cost": sol.cost,
            }
        )
    ver, nan = p3.verification, float("nan")
    row.update(
        p3_status=p3.status.value,
        p3_iterations=p3.iterations,
        p3_wall_s=_wall(p3),
        p3_solver_s=p3.timing.solver,
        p3_ws_plus_scp_s=_wall(p3) + _wall(warm),
        p3_cost=p3.cost,
        p3_terminal_miss_m=ver.terminal_error.get("position_m", nan) if ver else nan,
        p3_terminal_miss_m_s=ver.terminal_error.get("velocity_m_s", nan) if ver else nan,
        p3_max_gap_m=ver.max_defect if ver else nan,
        p3_keep_out=ver.node_violations.get("keep_out", nan) if ver else nan,
        verification_s=sum(s.timing.verification for s in (p1, p2, p3)),
    )
    return row


def summarize(rows: list[dict[str, Any]]) -> list[str]:
    """Median/p95 wall times, failure rates, iterations, solver share and C_CVX(t_1)."""
    lines = [
        f"{'problem':<22} {'n':>3} {'fail':>6} {'conv':>6} {'med s':>7} {'p95 s':>7} "
        f"{'mean s':>7} {'solver':>7}"
    ]
    for label, key in (("1 tpbvp", "p1"), ("2 convex", "p2"), ("3 scp (from warm st.)", "p3")):
        wall = np.array([r[f"{key}_wall_s"] for r in rows], dtype=float)
        solver = np.array([r[f"{key}_solver_s"] for r in rows], dtype=float)
        status = [r[f"{key}_status"] for r in rows]
        lines.append(
            f"{label:<22} {len(rows):>3} {np.mean([s in FAILED for s in status]):>6.0%} "
            f"{np.mean([s == 'converged' for s in status]):>6.0%} {np.median(wall):>7.3f} "
            f"{np.percentile(wall, 95):>7.3f} {wall.mean():>7.3f} "
            f"{solver.sum() / max(wall.sum(), 1e-12):>7.0%}"
        )
    total = np.array([r["p3_ws_plus_scp_s"] for r in rows], dtype=float)
    its = np.array([r["p3_iterations"] for r in rows], dtype=float)
    ctg = np.array([r["C_cvx_t1"] for r in rows], dtype=float)
    miss = np.array([r["p3_terminal_miss_m"] for r in rows], dtype=float)
    lines += [
        f"{'3 warm start + scp':<22} {len(rows):>3} {'':>6} {'':>6} {np.median(total):>7.3f} "
        f"{np.percentile(total, 95):>7.3f} {total.mean():>7.3f}",
        f"SCP iterations: median {np.median(its):.0f}, mean {its.mean():.1f}, max {its.max():.0f}",
        f"C_CVX(t_1): > 0 for {np.mean(ctg > 0):.0%} of instances, median {np.median(ctg):.0f}, "
        f"max {ctg.max():.0f}",
    ]
    if np.any(np.isfinite(miss)):
        lines.append(
            f"Problem 3 terminal miss under the nonlinear replay: median "
            f"{np.nanmedian(miss):.3f} m, max {np.nanmax(miss):.3f} m"
        )
    return lines


def _warm_up(config: RendezvousSolverConfig, instance: RendezvousInstance) -> float:
    """Canonicalize (or load) the three parametric subproblems, untimed by the bench."""
    start = time.perf_counter()
    for method in METHODS:
        solve(instance, config, method=method, verify=False)
    return time.perf_counter() - start


def run_bench(args: argparse.Namespace) -> int:
    config = config_from_args(args)
    check_output_file(args.csv, "--csv")
    scenario, target = scenario_from_args(args)
    instances = sample_instances(
        np.random.default_rng(args.seed), args.n, scenario=scenario, target=target
    )
    print(
        f"compiled or loaded the subproblems (N = {scenario.n_nodes}) in "
        f"{_warm_up(config, instances[0]):.1f} s"
    )
    verify, rows = not args.no_verify, []
    from tqdm import tqdm  # only the benchmark needs it

    with tqdm(total=len(instances), desc="rendezvous", unit="instance") as bar:
        for index, instance in enumerate(instances):
            p1 = solve(instance, config, method="tpbvp", verify=verify)
            p2 = solve(instance, config, method="convex", verify=verify)
            warm = p2 if args.warmstart == "convex" else p1
            p3 = solve(instance, config, method="scp", warmstart=warm, verify=verify)
            rows.append(bench_row(index, instance, p1, p2, p3, warm))
            bar.set_postfix(status=p3.status.value, it=p3.iterations)
            bar.update()
    write_csv(args.csv, BENCH_FIELDS, rows)
    print("\n".join(summarize(rows)))
    print(f"wrote {args.csv}")
    return 0
