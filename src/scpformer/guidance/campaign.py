"""Seeded closed-loop runs into a folder: the engine of ``scpformer simulate FAMILY``.

The families (:data:`FAMILIES`): ``rendezvous`` (:mod:`.rendezvous_mpc`), ``pdg6dof``
(:mod:`.pdg6dof_mpc`) and ``robust-rendezvous`` (:mod:`.robust_rendezvous_mpc`); a
:class:`Campaign` flies the family of its ``config`` (the family's
``MPCConfig``) through the family's ``fly`` and ``open_loop_plan``.

``DIR/runs.csv`` holds one row per finished run (:data:`COLUMNS`, :data:`PDG_COLUMNS`),
rewritten atomically after each run; ``DIR/run-NNNN.npz`` the run's flown states, controls
and re-plans (the family's ``ClosedLoopResult.arrays``); ``DIR/settings.json`` the settings
the folder was started with. A rerun with the same settings skips the runs already in the
CSV; other settings are refused (the rows would not be comparable).

Run ``r`` of seed ``S`` flies with the error seed drawn from ``SeedSequence([S, r])``: two
warm starts run with the same ``S`` see the same errors run by run (common random numbers),
and the same instance: with ``instances="sampled"`` one of the family's sampler (seed
``[S, r]``); for ``pdg6dof`` with ``instances="default"`` the default instance with the
initial-state dispersion of the errors drawn from seed ``[S, r]``.
"""

from __future__ import annotations

import csv
import io
import json
import math
import multiprocessing as mp
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from itertools import islice
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.files import atomic_path, save_npz_atomic, write_text_atomic
from scpformer.guidance import pdg6dof_mpc as pdg
from scpformer.guidance import robust_rendezvous_mpc as robust
from scpformer.guidance.rendezvous_art import uses_art
from scpformer.guidance.rendezvous_mpc import MPCConfig, fly, open_loop_plan
from scpformer.pdg6dof import PDGInstance
from scpformer.rendezvous import RendezvousInstance, sample_instances
from scpformer.robust_rendezvous import RobustInstance
from scpformer.robust_rendezvous import sample_instances as sample_robust
from scpformer.validation import check_int

#: Columns of ``runs.csv``; units: metres, m/s (delta-v), seconds.
COLUMNS = (
    "run", "seed", "warmstart", "success", "terminal_position_error",
    "terminal_velocity_error", "fuel", "open_loop_fuel", "replans", "replans_failed",
    "replan_time_median_s", "replan_time_p99_s", "replan_period_s",
    "replan_iterations_median", "violations", "keep_out_violation", "cone_violation_m",
)  # fmt: skip
#: Columns of ``runs.csv`` of the landing; units: U_L, U_L/U_T, deg, U_M (propellant), U_T
#: (``replan_period_s``, the median time between re-plans in the nondimensional time of
#: Table 1, to compare with the re-plans' wall time in seconds), seconds (wall times).
PDG_COLUMNS = (
    "run", "seed", "warmstart", "success", "terminal_position_error",
    "terminal_velocity_error", "terminal_tilt_deg", "terminal_rate_deg", "fuel",
    "open_loop_fuel", "replans", "replans_failed", "replan_time_median_s",
    "replan_time_p99_s", "replan_period_s", "replan_iterations_median", "tscvx_fallbacks",
    "violations", "flight_time",
)  # fmt: skip
#: Columns of ``runs.csv`` of the robust rendezvous: :data:`COLUMNS` (``cone_violation_m`` is
#: 0, the problem has no cone), the flown nodes whose free drift entered the ellipsoid, the
#: flown nodes whose plan fails the passive-safety Monte Carlo test and the largest violation
#: probability of a node (``robust_rendezvous_mpc.RobustClosedLoopResult.path_violations``).
ROBUST_COLUMNS = (*COLUMNS, "drift_entries", "passive_safety_nodes", "passive_safety_p_max")
INSTANCES = ("default", "sampled")
#: Draws of a run's instance stream tried for one with a flyable open-loop plan.
MAX_DRAWS = 10
#: Cost difference below which two re-plans tie [m/s]: the SCP's cost tolerance J_tol of
#: Eq. 19 (Table 1, 1e-6 m/s).
TIE_M_S = 1e-6
#: The families a campaign flies, by the type of its config.
FAMILIES = ("rendezvous", "pdg6dof", "robust-rendezvous")


