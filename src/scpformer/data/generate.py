"""Generate a dataset: sample, solve and store instances, in parallel, resumably.

``generate(family, config)`` plans ``ceil(n / shard_size)`` shards of consecutive instance
indices, keeps every shard an earlier run finished (after checking its checksum), deletes what
an interrupted run left half-written, and solves the rest on a local process pool or on Ray
actors (:mod:`scpformer.data.executors`). A shard is written as soon as its last instance comes
back, then the manifest is updated; killing the process at any moment loses at most the
unfinished shards' solves.

Instance ``i`` draws from its own seed stream, whatever ``n`` is, so running again with a larger
``n`` grows a dataset: its shards are kept and new ones planned after them
(:meth:`~scpformer.data.storage.Manifest.grown_to`). A smaller ``n`` is refused.

Failed, infeasible, timed-out and crashed instances are stored like solved ones, with their
status: failure rates are results.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from scpformer import __version__
from scpformer.data import storage
from scpformer.data.errors import DatasetError
from scpformer.data.executors import Executor, LocalPool, RayPool, TaskResult
from scpformer.data.family import DatasetFamily, Field, full_schema
from scpformer.data.splits import SPLITS_NAME
from scpformer.data.storage import Manifest, ShardInfo
from scpformer.validation import check_int

START_METHODS = ("forkserver", "spawn", "fork")


MAX_INSTANCES = 10**8  # base instances of one dataset (the papers' largest: 400,000)


@dataclass(frozen=True, kw_only=True)
class GenerateConfig:
    """How to generate a dataset; ``n``, ``seed`` and ``shard_size`` define it, the rest how."""

    n: int  # number of base instances to sample and solve
    out: Path  # dataset folder (created, or resumed when it holds the same dataset)
    seed: int = 0  # root of the numpy SeedSequence; instance i uses child i
    shard_size: int = 64  # instances per HDF5 shard (the unit of resumption)
    workers: int | None = None  # worker processes or actors (None: every CPU)
    ray_address: str | None = None  # Ray cluster address ("local" starts one); None: local pool
    time_limit: float = 300.0  # s per instance after warm-up; then status "timeout"
    start_method: str = "forkserver"  # multiprocessing start method of the local pool

    def __post_init__(self) -> None:
        object.__setattr__(self, "out", Path(self.out))
        for name in ("n", "shard_size"):
            object.__setattr__(self, name, check_int(name, getattr(self, name), least=1))
        if self.n > MAX_INSTANCES:
            raise ValueError(
                f"n must be at most {MAX_INSTANCES:,} (the plan of shards is held in memory), "
                f"got {self.n:,}"
            )
        object.__setattr__(self, "seed", check_int("seed", self.seed, least=0))
        if self.workers is not None:
            object.__setattr__(self, "workers", check_int("workers", self.workers, least=1))
        if not (math.isfinite(self.time_limit) and self.time_limit > 0.0):
            raise ValueError(
                f"time_limit must be a positive number of seconds, got {self.time_limit}"
            )
        if self.start_method not in START_METHODS:
            raise ValueError(
                f"start_method must be one of {START_METHODS}, got {self.start_method}"
            )


@dataclass(frozen=True)
class Progress:
    """Counts after one more instance came back (for progress bars)."""

    done: int  # instances finished, earlier runs included
    total: int  # planned instances
    solved: int  # of ``done``, with a success status
    failed: int  # of ``done``, with any other status
    result: TaskResult | None = None  # the instance that just came back


@dataclass(frozen=True)
class GenerationReport:
    """What a run did, and where its time went."""

    folder: Path
    manifest: Manifest
    generated: int  # instances solved by this run
    resumed: int  # instances kept from earlier runs
    wall_time: float  # s of this run, folder checks to last shard
    startup_time: float  # s until every worker had warmed up
    task_time: float  # sum over this run's instances of the worker's sample-and-solve time
    solve_time: float  # sum of the time inside the family's solver
    workers: int
    backend: str
    notices: tuple[str, ...] = field(default_factory=tuple)

    @property
    def solver_share(self) -> float:
        """Share of the workers' wall time spent in the solver (1 - overhead)."""
        capacity = self.workers * self.wall_time
        return self.solve_time / capacity if capacity > 0 else float("nan")


