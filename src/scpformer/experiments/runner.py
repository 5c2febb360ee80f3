"""What every experiment shares: options, test instances, resumable CSV, executors, provenance.

An experiment run writes into its folder ``OUT``:

* ``results.csv``: one row per test instance, appended as soon as the instance is done, so an
  interrupted run loses at most the instances in flight; a rerun with the same settings skips
  the instances already in the file (``OUT/config.json`` records the settings and a rerun with
  different ones is refused);
* ``*.png`` figures and ``report.md`` (see :mod:`scpformer.experiments.report`).

The per-instance work runs on the dataset engine's executors
(:mod:`scpformer.data.executors`): local worker processes by default, Ray actors with
``--ray ADDRESS``. An experiment hands them a :class:`TaskFamily`, whose "instance" ``i`` is
the ``i``-th task of the run (recovered from the stream the engine gives instance ``i``, whose
``spawn_key`` is ``(i,)``), so the engine's warm-up, time limit and crash handling apply
unchanged.
"""

from __future__ import annotations

import csv
import json
import math
import os
import sys
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, ClassVar, Protocol

import numpy as np

from scpformer.data.errors import DatasetError
from scpformer.data.executors import Executor, LocalPool, RayPool
from scpformer.data.family import SampleResult
from scpformer.data.splits import load_splits
from scpformer.data.storage import ShardedSamples, file_sha256, read_manifest
from scpformer.files import check_output_folder, require_model_path, write_text_atomic
from scpformer.validation import check_int, shown

RESULTS_NAME = "results.csv"
CONFIG_NAME = "config.json"
KEY = "index"  # the dataset sample position of a row
DEFAULT_TIME_LIMIT = 600.0  # s per task before its worker is restarted


@dataclass(frozen=True, kw_only=True)
class RunOptions:
    """What ``scpformer experiment run`` was asked (the experiment resolves the defaults)."""

    out: Path  # the experiment's folder
    models: tuple[Path, ...] = ()  # training run folders or checkpoint files
    data: Path | None = None  # dataset folder (split)
    n: int | None = None  # test instances (None: the experiment's default)
    workers: int | None = None  # local worker processes (None: every CPU)
    ray: str | None = None  # Ray address ("local" starts one) or None for local processes
    seed: int = 0  # seed of the instance selection (and of the executors' streams)
    time_limit: float = DEFAULT_TIME_LIMIT  # s per task

    def __post_init__(self) -> None:
        object.__setattr__(self, "out", Path(self.out))
        object.__setattr__(self, "models", tuple(Path(m) for m in self.models))
        if self.data is not None:
            object.__setattr__(self, "data", Path(self.data))
        for name in ("n", "workers"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, check_int(name, getattr(self, name), least=1))
        if not (math.isfinite(self.time_limit) and self.time_limit > 0):
            raise ValueError(f"time_limit must be positive, got {shown(self.time_limit)}")


# ======================================================================================
# inputs: dataset, test split, models
# ======================================================================================
def require_data(options: RunOptions) -> Path:
    """The dataset folder of ``options`` (``ValueError`` naming ``--data`` when unusable)."""
    if options.data is None:
        raise ValueError("--data DIR is required (a dataset folder made by `scpformer generate`)")
    folder = options.data
    if not (folder / "manifest.json").is_file():
        raise ValueError(f"--data {folder}: not a dataset folder (no manifest.json)")
    return folder


def require_models(options: RunOptions, count: int | None = None) -> tuple[Path, ...]:
    """The ``--model`` paths, each an existing run folder or checkpoint file."""
    if not options.models:
        raise ValueError("--model RUN is required (a folder made by `scpformer train`)")
    if count is not None and len(options.models) != count:
        raise ValueError(f"--model: expected {count} run(s), got {len(options.models)}")
    return tuple(require_model_path(path) for path in options.models)


def require_n(options: RunOptions) -> int:
    """``options.n`` (:func:`scpformer.experiments.run_experiment` fills in the default)."""
    if options.n is None:
        raise ValueError("n is required (run through scpformer.experiments.run_experiment)")
    return int(options.n)


