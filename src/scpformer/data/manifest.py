"""A dataset's manifest (``DIR/manifest.json``) and the digests that tie its files together.

The manifest holds the family, the full resolved configuration, the seed, versions, the
schema, the shard list, counts and checksums; it is rewritten atomically after every shard.
:func:`identity_digest` is what every shard carries as ``config_sha256``, so that a shard
made with other settings is never adopted; :func:`content_id` identifies a dataset's values
whatever the worker count or backend that produced them.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from scpformer.data.errors import (
    RESUME_HINT,
    DatasetError,
    disk_full_as_error,
    short_message,
)
from scpformer.data.family import Field
from scpformer.files import write_text_atomic
from scpformer.validation import check_int, check_type, known_fields

FORMAT_VERSION = 1
MANIFEST_NAME = "manifest.json"
TMP_SUFFIX = ".tmp"
# The fields a run must share with a folder to resume into it (and the source's content id).
IDENTITY_FIELDS = (
    "format_version",
    "family",
    "kind",
    "seed",
    "n",
    "shard_size",
    "config",
    "transform",
)
SHARD_GLOB = "shard-*.h5"


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
        # a manifest names its shards; a name that leaves the folder ("../x.h5", an absolute path)
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
        identity = {name: getattr(self, name) for name in IDENTITY_FIELDS}
        identity["source"] = (self.source or {}).get("content_id")
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
            raise ValueError(f"field {name!r}, entry {i}: {short_message(err)}") from None
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


def write_manifest(folder: Path | str, manifest: Manifest) -> None:
    """Write ``folder/manifest.json`` atomically (strict JSON: no NaN or infinity).

    Raises
    ------
    DatasetError
        When a value is not finite (JSON has no NaN; the field is named), nothing written.
    DiskFullError
        When the disk fills up, naming the path; the earlier manifest is kept.
    """
    path = Path(folder) / MANIFEST_NAME
    data = manifest.to_dict()
    try:
        text = json.dumps(data, indent=1, allow_nan=False) + "\n"
    except ValueError:
        where = _first_non_finite(data) or "a value"
        raise DatasetError(
            f"{path}: {where} is not a finite number (NaN or infinity), which a manifest cannot "
            "hold; nothing was written"
        ) from None
    with disk_full_as_error(path, RESUME_HINT):
        write_text_atomic(path, text)


def _first_non_finite(value: Any, where: str = "") -> str | None:
    """The dotted name of the first NaN or infinite float inside ``value`` (JSON-like)."""
    if isinstance(value, float) and not math.isfinite(value):
        return where or "a value"
    if isinstance(value, dict):
        items: Any = value.items()
    else:
        items = enumerate(value) if isinstance(value, list | tuple) else ()
    for key, item in items:
        found = _first_non_finite(item, f"{where}.{key}" if where else str(key))
        if found is not None:
            return found
    return None


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
    if path.is_dir():
        raise DatasetError(f"{path} is a folder, not a manifest file: no dataset in {folder}")
    if not path.is_file():
        hint = ""
        if any(Path(folder).glob(SHARD_GLOB)):
            hint = f"; its shards remain: rebuild it with `scpformer dataset repair {folder}`"
        raise DatasetError(f"no dataset in {folder} ({MANIFEST_NAME} not found{hint})")
    damaged = f"{path}: the manifest is damaged"
    try:
        data = json.loads(path.read_text(), parse_constant=_refuse_constant)
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise DatasetError(f"{damaged} (not valid JSON: {err})") from None
    except ValueError as err:  # NaN or Infinity, which JSON does not have
        raise DatasetError(f"{damaged} (not valid JSON: {err})") from None
    if not isinstance(data, dict):
        raise DatasetError(f"{damaged} (a JSON {type(data).__name__}, not an object)")
    try:
        manifest = Manifest.from_dict(data)
    except KeyError as err:
        raise DatasetError(f"{damaged} (it has no field {err})") from None
    except (TypeError, ValueError) as err:  # the JSON itself was read above
        raise DatasetError(f"{damaged} ({err})") from None
    if not isinstance(data.get("shards"), list):
        raise DatasetError(f"{damaged} (it has no list of shards)")
    inconsistency = _inconsistency(manifest, data)
    if inconsistency is not None:
        raise DatasetError(f"{damaged} ({inconsistency})")
    return manifest


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON value")


def _inconsistency(manifest: Manifest, data: Mapping[str, Any]) -> str | None:
    """Why a read manifest contradicts itself (an edited ``n``, plan or shard list), or None.

    Every manifest this package writes lists shards that lie on its plan and records the
    counts derived from them; an edit to one without the other shows here.
    """
    planned = set(manifest.planned_ranges())
    for shard in manifest.shards:
        if (shard.start, shard.stop) not in planned:
            return (
                f"shard {shard.file} covers [{shard.start}, {shard.stop}), which is not a shard "
                f"of the plan for n = {manifest.n}"
            )
    written = data.get("counts")
    if written is not None and written != manifest.counts():
        if not isinstance(written, dict):
            return "its counts are not a JSON object"
        differ = [k for k, v in manifest.counts().items() if written.get(k) != v]
        return f"its counts ({', '.join(differ)}) do not match its shards and n = {manifest.n}"
    if "complete" in data and data["complete"] != manifest.complete:
        return f"it says complete = {data['complete']} of its shards and n = {manifest.n}"
    return None


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
