"""Shard files (``DIR/shard-00000.h5``): writing, reading and checking them.

A shard holds samples [start, stop): one HDF5 dataset per field, shape (count, *field.shape);
its attributes repeat the shard's identity (:func:`scpformer.data.manifest.shard_header`). A
shard's ``sha256`` covers its bytes; its ``content_sha256`` covers the values of the
deterministic fields only (timings excluded), so two runs with the same seed have equal
content digests whatever the worker count or backend. Every reader checks a shard's sha256
before its first use in a process (:func:`require_intact`).
"""

from __future__ import annotations

import hashlib
import io
from collections import Counter
from collections.abc import Collection, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from scpformer.data.errors import (
    RESUME_HINT,
    DatasetError,
    disk_full_as_error,
    short_message,
)
from scpformer.data.family import Field
from scpformer.data.manifest import (
    MANIFEST_NAME,
    SHARD_GLOB,
    TMP_SUFFIX,
    Manifest,
    ShardInfo,
    file_sha256,
    identity_digests,
    read_manifest,
    write_manifest,
)
from scpformer.files import interrupts_deferred, write_bytes_atomic

_CHUNK_BYTES = 1 << 16  # target HDF5 chunk size of compressed fields
_COMPRESS_MIN = 16  # compress fields with at least this many elements per sample


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
    if path.is_dir():
        return f"{info.file}: a folder, not a shard file"
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


def require_consistent(folder: Path, manifest: Manifest) -> None:
    """Check that every listed shard was made for this manifest (its ``config_sha256`` is one
    of :func:`~scpformer.data.manifest.identity_digests`), as ``dataset verify`` does.

    An edited ``family``, seed, ``n`` or configuration in ``manifest.json`` shows here,
    before anything is read or written on its word. Reads each shard's attributes only (a
    missing or damaged shard is left to the checksum check of whatever reads it).

    Raises
    ------
    DatasetError
        Naming the manifest and the first shard that disagrees, or a damaged shard.
    """
    folder = Path(folder)
    identities = identity_digests(manifest)
    for info in manifest.shards:
        path = folder / info.file
        if not path.is_file():
            continue  # a missing shard is reported where it is read, and by verify
        try:
            made_with = shard_attrs(path).get("config_sha256")
        except DatasetError:
            continue  # likewise a damaged one
        if made_with is not None and str(made_with) not in identities:
            raise DatasetError(
                f"{folder / MANIFEST_NAME}: the manifest is damaged (its family, seed, n or "
                f"configuration differ from those {info.file} was made with); see "
                f"`scpformer dataset verify {folder}`"
            )


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
    with disk_full_as_error(f"{path.name} in {path.parent}", RESUME_HINT):
        write_bytes_atomic(path, data)
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
            return {f.name: read_field(h5, f, ()) for f in wanted}
    except (OSError, KeyError, RuntimeError) as err:
        raise DatasetError(f"{path} is corrupt or truncated ({short_message(err)})") from None


def read_field(h5: h5py.File, f: Field, where: Any) -> np.ndarray:
    """Field ``f`` of an open shard at index ``where`` (strings as object arrays of ``str``)."""
    ds = h5[f.name]
    if f.dtype == "str":
        return np.asarray(ds.asstr()[where], dtype=object)
    return np.asarray(ds[where])


def shard_attrs(path: Path) -> dict[str, Any]:
    """The attributes of a shard file (its identity and content digest)."""
    try:
        with h5py.File(path, "r") as h5:
            return {k: (v.item() if hasattr(v, "item") else v) for k, v in h5.attrs.items()}
    except (OSError, RuntimeError) as err:
        raise DatasetError(f"{path} is corrupt or truncated ({short_message(err)})") from None


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
        return [f"{info.file}: unreadable ({short_message(err)})"]
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