def _budget_setting(config: Any) -> dict[str, float]:
    """The time budget as a setting when one is set (folders flown without one resume)."""
    budget = config.time_budget_s
    return {} if budget is None else {"time_budget_s": budget}


def _model_setting(config: Any, family: str) -> dict[str, str]:
    """The learned model as settings, when the loop flies or compares one: what ``--model``
    says and the digest of its weights (:func:`~scpformer.pretrained.model_fingerprint`), so
    that a folder flown with one shipped model refuses to resume with its successor."""
    if not (pdg.uses_tscvx(config) if family == "pdg6dof" else uses_art(config)):
        return {}
    from scpformer.pretrained import model_fingerprint

    return {"model": config.model or "default",
            "model_sha256": model_fingerprint(config.model, family, guidance=True)}  # fmt: skip


def family_of(config: Any) -> str:
    """The family whose ``MPCConfig`` ``config`` is; ``ValueError`` for anything else."""
    if isinstance(config, MPCConfig):
        return "rendezvous"
    if isinstance(config, pdg.MPCConfig):
        return "pdg6dof"
    if isinstance(config, robust.MPCConfig):
        return "robust-rendezvous"
    raise ValueError(f"config must be an MPCConfig (rendezvous, pdg6dof or robust-rendezvous), got "
                     f"{type(config).__name__}")  # fmt: skip


def columns(family: str) -> tuple[str, ...]:
    """The columns of ``runs.csv`` of ``family``."""
    return {"pdg6dof": PDG_COLUMNS, "robust-rendezvous": ROBUST_COLUMNS}.get(family, COLUMNS)


def tie(family: str) -> float:
    """Cost difference below which two re-plans tie, in the family's cost unit."""
    return pdg.TIE_U_M if family == "pdg6dof" else TIE_M_S


