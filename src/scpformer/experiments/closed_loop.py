"""What the closed-loop experiments (``mpc-*``) share: flying every warm start's campaign into
its own folder of the experiment's output (with progress, summary and figure), the
side-by-side ``results.csv``, and the per-re-plan tables read back from the runs' npz.

Output of every closed-loop experiment (``OUT``): one resumable campaign folder ``OUT/<w>``
per warm start ``w`` (``runs.csv``, ``run-NNNN.npz``, ``settings.json``, ``simulate.png``),
``config.json``, ``results.csv`` (one row per run, the warm starts side by side),
``report.md`` and ``results.json``.

The sampled instances of the rendezvous experiments are never used in training: the
sampler's stream of run ``r`` is ``SeedSequence([S, r])``, while the dataset engine draws
instance ``i`` of a dataset of seed ``S'`` from ``SeedSequence(S', spawn_key=(i,))``
(:mod:`scpformer.data.executors`); the two never coincide, whatever the seeds.
"""

from __future__ import annotations

import csv
import io
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from scpformer.experiments import report as rep
from scpformer.experiments.paired import Outcomes, paired_table
from scpformer.experiments.runner import RunOptions, check_settings, require_n
from scpformer.files import write_text_atomic
from scpformer.guidance.campaign import Campaign, plot_campaign, run_campaign, summarize

#: A cell of a summary table: its text for a warm start.
Cell = Callable[[str], str]


@dataclass(frozen=True)
class Flights:
    """The flown campaigns of a closed-loop experiment, read back for its report.

    Attributes
    ----------
    rows : dict
        Each warm start's rows of ``runs.csv``.
    summaries : dict
        Each warm start's campaign summary (:func:`~scpformer.guidance.campaign.summarize`).
    out : Path
        The experiment's folder (each warm start's campaign in ``out / w``).
    warmstarts : tuple of str
        The warm starts flown, in order.
    """

    rows: dict[str, list[dict[str, str]]]
    summaries: dict[str, dict[str, Any]]
    out: Path
    warmstarts: tuple[str, ...]

    @property
    def n_runs(self) -> int:
        """The runs flown by every warm start (0 when one flew none)."""
        return min((len(t) for t in self.rows.values()), default=0)

    @cached_property
    def arrays(self) -> dict[str, dict[str, np.ndarray]]:
        """Each warm start's per-re-plan tables (:func:`replan_arrays`), read once."""
        return {w: replan_arrays(self.out / w, self.rows[w]) for w in self.warmstarts}

    def successes(self, warmstart: str) -> str:
        """``"k/n"``: the runs of ``warmstart`` that succeeded, of those flown."""
        table = self.rows[warmstart]
        return f"{int(succeeded(table).sum())}/{len(table)}"

    def replans(self, warmstart: str) -> str:
        """``"re-plans (failed)"`` of ``warmstart``, summed over its runs."""
        summary = self.summaries[warmstart]
        return f"{summary['replans']} ({summary['replans_failed']})"

    def replan_times(self, warmstart: str) -> str:
        """The median and p99 re-plan wall time of ``warmstart`` [s]."""
        summary = self.summaries[warmstart]
        return (f"{rep.fmt(summary['replan_time_median_s'])} / "
                f"{rep.fmt(summary['replan_time_p99_s'])}")  # fmt: skip

    def replan_iterations(self, warmstart: str) -> str:
        """The median, mean and p99 SCP iterations per re-plan of ``warmstart``."""
        summary = self.summaries[warmstart]
        mean = float(np.mean(self.arrays[warmstart]["replan_iterations"]))
        return (f"{rep.fmt(summary['replan_iterations_median'])} / {rep.fmt(mean)} / "
                f"{rep.fmt(summary['replan_iterations_p99'])}")  # fmt: skip

    def spread(self, name: str, scale: float = 1.0, *, p95: bool = False) -> Cell:
        """The cell of the float column ``name`` of ``runs.csv`` times ``scale``: its median
        and maximum over a warm start's runs (``"median / max"``), or with ``p95`` its 95th
        percentile too (``"median / p95 / max"``)."""

        def cell(warmstart: str) -> str:
            values = column(self.rows[warmstart], name)
            stats = [float(np.median(values)), *([percentile(values, 95)] if p95 else []),
                     float(values.max())]  # fmt: skip
            return " / ".join(rep.fmt(scale * v) for v in stats)

        return cell

    def table(self, lines: Sequence[tuple[str, Cell]]) -> str:
        """The markdown summary table: a row per ``(quantity, cell)`` of ``lines``, a column
        per warm start."""
        rows = [(quantity, *(cell(w) for w in self.warmstarts)) for quantity, cell in lines]
        return rep.markdown_table(("quantity", *self.warmstarts), rows)


