"""Measure candidate ART sizes to choose the ``small`` preset.

For each candidate: parameters; training seconds per epoch of 5000 random sequences of 100
steps (forward + backward + AdamW at batch 32 on ``--train-threads`` threads, extrapolated
from ``--train-steps`` timed steps); the 100-step cached rollout with the rendezvous dynamics
in the loop at batch 1 and the throughput at batch 64 (one thread, as `scpformer bench art`).
Times are medians; CPU time of this process is printed beside wall time because the machine
is shared.

Run: ``PYTHONPATH=src python benchmarks/art_presets.py [--repeats 3]``
"""

from __future__ import annotations

import argparse

import torch

from scpformer.cli import bench_art
from scpformer.models.art import ART, ArtConfig

CANDIDATES = {
    "L3-C96-H3 (small)": ArtConfig(n_layer=3, n_head=3, n_embd=96),
    "L4-C128": ArtConfig(n_layer=4, n_head=4, n_embd=128),
    "L3-C128": ArtConfig(n_layer=3, n_head=4, n_embd=128),
    "L2-C128": ArtConfig(n_layer=2, n_head=4, n_embd=128),
    "L4-C96": ArtConfig(n_layer=4, n_head=4, n_embd=96),
    "L3-C96": ArtConfig(n_layer=3, n_head=4, n_embd=96),
    "L4-C64": ArtConfig(n_layer=4, n_head=4, n_embd=64),
    "paper": ArtConfig(),
}
SEQUENCES = 5000  # sequences per epoch
STEPS = 100  # time steps per sequence


def train_epoch_seconds(config: ArtConfig, batch: int, steps: int) -> tuple[float, float]:
    """(wall, cpu) seconds of one epoch of SEQUENCES sequences, from ``steps`` timed steps."""
    torch.manual_seed(0)
    model = ART(config).train()
    optimizer = torch.optim.AdamW(model.parameters(), lr=3e-4)
    sizes = {"rtg": 1, "ctg": 1, "state": 6, "action": 3}
    data = {key: torch.randn(batch, STEPS, d) for key, d in sizes.items()}

    def step() -> None:
        optimizer.zero_grad(set_to_none=True)
        model(data)[1].backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        optimizer.step()

    wall, cpu = bench_art.time_runs(step, steps)
    return wall * SEQUENCES / batch, cpu * SEQUENCES / batch


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--train-steps", type=int, default=3)
    parser.add_argument("--train-threads", type=int, default=2)
    parser.add_argument("--train-batch", type=int, default=32)
    parser.add_argument("--only", nargs="*", help="candidate names to run")
    args = parser.parse_args()
    dynamics = bench_art.rendezvous_dynamics(STEPS, 0)
    print(
        f"{'candidate':<24} {'params M':>8} {'epoch s':>8} {'(cpu)':>7} {'b1 ms':>7} "
        f"{'(cpu)':>7} {'b64 traj/s':>10} {'(cpu)':>7}",
        flush=True,
    )
    for name, config in CANDIDATES.items():
        if args.only and name not in args.only:
            continue
        torch.set_num_threads(args.train_threads)
        epoch = train_epoch_seconds(config, args.train_batch, args.train_steps)
        torch.set_num_threads(1)
        model = ART(config).eval()
        setup = {
            "model": model,
            "frame": "rtn",
            "normalization": bench_art.unit_normalization(STEPS, 6, 3),
            "target": None,
            "steps": STEPS,
            "dynamics": dynamics,
        }
        one = bench_art.time_mode(setup, "cached", 1, args.repeats)
        many = bench_art.time_mode(setup, "cached", 64, args.repeats)
        print(
            f"{name:<24} {model.num_parameters() / 1e6:>8.2f} {epoch[0]:>8.0f} {epoch[1]:>7.0f} "
            f"{1e3 * one.wall_s:>7.1f} {1e3 * one.cpu_s:>7.1f} {many.per_second:>10.1f} "
            f"{64 / many.cpu_s:>7.1f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