@dataclass(frozen=True, kw_only=True)
class Campaign:
    """What ``scpformer simulate FAMILY`` runs (the family of ``config``).

    Attributes
    ----------
    runs
        Number of runs (>= 1).
    seed
        Seed of the error draws (and of the sampled instances), >= 0.
    instances
        ``"default"``: every run flies the default instance (rendezvous: Table 1, the ART
        paper's nominal case; pdg6dof: Table 1 of the T-SCvx paper with the run's initial-state
        dispersion); ``"sampled"``: run ``r`` flies an instance of the family's sampler.
    config
        The loop's configuration (warm start, re-planning period, errors): the
        ``MPCConfig`` of :mod:`.rendezvous_mpc` or of :mod:`.pdg6dof_mpc`.
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
        family_of(self.config)

    @property
    def family(self) -> str:
        return family_of(self.config)

    def settings(self) -> dict[str, Any]:
        """What must match for a folder to be resumed (the run count may grow)."""
        cfg = self.config
        if self.family == "pdg6dof":
            errors = cfg.errors
            return {
                "family": "pdg6dof", "seed": self.seed, "instances": self.instances,
                "warmstart": cfg.warmstart, "replan_every": cfg.replan_every,
                "min_remaining_time": cfg.min_remaining_time, "compare": list(cfg.compare),
                "tracking": asdict(cfg.tracking) if cfg.tracking is not None else None,
                "thrust_margin": cfg.thrust_margin, "gimbal_margin_deg": cfg.gimbal_margin_deg,
                **_model_setting(cfg, "pdg6dof"),
                **_budget_setting(cfg),
                **({"replan_iter_max": cfg.replan_iter_max}
                   if cfg.replan_iter_max is not None else {}),
                "errors": {
                    name: getattr(errors, name) for name in (
                        "thrust_magnitude", "pointing_deg", "mass_fraction",
                        "inertia_fraction", "aero_fraction")
                } | {"navigation": errors.navigation is not None,
                     "dispersion": errors.dispersion is not None},
            }  # fmt: skip
        robust_only = {"safety_samples": cfg.safety_samples} if self.family != "rendezvous" else {}
        if getattr(cfg, "mission_risk", None) is not None:  # absent from older folders
            robust_only["mission_risk"] = cfg.mission_risk
        if getattr(cfg, "covariance", "eq14") != "eq14":  # absent from older folders
            robust_only["covariance"] = cfg.covariance
        return {
            "family": self.family, "seed": self.seed, "instances": self.instances,
            "warmstart": cfg.warmstart, "replan_every": cfg.replan_every,
            "compare": list(cfg.compare),
            "errors": {
                name: getattr(cfg.errors, name) is not None
                for name in ("navigation", "actuation", "process_noise")
            },
        } | robust_only | _model_setting(cfg, self.family) | _budget_setting(cfg)  # fmt: skip

    def run_seed(self, run: int) -> int:
        return int(np.random.SeedSequence([self.seed, run]).generate_state(1)[0])

    def instance(self, run: int) -> Any:
        """The first instance of run ``run``'s stream (the one it flies unless its open-loop
        plan fails: :meth:`planned`)."""
        return next(self._draws(run))

    def _draws(self, run: int) -> Iterator[Any]:
        """The instances of run ``run``'s stream, in order (a fixed instance every time)."""
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, run]))
        while True:
            if self.family == "pdg6dof":
                if self.instances == "default":
                    yield pdg.dispersed_instance(PDGInstance(), self.config.errors.dispersion,
                                                 rng)  # fmt: skip
                else:
                    yield pdg.sampled_instance(rng)
            elif self.family == "robust-rendezvous":
                yield RobustInstance() if self.instances == "default" else sample_robust(rng, 1)[0]
            else:
                yield RendezvousInstance() if self.instances == "default" else sample_instances(
                    rng, 1)[0]  # fmt: skip

    def planned(self, run: int) -> tuple[Any, Any, int]:
        """The instance run ``run`` flies, its open-loop plan, and which draw of the run's
        stream it is (0: the first).

        A mission starts only from a flyable plan, so a drawn instance whose open-loop plan
        fails (e.g. a chance-constrained draw whose three-stage solve ends at the iteration
        cap, as about 0.2% of the dataset's draws do) is replaced by the next draw of the same
        stream, up to :data:`MAX_DRAWS` draws. Runs whose first draw is flyable fly exactly
        what they flew before this rule; a fixed instance (the rendezvous families'
        ``default``) is never replaced.

        Raises
        ------
        ValueError
            When no draw has a flyable plan (naming the run and the last failure).
        """
        fixed = self.instances == "default" and self.family != "pdg6dof"
        failures: list[str] = []
        for draw, instance in enumerate(islice(self._draws(run), 1 if fixed else MAX_DRAWS)):
            try:
                return instance, _open_loop(self, instance), draw
            except ValueError as err:
                failures.append(str(err))
        raise ValueError(f"run {run}: no flyable open-loop plan in {len(failures)} draw(s) of "
                         f"its instance; the last: {failures[-1]}")  # fmt: skip

    def open_loop_plan(self, instance: Any) -> Any:
        if self.family == "pdg6dof":
            return pdg.open_loop_plan(instance, self.config)
        if self.family == "robust-rendezvous":
            return robust.open_loop_plan(instance, self.config)
        return open_loop_plan(instance, self.config)

    def fly(self, instance: Any, seed: int, plan: Any) -> Any:
        if self.family == "pdg6dof":
            return pdg.fly(instance, self.config, seed=seed, open_loop=plan)
        if self.family == "robust-rendezvous":
            return robust.fly(instance, self.config, seed=seed, open_loop=plan)
        return fly(instance, self.config, seed=seed, open_loop=plan)


