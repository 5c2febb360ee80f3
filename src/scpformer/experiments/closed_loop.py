"""What the closed-loop experiments (``mpc-*``) share: flying every warm start's campaign into
its own folder of the experiment's output (with progress, summary and figure), the
side-by-side ``results.csv``, and the per-re-plan tables read back from the runs' npz."""

from __future__ import annotations

import csv
import io
import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.experiments import report as rep
from scpformer.experiments.runner import RunOptions, check_settings, require_n
from scpformer.files import write_text_atomic
from scpformer.guidance.campaign import Campaign, plot_campaign, run_campaign, summarize

#: ``analyse(rows, summaries, out, report)`` of an experiment: its sections of the report.
Analysis = Callable[
    [dict[str, list[dict[str, str]]], dict[str, dict[str, Any]], Path, rep.Report], None
]


def run_experiment(
    options: RunOptions,
    *,
    experiment: str,
    name: str,
    reproduces: str,
    command: str,
    settings: dict[str, Any],
    warmstarts: tuple[str, ...],
    campaign_of: Callable[[int, int, str], Campaign],
    family: str,
    run_columns: tuple[str, ...],
    analyse: Analysis,
    differences: tuple[str, ...],
) -> Path:
    """Run the closed-loop experiment ``experiment`` into ``options.out`` (its report
    named ``name``); returns the report's path.

    Records ``settings`` (with the experiment's name, run count, seed, folder and warm
    starts) in ``OUT/config.json`` and refuses a folder of other settings; flies
    ``campaign_of(n, seed, w)`` for every warm start ``w`` (:func:`fly_warmstarts`, resumed
    run by run); writes ``OUT/results.csv`` (:func:`results_csv`) and the report, whose
    sections ``analyse`` adds.
    """
    n, out = require_n(options), Path(options.out)
    record = {"experiment": experiment, "n": n, "seed": options.seed, "out": str(out),
              **settings, "warmstarts": list(warmstarts)}  # fmt: skip
    check_settings(out, record)
    rows, summaries = fly_warmstarts(
        experiment, out, warmstarts, lambda w: campaign_of(n, options.seed, w),
        family=family, workers=options.workers or 1, ray=options.ray,
    )  # fmt: skip
    write_text_atomic(out / "results.csv", results_csv(rows, warmstarts, run_columns))
    report = rep.Report(name=name, reproduces=reproduces, command=command, settings=record,
                        differences=differences)  # fmt: skip
    analyse(rows, summaries, out, report)
    return report.write(out)


def fly_warmstarts(
    name: str,
    out: Path,
    warmstarts: tuple[str, ...],
    campaign_of: Callable[[str], Campaign],
    *,
    family: str,
    workers: int = 1,
    ray: str | None = None,
) -> tuple[dict[str, list[dict[str, str]]], dict[str, dict[str, Any]]]:
    """Fly ``campaign_of(w)`` into ``out / w`` for every warm start ``w`` in order (each a
    resumable campaign folder with its ``simulate.png``); returns the rows of ``runs.csv``
    and the summary of each. One worker unless asked: re-plan wall times are measured.
    ``ray``: fly the runs as tasks on that Ray cluster (:func:`run_campaign`)."""
    rows: dict[str, list[dict[str, str]]] = {}
    summaries: dict[str, dict[str, Any]] = {}
    for warmstart in warmstarts:
        folder = out / warmstart
        campaign = campaign_of(warmstart)

        def progress(row: dict[str, Any], ws: str = warmstart, n: int = campaign.runs) -> None:
            print(f"{name}: {ws} run {row['run'] + 1}/{n}: success {row['success']}",
                  file=sys.stderr, flush=True)  # fmt: skip

        rows[warmstart] = run_campaign(campaign, folder, on_run=progress, workers=workers,
                                       ray=ray)  # fmt: skip
        summaries[warmstart] = summarize(rows[warmstart], folder, family)
        if rows[warmstart]:
            plot_campaign(rows[warmstart], folder, folder / "simulate.png", family)
    return rows, summaries


