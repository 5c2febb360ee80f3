"""The speed a user feels: CLI start-up, ``--help`` of every command, solve overhead, replay
check.

Measures, interleaved so that the trees compared see the same machine load:

1. ``--help`` of every command (``scpformer --help``, then every command and sub-command of
   :data:`scpformer.cli.commands.COMMANDS` and of the parsers they build, e.g.
   ``scpformer generate rendezvous --help``): process wall time, median of ``--help-runs``,
   for the source tree ``--after`` (default: this checkout's ``src``) and, when given, the
   source tree ``--before``; a command above ``--limit`` seconds (0.5) is flagged, and the
   exit status is 1 when the ``--after`` tree has one;
2. with ``--before``: ``scpformer solve rendezvous`` process wall time minus the solve time
   the command itself reports (warm start + SCP wall time, the latter including the
   verification), median of ``--solve-runs``;
3. with ``--before``: the rendezvous replay check (``verify_solution`` of
   :mod:`scpformer.problems.rendezvous.problem`) per solve, run by each tree in a child
   process on the same ``--n`` SCP plans of sampled instances (solved once, here), each
   instance verified once on a cold cache; median over the instances, and the largest
   difference of the two trees' replayed RTN positions.

``--before`` is a source folder (``src`` of another checkout, e.g. one made by ``git
worktree add``). The load average before and after is printed: timings on a shared machine
are noisy.

Usage: python benchmarks/cli_speed.py [--before OTHER/src] [--help-runs 5] [--limit 0.5]
       [--solve-runs 5] [--n 20] [--help-only]
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
    ARGS`` importing ``src`` (a ``RuntimeError`` when it fails)."""
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
    from scpformer.problems.rendezvous.instance import sample_instances
    from scpformer.rendezvous import solve

    plans: dict[str, np.ndarray] = {}
    kept = []
    for instance in sample_instances(np.random.default_rng(seed), n):
        sol = solve(instance, method="scp", verify=False)
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


def command_paths() -> list[tuple[str, ...]]:
    """Every command of the ``scpformer`` parser of this process (``--after``'s when run as
    the script): ``()``, then the commands of ``COMMANDS`` and the sub-commands of their
    parsers, in the order ``--help`` lists them."""
    from scpformer.cli.main import build_parser

    paths: list[tuple[str, ...]] = []

    def walk(parser: argparse.ArgumentParser, path: tuple[str, ...]) -> None:
        paths.append(path)
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name in list(action.choices):
                    walk(action.choices[name], (*path, name))

    walk(build_parser(), ())
    return paths


def _list_commands(src: Path) -> list[tuple[str, ...]]:
    """:func:`command_paths` of the tree ``src`` (in a child process that imports it)."""
    env = {**os.environ, "PYTHONPATH": str(src)}
    done = subprocess.run([sys.executable, __file__, "--list-commands"], env=env,
                          capture_output=True, text=True, check=True)  # fmt: skip
    return [tuple(json.loads(line)) for line in done.stdout.splitlines()]


def help_times(trees: dict[str, Path], runs: int, limit: float) -> bool:
    """Print the median ``--help`` wall time of every command per tree; True when a command
    of the last tree (``after``) is above ``limit`` seconds."""
    paths = _list_commands(trees["after"])
    times: dict[tuple[str, ...], dict[str, list[float]]] = {
        p: {n: [] for n in trees} for p in paths
    }
    failed: dict[tuple[str, ...], set[str]] = {p: set() for p in paths}
    for _ in range(runs):
        for path in paths:
            for name, src in trees.items():
                if name in failed[path]:
                    continue
                try:
                    times[path][name].append(_process(src, *path, "--help")[0])
                except RuntimeError:
                    failed[path].add(name)  # e.g. a command the before tree lacks
    width = max(len(" ".join(p)) for p in paths) + len("scpformer  --help")
    header = "  ".join(f"{name:>8s}" for name in trees)
    print(f"--help wall time [s], median of {runs} (flag: above {limit} s)")
    print(f"{'command':<{width}}  {header}")
    slow = False
    for path in paths:
        cells = []
        for name in trees:
            if name in failed[path]:
                cells.append(f"{'fails':>8s}")
                continue
            median = statistics.median(times[path][name])
            flag = " *" if median > limit else "  "
            cells.append(f"{median:6.3f}{flag}")
            slow |= name == "after" and median > limit
        command = " ".join(("scpformer", *path, "--help"))
        print(f"{command:<{width}}  {'  '.join(cells)}")
    print(f"commands above {limit} s (after): {'yes' if slow else 'none'}")
    return slow


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, help="source folder of the tree compared with")
    parser.add_argument("--after", type=Path, default=HERE / "src")
    parser.add_argument("--help-runs", type=int, default=5)
    parser.add_argument("--limit", type=float, default=0.5, help="flag --help above this [s]")
    parser.add_argument("--help-only", action="store_true", help="time --help only")
    parser.add_argument("--solve-runs", type=int, default=5)
    parser.add_argument("--n", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--replay-child", nargs=2, type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--list-commands", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.replay_child:
        replay_child(*args.replay_child)
        return 0
    if args.list_commands:
        print("\n".join(json.dumps(path) for path in command_paths()))
        return 0
    trees = {"after": args.after}
    if args.before is not None:
        trees = {"before": args.before, "after": args.after}
    for name, src in trees.items():
        if not (src / "scpformer" / "__init__.py").is_file():
            parser.error(f"--{name} {src}: not a source folder holding scpformer/")
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    slow = help_times(trees, args.help_runs, args.limit)
    if args.before is not None and not args.help_only:
        process_times(trees, args.help_runs, args.solve_runs)
        replay_times(trees, args.n, args.seed)
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    return 1 if slow else 0


if __name__ == "__main__":
    sys.exit(main())