def read_rows(path: Path) -> list[dict[str, str]]:
    """The rows of an existing ``runs.csv`` (empty when there is none)."""
    if not path.exists():
        return []
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def _csv_text(rows: Iterable[dict[str, Any]], fieldnames: tuple[str, ...] = COLUMNS) -> str:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=fieldnames, extrasaction="ignore",
                            lineterminator="\n")  # fmt: skip
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
    workers: int = 1,
    ray: str | None = None,
) -> list[dict[str, str]]:
    """Fly the runs not yet in ``folder/runs.csv``; return every row (old and new).

    ``on_start(done, total)`` is called once before the first new run, ``on_run(row)`` after
    each (a progress bar). Open-loop plans are solved once per instance and process; a
    sampled instance without one is replaced by the next draw (:meth:`Campaign.planned`).
    ``workers > 1`` flies runs in that many local processes (``forkserver``, as the dataset
    engine's pool); a run's numbers do not depend on it (each run has its own seed), but the
    re-plan wall times then share the cores: time with one worker. ``ray`` (an address, or
    ``"local"`` to start a private instance of ``workers`` CPUs) flies them as Ray tasks of
    one CPU each instead; their arrays come back to this process, which writes every file.

    Raises
    ------
    ValueError
        When the folder holds runs of other settings, or no draw of a run's instance has a
        flyable open-loop plan (:meth:`Campaign.planned`).
    """
    check_int("workers", workers, least=1)
    folder = Path(folder)
    csv_path = folder / "runs.csv"
    rows = read_rows(csv_path)
    _check_settings(folder, campaign.settings(), bool(rows))
    done = {int(r["run"]) for r in rows}
    todo = [r for r in range(campaign.runs) if r not in done]
    if on_start is not None:
        on_start(campaign.runs - len(todo), campaign.runs)
    flown = _flown_ray(campaign, folder, todo, ray, workers) if ray else _flown(
        campaign, folder, todo, workers)  # fmt: skip
    for row in flown:
        rows.append({k: str(_cell(v)) for k, v in row.items()})
        rows.sort(key=lambda r: int(r["run"]))
        write_text_atomic(csv_path, _csv_text(rows, columns(campaign.family)))
        if on_run is not None:
            on_run(row)
    return [r for r in rows if int(r["run"]) < campaign.runs]


_PLANS: dict[Any, Any] = {}  # this process's open-loop plan of the last instance flown


def _open_loop(campaign: Campaign, instance: Any) -> Any:
    """``campaign.open_loop_plan(instance)``, solved once per instance, configuration and
    process (the plan depends on the loop's configuration too: its solver, the landing's
    planning margins, the rendezvous' mission risk)."""
    key = (instance, campaign.config)
    if key not in _PLANS:
        plan = campaign.open_loop_plan(instance)  # raises before the cache is touched
        _PLANS.clear()
        _PLANS[key] = plan
    return _PLANS[key]


