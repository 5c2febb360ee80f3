"""``report.md`` of an experiment run, the paper-vs-ours table, provenance and figure helpers.

A report holds, in order: what the run reproduces, the command that ran it, its provenance,
the resolved configuration, the commands that made its dataset and models, the table with
the paper's number beside ours for every quantity the paper reports, the figures, and where
our formulation differs from the paper's code.

Beside ``report.md``, ``results.json`` holds the paper-vs-ours rows in machine-readable form
(:meth:`Report.results`), which ``scpformer report`` gathers into ``docs/RESULTS.md``
(:mod:`scpformer.experiments.summary`).

Provenance
----------
Every ``results.json`` has a ``"run"`` object (:func:`run_record`): the package version, the
git commit of the checkout the package was imported from and whether its tracked files had
uncommitted changes (``dirty``), the date (UTC, ISO 8601), the machine (CPU model, logical
cores, threads the run used: one per worker process, each with one torch thread) and the
command lines that regenerate the result from seeds (dataset, split, training, experiment).
Paths in those commands are written relative to the repository, and a path inside the folder
named by the ``DATA`` environment variable as ``$DATA/...``. What cannot be known is written
``"unknown"``.

Status of a row
---------------
:func:`row_status` compares the paper's cell with ours, both as printed, by this rule:

1. The paper gives nothing to compare (``n/a``, "figure only", "no number", "Fig. N only",
   or a cell without any number or yes/no): **not rated**.
2. ``yes`` / ``no``: **reproduced** when our cell starts with the same word, otherwise
   **not reproduced**.
3. A bound (``> a``, ``>= a``, ``< a``, ``<= a``): **reproduced** when our first number
   meets it (``>=`` and ``<=`` to within ``1e-3 max(1, |a|)``, a solver's tolerance),
   otherwise **not reproduced**.
4. Two numbers ``a vs b`` (a ratio the paper reports) and ours ``c vs d``: **reproduced**
   when ``c/d`` lies on the same side of 1 as ``a/b`` and within a factor 1.5 of it,
   **partly** when only the side of 1 agrees, **not reproduced** otherwise.
5. One number ``a`` (also ``~a``, ``up to a``, a range ``a-b``, with units or a ``%``) and
   ours ``y`` (our first number): **reproduced** when ``y`` is within 25% of ``a`` (of the
   nearest end of a range), **partly** when it has the same sign and is within a factor 3,
   **not reproduced** otherwise.

An experiment may set a row's status itself (``Comparison.status``), for claims the rule
cannot read (e.g. "lower with ART"); that status is used as given. The status of an
experiment is **reproduced** when every rated row is, **not reproduced** when no rated row is
reproduced or partly, and **partly** otherwise.
"""

from __future__ import annotations

import datetime
import json
import math
import os
import platform
import re
import subprocess
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from scpformer.files import atomic_path
from scpformer.files import write_text_atomic as atomic_write_text

REPORT_NAME = "report.md"
RESULTS_JSON_NAME = "results.json"  # the comparison rows, machine-readable

# Where our rendezvous formulation differs from the public ART code (every rendezvous report).
RENDEZVOUS_DIFFERENCES: tuple[str, ...] = (
    "Approach cone vertex: ours sits 5 m behind the docking port "
    "(`RendezvousScenario.cone_vertex_setback_m = 5`); the ART paper's public code "
    "(`art-aeroconf24`) puts it at the port (the later `transformermpc-ral24` code sets it 5 m "
    "back, as we do). "
    "With the vertex at the port Problem 2 is infeasible in our model (the last coast arc "
    "cannot lie in the cone), so we keep the setback. Its cost, measured once outside these "
    "experiments: on 20 instances from the ART code's own sampler, moving that "
    "code's vertex to ours lowers its costs by a median of 2.8%, almost all of the cost "
    "difference between the two programs; our costs are therefore not comparable to the "
    "paper's at the percent level.",
    "Conic solver: the dataset's solver (Clarabel by default, interior point) through cvxpy; "
    "the paper solves with ECOS (its ref. [37]). "
    "Interior-point solutions never have exactly zero impulses, hence the 0.1 mm/s threshold "
    "of the impulse accuracy (`experiments.forecast.IMPULSE_THRESHOLD`).",
    "Dataset and model sizes: the paper trains on N_d = 400,000 trajectories with its Table 4 "
    "model; ours are the dataset and preset named in the commands above (orders of magnitude "
    "smaller, trained on two CPU cores).",
    "Splits are grouped by base instance (the convex and SCP twins of one instance never "
    "straddle train and test); the public ART code splits sequences, which leaks twins.",
)