def results_csv(
    rows: dict[str, list[dict[str, str]]], warmstarts: tuple[str, ...], columns: tuple[str, ...]
) -> str:
    """``OUT/results.csv``: one line per run, its index and error seed, then each warm
    start ``w``'s ``columns`` as ``w_<column>``."""
    header = ["index", "seed"] + [f"{w}_{c}" for w in warmstarts for c in columns]
    by_run: dict[int, dict[str, str]] = {}
    for warmstart, table in rows.items():
        for row in table:
            line = by_run.setdefault(int(row["run"]), {"index": row["run"], "seed": row["seed"]})
            line.update({f"{warmstart}_{c}": row.get(c, "") for c in columns})
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=header, lineterminator="\n")
    writer.writeheader()
    for run_index in sorted(by_run):
        writer.writerow(by_run[run_index])
    return buf.getvalue()


def relative(percent: float, less: str, more: str) -> str:
    """``"12.3% fewer"`` for a positive saving, ``"4.5% more"`` for a negative one."""
    return f"{abs(percent):.1f}% {less if percent >= 0 else more}"


def speedup(ratio: float) -> str:
    """``"2.10x shorter"`` for a ratio above 1 (cold over warm), ``"1.09x longer"`` below."""
    return f"{ratio:.2f}x shorter" if ratio >= 1 else f"{1 / ratio:.2f}x longer"


def replan_arrays(folder: Path, table: list[dict[str, str]]) -> dict[str, np.ndarray]:
    """Every ``replan_*`` and ``compare_*`` table of the runs of ``table`` (their
    ``folder/run-NNNN.npz``), concatenated over the runs in order; a table a run lacks (an
    older run) is filled with empty strings."""
    runs = []
    for row in table:
        path = folder / f"run-{int(row['run']):04d}.npz"
        if path.exists():
            with np.load(path) as data:
                runs.append({k: np.asarray(data[k]) for k in data.files
                             if k.startswith(("replan_", "compare_"))})  # fmt: skip
    keys = sorted({k for run in runs for k in run})
    out = {}
    for key in keys:
        prefix = key.split("_", 1)[0]
        parts = [run.get(key, np.full(run[f"{prefix}_node"].size, "")) for run in runs]
        out[key] = np.concatenate(parts)
    return out


def column(table: list[dict[str, str]], name: str) -> np.ndarray:
    """The float column ``name`` of ``runs.csv`` rows."""
    return np.array([float(r[name]) for r in table], dtype=float)


def succeeded(table: list[dict[str, str]]) -> np.ndarray:
    """The ``success`` column of ``runs.csv`` rows as booleans."""
    return np.array([r["success"].strip().lower() in ("true", "1") for r in table], dtype=bool)


def percentile(values: np.ndarray, q: float) -> float:
    """``np.percentile`` that is NaN for no values."""
    return float(np.percentile(values, q)) if values.size else math.nan


def fuel_ratio(table: list[dict[str, str]]) -> np.ndarray:
    """Each run's closed-loop fuel over its open-loop optimum's (delta-v or propellant)."""
    return column(table, "fuel") / column(table, "open_loop_fuel")


def compared(arrays: dict[str, np.ndarray], other: str) -> dict[str, np.ndarray]:
    """The comparison solves of ``other`` among a flight's re-plan arrays
    (:func:`replan_arrays`; one per flown re-plan, in its order): every ``compare_*`` table
    without its prefix (``iterations``, ``wall_s``, ``cost``, ``accepted``, ...)."""
    sel = arrays["compare_warmstart"].astype(str) == other
    return {k.removeprefix("compare_"): v[sel] for k, v in arrays.items()
            if k.startswith("compare_")}  # fmt: skip


def add_figures(report: rep.Report, out: Path, warmstarts: tuple[str, ...], flown: str) -> None:
    """Each warm start's ``simulate.png`` that exists, captioned with what it shows
    (``flown``: the flown trajectories or descents)."""
    for w in warmstarts:
        if (out / w / "simulate.png").exists():
            report.figures.append((f"{w}/simulate.png", f"{w}: flown {flown} and re-plan "
                                   "wall times against the re-planning period"))  # fmt: skip