ProgressCallback = Callable[[Progress], None]
NoticeCallback = Callable[[str], None]


def generate(
    family: DatasetFamily,
    config: GenerateConfig,
    *,
    on_progress: ProgressCallback | None = None,
    on_notice: NoticeCallback | None = None,
) -> GenerationReport:
    """Generate (or resume) the dataset ``config`` describes for ``family``.

    Parameters
    ----------
    family
        The problem family (see :class:`scpformer.data.family.DatasetFamily`).
    config
        Size, seed, folder and execution settings.
    on_progress
        Called after every instance that comes back, and once at the start.
    on_notice
        Called with one line for each event worth telling (resumption, repairs).

    Returns
    -------
    GenerationReport

    Raises
    ------
    DatasetError
        When the folder holds another dataset, a worker cannot start, Ray is unreachable, or
        the disk fills up (finished shards are kept in every case).
    """
    start = time.perf_counter()
    notices: list[str] = []

    def notice(text: str) -> None:
        notices.append(text)
        if on_notice is not None:
            on_notice(text)

    if config.out.exists() and not config.out.is_dir():
        raise DatasetError(f"--out {config.out} is a file, not a folder")
    if config.out.is_dir():  # refuse another dataset's folder before adding a lock file to it
        _check_contents(config.out, new_manifest(family, config), lambda _: None)
    with storage.locked_folder(config.out):
        return _generate_locked(family, config, on_progress, notice, notices, start)


def _generate_locked(
    family: DatasetFamily,
    config: GenerateConfig,
    on_progress: ProgressCallback | None,
    notice: NoticeCallback,
    notices: list[str],
    start: float,
) -> GenerationReport:
    manifest = prepare_folder(family, config, notice)
    resumed = manifest.counts()["samples"]
    finished = {s.file for s in manifest.shards}
    todo = {
        storage.shard_name(i): r
        for i, r in enumerate(manifest.planned_ranges())
        if storage.shard_name(i) not in finished
    }
    if resumed and todo:
        notice(f"resuming: {resumed} of {config.n} instances already stored")
    run = _Run(family, config, manifest, on_progress)
    run.report_progress(None)
    stats = run.execute(todo) if todo else _RunStats()
    return GenerationReport(
        folder=config.out,
        manifest=run.manifest,
        generated=stats.generated,
        resumed=resumed,
        wall_time=time.perf_counter() - start,
        startup_time=stats.startup_time,
        task_time=stats.task_time,
        solve_time=stats.solve_time,
        workers=stats.workers,
        backend=stats.backend,
        notices=tuple(notices),
    )


# -- the output folder -------------------------------------------------------------------------
def new_manifest(family: DatasetFamily, config: GenerateConfig) -> Manifest:
    """The manifest of the dataset ``config`` describes, with no shard yet."""
    return Manifest(
        family=family.name,
        seed=int(config.seed),
        n=int(config.n),
        shard_size=int(config.shard_size),
        config=json.loads(json.dumps(family.config_dict())),
        schema=full_schema(family),
        package_version=__version__,
        versions=family.versions(),
        success_statuses=tuple(sorted(family.success_statuses)),
    )


def prepare_folder(
    family: DatasetFamily, config: GenerateConfig, notice: NoticeCallback
) -> Manifest:
    """Create the folder or check that it holds this very dataset, then repair it.

    Repairs: temporary files of an interrupted run are deleted; listed shards that fail their
    checksum are deleted (to be redone); shard files that a run finished but did not list
    (killed between the two writes) are adopted when intact.
    """
    folder = config.out
    if folder.exists() and not folder.is_dir():
        raise DatasetError(f"--out {folder} is a file, not a folder")
    folder.mkdir(parents=True, exist_ok=True)
    wanted = new_manifest(family, config)
    manifest = repair(folder, _check_contents(folder, wanted, notice), notice)
    run = {
        "started": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "backend": "ray" if config.ray_address else "local",
        "ray_address": config.ray_address,
        "workers": config.workers,
        "time_limit": config.time_limit,
        "package_version": __version__,
    }
    manifest = dataclasses.replace(manifest, runs=(*manifest.runs, run))
    storage.write_manifest(folder, manifest)
    return manifest