def select_test_instances(folder: Path, n: int, seed: int) -> np.ndarray:
    """``n`` sample positions of the test split, drawn without replacement with ``seed``.

    A seeded permutation of the whole test split, cut after ``n``: a larger ``n`` extends the
    selection of a smaller one, so a rerun with a larger ``--n`` keeps the rows already done.
    """
    try:
        test = load_splits(folder).indices["test"]
    except DatasetError as err:
        raise ValueError(f"--data {folder}: {err}") from None
    if test.size == 0:
        raise ValueError(f"--data {folder}: the test split is empty")
    order = np.random.default_rng(seed).permutation(test)
    if n > order.size:  # said, not silent: the results hold fewer rows than asked for
        print(
            f"scpformer: warning: --n {n}: the test split of {folder} holds {order.size} "
            f"samples; all {order.size} are used",
            file=sys.stderr,
        )
    return order[: min(n, order.size)]


def read_fields(folder: Path, positions: Sequence[int], names: Iterable[str]) -> list[dict]:
    """The values of fields ``names`` of the samples at ``positions``, one dict per sample."""
    samples = ShardedSamples(folder)
    try:
        known = {f.name for f in samples.manifest.schema}
        names = list(names)
        missing = [name for name in names if name not in known]
        if missing:
            raise ValueError(f"--data {folder}: the dataset has no field(s) {missing}")
        return [{name: samples.read(name, int(p)) for name in names} for p in positions]
    finally:
        samples.close()


@dataclass(frozen=True)
class Study:
    """The checked inputs of a run: dataset, its manifest, the models and their checkpoints."""

    data: Path
    manifest: Any  # scpformer.data.storage.Manifest
    models: tuple[Path, ...]
    checkpoints: tuple[Any, ...]  # scpformer.train.checkpoint.Checkpoint, in --model order

    def provenance(self) -> list[str]:
        """The commands that made the dataset and the models."""
        return [*dataset_commands(self.data), *map(model_command, self.models)]


def open_study(options: RunOptions, family: str, models: int | None = None) -> Study:
    """Check ``--data`` (a ``family`` dataset) and ``--model`` (``models`` runs of it)."""
    data = require_data(options)
    paths = require_models(options, models)
    manifest = read_manifest(data)
    if manifest.family != family:
        raise ValueError(f"--data {data}: a {manifest.family} dataset, not {family}")
    from scpformer.train.checkpoint import load_checkpoint

    checkpoints = tuple(load_checkpoint(p, family=family) for p in paths)
    return Study(data, manifest, paths, checkpoints)


@dataclass(frozen=True)
class InstanceTask:
    """One test instance: its dataset position and theta."""

    index: int
    theta: np.ndarray


def theta_tasks(folder: Path, positions: Sequence[int]) -> list[InstanceTask]:
    """The :class:`InstanceTask` of each sample position."""
    fields = read_fields(folder, positions, ["theta"])
    return [
        InstanceTask(int(p), np.asarray(f["theta"])) for p, f in zip(positions, fields, strict=True)
    ]


# ======================================================================================
# resumable per-instance results
# ======================================================================================
def check_out_folder(out: Path) -> None:
    """Refuse an ``--out`` that is a file, cannot be written, or holds files of something else
    than an experiment run (no ``config.json``): the run would overwrite them."""
    check_output_folder(out, "--out")
    if out.is_dir() and not (out / CONFIG_NAME).exists():
        others = sorted(p.name for p in out.iterdir())
        if others:
            raise ValueError(
                f"--out {out} is not empty and holds no experiment run ({CONFIG_NAME} missing; "
                f"found {', '.join(others[:3])}); choose an empty or new --out folder"
            )


