"""One split of a ``pdg6dof`` dataset as in-memory arrays, for non-torch consumers.

The lookup-table baselines of T-SCvx (paper Sec. IV.C) and the measurements of Tables 4-5
need whole splits as plain arrays rather than lazily read torch items. They see exactly the
items of :class:`~scpformer.data.torch_views.SolutionDataset` (one per solved sample) and
:class:`~scpformer.data.torch_views.TightFlagsDataset` (one per sample and SCvx iteration
``k = 1..iterations``), read shard by shard so that the ``(iter_max, 7 N)`` flag column is
never held whole.

The solution of a sample is flattened as the solution network predicts it (the solution
network's contract): ``[x.ravel(), u.ravel(), t_f]``, ``N * 17 + 1`` values.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scpformer.data import storage
from scpformer.data.splits import Splits
from scpformer.data.torch_views import SolutionDataset

N_THETA = 16  # len(THETA_NAMES)
SOLUTION_FIELDS = ("x", "u", "tf")


@dataclass(frozen=True, eq=False)
class SplitArrays:
    """The solved samples of one split, and their (theta, k) -> flags items."""

    positions: np.ndarray  # (S,) sample positions in the dataset
    theta: np.ndarray  # (S, 16) raw instance parameters
    solution: np.ndarray  # (S, N * 17 + 1) raw flattened (x, u, t_f)
    item_sample: np.ndarray  # (I,) row of ``theta`` each tight item belongs to
    item_k: np.ndarray  # (I,) 1-based SCvx iteration k
    flags: np.ndarray  # (I, 7 N) bool tight flags of iteration k
    n_nodes: int  # N
    splits: Splits  # the dataset's splits and training statistics
    content_id: str  # storage.content_id of the dataset

    @property
    def item_theta(self) -> np.ndarray:
        """(I, 16) theta of every tight item."""
        return self.theta[self.item_sample]


def flatten_solution(x: np.ndarray, u: np.ndarray, tf: np.ndarray) -> np.ndarray:
    """``(..., N, 14), (..., N, 3), (...)`` -> ``(..., N * 17 + 1)`` as ``[x, u, t_f]``."""
    lead = np.shape(tf)
    return np.concatenate(
        [np.reshape(x, (*lead, -1)), np.reshape(u, (*lead, -1)), np.asarray(tf)[..., None]],
        axis=-1,
    )


def unflatten_solution(flat: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of :func:`flatten_solution`: ``(x (..., N, 14), u (..., N, 3), t_f (...))``."""
    lead = flat.shape[:-1]
    if flat.shape[-1] != 17 * n_nodes + 1:
        raise ValueError(f"a flat solution of N={n_nodes} has {17 * n_nodes + 1} values")
    x = flat[..., : 14 * n_nodes].reshape(*lead, n_nodes, 14)
    u = flat[..., 14 * n_nodes : 17 * n_nodes].reshape(*lead, n_nodes, 3)
    return x, u, flat[..., -1]


def solution_stats(splits: Splits) -> tuple[np.ndarray, np.ndarray]:
    """Training mean and std of the flattened solution (``dataset split`` statistics)."""
    missing = [name for name in SOLUTION_FIELDS if name not in splits.stats]
    if missing:
        raise ValueError(f"the splits hold no training statistics of {missing}")
    mean = flatten_solution(*(splits.stats[name].mean for name in SOLUTION_FIELDS))
    std = flatten_solution(*(splits.stats[name].std for name in SOLUTION_FIELDS))
    return mean, std


def read_split_arrays(
    folder: Path | str, split: str = "train", *, accepted_only: bool = False, tight: bool = True
) -> SplitArrays:
    """The solved samples of ``split`` at ``folder`` as arrays (module docstring).

    ``accepted_only`` keeps the tight items of accepted iterations, as ``TightFlagsDataset``;
    ``tight=False`` reads no flags (no items).
    """
    view = SolutionDataset(folder, split, normalize=False)
    samples = view.samples
    try:
        small = ("theta", "iterations", "accepted", *SOLUTION_FIELDS)
        columns = _gather(samples, view.positions, small)
        sample, k0 = _items(columns["iterations"], columns["accepted"], accepted_only)
        if not tight:
            sample, k0 = sample[:0], k0[:0]
        flags = _gather_flags(samples, view.positions, sample, k0)
    finally:
        samples.close()
    return SplitArrays(
        positions=view.positions,
        theta=columns["theta"].astype(float),
        solution=flatten_solution(columns["x"], columns["u"], columns["tf"]),
        item_sample=sample,
        item_k=k0 + 1,
        flags=flags,
        n_nodes=int(samples.manifest.field("x").shape[0]),
        splits=view.splits,
        content_id=storage.content_id(samples.manifest),
    )


def _items(
    iterations: np.ndarray, accepted: np.ndarray, accepted_only: bool
) -> tuple[np.ndarray, np.ndarray]:
    """(sample row, k - 1) of every iteration of every sample, as TightFlagsDataset orders them."""
    counts = np.clip(iterations.astype(np.int64), 0, accepted.shape[1] if accepted.ndim else 0)
    sample = np.repeat(np.arange(len(counts)), counts)
    k0 = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    if accepted_only and len(sample):
        keep = accepted[sample, k0]
        sample, k0 = sample[keep], k0[keep]
    return sample, k0


def _shard_rows(samples: storage.ShardedSamples, positions: np.ndarray):
    """Per finished shard: (path, rows of ``positions`` inside it, their slice of positions)."""
    for number, info in enumerate(samples.manifest.shards):
        lo, hi = samples.offsets[number], samples.offsets[number + 1]
        start, stop = np.searchsorted(positions, [lo, hi])
        if stop > start:
            path = storage.require_intact(samples.folder, info)
            yield path, positions[start:stop] - lo, slice(start, stop)


def _gather(
    samples: storage.ShardedSamples, positions: np.ndarray, names: tuple[str, ...]
) -> dict[str, np.ndarray]:
    """Rows ``positions`` (sorted) of the fields ``names``, reading one shard at a time."""
    manifest = samples.manifest
    parts: dict[str, list[np.ndarray]] = {name: [] for name in names}
    for path, rows, _ in _shard_rows(samples, positions):
        columns = storage.read_columns(path, manifest.schema, names)
        for name in names:
            parts[name].append(columns[name][rows])
    return {
        name: np.concatenate(chunks) if chunks else manifest.field(name).empty(0)
        for name, chunks in parts.items()
    }


def _gather_flags(
    samples: storage.ShardedSamples, positions: np.ndarray, sample: np.ndarray, k0: np.ndarray
) -> np.ndarray:
    """(I, 7 N) tight flags of the items (row ``sample`` of ``positions``, iteration ``k0``)."""
    schema = samples.manifest.schema
    width = samples.manifest.field("tight_flags").shape[1]
    flags = np.zeros((len(sample), width), dtype=bool)
    for path, rows, where in _shard_rows(samples, positions):
        chosen = (sample >= where.start) & (sample < where.stop)
        if chosen.any():
            column = storage.read_columns(path, schema, ("tight_flags",))["tight_flags"]
            flags[chosen] = column[rows[sample[chosen] - where.start], k0[chosen]]
    return flags
