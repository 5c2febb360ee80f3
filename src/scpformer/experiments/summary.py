"""``docs/RESULTS.md``: every experiment's paper-vs-ours rows on one page (``scpformer report``).

Each experiment folder ``RESULTS_DIR/NAME/`` holds ``report.md`` and ``results.json``
(written together by :meth:`scpformer.experiments.report.Report.write`). This module reads
the ``results.json`` of every folder that has a ``report.md`` and writes one Markdown page:
an overview (status, where and when each result was measured, whether it is stale), then per
paper table or figure the paper's number, ours, the status of each row, and the commands that
reproduce ours (dataset, models, experiment), with a link to the full report. Registry
experiments without a folder are listed as not run yet.

Status: :func:`scpformer.experiments.report.row_status` (the rule is in that module's
docstring), or the status an experiment recorded for a row.

Stale: a result records the commit it was measured at (``results.json`` ``"run"``
``"commit"``). It is **stale** when a later commit changed a source path its registry entry
declares (:attr:`scpformer.experiments.Experiment.depends_on`), i.e. when ``git log
--format=%H COMMIT..HEAD -- PATHS`` is non-empty in the checkout the package runs from. Any
change counts, a comment as much as an algorithm: a stale result may still be right, but it
was not measured with the code of today. Uncommitted changes do not count.
When the commit is unknown or git cannot answer, the page says so ("stale: unknown").
"""

from __future__ import annotations

import json
import os
import subprocess
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from scpformer.experiments.report import (
    REPORT_NAME,
    RESULTS_JSON_NAME,
    UNKNOWN,
    experiment_status,
    markdown_table,
    repository_root,
    row_status,
)

ROW_KEYS = ("paper_item", "metric", "paper", "ours", "command")  # required in every row
TITLE = "Results: the papers' numbers beside ours"


class ResultsError(ValueError):
    """A results folder or ``results.json`` that cannot be summarized (names the file)."""


@dataclass(frozen=True)
class ExperimentResults:
    """One experiment folder's ``results.json``, checked."""

    folder: Path
    experiment: str
    reproduces: str  # the paper table or figure
    command: str  # the experiment's command line
    provenance: tuple[str, ...]  # the commands that made its data and models
    rows: tuple[dict[str, str], ...]  # ROW_KEYS (+ "note", "status")
    run: dict[str, Any] = field(default_factory=dict)  # version, commit, date, machine, commands

    def statuses(self) -> list[str]:
        """Each row's status: the one recorded, else :func:`row_status`."""
        return [r.get("status") or row_status(r["paper"], r["ours"]) for r in self.rows]


def read_results(folder: Path) -> ExperimentResults:
    """The checked ``results.json`` of one experiment folder.

    Raises
    ------
    ResultsError
        Naming the file: missing, not JSON, or without the keys of :data:`ROW_KEYS`.
    """
    path = Path(folder) / RESULTS_JSON_NAME
    if not path.is_file():
        raise ResultsError(
            f"{path}: missing (every report.md needs its results.json; rerun the experiment "
            "with `scpformer experiment run` to write both)"
        )
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ResultsError(f"{path}: not readable JSON ({err})") from None
    if not isinstance(data, dict) or not isinstance(data.get("rows"), list):
        raise ResultsError(f"{path}: expected an object with a list 'rows'")
    for i, row in enumerate(data["rows"]):
        missing = [k for k in ROW_KEYS if not isinstance(row, dict) or k not in row]
        if missing:
            raise ResultsError(f"{path}: row {i} lacks {', '.join(missing)}")
    provenance = data.get("provenance", [])
    run = data.get("run", {})
    if not isinstance(run, dict):
        raise ResultsError(f"{path}: 'run' must be an object")
    return ExperimentResults(
        folder=Path(folder),
        experiment=str(data.get("experiment", Path(folder).name)),
        reproduces=str(data.get("reproduces", "")),
        command=str(data.get("command", "")),
        provenance=tuple(str(line) for line in provenance),
        rows=tuple({k: str(v) for k, v in row.items()} for row in data["rows"]),
        run=run,
    )