def _check_contents(folder: Path, wanted: Manifest, notice: NoticeCallback) -> Manifest:
    """The manifest to resume (``wanted`` when new); refuses a folder of anything else."""
    if (folder / storage.MANIFEST_NAME).exists():
        return _resumable(storage.read_manifest(folder), wanted, folder, notice)
    _require_empty(folder, wanted)
    return wanted


def _resumable(old: Manifest, wanted: Manifest, folder: Path, notice: NoticeCallback) -> Manifest:
    """``old`` to resume, or grown to ``wanted.n`` (see :meth:`Manifest.grown_to`)."""
    why = storage.describe_mismatch(dataclasses.replace(old, n=wanted.n), wanted)
    if why is not None:
        raise DatasetError(
            f"{folder} holds another dataset ({old.family}, seed {old.seed}, n {old.n}): it "
            f"differs in {why}; choose another --out folder or repeat its original command"
        )
    if wanted.n < old.n:
        raise DatasetError(
            f"{folder} holds {old.n} instances and a dataset only grows: --n {wanted.n} would "
            f"drop some; use --n {old.n} to resume it, more to grow it, or another --out folder"
        )
    if (old.package_version, old.versions) != (wanted.package_version, wanted.versions):
        notice(
            f"resuming data written with scpformer {old.package_version} {old.versions} "
            f"using {wanted.package_version} {wanted.versions}"
        )
    return _grown(old, wanted.n, folder, notice) if wanted.n > old.n else old


def _grown(old: Manifest, n: int, folder: Path, notice: NoticeCallback) -> Manifest:
    notice(f"growing the dataset from {old.n} to {n} instances; the {old.n} stored are kept")
    if (folder / SPLITS_NAME).exists():
        notice(
            f"{SPLITS_NAME} splits the first {old.n} instances only: run `scpformer dataset "
            f"split {folder}` again once this run is complete"
        )
    return old.grown_to(n)


def _require_empty(folder: Path, wanted: Manifest) -> None:
    """Refuse a folder without manifest unless it holds nothing or only this dataset's shards."""
    skipped = (storage.LOCK_NAME,)
    others = [
        p
        for p in folder.iterdir()
        if not p.name.endswith(storage.TMP_SUFFIX) and p.name not in skipped
    ]
    shards = [p for p in others if p.match(storage.SHARD_GLOB)]
    foreign = [p for p in shards if _shard_identity(p) != storage.identity_digest(wanted)]
    if shards and not foreign and len(shards) == len(others):
        return  # the manifest was lost: repair() adopts the shards whose metadata matches
    if foreign:
        raise DatasetError(
            f"{folder} has no {storage.MANIFEST_NAME} and holds shards of another dataset "
            f"(e.g. {foreign[0].name}); rebuild its manifest with `scpformer dataset repair "
            f"{folder}` or choose another --out folder"
        )
    if others:
        raise DatasetError(
            f"{folder} is not empty and holds no dataset ({storage.MANIFEST_NAME} missing; "
            f"found {', '.join(sorted(p.name for p in others)[:3])}); choose an empty or new "
            "--out folder"
        )


def _shard_identity(path: Path) -> str | None:
    """The ``config_sha256`` a shard file carries (``None`` if unreadable or absent)."""
    try:
        return storage.shard_attrs(path).get("config_sha256")
    except DatasetError:
        return None