class ClosedLoopExperiment(Protocol):
    """What a closed-loop experiment module (``mpc_*``) defines for :func:`run_experiment`.

    Attributes
    ----------
    NAME, REPRODUCES : str
        The registry name and what the experiment reproduces.
    FAMILY : str
        The problem family flown (:func:`~scpformer.guidance.campaign.summarize`).
    SETTINGS : dict
        The experiment's own settings, recorded in ``OUT/config.json``.
    WARMSTARTS : tuple of str
        The warm starts flown, in order (a campaign folder ``OUT/<w>`` each).
    RUN_COLUMNS : tuple of str
        The columns of ``runs.csv`` that ``OUT/results.csv`` keeps per warm start.
    DIFFERENCES : tuple of str
        The report's differences from the reference.
    """

    NAME: str
    REPRODUCES: str
    FAMILY: str
    SETTINGS: dict[str, Any]
    WARMSTARTS: tuple[str, ...]
    RUN_COLUMNS: tuple[str, ...]
    DIFFERENCES: tuple[str, ...]

    def campaign(self, n: int, seed: int, warmstart: str) -> Campaign:
        """The campaign warm start ``warmstart`` flies: ``n`` runs of seed ``seed``."""

    def runs_text(self, n_runs: int) -> str:
        """The report's "Runs" section: what ``n_runs`` runs per warm start flew."""

    def analyse(self, flights: Flights, report: rep.Report) -> None:
        """The report's further sections, comparisons and figures (runs were flown)."""


def shipped_model_commands(family: str) -> list[str]:
    """The commands that made the shipped model the learned starts of ``family``'s re-plans
    load (:func:`~scpformer.pretrained.default_model` with ``guidance=True``): the recipe of
    its ``MODEL_CARD.md``, under a comment naming the model."""
    from scpformer.pretrained import default_model

    folder = default_model(family, guidance=True)
    card = (folder / "MODEL_CARD.md").read_text()
    recipe = card.split("```sh\n", 1)[-1].split("```", 1)[0] if "```sh\n" in card else ""
    return [f"# the shipped model {folder.name} (scpformer/pretrained/{folder.name}/"
            "MODEL_CARD.md), made by:", *recipe.splitlines()]  # fmt: skip


def run_experiment(
    options: RunOptions, experiment: ClosedLoopExperiment, *, command: str, name: str
) -> Path:
    """Run the closed-loop ``experiment`` into ``options.out`` (its report named ``name``);
    returns the report's path.

    Records the experiment's settings (with its name, run count, seed, folder and warm
    starts) in ``OUT/config.json`` and refuses a folder of other settings (warm starts may be
    appended to those a folder holds: they fly beside the runs already there); flies
    ``experiment.campaign(n, seed, w)`` for every warm start ``w`` (:func:`fly_warmstarts`,
    resumed run by run); writes ``OUT/results.csv`` (:func:`results_csv`) and the report:
    its "Runs" section, then, when every warm start flew, what ``experiment.analyse`` adds.
    """
    n, out, warmstarts = require_n(options), Path(options.out), experiment.WARMSTARTS
    record = {"experiment": experiment.NAME, "n": n, "seed": options.seed, "out": str(out),
              **experiment.SETTINGS, "warmstarts": list(warmstarts)}  # fmt: skip
    check_settings(out, record, grows=("warmstarts",))
    rows, summaries = fly_warmstarts(
        experiment.NAME, out, warmstarts, lambda w: experiment.campaign(n, options.seed, w),
        family=experiment.FAMILY, workers=options.workers or 1, ray=options.ray,
    )  # fmt: skip
    write_text_atomic(out / "results.csv", results_csv(rows, warmstarts, experiment.RUN_COLUMNS))
    report = rep.Report(name=name, reproduces=experiment.REPRODUCES, command=command,
                        settings=record, differences=experiment.DIFFERENCES,
                        provenance=shipped_model_commands(experiment.FAMILY))  # fmt: skip
    flights = Flights(rows, summaries, out, warmstarts)
    report.sections.append(("Runs", experiment.runs_text(flights.n_runs)))
    if flights.n_runs:
        experiment.analyse(flights, report)
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