def check_settings(out: Path, settings: Mapping[str, Any], *, grows: tuple[str, ...] = ()) -> None:
    """Record ``settings`` in ``OUT/config.json``; refuse a folder made with other settings.

    ``n`` may differ (a larger run extends a smaller one), and so may where the folder is
    (``out``: a moved or renamed results folder resumes); so may the lists named in
    ``grows`` when the new list starts with the old one (e.g. a closed-loop experiment's
    warm starts: a start added to a folder flies beside the runs already there, each start
    in its own sub-folder). Everything else must match.
    """
    path = out / CONFIG_NAME
    plain = json.loads(json.dumps(settings, default=str))
    if path.is_file():
        try:
            old = json.loads(path.read_text())
        except ValueError:
            old = None
        if not isinstance(old, dict):
            raise ValueError(f"--out {out}: {CONFIG_NAME} is unreadable; use a new --out")
        ignore = {"n", "out", "workers", "ray", "time_limit"}
        changed = sorted(
            k for k in set(old) | set(plain)
            if k not in ignore and old.get(k) != plain.get(k)
            and not (k in grows and _extends(plain.get(k), old.get(k)))
        )  # fmt: skip
        if changed:
            raise ValueError(
                f"--out {out} holds a run with other settings ({', '.join(changed)}); "
                "use a new --out or the same settings"
            )
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, json.dumps(plain, indent=1) + "\n")


def _extends(new: Any, old: Any) -> bool:
    """Whether the list ``new`` starts with the list ``old``."""
    return isinstance(new, list) and isinstance(old, list) and new[: len(old)] == old


class ResultsCSV:
    """``OUT/results.csv``: rows appended and flushed one instance at a time."""

    def __init__(self, path: Path, columns: Sequence[str]) -> None:
        self.path, self.columns = Path(path), list(columns)
        if KEY not in self.columns:
            raise ValueError(f"columns must include {KEY!r}")
        if self.path.is_file() and self.path.stat().st_size:
            with self.path.open(newline="") as handle:
                header = next(csv.reader(handle), [])
            if header != self.columns:
                raise ValueError(
                    f"{self.path}: its columns differ from this experiment's; use a new --out"
                )

    def rows(self) -> list[dict[str, str]]:
        """Every complete row written so far (a torn last line is dropped)."""
        if not self.path.is_file():
            return []
        with self.path.open(newline="") as handle:
            rows = list(csv.DictReader(handle))
        return [r for r in rows if None not in r.values() and None not in r]

    def done(self) -> set[int]:
        """Keys of the instances already written."""
        return {int(r[KEY]) for r in self.rows()}

    def append(self, row: Mapping[str, Any]) -> None:
        """Write one row (missing columns empty, unknown ones an error) and flush it to disk."""
        unknown = set(row) - set(self.columns)
        if unknown:
            raise ValueError(f"row has columns not in the results table: {sorted(unknown)}")
        new = not self.path.is_file() or not self.path.stat().st_size
        if not new:
            _terminate_last_line(self.path)
        with self.path.open("a", newline="") as handle:
            writer = csv.DictWriter(handle, fieldnames=self.columns)
            if new:
                writer.writeheader()
            writer.writerow({k: _cell(row.get(k, "")) for k in self.columns})
            handle.flush()
            os.fsync(handle.fileno())


def _terminate_last_line(path: Path) -> None:
    """Drop a torn last line left by a killed run (every complete row ends with a newline)."""
    data = path.read_bytes()
    if data and not data.endswith(b"\n"):
        path.write_bytes(data[: data.rfind(b"\n") + 1])


def _cell(value: Any) -> Any:
    if isinstance(value, float | np.floating):
        return repr(float(value))
    if isinstance(value, np.integer | np.bool_):
        return value.item()
    return value


_SPECIAL_CELLS = {"": math.nan, "True": 1.0, "False": 0.0}


def column(rows: Sequence[Mapping[str, str]], name: str) -> np.ndarray:
    """A numeric column of CSV rows (empty cells are NaN; True/False are 1/0)."""
    cells = (row.get(name, "") for row in rows)
    return np.array(
        [_SPECIAL_CELLS.get(c, None) if c in _SPECIAL_CELLS else float(c) for c in cells],
        dtype=float,
    )


