"""Self-describing, sharded, crash-safe dataset storage: HDF5 shards and a JSON manifest.

A dataset is a folder::

    DIR/manifest.json        family, full resolved config, seed, versions, schema, shard list,
                             counts and checksums (rewritten atomically after every shard)
    DIR/shard-00000.h5       samples [start, stop): one HDF5 dataset per field, shape
                             (count, *field.shape); attributes repeat the shard's identity:
                             ``config_sha256`` (digest of the resolved configuration) and
                             ``dataset`` (the manifest without shards, to rebuild a lost one)
    DIR/splits.h5            (optional) grouped splits and training-set statistics
    DIR/.lock                held (flock) by the one process writing the folder

Every file is written under a temporary name (``*.tmp``), flushed to disk and renamed, so a
killed process leaves either a whole file or a temporary one that the next run deletes. A
shard's ``sha256`` covers its bytes; its ``content_sha256`` covers the values of the
deterministic fields only (timings excluded), so two runs with the same seed have equal content
digests whatever the worker count or backend. Every reader checks a shard's sha256 before its
first use in a process (:func:`require_intact`).
"""

from __future__ import annotations

import dataclasses
import fcntl
import hashlib
import io
import json
import math
import os
from collections import Counter
from collections.abc import Collection, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from scpformer.data.errors import DatasetError, DiskFullError, is_disk_full
from scpformer.data.family import Field
from scpformer.files import interrupts_deferred, write_bytes_atomic
from scpformer.validation import check_int, check_type, known_fields

FORMAT_VERSION = 1
MANIFEST_NAME = "manifest.json"
TMP_SUFFIX = ".tmp"
SHARD_GLOB = "shard-*.h5"
LOCK_NAME = ".lock"
_CHUNK_BYTES = 1 << 16  # target HDF5 chunk size of compressed fields
_COMPRESS_MIN = 16  # compress fields with at least this many elements per sample


def shard_name(number: int) -> str:
    """File name of shard ``number``."""
    return f"shard-{number:05d}.h5"


