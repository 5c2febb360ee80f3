"""Train/validation/test splits grouped by base instance, and training-set statistics.

Samples that share a group key (by default ``base_index``: the solved instance a sample comes
from) always land in the same split, so the rotated copies of one instance, or the convex and
SCP twins of one rendezvous, never straddle train and test -- the leak of the public ART code.
Groups, not samples, are shuffled with a seeded Generator and cut by the given fractions (the
T-SCvx paper uses 80% train and validation, 20% test).

Normalization statistics (per-element mean and standard deviation of every field marked
``normalize``) are computed on the training split only, over samples with a success status,
streaming shard by shard, and stored with the splits in ``DIR/splits.h5``.
"""

from __future__ import annotations

import hashlib
import io
import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path

import h5py
import numpy as np

from scpformer.data import storage
from scpformer.data.errors import DatasetError, disk_full_as_error, short_message
from scpformer.data.storage import ShardedSamples
from scpformer.files import write_bytes_atomic

SPLITS_NAME = "splits.h5"
SPLIT_NAMES = ("train", "validation", "test")
STD_FLOOR = 1e-12  # a feature whose std is below this is constant: its std is stored as 1


@dataclass(frozen=True, kw_only=True)
class SplitConfig:
    """How to split; defaults follow the T-SCvx paper (Sec. III.E.3: 80/20)."""

    fractions: tuple[float, float, float] = (0.8, 0.0, 0.2)  # train, validation, test (groups)
    seed: int = 0  # seed of the group permutation
    group_field: str = "base_index"  # samples with equal values stay in one split

    def __post_init__(self) -> None:
        fractions = tuple(float(f) for f in self.fractions)
        nonnegative = all(f >= 0.0 for f in fractions)  # False for NaN as well
        if len(fractions) != 3 or not nonnegative or not abs(sum(fractions) - 1.0) <= 1e-9:
            raise ValueError(
                f"fractions must be 3 nonnegative numbers summing to 1, got {fractions}"
            )
        object.__setattr__(self, "fractions", fractions)


@dataclass(frozen=True)
class Stats:
    """Per-element training statistics of one field."""

    mean: np.ndarray  # field shape
    std: np.ndarray  # field shape, floored (see STD_FLOOR)
    count: np.ndarray  # finite training values per element