def flight(campaign: Campaign, run: int) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Fly run ``run`` of ``campaign`` (in any process): its ``runs.csv`` row and the arrays
    of its ``run-NNNN.npz`` (with ``instance_draw``, see :meth:`Campaign.planned`)."""
    instance, plan, draw = campaign.planned(run)
    seed = campaign.run_seed(run)
    result = campaign.fly(instance, seed, plan)
    return {"run": run, "seed": seed, **result.summary()}, result.arrays() | {
        "instance_draw": np.array(draw)
    }


def fly_run(campaign: Campaign, folder: Path, run: int) -> dict[str, Any]:
    """Fly run ``run`` of ``campaign``, write its ``run-NNNN.npz`` into ``folder`` and return
    its ``runs.csv`` row (in any process)."""
    row, arrays = flight(campaign, run)
    save_npz_atomic(folder / f"run-{run:04d}.npz", arrays)
    return row


def _flown_ray(
    campaign: Campaign, folder: Path, runs: list[int], address: str, workers: int
) -> Iterator[dict[str, Any]]:
    """The rows of ``runs`` as their Ray tasks finish; this process writes the npz files."""
    import ray

    from scpformer.data.executors import connect_ray

    owns = connect_ray(address, workers)
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(flight)
        pending = {remote.remote(campaign, run): run for run in runs}
        while pending:
            (ref,), _ = ray.wait(list(pending), num_returns=1)
            run = pending.pop(ref)
            row, arrays = ray.get(ref)
            save_npz_atomic(folder / f"run-{run:04d}.npz", arrays)
            yield row
    finally:
        if owns:
            ray.shutdown()


def one_torch_thread() -> None:
    """Limit a pool's worker process to one torch thread (:func:`single_thread_inference`):
    the pool's processes share the cores, and without it each would start one thread per
    core. Nothing to do without torch (the classical starts need none)."""
    try:  # imported here: scpformer.models imports torch
        from scpformer.models.capabilities import single_thread_inference

        single_thread_inference()
    except ImportError:
        return


def _flown(
    campaign: Campaign, folder: Path, runs: list[int], workers: int
) -> Iterator[dict[str, Any]]:
    """The rows of ``runs`` as they finish: in order in this process, or from a pool."""
    if workers == 1 or len(runs) < 2:
        for run in runs:
            yield fly_run(campaign, folder, run)
        return
    context = mp.get_context("forkserver")
    with ProcessPoolExecutor(min(workers, len(runs)), mp_context=context,
                             initializer=one_torch_thread) as pool:  # fmt: skip
        futures = [pool.submit(fly_run, campaign, folder, run) for run in runs]
        for future in as_completed(futures):
            yield future.result()


# ======================================================================================
# summary and figure
# ======================================================================================
def _truthy(text: str) -> bool:
    return text.strip().lower() in ("true", "1")


def _replan_tables(rows: list[dict[str, str]], folder: Path) -> dict[str, np.ndarray]:
    """The re-plan and comparison tables of every flown run, concatenated."""
    keys = ("replan_wall_s", "replan_iterations", "replan_cost", "replan_node",
            "compare_wall_s", "compare_iterations", "compare_cost", "compare_node",
            "compare_warmstart", "replan_accepted", "compare_accepted")  # fmt: skip
    parts: dict[str, list[np.ndarray]] = {k: [] for k in keys}
    for _, data in _flown_runs(rows, folder):
        for k in keys:
            if k in data:
                parts[k].append(data[k])
    return {k: np.concatenate(v) if v else np.zeros(0) for k, v in parts.items()}


def summarize(
    rows: list[dict[str, str]], folder: str | Path, family: str = "rendezvous"
) -> dict[str, Any]:
    """Success rate, median fuel (delta-v; propellant for ``pdg6dof``) vs open loop, re-plan
    iterations and wall times (median, p99 over every re-plan of every run) and, with
    comparison solves, the per-re-plan win/tie/loss of the flown warm start against each
    compared one (cost, tie within :func:`tie`) with their iterations and times. For
    ``pdg6dof`` a re-plan that was not accepted (not converged, or not verified) counts as
    failed in the comparison, whatever its cost."""
    folder = Path(folder)
    if not rows:
        return {"runs": 0}
    tie_cost = tie(family)
    fuel = np.array([float(r["fuel"]) for r in rows])
    open_fuel = np.array([float(r["open_loop_fuel"]) for r in rows])
    tables = _replan_tables(rows, folder)
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
        "family": family,
    }
    if family == "pdg6dof":
        for key in ("terminal_tilt_deg", "terminal_rate_deg"):
            out[f"{key}_median"] = float(np.median([float(r[key]) for r in rows]))
        out["tscvx_fallbacks"] = int(sum(int(r["tscvx_fallbacks"]) for r in rows))
        out["failed_runs"] = [int(r["run"]) for r in rows if not _truthy(r["success"])]
    names = tables["compare_warmstart"]
    for name in sorted(set(names.tolist())):
        sel = names == name
        cost = tables["compare_cost"][sel]
        # the comparison solves follow the flown re-plans one to one, in order
        flown = tables["replan_cost"]
        if flown.size != cost.size:
            continue
        if family == "pdg6dof" and tables["replan_accepted"].size == flown.size:
            flown = np.where(tables["replan_accepted"], flown, np.nan)
            cost = np.where(tables["compare_accepted"][sel], cost, np.nan)
        ok = np.isfinite(flown) & np.isfinite(cost)
        diff = flown[ok] - cost[ok]
        out[f"vs_{name}"] = {
            "win": int((diff < -tie_cost).sum()),
            "tie": int((np.abs(diff) <= tie_cost).sum()),
            "loss": int((diff > tie_cost).sum()),
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
    if s.get("family") == "pdg6dof":
        return _pdg_summary_text(s)
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
    return "\n".join(lines + _comparison_lines(s))


def _comparison_lines(s: dict[str, Any]) -> list[str]:
    """One line per comparison warm start (``vs_*``): per re-plan win / tie / loss of the
    cost, the failures of each side where counted, and the other side's iterations and wall
    time."""
    lines = []
    for key, value in s.items():
        if not key.startswith("vs_"):
            continue
        other = key[3:]
        failed = (
            f" ({value['failed_flown']} failed {s['warmstart']}, {value['failed_other']} "
            f"failed {other})"
            if "failed_flown" in value
            else ""
        )
        lines.append(
            f"{s['warmstart']} vs {other} per re-plan (cost): {value['win']} win, "
            f"{value['tie']} tie, {value['loss']} loss{failed}; {other}: iterations median "
            f"{value['iterations_median']:g}, p99 {value['iterations_p99']:g}, wall time "
            f"median {value['time_median_s']:.3f} s, p99 {value['time_p99_s']:.3f} s"
        )
    return lines


def _pdg_summary_text(s: dict[str, Any]) -> str:
    lines = [
        f"{s['runs']} runs, warm start {s['warmstart']}: success {100 * s['success_rate']:.0f}%"
        + (f" (failed runs: {', '.join(map(str, s['failed_runs']))})" if s["failed_runs"]
           else ""),
        f"propellant median {s['fuel_median']:.4f} U_M vs open loop "
        f"{s['open_loop_fuel_median']:.4f} U_M (ratio median {s['fuel_ratio_median']:.4f})",
        f"touchdown error median {s['terminal_position_error_median']:.4f} U_L, "
        f"{s['terminal_velocity_error_median']:.4f} U_L/U_T, tilt "
        f"{s['terminal_tilt_deg_median']:.2f} deg, rate {s['terminal_rate_deg_median']:.2f} "
        "deg/U_T",
        f"{s['replans']} re-plans ({s['replans_failed']} failed, {s['tscvx_fallbacks']} T-SCvx "
        "fallbacks to its full subproblem or cold SCvx): iterations median "
        f"{s['replan_iterations_median']:g}, p99 {s['replan_iterations_p99']:g}; wall time "
        f"median {s['replan_time_median_s']:.3f} s, "
        f"p99 {s['replan_time_p99_s']:.3f} s (re-planning period {s['replan_period_s']:.3f} "
        "U_T, median over runs)",
        f"constraint violations along the flown trajectories: {s['violations']} samples",
    ]  # fmt: skip
    return "\n".join(lines + _comparison_lines(s))


def plot_campaign(
    rows: list[dict[str, str]], folder: str | Path, path: str | Path, family: str = "rendezvous"
) -> Path:
    """Closed-loop trajectories (rendezvous: T-R and T-N planes; pdg6dof: altitude against
    horizontal distance and tilt against time) vs the open-loop plan, and the histogram of
    re-plan wall times against the re-planning period; written atomically to ``path``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    folder = Path(folder)
    fig = Figure(figsize=(15.0, 4.8))
    FigureCanvasAgg(fig)
    ax_tr, ax_tn, ax_h = (fig.add_subplot(1, 3, i) for i in (1, 2, 3))
    if family == "pdg6dof":
        _plot_pdg(rows, folder, ax_tr, ax_tn)
        _plot_wall_times(rows, folder, ax_h, "U_T")
        return _save(fig, path)
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
    _plot_wall_times(rows, folder, ax_h, "s")
    return _save(fig, path)