@dataclass(frozen=True, kw_only=True)
class ShardInfo:
    """One finished shard as listed in the manifest."""

    file: str  # file name inside the dataset folder
    start: int  # first base index covered
    stop: int  # one past the last base index covered
    count: int  # samples stored (stop - start for generated datasets)
    sha256: str  # of the file's bytes
    content_sha256: str  # of the deterministic field values (see module docstring)
    bytes: int  # file size
    status_counts: dict[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        # a manifest names its shards; a name that leaves the folder ("../x.h5", "/tmp/x")
        # would let a regeneration delete a file outside the dataset
        if not isinstance(self.file, str) or Path(self.file).name != self.file:
            raise ValueError(f"shard file {self.file!r} is not a file name inside the folder")
        if not self.file.endswith(".h5") or self.file.startswith("."):
            raise ValueError(f"shard file {self.file!r} is not a shard (*.h5)")
        for name in ("start", "stop", "count", "bytes"):
            value = check_int(f"shard {self.file}: {name}", getattr(self, name), least=0)
            object.__setattr__(self, name, value)
        if self.stop < self.start:
            raise ValueError(f"shard {self.file}: stop {self.stop} before start {self.start}")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass(frozen=True, kw_only=True)
class Manifest:
    """The manifest of a dataset folder (see the module docstring)."""

    family: str  # registry name of the problem family
    seed: int  # root of the SeedSequence every instance stream is spawned from
    n: int  # planned number of base instances
    shard_size: int  # base instances per shard
    config: dict[str, Any]  # the family's full resolved configuration
    schema: tuple[Field, ...]  # every per-sample field (common ones first)
    package_version: str  # scpformer version that wrote the data
    versions: dict[str, str]  # libraries the results depend on
    success_statuses: tuple[str, ...]  # statuses counted as solved
    kind: str = "generated"  # "generated" or "transformed"
    transform: dict[str, Any] | None = None  # name and config of the transform (if transformed)
    source: dict[str, Any] | None = None  # the dataset a transform read (path, checksum)
    plan: tuple[tuple[int, int], ...] | None = None  # shard ranges when not from n, shard_size
    grown_from: tuple[int, ...] = ()  # earlier n of a grown dataset, oldest first
    shards: tuple[ShardInfo, ...] = ()
    runs: tuple[dict[str, Any], ...] = ()  # one record per (re)start: backend, workers, limits
    format_version: int = FORMAT_VERSION

    def __post_init__(self) -> None:
        for name, least in (("n", 0), ("shard_size", 1), ("seed", 0), ("format_version", 1)):
            object.__setattr__(self, name, check_int(name, getattr(self, name), least=least))
        if self.format_version > FORMAT_VERSION:
            raise ValueError(
                f"format_version {self.format_version} is newer than this scpformer reads "
                f"({FORMAT_VERSION}): update scpformer"
            )

    # -- plan and progress -------------------------------------------------------------------
    def planned_ranges(self) -> list[tuple[int, int]]:
        """``(start, stop)`` of every planned shard, in order."""
        if self.plan is not None:
            return [tuple(r) for r in self.plan]
        n_shards = math.ceil(self.n / self.shard_size)
        return [
            (s * self.shard_size, min((s + 1) * self.shard_size, self.n)) for s in range(n_shards)
        ]

    def grown_to(self, n: int) -> Manifest:
        """This dataset planned to ``n > self.n`` instances: its shards kept, new ones after.

        Instance ``i`` is drawn from its own seed stream whatever ``n`` is, so the first
        ``self.n`` instances stay valid. New shards of ``shard_size`` start at ``self.n`` (a
        last partial shard is kept as it is), and ``self.n`` joins :attr:`grown_from`, so the
        identity digest the kept shards carry still checks out (:func:`identity_digests`).
        """
        if n <= self.n:
            raise ValueError(f"a dataset grows to more than its {self.n} instances, not to {n}")
        added = [(a, min(a + self.shard_size, n)) for a in range(self.n, n, self.shard_size)]
        ranges = tuple(self.planned_ranges()) + tuple(added)
        uniform = dataclasses.replace(self, n=n, plan=None).planned_ranges()
        return dataclasses.replace(
            self,
            n=n,
            plan=None if list(ranges) == uniform else ranges,
            grown_from=(*self.grown_from, self.n),
        )

    @property
    def complete(self) -> bool:
        """Whether every planned shard is finished."""
        return len(self.shards) == len(self.planned_ranges())

    def counts(self) -> dict[str, Any]:
        """Samples in finished shards, solved and failed, and per status."""
        by_status: Counter[str] = Counter()
        for shard in self.shards:
            by_status.update(shard.status_counts)
        solved = sum(v for k, v in by_status.items() if k in self.success_statuses)
        samples = sum(s.count for s in self.shards)
        return {
            "samples": samples,
            "solved": solved,
            "failed": samples - solved,
            "shards": len(self.shards),
            "planned_shards": len(self.planned_ranges()),
            "by_status": dict(sorted(by_status.items())),
        }

    def with_shard(self, info: ShardInfo) -> Manifest:
        """A copy listing ``info`` (replacing a shard of the same file), in plan order."""
        shards = [s for s in self.shards if s.file != info.file] + [info]
        return dataclasses.replace(self, shards=tuple(sorted(shards, key=lambda s: s.file)))

    def without_shard(self, file: str) -> Manifest:
        """A copy without shard ``file``."""
        return dataclasses.replace(self, shards=tuple(s for s in self.shards if s.file != file))

    def identity(self) -> dict[str, Any]:
        """What must match for a run to resume into this folder (JSON-normalized)."""
        identity = {
            "format_version": self.format_version,
            "family": self.family,
            "kind": self.kind,
            "seed": self.seed,
            "n": self.n,
            "shard_size": self.shard_size,
            "config": self.config,
            "transform": self.transform,
            "source": (self.source or {}).get("content_id"),
        }
        return json.loads(json.dumps(identity))

    # -- serialization -----------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        out = {
            "format_version": self.format_version,
            "family": self.family,
            "kind": self.kind,
            "seed": self.seed,
            "n": self.n,
            "shard_size": self.shard_size,
            "package_version": self.package_version,
            "versions": self.versions,
            "config": self.config,
            "success_statuses": list(self.success_statuses),
            "transform": self.transform,
            "source": self.source,
            "plan": [list(r) for r in self.plan] if self.plan is not None else None,
            "grown_from": list(self.grown_from),
            "counts": self.counts(),
            "complete": self.complete,
            "schema": [f.to_dict() for f in self.schema],
            "runs": list(self.runs),
            "shards": [s.to_dict() for s in self.shards],
        }
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Manifest:
        """The manifest of :meth:`to_dict`'s JSON; ``ValueError`` naming the field at fault."""
        derived = ("counts", "complete")  # written for readers, recomputed from the shards
        data = {k: v for k, v in dict(data).items() if k not in derived}
        data = known_fields(cls, data, "manifest", complete=True)

        def shard(entry: Any) -> ShardInfo:
            return ShardInfo(**known_fields(ShardInfo, entry, "shard", complete=True))

        def schema_field(entry: Any) -> Field:
            return Field.from_dict(known_fields(Field, entry, "schema entry", complete=True))

        def count(entry: Any) -> int:
            return check_int("value", entry, least=0)

        for name, item in (
            ("schema", schema_field),
            ("shards", shard),
            ("runs", lambda r: check_type("run record", r, dict)),
            ("grown_from", count),
            ("success_statuses", lambda r: check_type("status", r, str)),
            ("plan", lambda r: _list_field("range", r, count)),
        ):
            if name in data and not (name == "plan" and data[name] is None):
                data[name] = _list_field(name, data[name], item)
        return cls(**data)

    def field(self, name: str) -> Field:
        """The schema entry of ``name``."""
        for f in self.schema:
            if f.name == name:
                return f
        raise DatasetError(f"the {self.family} dataset has no field {name!r}")


