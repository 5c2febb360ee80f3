"""The speed a user feels (issue 16, item 6): CLI start-up, solve overhead, replay check.

Measures, side by side in one run (interleaved, so that both see the same machine load):

1. ``scpformer --help`` wall time of a process, for the source tree ``--before`` (default
   ``/work/main/src``) and ``--after`` (default: this checkout's ``src``), median of
   ``--help-runs``;
2. ``scpformer solve rendezvous`` process wall time minus the solve time the command itself
   reports (warm start + SCP wall time, the latter including the verification), median of
   ``--solve-runs``;
3. the rendezvous replay check (:func:`scpformer.problems.rendezvous.problem.verify_solution`)
   per solve, run by each tree in a child process on the same ``--n`` SCP plans of sampled
   instances (solved once, here), each instance verified once on a cold cache; median over
   the instances, and the largest difference of the two trees' replayed RTN positions.

The load average before and after is printed: timings on a shared machine are noisy.

Usage: python benchmarks/cli_speed.py [--help-runs 10] [--solve-runs 5] [--n 20]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
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


def replay_child(plans: Path, out: Path) -> None:
    """Time the replay check of every plan in ``plans`` with the package on ``sys.path``."""
    from scpformer.problems.rendezvous import problem
    from scpformer.problems.rendezvous.instance import RendezvousInstance

    data = np.load(plans)
    instances = [RendezvousInstance.from_dict(d) for d in json.loads(str(data["instances"]))]
    cache = getattr(problem, "_osculating_initial_state", None)  # absent before the change
    walls, cpus, rtn, passed = [], [], [], []
    for k, instance in enumerate(instances):
        x, dv = data[f"x{k}"], data[f"dv{k}"]
        model = problem.linear_model(instance)
        if cache is not None:
            cache.cache_clear()  # every instance is verified once, as in a solve
        start, cpu = time.perf_counter(), time.process_time()
        ver = problem.verify_solution(instance, model, x, dv, "scp")
        walls.append(time.perf_counter() - start)
        cpus.append(time.process_time() - cpu)
        passed.append(ver.passed)
        rtn.append(problem.replay(instance, dv).rtn)
    np.savez(out, wall=walls, cpu=cpus, passed=passed, **{f"rtn{k}": r for k, r in enumerate(rtn)})


def replay_times(trees: dict[str, Path], n: int, seed: int) -> None:
    """Replay check per solve of each tree on the same ``n`` SCP plans (solved here)."""
    from scpformer.problems.rendezvous import problem
    from scpformer.problems.rendezvous.instance import sample_instances

    plans: dict[str, np.ndarray] = {}
    kept = []
    for instance in sample_instances(np.random.default_rng(seed), n):
        sol = problem.solve(instance, "scp", verify=False)
        if sol.trajectory is not None:
            plans[f"x{len(kept)}"], plans[f"dv{len(kept)}"] = sol.trajectory.x, sol.trajectory.u
            kept.append(instance.to_dict())
    results = {}
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "plans.npz"
        np.savez(path, instances=json.dumps(kept), **plans)
        for name, src in trees.items():
            out = Path(folder) / f"{name}.npz"
            env = {**os.environ, "PYTHONPATH": str(src)}
            command = [sys.executable, __file__, "--replay-child", str(path), str(out)]
            subprocess.run(command, env=env, check=True)
            results[name] = dict(np.load(out))
    for name, res in results.items():
        print(
            f"{name:6s}  replay check {1e3 * np.median(res['wall']):.1f} ms wall, "
            f"{1e3 * np.median(res['cpu']):.1f} ms CPU per solve (median of {len(kept)} "
            f"instances; passed {int(np.sum(res['passed']))}/{len(kept)})"
        )
    before, after = results.values()
    gap = max(np.abs(before[f"rtn{k}"] - after[f"rtn{k}"]).max(axis=0)[:3].max()
              for k in range(len(kept)))  # fmt: skip
    same = bool(np.array_equal(before["passed"], after["passed"]))
    print(f"largest RTN position difference of the two replays {gap:.2e} m; verdicts equal: {same}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, default=Path("/work/main/src"))
    parser.add_argument("--after", type=Path, default=HERE / "src")
    parser.add_argument("--help-runs", type=int, default=10)
    parser.add_argument("--solve-runs", type=int, default=5)
    parser.add_argument("--n", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--replay-child", nargs=2, type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.replay_child:
        replay_child(*args.replay_child)
        return 0
    trees = {"before": args.before, "after": args.after}
    print(f"load average before: {os.getloadavg()[0]:.2f}")
    process_times(trees, args.help_runs, args.solve_runs)
    replay_times(trees, args.n, args.seed)
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
