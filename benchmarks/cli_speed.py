"""The speed a user feels (issue 16, item 6): CLI start-up, solve overhead, replay check.

Measures, side by side in one run (interleaved, so that both see the same machine load):

1. ``scpformer --help`` wall time of a process, for the source tree ``--before`` (default
   ``/work/main/src``) and ``--after`` (default: this checkout's ``src``), median of
   ``--help-runs``;
2. ``scpformer solve rendezvous`` process wall time minus the solve time the command itself
   reports (warm start + SCP wall time, the latter including the verification), median of
   ``--solve-runs``;
3. the rendezvous replay check (:func:`scpformer.problems.rendezvous.problem.verify_solution`)
   per solve on ``--n`` sampled instances, with the adaptive ``solve_ivp`` propagation (the
   previous implementation, ``method="adaptive"``) and the checked fixed-step one (the
   default), each on a cold per-instance cache, median over the instances; also the largest
   difference of the two replays' RTN states and terminal misses.

The load average before and after is printed: timings on a shared machine are noisy.

Usage: python benchmarks/cli_speed.py [--help-runs 10] [--solve-runs 5] [--n 20]
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[1]


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _process(src: Path, *args: str) -> tuple[float, float, str]:
    """Wall and CPU (user + system) time [s] and stdout of ``python -m scpformer.cli.main
    ARGS`` importing ``src``."""
    env = {**os.environ, "PYTHONPATH": str(src)}
    cpu = _children_cpu()
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "scpformer.cli.main", *args],
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    wall = time.perf_counter() - start
    if done.returncode not in (0, 1):
        raise RuntimeError(f"scpformer {' '.join(args)} failed: {done.stderr.strip()}")
    return wall, _children_cpu() - cpu, done.stdout


def reported_solve_time(stdout: str) -> float:
    """Warm start time + SCP wall time [s] as printed by ``scpformer solve rendezvous``."""
    warm = re.search(r"warm start \(\w+\): \w+ in ([0-9.]+) s", stdout)
    total = re.search(r"^wall time\s+([0-9.]+) s", stdout, re.MULTILINE)
    if warm is None or total is None:
        raise RuntimeError(f"no solve times in the output:\n{stdout}")
    return float(warm.group(1)) + float(total.group(1))


def process_times(trees: dict[str, Path], help_runs: int, solve_runs: int) -> None:
    """Print the medians of ``--help`` and of the solve overhead (wall and CPU) per tree."""
    helps: dict[str, list[tuple[float, float]]] = {name: [] for name in trees}
    solves: dict[str, list[tuple[float, float, float]]] = {name: [] for name in trees}
    bare = []
    for _ in range(help_runs):
        start = time.perf_counter()
        subprocess.run([sys.executable, "-c", "pass"], check=True)
        bare.append(time.perf_counter() - start)
        for name, src in trees.items():
            helps[name].append(_process(src, "--help")[:2])
    for _ in range(solve_runs):
        for name, src in trees.items():
            wall, cpu, out = _process(src, "solve", "rendezvous")
            solves[name].append((wall, wall - reported_solve_time(out), cpu))
    print(f"python -c pass: {statistics.median(bare):.3f} s wall (median of {help_runs})")
    for name in trees:
        help_wall, help_cpu = (statistics.median(v) for v in zip(*helps[name], strict=True))
        wall, overhead, cpu = (statistics.median(v) for v in zip(*solves[name], strict=True))
        print(
            f"{name:6s}  --help {help_wall:.3f} s wall, {help_cpu:.3f} s CPU "
            f"(median of {help_runs}) | solve rendezvous: process {wall:.3f} s wall, "
            f"{cpu:.3f} s CPU, minus the reported solve {overhead:.3f} s (median of {solve_runs})"
        )


def replay_times(n: int, seed: int) -> None:
    from scpformer.dynamics import truth
    from scpformer.problems.rendezvous import problem
    from scpformer.problems.rendezvous.instance import sample_instances

    fixed = truth.propagate_relative
    instances = sample_instances(np.random.default_rng(seed), n)
    times: dict[str, list[float]] = {"adaptive": [], "fixed": []}
    gaps = []
    for instance in instances:
        sol = problem.solve(instance, "scp", verify=False)
        if sol.trajectory is None:
            continue
        x, dv = sol.trajectory.x, sol.trajectory.u
        model = problem.linear_model(instance)
        results = {}
        for method in ("adaptive", "fixed"):
            problem.propagate_relative = lambda *a, m=method, **k: fixed(*a, method=m, **k)
            problem._osculating_initial_state.cache_clear()
            start = time.perf_counter()
            ver = problem.verify_solution(instance, model, x, dv, "scp")
            times[method].append(time.perf_counter() - start)
            results[method] = (ver, problem.replay(instance, dv))
        problem.propagate_relative = fixed
        (va, ra), (vf, rf) = results["adaptive"], results["fixed"]
        if va.passed != vf.passed:
            raise RuntimeError("the two propagations disagree on pass/fail")
        gaps.append(
            (
                np.abs(ra.rtn[:, :3] - rf.rtn[:, :3]).max(),
                np.abs(ra.rtn[:, 3:] - rf.rtn[:, 3:]).max(),
                abs(va.terminal_error["position_m"] - vf.terminal_error["position_m"]),
            )
        )
    worst = np.max(gaps, axis=0)
    count = len(times["fixed"])
    for method, label in (("adaptive", "before (solve_ivp)"), ("fixed", "after (fixed step)")):
        print(
            f"replay check {label}: {1e3 * statistics.median(times[method]):.1f} ms per solve "
            f"(median of {count} instances, max {1e3 * max(times[method]):.1f} ms)"
        )
    print(
        f"largest difference of the two replays: RTN position {worst[0]:.2e} m, velocity "
        f"{worst[1]:.2e} m/s, terminal miss {worst[2]:.2e} m; pass/fail identical"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, default=Path("/work/main/src"))
    parser.add_argument("--after", type=Path, default=HERE / "src")
    parser.add_argument("--help-runs", type=int, default=10)
    parser.add_argument("--solve-runs", type=int, default=5)
    parser.add_argument("--n", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(f"load average before: {os.getloadavg()[0]:.2f}")
    process_times({"before": args.before, "after": args.after}, args.help_runs, args.solve_runs)
    replay_times(args.n, args.seed)
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
