"""Seeded closed-loop runs into a folder: the engine of ``scpformer simulate rendezvous``.

``DIR/runs.csv`` holds one row per finished run (:data:`COLUMNS`), rewritten atomically after
each run; ``DIR/run-NNNN.npz`` the run's flown states, impulses and re-plans
(:meth:`~scpformer.guidance.rendezvous_mpc.ClosedLoopResult.arrays`); ``DIR/settings.json``
the settings the folder was started with. A rerun with the same settings skips the runs
already in the CSV; other settings are refused (the rows would not be comparable).

Run ``r`` of seed ``S`` flies with the error seed drawn from ``SeedSequence([S, r])``: two
warm starts run with the same ``S`` see the same errors run by run (common random numbers),
and, with ``instances="sampled"``, the same instance (Table 1 sampler, seed ``[S, r]``).
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.files import atomic_path, save_npz_atomic, write_text_atomic
from scpformer.guidance.rendezvous_mpc import MPCConfig, fly, open_loop_plan
from scpformer.rendezvous import RendezvousInstance, sample_instances
from scpformer.validation import check_int

#: Columns of ``runs.csv``; units: metres, m/s (delta-v), seconds.
COLUMNS = (
    "run", "seed", "warmstart", "success", "terminal_position_error",
    "terminal_velocity_error", "fuel", "open_loop_fuel", "replans", "replans_failed",
    "replan_time_median_s", "replan_time_p99_s", "replan_period_s",
    "replan_iterations_median", "violations", "keep_out_violation", "cone_violation_m",
)  # fmt: skip
INSTANCES = ("default", "sampled")
#: Cost difference below which two re-plans tie [m/s]: the SCP's cost tolerance J_tol of
#: Eq. 19 (Table 1, 1e-6 m/s).
TIE_M_S = 1e-6


@dataclass(frozen=True, kw_only=True)
class Campaign:
    """What ``scpformer simulate rendezvous`` runs.

    Attributes
    ----------
    runs
        Number of runs (>= 1).
    seed
        Seed of the error draws (and of the sampled instances), >= 0.
    instances
        ``"default"``: every run flies the default instance (Table 1, the ART paper's
        nominal case); ``"sampled"``: run ``r`` flies an instance of the Table 1 sampler.
    config
        The loop's configuration (warm start, re-planning period, errors).
    """

    runs: int
    seed: int = 0
    instances: str = "default"
    config: MPCConfig

    def __post_init__(self) -> None:
        check_int("runs", self.runs, least=1)
        check_int("seed", self.seed, least=0)
        if self.instances not in INSTANCES:
            raise ValueError(f"instances must be one of {', '.join(INSTANCES)}, "
                             f"got {self.instances!r}")  # fmt: skip
        if not isinstance(self.config, MPCConfig):
            raise ValueError(f"config must be an MPCConfig, got {type(self.config).__name__}")

    def settings(self) -> dict[str, Any]:
        """What must match for a folder to be resumed (the run count may grow)."""
        cfg = self.config
        return {
            "family": "rendezvous", "seed": self.seed, "instances": self.instances,
            "warmstart": cfg.warmstart, "replan_every": cfg.replan_every,
            "compare": list(cfg.compare),
            "errors": {
                name: getattr(cfg.errors, name) is not None
                for name in ("navigation", "actuation", "process_noise")
            },
        }  # fmt: skip

    def run_seed(self, run: int) -> int:
        return int(np.random.SeedSequence([self.seed, run]).generate_state(1)[0])

    def instance(self, run: int) -> RendezvousInstance:
        if self.instances == "default":
            return RendezvousInstance()
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, run]))
        return sample_instances(rng, 1)[0]


def read_rows(path: Path) -> list[dict[str, str]]:
    """The rows of an existing ``runs.csv`` (empty when there is none)."""
    if not path.exists():
        return []
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def _csv_text(rows: Iterable[dict[str, Any]]) -> str:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=COLUMNS, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: _cell(v) for k, v in row.items()})
    return buf.getvalue()


def _cell(value: Any) -> Any:
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else str(value)
    return value


def _check_settings(folder: Path, settings: dict[str, Any], have_rows: bool) -> None:
    path = folder / "settings.json"
    if path.exists():
        old = json.loads(path.read_text())
        if old != settings:
            diff = sorted(k for k in set(old) | set(settings) if old.get(k) != settings.get(k))
            raise ValueError(
                f"{folder} holds runs of other settings ({', '.join(diff)} differ): use "
                "another --out folder"
            )
    elif have_rows:
        raise ValueError(f"{folder}/runs.csv exists without settings.json: use another --out")
    else:
        write_text_atomic(path, json.dumps(settings, indent=1, sort_keys=True) + "\n")


def run_campaign(
    campaign: Campaign,
    folder: str | Path,
    *,
    on_run: Callable[[dict[str, Any]], None] | None = None,
    on_start: Callable[[int, int], None] | None = None,
) -> list[dict[str, str]]:
    """Fly the runs not yet in ``folder/runs.csv``; return every row (old and new).

    ``on_start(done, total)`` is called once before the first new run, ``on_run(row)`` after
    each (a progress bar). Open-loop plans are solved once per instance.

    Raises
    ------
    ValueError
        When the folder holds runs of other settings, or an instance's open-loop plan fails.
    """
    folder = Path(folder)
    csv_path = folder / "runs.csv"
    rows = read_rows(csv_path)
    _check_settings(folder, campaign.settings(), bool(rows))
    done = {int(r["run"]) for r in rows}
    todo = [r for r in range(campaign.runs) if r not in done]
    if on_start is not None:
        on_start(campaign.runs - len(todo), campaign.runs)
    plans: dict[RendezvousInstance, Any] = {}
    for run in todo:
        instance = campaign.instance(run)
        if instance not in plans:
            plans = {instance: open_loop_plan(instance, campaign.config)}
        seed = campaign.run_seed(run)
        result = fly(instance, campaign.config, seed=seed, open_loop=plans[instance])
        save_npz_atomic(folder / f"run-{run:04d}.npz", result.arrays())
        row = {"run": run, "seed": seed, **result.summary()}
        rows.append({k: str(_cell(v)) for k, v in row.items()})
        rows.sort(key=lambda r: int(r["run"]))
        write_text_atomic(csv_path, _csv_text(rows))
        if on_run is not None:
            on_run(row)
    return [r for r in rows if int(r["run"]) < campaign.runs]


# ======================================================================================
# summary and figure
# ======================================================================================
def _truthy(text: str) -> bool:
    return text.strip().lower() in ("true", "1")


def _replan_tables(folder: Path, runs: Iterable[int]) -> dict[str, np.ndarray]:
    keys = ("replan_wall_s", "replan_iterations", "replan_cost", "replan_node",
            "compare_wall_s", "compare_iterations", "compare_cost", "compare_node",
            "compare_warmstart")  # fmt: skip
    parts: dict[str, list[np.ndarray]] = {k: [] for k in keys}
    for run in runs:
        path = folder / f"run-{run:04d}.npz"
        if not path.exists():
            continue
        with np.load(path) as data:
            for k in keys:
                parts[k].append(np.asarray(data[k]))
    return {k: np.concatenate(v) if v else np.zeros(0) for k, v in parts.items()}


def summarize(rows: list[dict[str, str]], folder: str | Path) -> dict[str, Any]:
    """Success rate, median delta-v vs open loop, re-plan iterations and wall times (median,
    p99 over every re-plan of every run) and, with comparison solves, the per-re-plan
    win/tie/loss of the flown warm start against each compared one (cost, tie within
    :data:`TIE_M_S`) with their iterations and times."""
    folder = Path(folder)
    if not rows:
        return {"runs": 0}
    fuel = np.array([float(r["fuel"]) for r in rows])
    open_fuel = np.array([float(r["open_loop_fuel"]) for r in rows])
    tables = _replan_tables(folder, (int(r["run"]) for r in rows))
    wall, iters = tables["replan_wall_s"], tables["replan_iterations"]
    out: dict[str, Any] = {
        "runs": len(rows),
        "warmstart": rows[0]["warmstart"],
        "success_rate": float(np.mean([_truthy(r["success"]) for r in rows])),
        "fuel_median": float(np.median(fuel)),
        "open_loop_fuel_median": float(np.median(open_fuel)),
        "fuel_ratio_median": float(np.median(fuel / open_fuel)),
        "terminal_position_error_median": float(
            np.median([float(r["terminal_position_error"]) for r in rows])
        ),
        "terminal_velocity_error_median": float(
            np.median([float(r["terminal_velocity_error"]) for r in rows])
        ),
        "replans": int(wall.size),
        "replans_failed": int(sum(int(r["replans_failed"]) for r in rows)),
        "replan_iterations_median": float(np.median(iters)) if iters.size else math.nan,
        "replan_iterations_p99": float(np.percentile(iters, 99)) if iters.size else math.nan,
        "replan_time_median_s": float(np.median(wall)) if wall.size else math.nan,
        "replan_time_p99_s": float(np.percentile(wall, 99)) if wall.size else math.nan,
        "replan_period_s": float(np.median([float(r["replan_period_s"]) for r in rows])),
        "violations": int(sum(int(r["violations"]) for r in rows)),
    }
    names = tables["compare_warmstart"]
    for name in sorted(set(names.tolist())):
        sel = names == name
        cost = tables["compare_cost"][sel]
        # the comparison solves follow the flown re-plans one to one, in order
        flown = tables["replan_cost"]
        if flown.size != cost.size:
            continue
        ok = np.isfinite(flown) & np.isfinite(cost)
        diff = flown[ok] - cost[ok]
        out[f"vs_{name}"] = {
            "win": int((diff < -TIE_M_S).sum()),
            "tie": int((np.abs(diff) <= TIE_M_S).sum()),
            "loss": int((diff > TIE_M_S).sum()),
            "failed_flown": int((~np.isfinite(flown)).sum()),
            "failed_other": int((~np.isfinite(cost)).sum()),
            "iterations_median": float(np.median(tables["compare_iterations"][sel])),
            "iterations_p99": float(np.percentile(tables["compare_iterations"][sel], 99)),
            "time_median_s": float(np.median(tables["compare_wall_s"][sel])),
            "time_p99_s": float(np.percentile(tables["compare_wall_s"][sel], 99)),
        }
    return out


def summary_text(summary: dict[str, Any]) -> str:
    """The summary printed at the end of ``scpformer simulate``."""
    if not summary.get("runs"):
        return "no runs"
    s = summary
    lines = [
        f"{s['runs']} runs, warm start {s['warmstart']}: success {100 * s['success_rate']:.0f}%",
        f"delta-v median {1e3 * s['fuel_median']:.2f} mm/s vs open loop "
        f"{1e3 * s['open_loop_fuel_median']:.2f} mm/s (ratio median {s['fuel_ratio_median']:.3f})",
        f"terminal error median {s['terminal_position_error_median']:.3f} m, "
        f"{1e3 * s['terminal_velocity_error_median']:.3f} mm/s",
        f"{s['replans']} re-plans ({s['replans_failed']} failed): iterations median "
        f"{s['replan_iterations_median']:g}, p99 {s['replan_iterations_p99']:g}; wall time median "
        f"{s['replan_time_median_s']:.3f} s, p99 {s['replan_time_p99_s']:.3f} s "
        f"(re-planning period {s['replan_period_s']:.0f} s, median over runs)",
        f"constraint violations along the flown trajectories: {s['violations']} samples",
    ]
    for key, value in s.items():
        if key.startswith("vs_"):
            lines.append(
                f"{s['warmstart']} vs {key[3:]} per re-plan (cost): {value['win']} win, "
                f"{value['tie']} tie, {value['loss']} loss; {key[3:]}: iterations median "
                f"{value['iterations_median']:g}, p99 {value['iterations_p99']:g}, wall time "
                f"median {value['time_median_s']:.3f} s, p99 {value['time_p99_s']:.3f} s"
            )
    return "\n".join(lines)


def plot_campaign(rows: list[dict[str, str]], folder: str | Path, path: str | Path) -> Path:
    """Closed-loop trajectories (T-R and T-N planes) vs the open-loop plan, and the histogram
    of re-plan wall times against the re-planning period; written atomically to ``path``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    folder = Path(folder)
    fig = Figure(figsize=(15.0, 4.8))
    FigureCanvasAgg(fig)
    ax_tr, ax_tn, ax_h = (fig.add_subplot(1, 3, i) for i in (1, 2, 3))
    planned = False
    for row in rows:
        path_run = folder / f"run-{int(row['run']):04d}.npz"
        if not path_run.exists():
            continue
        with np.load(path_run) as data:
            rtn = np.asarray(data["rtn"])
            if not planned:  # the first run's plan (every run's, for the default instance)
                plan = np.asarray(data["open_loop_rtn"])
                for ax, c in ((ax_tr, 0), (ax_tn, 2)):
                    ax.plot(plan[:, 1], plan[:, c], "k--", lw=1.5, label="open-loop plan")
                planned = True
        ok = _truthy(row["success"])
        for ax, c in ((ax_tr, 0), (ax_tn, 2)):
            ax.plot(rtn[:, 1], rtn[:, c], lw=0.7, alpha=0.6, color="C0" if ok else "C3")
    for ax, label in ((ax_tr, "R [m]"), (ax_tn, "N [m]")):
        ax.set_xlabel("T [m]")
        ax.set_ylabel(label)
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
    ax_tr.legend(loc="best", fontsize=8)
    ax_tr.set_title("flown (blue: success, red: failure)")
    tables = _replan_tables(folder, (int(r["run"]) for r in rows))
    wall = tables["replan_wall_s"]
    if wall.size:
        period = float(np.median([float(r["replan_period_s"]) for r in rows]))
        bins = np.logspace(np.log10(max(wall.min(), 1e-3)), np.log10(max(period, wall.max())), 40)
        ax_h.hist(wall, bins=bins, color="C0")
        ax_h.axvline(period, color="C3", label=f"re-planning period {period:.0f} s")
        ax_h.set_xscale("log")
        ax_h.legend(loc="best", fontsize=8)
    ax_h.set_xlabel("re-plan wall time [s]")
    ax_h.set_ylabel("re-plans")
    fig.tight_layout()
    path = Path(path)
    with atomic_path(path, suffix=path.suffix or ".png") as tmp:
        fig.savefig(tmp, format=(path.suffix or ".png").lstrip("."), dpi=110)
    return path