@dataclass(frozen=True)
class Splits:
    """Sample positions of each split and the training statistics."""

    indices: dict[str, np.ndarray]  # split name -> sorted sample positions
    stats: dict[str, Stats]  # field name -> statistics on the training split
    config: SplitConfig
    content_id: str  # storage.content_id of the dataset they were made for

    def normalize(self, name: str, value: np.ndarray) -> np.ndarray:
        """``(value - mean) / std`` of field ``name`` (unchanged when it has no statistics)."""
        if name not in self.stats:
            return value
        return (value - self.stats[name].mean) / self.stats[name].std

    def denormalize(self, name: str, value: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`normalize`."""
        if name not in self.stats:
            return value
        return value * self.stats[name].std + self.stats[name].mean


def assign_groups(
    groups: np.ndarray, fractions: tuple[float, float, float], seed: int
) -> dict[str, np.ndarray]:
    """Sample positions per split, cutting a seeded permutation of the distinct groups."""
    unique = np.unique(groups)
    order = np.random.default_rng(seed).permutation(unique)
    n_train = round(fractions[0] * len(unique))
    n_val = min(round(fractions[1] * len(unique)), len(unique) - n_train)
    cuts = {
        "train": order[:n_train],
        "validation": order[n_train : n_train + n_val],
        "test": order[n_train + n_val :],
    }
    return {name: np.flatnonzero(np.isin(groups, members)) for name, members in cuts.items()}


def leaking_groups(indices: Mapping[str, np.ndarray], groups: np.ndarray) -> np.ndarray:
    """Group values that occur in more than one split (empty for grouped splits)."""
    members = [np.unique(groups[positions]) for positions in indices.values()]
    together = np.concatenate(members) if members else np.array([])
    values, counts = np.unique(together, return_counts=True)
    return values[counts > 1]


def training_stats(samples: ShardedSamples, train: np.ndarray) -> dict[str, Stats]:
    """Per-element mean and std of every ``normalize`` field over ``train`` successes."""
    manifest = samples.manifest
    status = samples.column("status").astype(str)
    chosen = np.zeros(len(samples), dtype=bool)
    chosen[train] = True
    chosen &= np.isin(status, list(manifest.success_statuses))
    names = [f.name for f in manifest.schema if f.normalize]
    acc = {name: _Moments() for name in names}
    for number, info in enumerate(manifest.shards):
        lo, hi = samples.offsets[number], samples.offsets[number + 1]
        rows = np.flatnonzero(chosen[lo:hi])
        if rows.size == 0:
            continue
        columns = storage.read_columns(
            storage.require_intact(samples.folder, info), manifest.schema, names
        )
        for name in names:
            acc[name].add(columns[name][rows].astype(float))
    return {name: acc[name].stats() for name in names}


class _Moments:
    """Streaming per-element count, mean and M2 (Chan et al.), NaN-aware."""

    def __init__(self) -> None:
        self.n = self.mean = self.m2 = None

    def add(self, values: np.ndarray) -> None:
        finite = np.isfinite(values)
        n = finite.sum(axis=0)
        filled = np.where(finite, values, 0.0)
        mean = filled.sum(axis=0) / np.maximum(n, 1)
        m2 = (np.where(finite, values - mean, 0.0) ** 2).sum(axis=0)
        if self.n is None:
            self.n, self.mean, self.m2 = n, mean, m2
            return
        total = self.n + n
        delta = mean - self.mean
        weight = np.divide(n, total, out=np.zeros_like(delta), where=total > 0)
        self.mean = self.mean + delta * weight
        self.m2 = self.m2 + m2 + delta**2 * self.n * weight
        self.n = total

    def stats(self) -> Stats:
        if self.n is None:
            raise DatasetError("the training split holds no solved sample to normalize with")
        std = np.sqrt(self.m2 / np.maximum(self.n, 1))
        return Stats(mean=self.mean, std=np.where(std < STD_FLOOR, 1.0, std), count=self.n)


def make_splits(
    folder: Path | str, config: SplitConfig | None = None, *, force: bool = False
) -> Splits:
    """Split the dataset at ``folder`` by groups, compute training statistics, store both.

    Splits already stored with the same configuration for the same data are returned as they
    are (nothing written). Other splits are replaced only with ``force``: a trained run
    depends on the splits it was trained with.

    Raises
    ------
    DatasetError
        When the dataset is incomplete or inconsistent (:func:`storage.require_consistent`),
        or ``folder`` holds other splits and ``force`` is false.
    """
    config = config or SplitConfig()
    folder = Path(folder)
    samples = ShardedSamples(folder)
    try:
        if not samples.manifest.complete:
            raise DatasetError(f"{folder} is incomplete: finish it before splitting")
        storage.require_consistent(folder, samples.manifest)
        content = storage.content_id(samples.manifest)
        existing = _existing_splits(folder, config, content, force)
        if existing is not None:
            return existing
        groups = samples.column(config.group_field)
        indices = assign_groups(groups, config.fractions, config.seed)
        splits = Splits(
            indices=indices,
            stats=training_stats(samples, indices["train"]),
            config=config,
            content_id=content,
        )
    finally:
        samples.close()
    write_splits(folder, splits)
    return splits


def _existing_splits(folder: Path, config: SplitConfig, content: str, force: bool) -> Splits | None:
    """The stored splits when they are the ones ``config`` makes for this data; ``None`` when
    there are none, or they differ and ``force`` allows replacing them."""
    path = folder / SPLITS_NAME
    if not path.exists():
        return None
    again = f"`scpformer dataset split {folder} --force` replaces them"
    try:
        old = load_splits(folder)
    except DatasetError as err:
        if force:
            return None
        raise DatasetError(f"{err}; {again}") from None
    if old.config == config and old.content_id == content:
        return old
    if force:
        return None
    if old.content_id != content:
        why = "made for other data"
    else:
        old_c, new_c = asdict(old.config), asdict(config)
        why = (
            "made with other settings ("
            + ", ".join(
                f"{k} {old_c[k]} there, {new_c[k]} here" for k in old_c if old_c[k] != new_c[k]
            )
            + ")"
        )
    raise DatasetError(f"{path} exists, {why}, and runs trained on it depend on it; {again}")


def splits_digest(splits: Splits) -> str:
    """sha256 over everything a ``splits.h5`` holds: configuration, data identity, sample
    positions and statistics (stored with them and checked by :func:`load_splits`)."""
    digest = hashlib.sha256()
    digest.update(json.dumps(asdict(splits.config), sort_keys=True).encode())
    digest.update(splits.content_id.encode())
    for name in sorted(splits.indices):
        digest.update(f"|indices/{name}|".encode())
        digest.update(np.ascontiguousarray(splits.indices[name], dtype=np.int64).tobytes())
    for name in sorted(splits.stats):
        for key in ("mean", "std", "count"):
            value = np.ascontiguousarray(getattr(splits.stats[name], key), dtype=np.float64)
            digest.update(f"|stats/{name}/{key}|{value.shape}|".encode())
            digest.update(value.tobytes())
    return digest.hexdigest()


def write_splits(folder: Path, splits: Splits) -> None:
    """Write ``folder/splits.h5`` atomically, with its :func:`splits_digest`.

    The file is built in memory and written with one plain write, so that a full disk fails
    one write (naming the path, no temporary file left), never inside HDF5.

    Raises
    ------
    DiskFullError
        When the disk fills up; an earlier ``splits.h5`` is kept.
    """
    path = Path(folder) / SPLITS_NAME
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as h5:
        h5.attrs["config"] = json.dumps(asdict(splits.config))
        h5.attrs["content_id"] = splits.content_id
        h5.attrs["sha256"] = splits_digest(splits)
        for name, positions in splits.indices.items():
            h5.create_dataset(f"indices/{name}", data=positions.astype(np.int64))
        for name, stats in splits.stats.items():
            for key in ("mean", "std", "count"):
                h5.create_dataset(f"stats/{name}/{key}", data=getattr(stats, key))
    with disk_full_as_error(path, "nothing was changed: free space and re-run"):
        write_bytes_atomic(path, buffer.getvalue())


def load_splits(folder: Path | str) -> Splits:
    """The splits stored with the dataset at ``folder``, after checking their checksum.

    Raises
    ------
    DatasetError
        When there are none, they are damaged (checksum, positions out of range, statistics
        that are not finite), or they were made for different data.
    """
    folder = Path(folder)
    path = folder / SPLITS_NAME
    if path.is_dir():
        raise DatasetError(f"{path} is a folder, not a splits file")
    if not path.is_file():
        raise DatasetError(f"no splits in {folder}: run `scpformer dataset split {folder}` first")
    remake = f"remake it with `scpformer dataset split {folder} --force`"
    try:
        with h5py.File(path, "r") as h5:
            config = SplitConfig(**json.loads(h5.attrs["config"]))
            indices = {name: h5[f"indices/{name}"][()] for name in SPLIT_NAMES}
            stats = {
                name: Stats(*(h5[f"stats/{name}/{k}"][()] for k in ("mean", "std", "count")))
                for name in h5.get("stats", {})
            }
            content = str(h5.attrs["content_id"])
            stored = h5.attrs.get("sha256")
    except (OSError, KeyError, TypeError, ValueError) as err:
        raise DatasetError(f"{path} is damaged ({short_message(err)}); {remake}") from None
    splits = Splits(indices=indices, stats=stats, config=config, content_id=content)
    if stored is None:
        raise DatasetError(f"{path} carries no checksum (an older scpformer made it); {remake}")
    if str(stored) != splits_digest(splits):
        raise DatasetError(f"{path} is damaged (its checksum differs from its content); {remake}")
    manifest = storage.read_manifest(folder)
    if content != storage.content_id(manifest):
        raise DatasetError(f"{path} was made for different data; {remake}")
    n = sum(s.count for s in manifest.shards)
    for name, positions in indices.items():
        if positions.size and (positions.min() < 0 or positions.max() >= n):
            raise DatasetError(
                f"{path} is damaged: split {name!r} holds sample positions outside [0, {n}); "
                f"{remake}"
            )
    for name, field_stats in stats.items():
        if not (np.isfinite(field_stats.mean).all() and np.isfinite(field_stats.std).all()):
            raise DatasetError(
                f"{path} is damaged: the statistics of {name!r} are not finite (NaN or "
                f"infinity), which would train to NaN; {remake}"
            )
    return splits


def check_splits(folder: Path | str) -> list[str]:
    """Problems of the stored splits: stale, overlapping, leaking groups, out of range."""
    folder = Path(folder)
    if not (folder / SPLITS_NAME).is_file():
        return []
    try:
        splits = load_splits(folder)
    except DatasetError as err:
        return [str(err)]
    samples = ShardedSamples(folder)
    try:
        groups = samples.column(splits.config.group_field)
    finally:
        samples.close()
    problems = []
    every = np.concatenate(list(splits.indices.values()))
    if every.size and (every.min() < 0 or every.max() >= len(groups)):
        problems.append(f"{SPLITS_NAME}: sample positions out of range")
        return problems
    if len(np.unique(every)) != len(every):
        problems.append(f"{SPLITS_NAME}: a sample is in more than one split")
    leaks = leaking_groups(splits.indices, groups)
    if leaks.size:
        problems.append(f"{SPLITS_NAME}: {len(leaks)} group(s) straddle splits")
    return problems