#: Legend of the dashed plan: runs of sampled instances each have their own.
FIRST_PLAN = "open-loop plan (first run)"


def _flown_runs(
    rows: list[dict[str, str]], folder: Path
) -> Iterator[tuple[dict[str, str], dict[str, np.ndarray]]]:
    """``(row, arrays of its run-NNNN.npz)`` for every row whose file is in ``folder``."""
    for row in rows:
        path = folder / f"run-{int(row['run']):04d}.npz"
        if path.exists():
            with np.load(path) as data:
                yield row, {key: np.asarray(data[key]) for key in data.files}


def _time_budget(folder: Path) -> float | None:
    """The re-plan time budget the campaign in ``folder`` flew with (its settings), if any."""
    path = folder / "settings.json"
    if not path.exists():
        return None
    budget = json.loads(path.read_text()).get("time_budget_s")
    return None if budget is None else float(budget)


def _plot_wall_times(rows: list[dict[str, str]], folder: Path, ax_h: Any, unit: str) -> None:
    """The histogram of the re-plan wall times against the median re-planning period (in
    seconds: a period in ``U_T`` is converted with the landing's ``TIME_UNIT_S``) and the
    time budget, if the campaign had one."""
    tables = _replan_tables(rows, folder)
    wall = tables["replan_wall_s"]
    if wall.size:
        period = float(np.median([float(r["replan_period_s"]) for r in rows]))
        label = f"{period:.0f} s"
        if unit == "U_T":
            label = f"{period:.3f} U_T = {period * pdg.TIME_UNIT_S:.2f} s"
            period *= pdg.TIME_UNIT_S
        # geomspace keeps the end points exact: logspace's round-off can drop the fastest
        bins = np.geomspace(max(wall.min(), 1e-3), max(period, wall.max()), 40)
        ax_h.hist(wall, bins=bins, color="C0")
        ax_h.axvline(period, color="C3", label=f"re-planning period {label}")
        budget = _time_budget(folder)
        if budget is not None:
            ax_h.axvline(budget, color="C1", ls="--", label=f"time budget {budget:.3g} s")
        ax_h.set_xscale("log")
        ax_h.legend(loc="best", fontsize=8)
    ax_h.set_xlabel("re-plan wall time [s]")
    ax_h.set_ylabel("re-plans")


