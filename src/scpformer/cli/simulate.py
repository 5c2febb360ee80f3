"""``scpformer simulate rendezvous|pdg6dof|robust-rendezvous``: closed-loop runs into a folder
(:mod:`scpformer.guidance`)."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from scpformer.files import check_output_folder


def run_simulate(args: argparse.Namespace) -> int:
    """Fly ``--runs`` closed-loop runs (resuming ``--out``), print the summary, draw the figure."""
    from scpformer.guidance import ErrorModels, MPCConfig
    from scpformer.guidance.campaign import (
        Campaign,
        plot_campaign,
        run_campaign,
        summarize,
        summary_text,
    )

    folder = check_output_folder(args.out, "--out")
    family = getattr(args, "family", "rendezvous")
    if family == "pdg6dof":
        from scpformer.guidance import pdg6dof_mpc as pdg

        config: Any = pdg.MPCConfig(
            replan_every=args.replan_every,
            warmstart=args.warmstart,
            compare=(args.compare,) if args.compare else (),
            errors=pdg.ErrorModels() if args.errors == "default" else pdg.ErrorModels.none(),
            tracking=pdg.TrackingWeights() if args.tracking == "lqr" else None,
            model=None if args.model is None else str(args.model),
            time_budget_s=args.time_budget,
            replan_iter_max=args.replan_iter_max,
            min_remaining_time=args.min_remaining_time,
        )
    else:
        from scpformer.guidance import robust_rendezvous_mpc as robust

        make = robust.MPCConfig if family == "robust-rendezvous" else MPCConfig
        model = getattr(args, "model", None)  # the ART model of art and best (rendezvous)
        risk = getattr(args, "mission_risk", None)  # robust-rendezvous only
        config = make(
            replan_every=args.replan_every,
            warmstart=args.warmstart,
            compare=(args.compare,) if args.compare else (),
            errors=ErrorModels() if args.errors == "table2" else ErrorModels.none(),
            **({"model": str(model)} if model is not None else {}),
            **({"mission_risk": risk} if risk is not None else {}),
            **({"covariance": args.covariance} if hasattr(args, "covariance") else {}),
            time_budget_s=args.time_budget,
        )
        if {args.warmstart, args.compare} & {"art", "best"}:
            from scpformer.models.capabilities import single_thread_inference

            single_thread_inference()
    campaign = Campaign(runs=args.runs, seed=args.seed, instances=args.instances, config=config)
    bar = _Bar(args.quiet)
    try:
        rows = run_campaign(
            campaign,
            folder,
            on_start=bar.start,
            on_run=bar.update,
            workers=args.workers,
            ray=args.ray,
        )
    finally:
        bar.close()
    print(summary_text(summarize(rows, folder, campaign.family)))
    if not args.no_figure and rows:
        path = plot_campaign(rows, folder, folder / "simulate.png", campaign.family)
        print(f"figure: {path}")
    print(f"runs: {folder / 'runs.csv'}")
    return 0


class _Bar:
    """tqdm bar over the runs, with the success count."""

    def __init__(self, quiet: bool) -> None:
        self.quiet, self.bar, self.ok = quiet, None, 0

    def start(self, done: int, total: int) -> None:
        if self.quiet or done >= total:
            return
        from tqdm import tqdm

        self.bar = tqdm(total=total, initial=done, desc="simulate", unit="run", file=sys.stderr)

    def update(self, row: dict[str, Any]) -> None:
        if self.bar is None:
            return
        self.ok += bool(row["success"])
        self.bar.set_postfix(success=self.ok, refresh=False)
        self.bar.update(1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