def series(cell: str) -> np.ndarray:
    """A space-separated list of numbers stored in one cell (e.g. a cost history)."""
    return np.array([float(v) for v in cell.split()], dtype=float)


def join_series(values: Iterable[float]) -> str:
    """Inverse of :func:`series`."""
    return " ".join(repr(float(v)) for v in values)


# ======================================================================================
# executors
# ======================================================================================
class TaskSolver(Protocol):
    """The per-instance work of an experiment (picklable; heavy state built in ``warm_up``)."""

    def warm_up(self) -> None:
        """Load models, compile subproblems (once per worker)."""

    def solve(self, task: Any) -> dict[str, Any]:
        """One task's CSV row (``KEY`` included)."""


class ModelSolver:
    """Base of the per-instance work that needs trained models (one torch thread per worker).

    The checkpoints travel to the workers as paths and are loaded in :meth:`warm_up`.
    """

    family: ClassVar[str] = "rendezvous"

    def __init__(self, checkpoints: Sequence[Path], data_config: dict[str, Any]) -> None:
        self.checkpoints, self.data_config = tuple(checkpoints), data_config
        self.models: list[Any] = []  # loaded Checkpoints, in the order of ``checkpoints``

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "models": []}

    def warm_up(self) -> None:
        import torch

        from scpformer.train.checkpoint import load_checkpoint

        torch.set_num_threads(1)
        self.models = [load_checkpoint(p, family=self.family) for p in self.checkpoints]

    def instance(self, theta: np.ndarray) -> Any:
        """The rendezvous instance of ``theta`` in the dataset's scenario."""
        from scpformer.data.rendezvous_family import RendezvousDataConfig, instance_from_theta

        config = RendezvousDataConfig.from_dict(self.data_config)
        return instance_from_theta(theta, config.scenario)

    @staticmethod
    def rollout(
        ckpt: Any, batch: Any, adapter: Any, *, art_mode: str, rtg0: np.ndarray, ctg0: np.ndarray
    ) -> Any:
        """ART's rollout (Algorithm 2) of the loaded checkpoint ``ckpt`` on ``batch``.

        Parameters
        ----------
        ckpt : scpformer.train.checkpoint.Checkpoint
            One of :attr:`models`: the network, its normalization and its state frame.
        batch, adapter
            The instances as the ART family ``adapter`` batches them.
        art_mode : str
            ``"transformer"`` (transformer only) or ``"dynamics"`` (dynamics in the loop).
        rtg0, ctg0 : numpy.ndarray
            The requested reward-to-go ``R(t_1)`` and constraint-to-go ``C(t_1)`` per instance.

        Returns
        -------
        scpformer.warmstart.art.ArtRollout
            The generated states ``x``, controls ``u`` and generation time.
        """
        from scpformer.warmstart.art import generate

        return generate(ckpt.model, ckpt.normalization, batch, adapter, frame=ckpt.frame,
                        art_mode=art_mode, rtg0=rtg0, ctg0=ctg0)  # fmt: skip


def result_columns(*columns: str) -> tuple[str, ...]:
    """The columns of a ``results.csv``: the instance's :data:`KEY`, ``columns``, then the
    ``status`` and ``message`` of every row (a failed instance's: :func:`failure_row`)."""
    return (KEY, *columns, "status", "message")


def failure_row(key: int, status: str, message: str) -> dict[str, Any]:
    """The row of an instance whose work did not return (error, timeout, crash)."""
    return {KEY: key, "status": status, "message": message}


def task_index(rng: np.random.Generator) -> int:
    """The task number ``i`` of the engine's stream ``SeedSequence(seed, spawn_key=(i,))``."""
    key = getattr(rng.bit_generator.seed_seq, "spawn_key", ())
    if len(key) != 1:
        raise ValueError("not an executor instance stream (spawn_key must be (index,))")
    return int(key[0])


