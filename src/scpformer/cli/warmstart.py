"""Warm starts of the solve commands: the provider of ``--warmstart ... --model RUN`` and the
summary rows (the flags are in :mod:`scpformer.cli.parsers.common`)."""

from __future__ import annotations

import argparse
import math
from typing import Any

from scpformer.scp.solution import Solution
from scpformer.warmstart import ArtWarmStart, WarmStart, WarmStartRecord


def art_provider(args: argparse.Namespace, family: str, **kwargs: Any) -> WarmStart | None:
    """The ART provider of ``--warmstart art [--model RUN]``, or None for a named warm start.

    Without ``--model`` (or with ``--model default``) the family's pretrained model shipped
    in :mod:`scpformer.pretrained` is used, after its checksum is verified.
    """
    art_flags = {"--model": args.model, "--art-mode": args.art_mode, "--rtg": args.rtg,
                 "--ctg": args.ctg}  # fmt: skip
    if args.warmstart != "art":
        given = [flag for flag, value in art_flags.items() if value is not None]
        if given:
            raise ValueError(f"{', '.join(given)}: used with --warmstart art only")
        return None
    from scpformer.models.capabilities import single_thread_inference
    from scpformer.pretrained import resolve_model

    single_thread_inference()
    return ArtWarmStart.from_checkpoint(
        resolve_model(args.model, family),
        family=family,
        art_mode=args.art_mode or "dynamics",
        rtg=args.rtg,
        ctg=0.0 if args.ctg is None else args.ctg,
        **kwargs,
    )


def warmstart_line(record: WarmStartRecord, solution: Solution | None = None) -> str:
    """One line: which warm start, its status or acceptance, and its time."""
    if record.source != "art":
        status = solution.status.value if solution is not None else "ok"
        return f"warm start ({record.source}): {status} in {record.time_s:.3f} s"
    decision = "accepted" if record.accepted else f"rejected, used {record.used}"
    return f"warm start (art): {decision} ({record.reason}) in {record.time_s:.3f} s"


def _number(value: float, scale: float, unit: str, digits: int) -> str:
    return f"{scale * value:.{digits}f} {unit}" if math.isfinite(value) else "-"


def comparison_rows(
    record: dict[str, Any],
    scp: Solution,
    scp_ctg: float,
    *,
    cost_scale: float = 1.0,
    cost_unit: str = "m/s",
    digits: int = 4,
) -> list[tuple[str, str]]:
    """Time, cost and constraint-to-go of the warm start beside the SCP's.

    ``record`` is ``Solution.extras["warmstart"]`` (:meth:`WarmStartRecord.to_dict`); the
    SCP's time is its solve's wall time without verification (the guess computed before it).
    """
    used = record["used"]
    scp_time = scp.timing.total - scp.timing.verification if scp.timing else math.nan
    width = 24

    def row(label: str, warm: str, solved: str) -> tuple[str, str]:
        return label, f"{warm:<{width}}{solved}"

    rows = [
        row("", f"warm start ({used})", "SCP"),
        row("  wall time", f"{record['time_s']:.3f} s", f"{scp_time:.3f} s"),
        row(
            "  cost sum |dv|",
            _number(record["cost"], cost_scale, cost_unit, digits),
            _number(scp.cost, cost_scale, cost_unit, digits),
        ),
        row("  constraint-to-go C(t_0)", _ctg(record["constraint_to_go"]), _ctg(scp_ctg)),
    ]
    details = record.get("details", {})
    if record["source"] == "art" and not record["accepted"]:
        art = (_number(details.get("art_cost", math.nan), cost_scale, cost_unit, digits),
               _ctg(details.get("art_constraint_to_go", math.nan)))  # fmt: skip
        rows.append(("  rejected ART guess", f"cost {art[0]}, C(t_0) {art[1]}"))
    return rows


def _ctg(value: float) -> str:
    return str(int(value)) if math.isfinite(value) else "-"