@dataclass(frozen=True, kw_only=True)
class Comparison:
    """One row of the paper-vs-ours table."""

    quantity: str
    paper: str  # the paper's number as printed (or "n/a: ..." when it gives none)
    ours: str
    note: str = ""
    status: str = ""  # one of STATUSES, set where the rule of row_status cannot read the claim


REPRODUCED, PARTLY, NOT_REPRODUCED, NOT_RATED = (
    "reproduced",
    "partly",
    "not reproduced",
    "not rated",
)
STATUSES = (REPRODUCED, PARTLY, NOT_REPRODUCED, NOT_RATED)
UNKNOWN = "unknown"

_NUMBER = r"[-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?"
_NO_NUMBER = re.compile(r"^n/a|figure only|no number|^fig\. \d+ only", re.IGNORECASE)


def _numbers(text: str) -> list[float]:
    text = re.sub(r"(?<=\d)\s*-\s*(?=\d)", " - ", text.replace(",", ""))  # ranges a-b
    return [float(v) for v in re.findall(_NUMBER, text)]


def row_status(paper: str, ours: str) -> str:
    """The status of one paper-vs-ours row by the rule of this module's docstring."""
    paper, ours = paper.strip(), ours.strip()
    lower = paper.lower()
    if _NO_NUMBER.search(lower):
        return NOT_RATED
    for word in ("yes", "no"):
        if lower == word:
            return REPRODUCED if ours.lower().startswith(word) else NOT_REPRODUCED
    mine = _numbers(ours)
    bound = re.match(rf"^(>=|<=|>|<)\s*({_NUMBER})", paper)
    if bound:
        if not mine:
            return NOT_REPRODUCED
        op, a, y = bound.group(1), float(bound.group(2)), mine[0]
        tol = 1e-3 * max(1.0, abs(a))  # a solver's tolerance
        met = {">": y > a, ">=": y >= a - tol, "<": y < a, "<=": y <= a + tol}[op]
        return REPRODUCED if met else NOT_REPRODUCED
    theirs = _numbers(re.sub(r"\(.*?\)", "", paper))
    if not theirs:
        return NOT_RATED
    if " vs " in paper and len(theirs) >= 2:
        if " vs " not in ours or len(mine) < 2 or 0 in (theirs[1], mine[1]):
            return NOT_REPRODUCED
        a, c = theirs[0] / theirs[1], mine[0] / mine[1]
        if (a > 1) != (c > 1) or a <= 0 or c <= 0:
            return NOT_REPRODUCED
        return REPRODUCED if max(a / c, c / a) <= 1.5 else PARTLY
    if not mine:
        return NOT_REPRODUCED
    y = mine[0]
    ranged = re.match(rf"^~?\s*{_NUMBER}\s*-\s*\d", paper)
    ends = theirs[:2] if ranged else theirs[:1]
    a = min(ends, key=lambda end: abs(y - end))
    if len(ends) == 2 and min(ends) <= y <= max(ends):
        return REPRODUCED
    if abs(y - a) <= 0.25 * abs(a):
        return REPRODUCED
    if a != 0 and y / a > 0 and max(y / a, a / y) <= 3:
        return PARTLY
    return NOT_REPRODUCED


def experiment_status(statuses: Iterable[str]) -> str:
    """The status of an experiment from those of its rows (this module's docstring)."""
    rated = [s for s in statuses if s != NOT_RATED]
    if not rated:
        return NOT_RATED
    if all(s == REPRODUCED for s in rated):
        return REPRODUCED
    if all(s == NOT_REPRODUCED for s in rated):
        return NOT_REPRODUCED
    return PARTLY


# ======================================================================================
# provenance
# ======================================================================================
def _git(folder: Path, *args: str, timeout: float = 10) -> subprocess.CompletedProcess | None:
    """``git -C folder ARGS`` with its output captured; ``None`` when git could not run."""
    try:
        return subprocess.run(
            ["git", "-C", str(folder), *args], capture_output=True, text=True, timeout=timeout
        )
    except (OSError, subprocess.SubprocessError):
        return None


