"""Check the ART generation-time targets on this machine (one thread).

100-step cached rollouts with the rendezvous dynamics in the loop (as ``scpformer bench
art``), random weights: ``small`` at batch 1 <= 30 ms, ``paper`` at batch 1 <= 0.3 s,
``small`` at batch 64 >= 100 trajectories/s, all with float32 weights. For the paper size it
also times, for information, the same rollout with bfloat16 and int8 weights (the relative
error of their controls against float32 beside). Prints median wall and CPU times and
PASS/FAIL per target (judged on wall time); exit status 1 on a miss. Timings depend on the
machine's load: run it on an otherwise idle machine (or ``nice -n -15``).

Usage: PYTHONPATH=src python benchmarks/art_targets.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import sys

import torch

from scpformer.cli import bench_art

STEPS = 100
TARGETS = (  # preset, batch, what, limit
    ("small", 1, "ms", 30.0),
    ("paper", 1, "ms", 300.0),
    ("small", 64, "traj/s", 100.0),
)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    torch.set_num_threads(1)
    failed = False
    setups = {}
    for preset, batch, unit, limit in TARGETS:
        if preset not in setups:
            bench_args = argparse.Namespace(
                model=None, preset=preset, target=False, steps=STEPS, seed=0
            )
            setups[preset] = bench_art.load_setup(bench_args)
        timing = bench_art.time_mode(setups[preset], "cached", batch, args.repeats)
        if unit == "ms":
            value, ok = 1e3 * timing.wall_s, 1e3 * timing.wall_s <= limit
            text = f"{value:.1f} ms (cpu {1e3 * timing.cpu_s:.1f} ms) <= {limit:.0f} ms"
        else:
            value, ok = timing.per_second, timing.per_second >= limit
            text = f"{value:.1f} traj/s (cpu {batch / timing.cpu_s:.1f}) >= {limit:.0f}"
        failed |= not ok
        print(f"{'PASS' if ok else 'FAIL'}  {preset} batch {batch}: {text}", flush=True)
    plan = [("cached", 1), ("cached, bf16", 1), ("cached, int8", 1)]
    for t in bench_art.time_plan(setups["paper"], plan, args.repeats)[1:]:
        print(
            f"info  paper batch 1, {t.mode}: {1e3 * t.wall_s:.1f} ms "
            f"(cpu {1e3 * t.cpu_s:.1f} ms), controls off by {t.error:.1e} (relative)"
        )
    print(f"median of {args.repeats} runs, 1 thread, {STEPS} steps")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