def collect(results_dir: Path) -> list[ExperimentResults]:
    """The results of every ``RESULTS_DIR/*/`` holding a ``report.md``, sorted by name.

    A ``results.json`` without its ``report.md`` (a run stopped between writing the two) is
    not summarized, but it is read all the same: when it is unreadable, the
    :class:`ResultsError` names it, rather than the experiment being listed as not run.
    """
    results_dir = Path(results_dir)
    if results_dir.exists() and not results_dir.is_dir():
        raise ResultsError(f"--results {results_dir} is a file, not a folder")
    if not results_dir.is_dir():
        raise ResultsError(f"--results {results_dir}: no such folder")
    results = [read_results(folder) for folder in experiment_folders(results_dir)]
    return [r for r in results if (r.folder / REPORT_NAME).exists()]


def experiment_folders(results_dir: Path) -> list[Path]:
    """The folders ``RESULTS_DIR/*/`` holding a ``report.md`` or a ``results.json``, sorted."""
    names = (REPORT_NAME, RESULTS_JSON_NAME)
    return sorted({p.parent for name in names for p in Path(results_dir).glob(f"*/{name}")})


def stale_commits(commit: str, paths: Sequence[str], repository: Path) -> list[str] | None:
    """The commits after ``commit`` that changed ``paths`` (newest first), or ``None`` when
    git cannot tell (no repository, unknown commit, no paths declared)."""
    if not paths or not commit or commit == UNKNOWN:
        return None
    try:
        log = subprocess.run(
            ["git", "-C", str(repository), "log", "--format=%H", f"{commit}..HEAD", "--", *paths],
            capture_output=True,
            text=True,
            timeout=60,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    if log.returncode != 0:
        return None
    return log.stdout.split()


def staleness(results: Sequence[ExperimentResults], repository: Path) -> dict[str, str]:
    """Per experiment: ``""`` (current), ``"stale: ..."`` or ``"stale: unknown (...)"``."""
    from scpformer.experiments import EXPERIMENTS

    out = {}
    for result in results:
        entry = EXPERIMENTS.get(result.experiment)
        commit = str(result.run.get("commit", UNKNOWN))
        later = stale_commits(commit, entry.depends_on if entry else (), repository)
        if later is None:
            why = "commit unknown" if commit == UNKNOWN else "no declared sources or no git"
            out[result.experiment] = f"stale: unknown ({why})"
        elif later:
            out[result.experiment] = (
                f"stale: {len(later)} later commit(s) changed its sources, newest {later[0][:7]}"
            )
        else:
            out[result.experiment] = ""
    return out


def _measured(run: Mapping[str, Any]) -> str:
    commit = str(run.get("commit", UNKNOWN))
    date = str(run.get("date", UNKNOWN))[:10]
    return f"{commit[:7] if commit != UNKNOWN else UNKNOWN}, {date}"


def render(
    results: Sequence[ExperimentResults],
    out: Path,
    not_run: Sequence[str] = (),
    stale: Mapping[str, str] | None = None,
) -> str:
    """The Markdown page; links are relative to ``out``'s folder.

    ``not_run`` names the paper items (e.g. registry entries) without results yet; ``stale``
    maps an experiment to its :func:`staleness` text (empty or absent: current).
    """
    stale = stale or {}
    parts = [
        f"# {TITLE}",
        "",
        "Generated by `scpformer report` from each experiment folder's `results.json`; do",
        "not edit. Each section is one paper table or figure: the paper's number, ours, the",
        "status of each row, and the commands that reproduce ours (dataset, models, then the",
        "experiment). The full reports hold the configuration, detailed tables, figures and",
        "where we differ.",
        "",
        "Status: **reproduced**, **partly** or **not reproduced** by the rule in",
        "`scpformer.experiments.report` (a number within 25% of the paper's, or a bound or",
        "yes/no met, is reproduced; the same sign within a factor 3 is partly); **not rated**",
        "where the paper prints no number. A result is **stale** when a commit after the one",
        "it was measured at changed a source file its experiment declares",
        "(`Experiment.depends_on`): it was not measured with today's code and needs a rerun",
        "(`scripts/reproduce_results.sh`).",
        "",
    ]
    overview = []
    for result in results:
        link = os.path.relpath(result.folder / RESULTS_JSON_NAME, Path(out).parent)
        status = experiment_status(result.statuses())
        flag = stale.get(result.experiment, "")
        overview.append(
            (
                f"{result.reproduces or result.experiment} (`{result.experiment}`)",
                status + (" (stale)" if flag else ""),
                f"[{_measured(result.run)}]({link.replace(os.sep, '/')})",
                flag or "current",
            )
        )
    if overview:
        parts += [
            markdown_table(("result", "status", "measured (commit, date)", "stale"), overview),
            "",
        ]
    for result in results:
        link = os.path.relpath(result.folder / REPORT_NAME, Path(out).parent)
        title = result.reproduces or result.experiment
        flag = stale.get(result.experiment, "")
        suffix = " (stale)" if flag else ""
        rows = [
            (r["metric"], r["paper"], r["ours"], status + suffix, r.get("note", ""))
            for r, status in zip(result.rows, result.statuses(), strict=True)
        ]
        commands = list(result.run.get("commands") or [])
        if not commands:
            commands = [*result.provenance, result.command or "# (command not recorded)"]
        machine = result.run.get("machine", {})
        parts += [
            f"## {title} (`{result.experiment}`){' - STALE' if flag else ''}",
            "",
            f"Full report: [{link}]({link.replace(os.sep, '/')})",
            "",
        ]
        if flag:
            parts += [f"**This result is {flag}.** Rerun it before relying on it.", ""]
        parts += [
            f"Measured at commit `{result.run.get('commit', UNKNOWN)}` on "
            f"{result.run.get('date', UNKNOWN)} (scpformer {result.run.get('version', UNKNOWN)}); "
            f"machine: {machine.get('cpu', UNKNOWN)}, {machine.get('cores', UNKNOWN)} cores, "
            f"{machine.get('threads', UNKNOWN)} threads used."
            + (f" {result.run['note']}" if result.run.get("note") else ""),
            "",
            markdown_table(("quantity", "paper", "ours", "status", "note"), rows)
            if rows
            else "No comparison rows (see the full report).",
            "",
            "Reproduce:",
            "",
            "```sh",
            *commands,
            "```",
            "",
        ]
    if not_run:
        parts += ["## Not run yet", "", *(f"- {item}" for item in not_run), ""]
    return "\n".join(parts)


def write_summary(results_dir: Path, out: Path) -> Path:
    """Gather ``RESULTS_DIR/*/results.json`` into ``out`` (written atomically).

    A results folder without any experiment folder (a mistyped ``--results``) is a
    :class:`ResultsError`: its page would list every experiment as not run and replace the
    page at ``out``.
    """
    from scpformer.experiments import EXPERIMENTS
    from scpformer.files import check_output_file
    from scpformer.files import write_text_atomic as atomic_write_text

    check_output_file(out, "--out")
    results = collect(results_dir)
    if not results and not experiment_folders(results_dir):
        raise ResultsError(  # a page of "not run yet" would only replace the one there
            f"--results {results_dir} holds no experiment folders (none has {REPORT_NAME} or "
            f"{RESULTS_JSON_NAME}); {out} is left as it is"
        )
    done = {r.experiment for r in results}
    not_run = [
        f"{e.reproduces} (`scpformer experiment run {name}`): {e.summary}"
        for name, e in EXPERIMENTS.items()
        if name not in done
    ]
    out = Path(out)
    stale = staleness(results, repository_root() or Path(results_dir))
    atomic_write_text(out, render(results, out, not_run, stale))
    return out