def repository_root() -> Path | None:
    """The git checkout the ``scpformer`` package was imported from (``None`` outside one)."""
    import scpformer

    top = _git(Path(scpformer.__file__).resolve().parent, "rev-parse", "--show-toplevel")
    if top is None:
        return None
    return Path(top.stdout.strip()) if top.returncode == 0 and top.stdout.strip() else None


def git_state(root: Path | None) -> tuple[str, bool | str]:
    """``(commit, dirty)`` of the checkout at ``root``; ``("unknown", "unknown")`` without git.

    ``dirty`` is whether tracked files differ from the commit (untracked files are ignored).
    """
    if root is None:
        return UNKNOWN, UNKNOWN
    head = _git(root, "rev-parse", "HEAD")
    if head is None:
        return UNKNOWN, UNKNOWN
    status = _git(root, "status", "--porcelain", "--untracked-files=no", timeout=30)
    if status is None or head.returncode != 0:
        return UNKNOWN, UNKNOWN
    dirty: bool | str = bool(status.stdout.strip()) if status.returncode == 0 else UNKNOWN
    return head.stdout.strip(), dirty


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo`` on Linux, else :func:`platform.processor`)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or UNKNOWN


def portable_path(text: str, root: Path | None = None) -> str:
    """``text`` with absolute paths made portable: inside the repository ``root`` relative to
    it (``ROOT/docs/x`` -> ``docs/x``, ``ROOT`` -> ``.``), inside the folder of the ``DATA``
    environment variable (when set) as ``$DATA/...``."""
    prefixes: dict[str, str] = {}
    data = os.environ.get("DATA", "").rstrip("/")
    if data and os.path.isabs(data):
        prefixes[data] = prefixes[str(Path(data).resolve())] = "$DATA"
    if root is not None:
        prefixes[str(root)] = "."
    for prefix in sorted(prefixes, key=len, reverse=True):
        name = prefixes[prefix]
        child = re.compile(rf"(?<![\w./-]){re.escape(prefix)}/")
        text = child.sub("" if name == "." else f"{name}/", text)
        bare = re.compile(rf"(?<![\w./-]){re.escape(prefix)}(?![\w./-])")
        text = bare.sub(name.replace("$", "\\$"), text)
    return text


def _portable(value: Any, root: Path | None) -> Any:
    if isinstance(value, str):
        return portable_path(value, root)
    if isinstance(value, Mapping):
        return {k: _portable(v, root) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_portable(v, root) for v in value]
    return value


def run_record(
    settings: Mapping[str, Any], command: str, provenance: Sequence[str]
) -> dict[str, Any]:
    """The provenance of a run made now on this machine (this module's docstring).

    ``threads``: the worker processes of ``settings["workers"]`` (every CPU when unset), one
    torch thread each; a Ray run (``settings["ray"]``) records ``"unknown"``.
    """
    import scpformer

    root = repository_root()
    commit, dirty = git_state(root)
    cores = os.cpu_count() or 0
    workers = settings.get("workers")
    threads: int | str = UNKNOWN if settings.get("ray") else int(workers or cores or 1)
    commands = [*provenance, command] if command else list(provenance)
    return {
        "version": scpformer.__version__,
        "commit": commit,
        "dirty": dirty,
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "machine": {"cpu": cpu_model(), "cores": cores or UNKNOWN, "threads": threads},
        "commands": [portable_path(line, root) for line in commands],
    }


def render_run_record(run: Mapping[str, Any]) -> str:
    """The provenance section of a ``report.md``."""
    machine = run.get("machine", {})
    dirty = run.get("dirty", UNKNOWN)
    state = {True: " (with uncommitted changes)", False: ""}.get(dirty, " (clean or not: unknown)")
    lines = [
        f"- scpformer {run.get('version', UNKNOWN)}, commit `{run.get('commit', UNKNOWN)}`{state}",
        f"- date: {run.get('date', UNKNOWN)}",
        f"- machine: {machine.get('cpu', UNKNOWN)}, {machine.get('cores', UNKNOWN)} logical "
        f"cores, {machine.get('threads', UNKNOWN)} threads used",
    ]
    if run.get("note"):
        lines.append(f"- {run['note']}")
    lines += ["", "Regenerate from seeds (from the repository's root):", "", "```sh"]
    lines += [*run.get("commands", []), "```"]
    return "\n".join(lines)


def fmt(value: float, digits: int = 3) -> str:
    """A number for a report cell (``n/a`` for NaN)."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    return f"{value:.{digits}g}"


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    """A GitHub-flavoured Markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in rows:
        lines.append("| " + " | ".join(str(c).replace("|", "\\|") for c in row) + " |")
    return "\n".join(lines)