def median_iterations(arrays: dict[str, np.ndarray], other: str) -> str | None:
    """``"a vs b (median over n re-plans)"``: the median iterations of a flight's re-plans
    and of ``other`` solved on the same problems, or ``None`` when the flight recorded no
    solve of ``other`` per re-plan."""
    flown, base = arrays["replan_iterations"], compared(arrays, other)["iterations"]
    if not flown.size or base.size != flown.size:
        return None
    return f"{np.median(flown):g} vs {np.median(base):g} (median over {flown.size} re-plans)"


def paired_replans(
    arrays: dict[str, np.ndarray], flown: str, other: str, *, cost_tie: float
) -> str | None:
    """The flown re-plans of ``flown`` against ``other`` solved on the same re-plan problems,
    re-plan by re-plan (:func:`~scpformer.experiments.paired.paired_table`: a draw is a
    re-plan, solved means accepted, a tie a cost difference within ``cost_tie``), then both
    p99 wall times; ``None`` when the flights recorded no solve of ``other`` per re-plan."""
    side, wall = compared(arrays, other), arrays["replan_wall_s"]
    if not wall.size or side["wall_s"].size != wall.size:
        return None
    ours = Outcomes(time=wall, iterations=arrays["replan_iterations"],
                    solved=arrays["replan_accepted"], cost=arrays["replan_cost"])  # fmt: skip
    base = Outcomes(time=side["wall_s"], iterations=side["iterations"],
                    solved=side["accepted"], cost=side["cost"])  # fmt: skip
    table = paired_table(f"{flown} (flown)", ours, f"{other} (same problems)", base,
                         cost_tie=cost_tie)  # fmt: skip
    return (f"{table}\n\nWall time p99: {flown} {percentile(ours.time, 99):.3f} s, {other} "
            f"{percentile(base.time, 99):.3f} s.")  # fmt: skip


def verdict_lines(
    arrays: dict[str, dict[str, np.ndarray]], compared_with: dict[str, tuple[str, ...]],
    flowns: Sequence[str], *, unit: str = "SCP iterations",
) -> list[str]:  # fmt: skip
    """Plainly, for each flight of ``flowns`` whose re-plans were also solved from every
    start of ``compared_with[flown]``: which start needs the fewest ``unit`` per re-plan
    (mean) and the least wall time (median) on those identical problems."""
    lines = []
    for flown in flowns:
        a = arrays[flown]
        sides = {flown: {"iterations": a["replan_iterations"], "wall_s": a["replan_wall_s"]},
                 **{o: compared(a, o) for o in compared_with[flown]}}  # fmt: skip
        if not a["replan_iterations"].size or any(
            v["iterations"].size != a["replan_iterations"].size for v in sides.values()
        ):
            continue
        it = {w: float(np.mean(v["iterations"])) for w, v in sides.items()}
        wall = {w: float(np.median(v["wall_s"])) for w, v in sides.items()}
        fewest, fastest = min(it, key=it.__getitem__), min(wall, key=wall.__getitem__)
        lines.append(
            f"- On the {a['replan_iterations'].size} re-plans of the `{flown}` flights: fewest "
            f"{unit} per re-plan: **{fewest}** (mean "
            + ", ".join(f"{w} {v:.2f}" for w, v in it.items())
            + f"); shortest median wall time: **{fastest}** ("
            + ", ".join(f"{w} {v:.3f} s" for w, v in wall.items())
            + ")."
        )
    return lines


def add_figures(report: rep.Report, out: Path, warmstarts: tuple[str, ...], flown: str) -> None:
    """Each warm start's ``simulate.png`` that exists, captioned with what it shows
    (``flown``: the flown trajectories or descents)."""
    for w in warmstarts:
        if (out / w / "simulate.png").exists():
            report.figures.append((f"{w}/simulate.png", f"{w}: flown {flown} and re-plan "
                                   "wall times against the re-planning period"))  # fmt: skip