def _list_field(name: str, value: Any, item: Any) -> tuple:
    """``value`` (a JSON list) with ``item`` applied to each entry; ``ValueError`` naming
    ``name`` and the entry's position when it is not a list or an entry does not convert."""
    if not isinstance(value, list | tuple):
        raise ValueError(f"field {name!r} must be a list, got {type(value).__name__}")
    out = []
    for i, entry in enumerate(value):
        try:
            out.append(item(entry))
        except (TypeError, ValueError, KeyError) as err:
            raise ValueError(f"field {name!r}, entry {i}: {_short(err)}") from None
    return tuple(out)


def describe_mismatch(old: Manifest, new: Manifest) -> str | None:
    """Why ``new`` cannot resume into a folder holding ``old`` (``None`` when it can)."""
    a, b = old.identity(), new.identity()
    for key in a:
        if a[key] != b[key]:
            if key == "config":
                diff = _first_difference(a[key], b[key])
                return f"a different {old.family} configuration ({diff})"
            return f"{key} {a[key]!r} (this run: {b[key]!r})"
    return None


def _first_difference(a: Any, b: Any, path: str = "config") -> str:
    if isinstance(a, dict) and isinstance(b, dict):
        for key in sorted(set(a) | set(b)):
            if a.get(key) != b.get(key):
                return _first_difference(a.get(key), b.get(key), f"{path}.{key}")
    return f"{path}: {a!r} there, {b!r} here"