def _plot_pdg(rows: list[dict[str, str]], folder: Path, ax_alt: Any, ax_tilt: Any) -> None:
    planned = False
    for row, data in _flown_runs(rows, folder):
        x, t = data["x"], data["t"]
        if not planned:  # the first run's open-loop plan
            plan, t_plan = data["open_loop_x"], data["open_loop_t"]
            ax_alt.plot(np.linalg.norm(plan[:, 1:3], axis=1), plan[:, 0], "k--", lw=1.5,
                        label=FIRST_PLAN)  # fmt: skip
            ax_tilt.plot(t_plan, _tilt_deg(plan), "k--", lw=1.5)
            planned = True
        color = "C0" if _truthy(row["success"]) else "C3"
        ax_alt.plot(np.linalg.norm(x[:, 1:3], axis=1), x[:, 0], lw=0.7, alpha=0.6, color=color)
        ax_tilt.plot(t, _tilt_deg(x), lw=0.7, alpha=0.6, color=color)
    ax_alt.set_xlabel("horizontal distance [U_L]")
    ax_alt.set_ylabel("altitude [U_L]")
    ax_alt.set_title("flown (blue: success, red: failure)")
    ax_alt.legend(loc="best", fontsize=8)
    ax_tilt.set_xlabel("t [U_T]")
    ax_tilt.set_ylabel("tilt [deg]")
    for ax in (ax_alt, ax_tilt):
        ax.grid(alpha=0.3)


def _tilt_deg(x: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(1.0 - 2.0 * (x[:, 8] ** 2 + x[:, 9] ** 2), -1.0, 1.0)))


def _save(fig: Any, path: str | Path) -> Path:
    fig.tight_layout()
    path = Path(path)
    with atomic_path(path, suffix=path.suffix or ".png") as tmp:
        fig.savefig(tmp, format=(path.suffix or ".png").lstrip("."), dpi=110)
    return path