@dataclass(frozen=True)
class TaskFamily:
    """Experiment tasks as a :class:`~scpformer.data.family.DatasetFamily` for the executors."""

    tasks: tuple[Any, ...]
    solver: Any  # a TaskSolver
    name: ClassVar[str] = "experiment"
    success_statuses: ClassVar[frozenset[str]] = frozenset({"ok"})

    def warm_up(self) -> None:
        self.solver.warm_up()

    def sample(self, rng: np.random.Generator) -> Any:
        return self.tasks[task_index(rng)]

    def encode_instance(self, task: Any) -> dict[str, Any]:
        return {}

    def solve(self, task: Any) -> SampleResult:
        row = self.solver.solve(task)
        return SampleResult("ok", "", {"row": row}, 0.0)


@dataclass
class ProgressPrinter:
    """Counts printed (to stderr) while an experiment runs."""

    total: int
    done: int = 0
    failed: int = 0

    def step(self, ok: bool) -> None:
        self.done += 1
        self.failed += 0 if ok else 1
        end = "\n" if self.done == self.total else ""
        print(
            f"\r{self.done}/{self.total} instances ({self.failed} failed)",
            end=end,
            file=sys.stderr,
            flush=True,
        )


def run_tasks(
    solver: Any,
    tasks: Sequence[Any],
    options: RunOptions,
    results: ResultsCSV,
    on_failure: Callable[[int, str, str], dict[str, Any]] = failure_row,
) -> list[dict[str, str]]:
    """Run the tasks (each with an ``index``) not in ``results`` yet, appending each row.

    A task that raises, times out or kills its worker gets ``on_failure(index, status,
    message)``. Returns the finished rows (status ``ok``) of ``tasks``, done now or before.
    """
    done = results.done()
    todo = [i for i, task in enumerate(tasks) if int(task.index) not in done]
    if todo:
        executor = make_executor(TaskFamily(tuple(tasks), solver), options, len(todo))
        progress = ProgressPrinter(len(todo))
        try:
            executor.submit(todo)
            while executor.pending():
                for result in executor.wait(timeout=1.0):
                    row = result.fields.get("row")
                    if result.status != "ok" or row is None:
                        key = int(tasks[result.index].index)
                        row = on_failure(key, result.status, result.message)
                    results.append(row)
                    progress.step(result.status == "ok")
        finally:
            executor.close()
    wanted = {int(task.index) for task in tasks}
    return [r for r in results.rows() if int(r[KEY]) in wanted and r.get("status") == "ok"]


def solve_tasks(
    solver: Any, tasks: Sequence[Any], options: RunOptions, columns: Sequence[str]
) -> list[dict[str, str]]:
    """Run ``tasks`` into ``OUT/results.csv`` of ``columns`` (resumed: :func:`run_tasks`).

    Returns
    -------
    list of dict
        The finished rows (status ``ok``) of ``tasks``, done now or before.
    """
    return run_tasks(solver, tasks, options, ResultsCSV(options.out / RESULTS_NAME, columns))


def make_executor(family: TaskFamily, options: RunOptions, tasks: int) -> Executor:
    """Local processes (default) or Ray actors, never more workers than tasks."""
    if options.ray:
        workers = min(options.workers, tasks) if options.workers else None
        return RayPool(family, options.seed, workers, options.time_limit, options.ray)
    workers = min(options.workers or os.cpu_count() or 1, tasks)
    return LocalPool(family, options.seed, workers, options.time_limit)