def identity_digest(manifest: Manifest) -> str:
    """sha256 of :meth:`Manifest.identity` (the resolved configuration included).

    Every shard carries it (attribute ``config_sha256``): a shard made with other solver
    settings is never adopted by a resume, and ``dataset verify`` reports it.
    """
    text = json.dumps(manifest.identity(), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def identity_digests(manifest: Manifest) -> frozenset[str]:
    """Every ``config_sha256`` a shard of ``manifest`` may carry: one per size it has had.

    A grown dataset's earlier shards were written when ``n`` was smaller
    (:meth:`Manifest.grown_to`); they hold the same instances.
    """
    sizes = (manifest.n, *manifest.grown_from)
    return frozenset(identity_digest(dataclasses.replace(manifest, n=n)) for n in sizes)


_HEADER_DROPPED = ("shards", "runs", "counts", "complete")


def shard_header(manifest: Manifest) -> dict[str, Any]:
    """The attributes every shard of ``manifest`` carries: its identity and how to rebuild it.

    ``dataset`` is the manifest without shards and runs (JSON), from which
    ``dataset repair`` rebuilds a deleted ``manifest.json``.
    """
    header = {k: v for k, v in manifest.to_dict().items() if k not in _HEADER_DROPPED}
    return {
        "family": manifest.family,
        "seed": manifest.seed,
        "format_version": FORMAT_VERSION,
        "package_version": manifest.package_version,
        "config_sha256": identity_digest(manifest),
        "dataset": json.dumps(header),
    }


def manifest_from_header(attrs: Mapping[str, Any]) -> Manifest:
    """The shard-less manifest a shard's attributes describe (see :func:`shard_header`).

    Raises
    ------
    DatasetError
        When the shard predates headers or its header is unreadable.
    """
    if "dataset" not in attrs:
        raise DatasetError("the shard carries no dataset header (written by an older version)")
    try:
        return Manifest.from_dict(json.loads(attrs["dataset"]))
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as err:
        raise DatasetError(f"the shard's dataset header is unreadable ({err})") from None


@contextmanager
def locked_folder(folder: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``folder/.lock`` while writing a dataset into ``folder``.

    Raises
    ------
    DatasetError
        When another process holds it (two runs writing one folder).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    with (folder / LOCK_NAME).open("a") as fh:
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise DatasetError(
                f"{folder} is being written by another scpformer run (it holds "
                f"{folder / LOCK_NAME}); wait for it to finish or choose another folder"
            ) from None
        try:
            yield
        finally:
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)


# -- atomic files ----------------------------------------------------------------------------
def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _fsync_file(path: Path) -> None:
    with path.open("rb+") as fh:
        os.fsync(fh.fileno())


def atomic_write_text(path: Path | str, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file, fsync and rename."""
    path = Path(path)
    try:
        write_bytes_atomic(path, text.encode())
        _fsync_dir(path.parent)
    except OSError as err:
        if is_disk_full(err):
            raise DiskFullError(
                f"disk full while writing {path}; finished shards are kept: free space and "
                "re-run the same command to resume"
            ) from None
        raise


def write_manifest(folder: Path | str, manifest: Manifest) -> None:
    """Write ``folder/manifest.json`` atomically."""
    text = json.dumps(manifest.to_dict(), indent=1) + "\n"
    atomic_write_text(Path(folder) / MANIFEST_NAME, text)


def read_manifest(folder: Path) -> Manifest:
    """The manifest of the dataset in ``folder``.

    Raises
    ------
    DatasetError
        When ``folder`` holds no manifest or an unreadable one.
    """
    path = Path(folder) / MANIFEST_NAME
    if not Path(folder).exists():
        raise DatasetError(f"no dataset in {folder} (no such folder)")
    if not Path(folder).is_dir():
        raise DatasetError(f"no dataset in {folder} (a file, not a dataset folder)")
    if not path.is_file():
        hint = ""
        if any(Path(folder).glob(SHARD_GLOB)):
            hint = f"; its shards remain: rebuild it with `scpformer dataset repair {folder}`"
        raise DatasetError(f"no dataset in {folder} ({MANIFEST_NAME} not found{hint})")
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise DatasetError(f"{path} is corrupt: {err}") from None
    if not isinstance(data, dict):
        raise DatasetError(
            f"{path} is corrupt: it holds a JSON {type(data).__name__}, not an object"
        )
    try:
        return Manifest.from_dict(data)
    except KeyError as err:
        raise DatasetError(f"{path} is corrupt: it has no field {err}") from None
    except (TypeError, ValueError) as err:  # the JSON itself was read above
        raise DatasetError(f"{path} is corrupt: {err}") from None


def content_id(manifest: Manifest) -> str:
    """Identity of a dataset's values: sha256 over its shards' content digests, in order.

    Unlike the manifest's own bytes it ignores run records and timings, so it is the same for
    every run that produced the same data (any worker count or backend).
    """
    text = "|".join(s.content_sha256 for s in manifest.shards)
    return hashlib.sha256(text.encode()).hexdigest()


def file_sha256(path: Path) -> str:
    """sha256 of a file's bytes, read in 1 MiB blocks."""
    digest = hashlib.sha256()
    with Path(path).open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


_INTACT: dict[tuple[str, int, int], str] = {}  # (path, size, mtime_ns) -> verified sha256


def shard_damage(folder: Path, info: ShardInfo) -> str | None:
    """Why shard ``info`` is missing or damaged (size, sha256), or ``None`` when intact.

    The sha256 of a file version (path, size, mtime) is computed once per process.
    """
    path = Path(folder) / info.file
    try:
        stat = path.stat()
    except OSError:
        return f"{info.file}: missing"
    if stat.st_size != info.bytes:
        return (
            f"{info.file}: truncated or altered ({stat.st_size} bytes, manifest says {info.bytes})"
        )
    key = (str(path.resolve()), stat.st_size, stat.st_mtime_ns)
    if _INTACT.get(key) != info.sha256:
        if file_sha256(path) != info.sha256:
            return f"{info.file}: corrupt (sha256 differs from the manifest)"
        _INTACT[key] = info.sha256
    return None


def require_intact(folder: Path, info: ShardInfo) -> Path:
    """The path of shard ``info`` after :func:`shard_damage` found it intact.

    Raises
    ------
    DatasetError
        Naming the shard, when it is missing or fails its checksum.
    """
    damage = shard_damage(folder, info)
    if damage is not None:
        raise DatasetError(
            f"{Path(folder) / info.file}: {damage.split(': ', 1)[1]}; nothing was read from it "
            f"(see `scpformer dataset verify {folder}`; re-running generate redoes the shard)"
        )
    return Path(folder) / info.file


# -- shards ----------------------------------------------------------------------------------
def content_digest(columns: Mapping[str, np.ndarray], schema: Sequence[Field]) -> str:
    """sha256 over the deterministic fields' values, in schema order."""
    digest = hashlib.sha256()
    for f in schema:
        if not f.deterministic:
            continue
        values = columns[f.name]
        digest.update(f"{f.name}|{f.dtype}|{values.shape}|".encode())
        if f.dtype == "str":
            digest.update("\0".join(str(v) for v in values.reshape(-1)).encode())
        else:
            digest.update(np.ascontiguousarray(values, dtype=f.numpy_dtype).tobytes())
    return digest.hexdigest()


def stack_records(records: Sequence[Mapping[str, Any]], schema: Sequence[Field]) -> dict:
    """Columns (count, *shape) of the given per-sample records, validated against ``schema``."""
    columns = {}
    for f in schema:
        column = f.empty(len(records))
        for i, record in enumerate(records):
            if f.name not in record:
                raise ValueError(f"sample {i} lacks field {f.name!r}")
            column[i] = f.coerce(record[f.name])
        columns[f.name] = column
    return columns


def _create(h5: h5py.File, f: Field, values: np.ndarray) -> None:
    if f.dtype == "str":
        data = np.array([str(v) for v in values], dtype=h5py.string_dtype("utf-8"))
        h5.create_dataset(f.name, data=data)
        return
    per_sample = int(np.prod(f.shape, dtype=np.int64))
    if per_sample < _COMPRESS_MIN or len(values) == 0:
        h5.create_dataset(f.name, data=values)
        return
    rows = max(1, min(len(values), _CHUNK_BYTES // max(per_sample * values.itemsize, 1)))
    h5.create_dataset(
        f.name,
        data=values,
        chunks=(rows, *f.shape),
        compression="gzip",
        compression_opts=4,
        shuffle=True,
    )


def write_shard(
    path: Path,
    columns: Mapping[str, np.ndarray],
    schema: Sequence[Field],
    *,
    start: int,
    stop: int,
    attrs: Mapping[str, Any],
) -> ShardInfo:
    """Write one shard atomically and return its manifest entry.

    The file is built in memory and written with one plain write, fsync and rename.

    Raises
    ------
    DiskFullError
        When the disk fills up; the temporary file is removed, earlier shards are untouched.
    """
    path = Path(path)
    count = len(columns[schema[0].name])
    content = content_digest(columns, schema)
    buffer = io.BytesIO()  # built in memory: a full disk fails one plain write, not HDF5
    with h5py.File(buffer, "w") as h5:
        for key, value in {**attrs, "start": start, "stop": stop, "count": count}.items():
            h5.attrs[key] = value
        h5.attrs["content_sha256"] = content
        for f in schema:
            _create(h5, f, columns[f.name])
    data = buffer.getvalue()
    try:
        write_bytes_atomic(path, data)
        _fsync_dir(path.parent)
    except OSError as err:
        if is_disk_full(err):
            raise DiskFullError(
                f"disk full while writing {path.name} in {path.parent}; finished shards are "
                "kept: free space and re-run the same command to resume"
            ) from None
        raise
    statuses = Counter(str(s) for s in columns["status"]) if "status" in columns else Counter()
    return ShardInfo(
        file=path.name,
        start=start,
        stop=stop,
        count=count,
        sha256=hashlib.sha256(data).hexdigest(),
        content_sha256=content,
        bytes=len(data),
        status_counts=dict(sorted(statuses.items())),
    )


def append_shard(
    folder: Path,
    manifest: Manifest,
    name: str,
    columns: Mapping[str, np.ndarray],
    *,
    start: int,
    stop: int,
    attrs: Mapping[str, Any],
) -> Manifest:
    """Write shard ``name`` of samples [start, stop) and the manifest that lists it.

    Ctrl-C and SIGTERM wait until both files are on disk (:func:`interrupts_deferred`), so an
    interrupted run never leaves a finished shard that its manifest does not list. Returns the
    new manifest.
    """
    folder = Path(folder)
    with interrupts_deferred():
        info = write_shard(
            folder / name, columns, manifest.schema, start=start, stop=stop, attrs=attrs
        )
        manifest = manifest.with_shard(info)
        write_manifest(folder, manifest)
    return manifest


def read_columns(path: Path, schema: Sequence[Field], names: Iterable[str] | None = None) -> dict:
    """Whole columns of one shard, as written (strings as object arrays of ``str``).

    Raises
    ------
    DatasetError
        When the file cannot be read (truncated, corrupt) or lacks a field.
    """
    wanted = [f for f in schema if names is None or f.name in set(names)]
    try:
        with h5py.File(path, "r") as h5:
            return {f.name: _read(h5, f, ()) for f in wanted}
    except (OSError, KeyError, RuntimeError) as err:
        raise DatasetError(f"{path} is corrupt or truncated ({_short(err)})") from None


def _read(h5: h5py.File, f: Field, where: Any) -> np.ndarray:
    ds = h5[f.name]
    if f.dtype == "str":
        return np.asarray(ds.asstr()[where], dtype=object)
    return np.asarray(ds[where])


def _short(err: BaseException) -> str:
    return str(err).splitlines()[0][:200] if str(err) else type(err).__name__


def shard_attrs(path: Path) -> dict[str, Any]:
    """The attributes of a shard file (its identity and content digest)."""
    try:
        with h5py.File(path, "r") as h5:
            return {k: (v.item() if hasattr(v, "item") else v) for k, v in h5.attrs.items()}
    except (OSError, RuntimeError) as err:
        raise DatasetError(f"{path} is corrupt or truncated ({_short(err)})") from None


def check_shard(
    folder: Path,
    info: ShardInfo,
    schema: Sequence[Field],
    identities: Collection[str] | None = None,
) -> list[str]:
    """Problems of one listed shard: missing, size, checksum, fields, shapes, content digest.

    With ``identities`` (:func:`identity_digests` of the manifest), a shard whose own
    ``config_sha256`` is none of them (made with other settings) is a problem too.
    """
    path = Path(folder) / info.file
    damage = shard_damage(folder, info)
    if damage is not None:
        return [damage]
    try:
        with h5py.File(path, "r") as h5:
            problems = [p for f in schema for p in _check_field(h5, f, info)]
            made_with = h5.attrs.get("config_sha256")
    except (OSError, RuntimeError) as err:
        return [f"{info.file}: unreadable ({_short(err)})"]
    if problems:
        return problems
    if identities is not None and made_with is not None and str(made_with) not in identities:
        return [f"{info.file}: made with another configuration than the manifest's"]
    columns = read_columns(path, schema)
    if content_digest(columns, schema) != info.content_sha256:
        return [f"{info.file}: content digest differs from the manifest"]
    return []


def _check_field(h5: h5py.File, f: Field, info: ShardInfo) -> list[str]:
    if f.name not in h5:
        return [f"{info.file}: field {f.name!r} missing"]
    ds = h5[f.name]
    if ds.shape != (info.count, *f.shape):
        return [
            f"{info.file}: field {f.name!r} has shape {ds.shape}, expected {(info.count, *f.shape)}"
        ]
    is_str = h5py.check_string_dtype(ds.dtype) is not None
    if (f.dtype == "str") != is_str or (not is_str and ds.dtype != np.dtype(f.dtype)):
        return [f"{info.file}: field {f.name!r} has dtype {ds.dtype}, expected {f.dtype}"]
    return []


def stray_files(folder: Path, manifest: Manifest) -> tuple[list[Path], list[Path]]:
    """Temporary files and shard files that the manifest does not list."""
    folder = Path(folder)
    listed = {s.file for s in manifest.shards}
    temps = sorted(folder.glob("*" + TMP_SUFFIX))
    unlisted = sorted(p for p in folder.glob(SHARD_GLOB) if p.name not in listed)
    return temps, unlisted


def verify_dataset(folder: Path) -> list[str]:
    """Every problem found in the dataset at ``folder`` (empty when it checks out).

    Checks each listed shard (presence, size, sha256, fields, shapes, dtypes, content digest),
    the manifest's counts, and reports temporary or unlisted files and missing shards.
    """
    folder = Path(folder)
    manifest = read_manifest(folder)
    identities = identity_digests(manifest)
    problems = [
        p
        for info in manifest.shards
        for p in check_shard(folder, info, manifest.schema, identities)
    ]
    temps, unlisted = stray_files(folder, manifest)
    problems += [f"{p.name}: leftover temporary file of an interrupted run" for p in temps]
    problems += [f"{p.name}: shard file not listed in the manifest" for p in unlisted]
    counts = manifest.counts()
    if not manifest.complete:
        problems.append(
            f"incomplete: {counts['shards']} of {counts['planned_shards']} shards finished "
            "(re-run the same generate command to finish)"
        )
    return problems


class ShardedSamples:
    """Random access to the samples of a dataset, reading HDF5 lazily (nothing preloaded).

    Sample positions run over the finished shards in manifest order. File handles are opened
    on first use and per process, so an object can be handed to ``DataLoader`` workers.
    """

    def __init__(self, folder: Path | str) -> None:
        self.folder = Path(folder)
        self.manifest = read_manifest(self.folder)
        counts = [s.count for s in self.manifest.shards]
        self.offsets = np.concatenate([[0], np.cumsum(counts, dtype=np.int64)])
        self._handles: dict[int, h5py.File] = {}
        self._pid = os.getpid()

    def __len__(self) -> int:
        return int(self.offsets[-1])

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_handles"] = {}
        return state

    def locate(self, position: int) -> tuple[int, int]:
        """(shard number in the manifest, row inside it) of a sample position."""
        if not 0 <= position < len(self):
            raise IndexError(f"sample {position} out of range [0, {len(self)})")
        shard = int(np.searchsorted(self.offsets, position, side="right") - 1)
        return shard, int(position - self.offsets[shard])

    def _handle(self, shard: int) -> h5py.File:
        if os.getpid() != self._pid:
            self._handles, self._pid = {}, os.getpid()
        if shard not in self._handles:
            info = self.manifest.shards[shard]
            path = require_intact(self.folder, info)
            try:
                self._handles[shard] = h5py.File(path, "r")
            except OSError as err:
                raise DatasetError(
                    f"{self.folder / info.file} is corrupt or truncated ({_short(err)}); "
                    f"run: scpformer dataset verify {self.folder}"
                ) from None
        return self._handles[shard]

    def read(self, name: str, position: int, *index: int | slice) -> np.ndarray:
        """One sample's value of field ``name`` (``index`` selects inside it, read lazily)."""
        shard, row = self.locate(position)
        return _read(self._handle(shard), self.manifest.field(name), (row, *index))

    def column(self, name: str) -> np.ndarray:
        """A whole column, shard by shard (meant for small per-sample fields)."""
        f = self.manifest.field(name)
        parts = [_read(self._handle(s), f, ()) for s in range(len(self.manifest.shards))]
        return np.concatenate(parts) if parts else f.empty(0)

    def close(self) -> None:
        """Close every open file."""
        for handle in self._handles.values():
            handle.close()
        self._handles = {}