@dataclass
class Report:
    """The sections of a ``report.md``; :meth:`write` renders them."""

    name: str
    reproduces: str
    command: str
    settings: dict[str, Any]
    provenance: list[str] = field(default_factory=list)
    comparisons: list[Comparison] = field(default_factory=list)
    sections: list[tuple[str, str]] = field(default_factory=list)  # (title, markdown)
    figures: list[tuple[str, str]] = field(default_factory=list)  # (file, caption)
    differences: Sequence[str] = RENDEZVOUS_DIFFERENCES
    run: dict[str, Any] | None = None  # provenance (run_record); made by write() when None

    def record(self) -> dict[str, Any]:
        """The provenance of this report: :attr:`run`, or :func:`run_record` of now."""
        if self.run is None:
            self.run = run_record(self.settings, self.command, self.provenance)
        return self.run

    def render(self) -> str:
        root = repository_root()
        parts = [
            f"# {self.name}: {self.reproduces}",
            "",
            "Command:",
            "",
            f"    {portable_path(self.command, root)}",
            "",
            "## Provenance",
            "",
            render_run_record(self.record()),
            "",
            "## Resolved configuration",
            "",
            "```json",
            json.dumps(_portable(self.settings, root), indent=1, default=str),
            "```",
            "",
            "## How the data and models were made",
            "",
            "```sh",
            *(portable_path(line, root) for line in self.provenance),
            "```",
            "",
        ]
        if self.comparisons:
            rows = [
                (c.quantity, c.paper, c.ours, c.status or row_status(c.paper, c.ours), c.note)
                for c in self.comparisons
            ]
            parts += [
                "## The paper's numbers beside ours",
                "",
                markdown_table(("quantity", "paper", "ours", "status", "note"), rows),
                "",
            ]
        for title, text in self.sections:
            parts += [f"## {title}", "", text, ""]
        if self.figures:
            parts += ["## Figures", ""]
            parts += [f"![{caption}]({file})\n\n*{caption}*\n" for file, caption in self.figures]
        parts += ["## Where our formulation differs from the paper's code", ""]
        parts += [f"- {text}" for text in self.differences]
        return "\n".join(parts) + "\n"

    def results(self) -> dict[str, Any]:
        """The comparison rows as plain values (``results.json``).

        ``{"experiment", "reproduces", "command", "provenance", "run", "rows"}``, each row
        ``{"paper_item", "metric", "paper", "ours", "note", "command"}`` (and ``"status"``
        when the experiment set one); ``"run"`` is :meth:`record`.
        """
        root = repository_root()
        command = portable_path(self.command, root)
        rows = []
        for c in self.comparisons:
            row = {
                "paper_item": self.reproduces,
                "metric": c.quantity,
                "paper": c.paper,
                "ours": c.ours,
                "note": c.note,
                "command": command,
            }
            if c.status:
                row["status"] = c.status
            rows.append(row)
        return {
            "experiment": self.name,
            "reproduces": self.reproduces,
            "command": command,
            "provenance": [portable_path(line, root) for line in self.provenance],
            "run": self.record(),
            "rows": rows,
        }

    def write(self, out: Path) -> Path:
        """Write ``OUT/report.md`` and ``OUT/results.json`` atomically; returns the report."""
        out = Path(out)
        atomic_write_text(out / RESULTS_JSON_NAME, json.dumps(self.results(), indent=1) + "\n")
        atomic_write_text(out / REPORT_NAME, self.render())
        return out / REPORT_NAME


def new_figure(
    ncols: int = 2, width: float = 10.0, height: float = 4.0, nrows: int = 1
) -> tuple[Figure, Any]:
    """A matplotlib Figure (Agg canvas, no pyplot state) with ``nrows`` x ``ncols`` axes
    (a flat array of ``ncols`` axes when ``nrows`` is 1)."""
    figure = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.subplots(nrows, ncols)
    return figure, axes


def save_figure(figure: Figure, path: Path) -> str:
    """Save as PNG (small: 100 dpi) and return the file name for the report.

    Written through a temporary file, so that a failed write (full disk) leaves an earlier
    figure at ``path`` untouched.
    """
    with atomic_path(path, suffix=Path(path).suffix or ".png") as tmp:
        figure.savefig(tmp, dpi=100)
    return Path(path).name