def repair(folder: Path, manifest: Manifest, notice: NoticeCallback) -> Manifest:
    """Delete temporary files and bad shards, adopt intact unlisted shards (see above)."""
    temps, unlisted = storage.stray_files(folder, manifest)
    for path in temps:
        path.unlink(missing_ok=True)
        notice(f"removed {path.name}, left half-written by an interrupted run")
    identities = storage.identity_digests(manifest)
    for info in manifest.shards:
        problems = storage.check_shard(folder, info, manifest.schema, identities)
        if problems:
            (folder / info.file).unlink(missing_ok=True)
            manifest = manifest.without_shard(info.file)
            notice(f"{problems[0]}: regenerating it")
    planned = {storage.shard_name(i): r for i, r in enumerate(manifest.planned_ranges())}
    for path in unlisted:
        info = _adoptable(path, manifest, planned.get(path.name), identities)
        if info is None:
            path.unlink(missing_ok=True)
            notice(f"removed {path.name}: not a shard of this dataset")
        else:
            manifest = manifest.with_shard(info)
    return manifest


def rebuild_manifest(folder: Path, notice: NoticeCallback) -> Manifest:
    """Rebuild a deleted ``folder/manifest.json`` from the headers its shards carry.

    Shards whose identity digest, range and checksums match are listed; others are left in
    place and named through ``notice``. A manifest that cannot be read (empty, truncated,
    tampered) is moved aside to ``manifest.json.corrupt`` and rebuilt the same way.

    Raises
    ------
    DatasetError
        When the folder still has a readable manifest, holds no shard, or no shard carries a
        header.
    """
    folder = Path(folder)
    manifest_path = folder / storage.MANIFEST_NAME
    if manifest_path.exists():
        try:
            storage.read_manifest(folder)
        except DatasetError:
            pass  # unreadable: rebuilt below, the old file kept aside
        else:
            raise DatasetError(
                f"{folder} has a {storage.MANIFEST_NAME}; nothing to rebuild (check it with "
                f"`scpformer dataset verify {folder}`)"
            )
    paths = sorted(folder.glob(storage.SHARD_GLOB)) if folder.is_dir() else []
    if not paths:
        raise DatasetError(f"no shard files in {folder}: nothing to rebuild a manifest from")
    manifest = _latest_header(paths)
    with storage.locked_folder(folder):
        if manifest_path.exists():
            aside = manifest_path.with_name(storage.MANIFEST_NAME + ".corrupt")
            manifest_path.replace(aside)
            notice(f"{storage.MANIFEST_NAME} could not be read; kept as {aside.name}")
        planned = {storage.shard_name(i): r for i, r in enumerate(manifest.planned_ranges())}
        identities = storage.identity_digests(manifest)
        for path in paths:
            info = _adoptable(path, manifest, planned.get(path.name), identities)
            if info is None:
                notice(f"{path.name}: damaged or of another dataset; left out and in place")
            else:
                manifest = manifest.with_shard(info)
        storage.write_manifest(folder, manifest)
    return manifest


def _latest_header(paths: list[Path]) -> Manifest:
    """The shard-less manifest in the shards' headers with the largest ``n``.

    Shards of a grown dataset carry the manifest of the run that wrote them; the latest one
    plans every shard and remembers the earlier sizes.
    """
    headers, reasons = [], []
    for path in paths:
        try:
            headers.append(storage.manifest_from_header(storage.shard_attrs(path)))
        except DatasetError as err:
            reasons.append(f"{path.name}: {err}")
    if not headers:
        raise DatasetError(f"no shard carries a readable dataset header ({reasons[0]})")
    return max(headers, key=lambda manifest: manifest.n)