# ======================================================================================
# provenance: the commands that made the data and the models
# ======================================================================================
def dataset_commands(folder: Path) -> list[str]:
    """``scpformer generate`` and ``dataset split`` lines that remake ``folder``.

    Read from the manifest (family, n, seed, workers of the first run, configuration values
    that differ from the family's defaults) and from ``splits.h5`` (fractions, seed).
    """
    from scpformer.data.family import build_family

    manifest = read_manifest(folder)
    line = f"scpformer generate {manifest.family} --n {manifest.n} --seed {manifest.seed}"
    line += f" --out {folder}"
    if manifest.shard_size != 64:
        line += f" --shard-size {manifest.shard_size}"
    try:
        defaults = build_family(manifest.family).config_dict()
        # rebuilt: values a manifest predates take the ones that dataset was made with
        changed = _differences(
            defaults, build_family(manifest.family, manifest.config).config_dict()
        )
    except Exception:  # an unknown or changed family: say nothing about its options
        changed = []
    commands = [line]
    if changed:
        commands.append("# configuration differing from the defaults: " + ", ".join(changed))
    try:
        config = load_splits(folder).config
        fractions = " ".join(f"{f:g}" for f in config.fractions)
        commands.append(
            f"scpformer dataset split {folder} --fractions {fractions} --seed {config.seed}"
        )
    except DatasetError:
        commands.append("# no splits.h5")
    return commands


def _differences(default: Any, actual: Any, path: str = "") -> list[str]:
    if isinstance(default, Mapping) and isinstance(actual, Mapping):
        out = []
        for key in sorted(set(default) | set(actual)):
            out += _differences(default.get(key), actual.get(key), f"{path}{key}.")
        return out
    norm = json.loads(json.dumps([default, actual], default=str))
    return [] if norm[0] == norm[1] else [f"{path[:-1]}={norm[1]}"]


def model_command(run: Path) -> str:
    """The ``scpformer train`` line that remakes a run, from ``RUN/config.json``."""
    folder = run if run.is_dir() else run.parent
    path = folder / "config.json"
    try:
        config = json.loads(path.read_text())
    except (OSError, ValueError):
        return f"# {run}: no readable config.json (command unknown)"
    train = config.get("train", {})
    parts = [
        f"scpformer train {config.get('kind', '?')} --data {config.get('data', '?')}",
        f"--out {folder}",
        f"--preset {config.get('preset', '?')}",
        f"--frame {config.get('frame', '?')}",
        *(f"--twin {twin}" for twin in config.get("twin_option") or ()),
    ]
    for key, flag in (
        ("epochs", "--epochs"),
        ("batch_size", "--batch-size"),
        ("lr", "--lr"),
        ("seed", "--seed"),
    ):
        if key in train:
            parts.append(f"{flag} {train[key]}")
    return " ".join(parts)


def settings_dict(options: RunOptions, study: Study | None = None, **extra: Any) -> dict[str, Any]:
    """The resolved settings recorded in ``config.json`` and ``report.md``.

    With ``study``: the dataset's solver configuration, each model's configuration and the
    sha256 of each checkpoint file (a rerun with retrained models is refused, not mixed in).
    """
    out = asdict(options)
    out["models"] = [str(m) for m in options.models]
    out["data"] = str(options.data) if options.data else None
    out["out"] = str(options.out)
    if study is not None:
        from scpformer.train.checkpoint import checkpoint_path

        out["solver"] = study.manifest.config.get("solver")
        out["model_configs"] = [
            {"kind": c.kind, "frame": c.frame, **c.config.to_dict()} for c in study.checkpoints
        ]
        out["checkpoints_sha256"] = [file_sha256(checkpoint_path(m)) for m in study.models]
    out.update(extra)
    return out


def select_and_record(
    options: RunOptions, study: Study, *, experiment: str, **extra: Any
) -> tuple[np.ndarray, dict[str, Any]]:
    """The test instances of a study's run and its settings, recorded in ``OUT/config.json``.

    Draws ``--n`` test instances (:func:`select_test_instances`), builds the settings
    (:func:`settings_dict` with ``experiment``, the instance count ``n`` and ``extra``, in
    that order) and records them, refusing a folder made with other settings
    (:func:`check_settings`).

    Returns
    -------
    positions : numpy.ndarray
        The dataset positions of the selected test instances.
    settings : dict
        The recorded settings.
    """
    positions = select_test_instances(study.data, require_n(options), options.seed)
    settings = settings_dict(options, study, experiment=experiment, n=int(positions.size),
                             **extra)  # fmt: skip
    check_settings(options.out, settings)
    return positions, settings
