"""Truth-replay verification of robust rendezvous plans: its cost per solve and the misses.

Samples ``--n`` Table 1 instances (``--seed``) and solves each with the public API,
``scpformer.robust_rendezvous.solve(instance, config, method="three_stage")`` in ``--mode``
with the default verification, which replays the impulses of every verified plan through the
two-body + J2 propagator (``RobustVerification.truth_replay``). Per plan it prints the number
of truth replays the solve ran (one per SCvx* stage it verified) and their total time [s],
and the terminal position [m] and velocity [mm/s] miss of the final plan, replayed once more
by :func:`scpformer.problems.robust_rendezvous.problem.replay`; then the median and max time
per replay and per solve, the largest misses and how many plans fail the default check
(``terminal_position_m``, ``terminal_velocity_m_s``). ``--save`` writes the impulses so that a
plan made by one version of the code can be replayed by another (``--load``: skip the solve and
replay the saved impulses; no verification time then).

Usage: python benchmarks/robust_truth_replay.py [--n 40] [--seed 0] [--save plans.npz]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np

from scpformer import robust_rendezvous
from scpformer.problems.robust_rendezvous.problem import (
    PassiveSafetyProblem,
    replay,
    replay_miss,
)


@contextmanager
def timed_replays() -> Iterator[list[float]]:
    """Collect the wall time [s] of every truth replay that a verification runs meanwhile."""
    times: list[float] = []
    original: Callable = PassiveSafetyProblem._replay

    def timed(self: PassiveSafetyProblem, z):  # type: ignore[no-untyped-def]
        start = time.perf_counter()
        try:
            return original(self, z)
        finally:
            times.append(time.perf_counter() - start)

    PassiveSafetyProblem._replay = timed  # type: ignore[method-assign]
    try:
        yield times
    finally:
        PassiveSafetyProblem._replay = original  # type: ignore[method-assign]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=40)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--mode", default="chance")
    parser.add_argument("--save", help="write the impulses of every plan to this .npz")
    parser.add_argument("--load", help="replay the impulses of this .npz instead of solving")
    args = parser.parse_args()
    config = robust_rendezvous.RobustSolverConfig(safety_mode=args.mode)
    tol = config.verification
    instances = robust_rendezvous.sample_instances(args.seed, args.n)
    plans = dict(np.load(args.load)) if args.load else {}
    pos, vel, per_replay, per_solve, failed, saved = [], [], [], [], 0, {}
    for k, instance in enumerate(instances):
        start = time.perf_counter()
        replays: list[float] = []
        if args.load:
            u, label = plans[f"u{k}"], "loaded"
        else:
            with timed_replays() as replays:
                sol = robust_rendezvous.solve(instance, config, method="three_stage")
            if sol.trajectory is None:
                print(f"{k:3d} {instance.waypoint} no trajectory ({sol.status.value})")
                continue
            u = sol.trajectory.u
            label = f"{sol.status.value} stage={sol.extras.get('stage')}"
            per_replay += replays
            per_solve.append(sum(replays))
        saved[f"u{k}"] = u
        miss = replay_miss(instance, replay(instance, u).rtn[-1])
        pos.append(miss["position_m"])
        vel.append(miss["velocity_m_s"] * 1e3)
        fails = miss["position_m"] > tol.terminal_position_m
        fails |= miss["velocity_m_s"] > tol.terminal_velocity_m_s
        failed += int(fails)
        print(f"{k:3d} {instance.waypoint:>2} miss {pos[-1]:6.3f} m {vel[-1]:6.3f} mm/s "
              f"{'FAIL' if fails else 'ok  '} replays {len(replays)} in {sum(replays):.3f} s  "
              f"{label} ({time.perf_counter() - start:.1f} s)", flush=True)  # fmt: skip
    if args.save:
        np.savez(args.save, **saved)
    if not pos:
        print("no plan to replay")
        return 1
    print(f"{len(pos)} plans ({args.mode}, seed {args.seed})")
    if per_replay:
        r, s = np.array(per_replay), np.array(per_solve)
        print(f"time per truth replay: median {np.median(r):.3f} s, max {r.max():.3f} s "
              f"({r.size} replays)")  # fmt: skip
        print(f"truth-replay verification per solve: median {np.median(s):.3f} s, "
              f"max {s.max():.3f} s")  # fmt: skip
    print(f"largest terminal miss: {max(pos):.3f} m, {max(vel):.3f} mm/s; fail the default "
          f"check ({tol.terminal_position_m:g} m, {tol.terminal_velocity_m_s * 1e3:g} mm/s): "
          f"{failed}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