def _adoptable(
    path: Path,
    manifest: Manifest,
    planned: tuple[int, int] | None,
    identities: frozenset[str],
) -> ShardInfo | None:
    """The manifest entry of an intact finished shard that the manifest missed, else None.

    ``identities``: :func:`storage.identity_digests` of ``manifest``, computed once per folder.
    """
    if planned is None:
        return None
    try:
        attrs = storage.shard_attrs(path)
        if attrs.get("config_sha256") not in identities:
            return None  # made with other settings, or by a version without the digest
        if (attrs.get("start"), attrs.get("stop")) != tuple(planned):
            return None
        columns = storage.read_columns(path, manifest.schema)
    except DatasetError:
        return None
    if storage.content_digest(columns, manifest.schema) != attrs.get("content_sha256"):
        return None
    statuses: dict[str, int] = {}
    for status in columns["status"]:
        statuses[str(status)] = statuses.get(str(status), 0) + 1
    return ShardInfo(
        file=path.name,
        start=planned[0],
        stop=planned[1],
        count=int(attrs["count"]),
        sha256=storage.file_sha256(path),
        content_sha256=str(attrs["content_sha256"]),
        bytes=path.stat().st_size,
        status_counts=dict(sorted(statuses.items())),
    )


# -- the run -----------------------------------------------------------------------------------
@dataclass
class _RunStats:
    generated: int = 0
    task_time: float = 0.0
    solve_time: float = 0.0
    startup_time: float = float("nan")
    workers: int = 0
    backend: str = "none"


class _Run:
    """Dispatches the missing shards' instances and writes each shard when it is complete."""

    def __init__(
        self,
        family: DatasetFamily,
        config: GenerateConfig,
        manifest: Manifest,
        on_progress: ProgressCallback | None,
    ) -> None:
        self.family, self.config, self.manifest = family, config, manifest
        self.on_progress = on_progress
        counts = manifest.counts()
        self.solved, self.failed = counts["solved"], counts["failed"]
        self.schema: tuple[Field, ...] = manifest.schema
        self.stats = _RunStats()

    def report_progress(self, result: TaskResult | None) -> None:
        if self.on_progress is not None:
            done = self.solved + self.failed
            self.on_progress(Progress(done, self.config.n, self.solved, self.failed, result))

    def execute(self, ranges: dict[str, tuple[int, int]]) -> _RunStats:
        owner = {i: name for name, (a, b) in ranges.items() for i in range(a, b)}
        buffers: dict[str, dict[int, TaskResult]] = {name: {} for name in ranges}
        executor = self._executor(len(owner))
        self.stats.workers, self.stats.backend = executor.n_workers, executor.backend
        try:
            executor.submit(sorted(owner))
            while executor.pending():
                for result in executor.wait(timeout=1.0):
                    name = owner[result.index]
                    buffers[name][result.index] = result
                    self._count(result)
                    start, stop = ranges[name]
                    if len(buffers[name]) == stop - start:
                        self._write(name, start, stop, buffers.pop(name))
        finally:
            self.stats.startup_time = executor.startup_time
            executor.close()
        return self.stats

    def _executor(self, tasks: int) -> Executor:
        """The backend, with no more workers than there are instances to solve."""
        c = self.config
        if c.ray_address:
            workers = min(c.workers, tasks) if c.workers else None
            return RayPool(self.family, c.seed, workers, c.time_limit, c.ray_address)
        workers = min(c.workers or os.cpu_count() or 1, tasks)
        return LocalPool(self.family, c.seed, workers, c.time_limit, c.start_method)

    def _count(self, result: TaskResult) -> None:
        self.stats.generated += 1
        self.stats.task_time += result.wall_time
        self.stats.solve_time += result.solve_time
        if result.status in self.family.success_statuses:
            self.solved += 1
        else:
            self.failed += 1
        self.report_progress(result)

    def _write(self, name: str, start: int, stop: int, results: dict[int, TaskResult]) -> None:
        records = [self._record(results[i]) for i in range(start, stop)]
        columns = storage.stack_records(records, self.schema)
        attrs = storage.shard_header(self.manifest)
        self.manifest = storage.append_shard(
            self.config.out, self.manifest, name, columns, start=start, stop=stop, attrs=attrs
        )

    def _record(self, result: TaskResult) -> dict[str, Any]:
        record = {f.name: f.empty(1)[0] for f in self.schema}
        record.update(result.fields)
        record.update(
            index=result.index,
            base_index=result.index,
            status=result.status,
            message=result.message,
            wall_time=result.wall_time,
        )
        return record
