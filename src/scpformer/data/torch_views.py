"""PyTorch ``Dataset`` views of stored datasets, read lazily from the HDF5 shards.

Nothing is loaded into RAM beyond the small per-sample columns used for indexing (status,
iteration counts); every item is read from its shard when asked for. With ``normalize`` the
fields that have training statistics (``DIR/splits.h5``, see :mod:`scpformer.data.splits`)
are standardized, as the T-SCvx paper does (Sec. III.E.3).

T-SCvx (6-DoF powered descent), one view per network:

* :class:`TightFlagsDataset` -- (theta, k) -> tight-constraint flags at SCvx iteration k, the
  input and target of the tight-constraint classifier;
* :class:`SolutionDataset` -- theta -> (x, u, t_f), those of the solution network.

ART (rendezvous and robust rendezvous):

* :class:`ArtSequenceDataset` -- per trajectory twin (convex and SCP) of each instance, the
  sequences (reward-to-go, constraint-to-go, state, action) ART trains on.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.data import Dataset

from scpformer.data.errors import DatasetError
from scpformer.data.splits import SPLIT_NAMES, STD_FLOOR, Splits, Stats, load_splits
from scpformer.data.storage import Manifest, ShardedSamples


class _StoredView(Dataset):
    """Samples of one split with chosen statuses, normalized on demand."""

    family: str = ""

    def __init__(
        self,
        folder: Path | str,
        split: str | None = "train",
        *,
        normalize: bool = True,
        statuses: Sequence[str] | None = None,
    ) -> None:
        self.samples = ShardedSamples(folder)
        manifest = self.samples.manifest
        if self.family and manifest.family != self.family:
            raise DatasetError(
                f"{type(self).__name__} reads {self.family} data, not {manifest.family}"
            )
        if split is not None and split not in SPLIT_NAMES:
            raise ValueError(f"split must be one of {SPLIT_NAMES} or None, got {split!r}")
        self.splits: Splits | None = load_splits(folder) if (normalize or split) else None
        self.normalize = normalize
        self.wanted = manifest.success_statuses if statuses is None else tuple(statuses)
        self.in_split = self._split_mask(split)
        chosen = self._status_mask("status") & self.in_split
        self.positions = np.flatnonzero(chosen)  # sample positions served by this view

    def _split_mask(self, split: str | None) -> np.ndarray:
        """Which sample positions belong to ``split`` (every one for None)."""
        if split is None:
            return np.ones(len(self.samples), dtype=bool)
        in_split = np.zeros(len(self.samples), dtype=bool)
        in_split[self.splits.indices[split]] = True
        return in_split

    def _status_mask(self, field: str) -> np.ndarray:
        """Which samples have a wanted status in the string column ``field``."""
        return np.isin(self.samples.column(field).astype(str), list(self.wanted))

    def _value(self, name: str, position: int) -> torch.Tensor:
        value = self.samples.read(name, position).astype(np.float64)
        if self.normalize and self.splits is not None:
            value = self.splits.normalize(name, value)
        return torch.as_tensor(value, dtype=torch.float32)


class TightFlagsDataset(_StoredView):
    """(theta, k) -> tight-constraint flags of SCvx iteration k (T-SCvx classifier).

    One item per (sample, iteration): ``theta`` (16,) float, ``k`` () int64 (1-based SCvx
    iteration), ``flags`` (7 N,) float 0/1 in the (name, node) order of
    :func:`scpformer.problems.pdg6dof.constraints.constraint_index`.
    ``accepted_only`` keeps the iterations whose step was accepted.
    """

    family = "pdg6dof"

    def __init__(
        self, folder: Path | str, split: str | None = "train", *, accepted_only: bool = False,
        **view: Any,
    ) -> None:  # fmt: skip
        """``view``: ``normalize`` and ``statuses`` of every stored view."""
        super().__init__(folder, split, **view)
        iterations = self.samples.column("iterations")[self.positions]
        pairs = [(p, k) for p, n in zip(self.positions, iterations, strict=True) for k in range(n)]
        items = np.array(pairs, dtype=np.int64).reshape(-1, 2)  # (items, 2): position, k - 1
        if accepted_only and len(items):
            accepted = self.samples.column("accepted")
            items = items[accepted[items[:, 0], items[:, 1]]]
        self.items = items

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        position, k0 = (int(v) for v in self.items[i])
        flags = self.samples.read("tight_flags", position, k0)
        return {
            "theta": self._value("theta", position),  # (16,)
            "k": torch.tensor(k0 + 1, dtype=torch.int64),  # ()
            "flags": torch.as_tensor(flags, dtype=torch.float32),  # (7N,)
        }


class SolutionDataset(_StoredView):
    """theta -> solution (x, u, t_f) (T-SCvx solution network).

    One item per sample: ``theta`` (16,), ``x`` (N, 14), ``u`` (N, 3), ``tf`` (), all float32
    and standardized when ``normalize``.
    """

    family = "pdg6dof"

    def __len__(self) -> int:
        return len(self.positions)

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        position = int(self.positions[i])
        return {name: self._value(name, position) for name in ("theta", "x", "u", "tf")}


# -- ART (rendezvous families) -------------------------------------------------------------------
ART_FAMILIES = ("rendezvous", "robust-rendezvous")
ART_FRAMES = ("rtn", "roe")
# Twins stored as references (the rendezvous Problem 1 twin: Table 2, the CVX-TPBVP warm start),
# served only when asked for by name: ART learns from Problems 2 and 3 (ART paper Sec. 3).
REFERENCE_TWINS = ("tpbvp",)


def art_twins(manifest: Manifest) -> tuple[str, ...]:
    """Twin prefixes ``p`` of a dataset whose schema holds ``p_status, p_dv, p_rtg, p_ctg``."""
    names = {f.name for f in manifest.schema}
    suffixes = ("_status", "_roe", "_rtn", "_dv", "_rtg", "_ctg")
    prefixes = [f.name[: -len("_dv")] for f in manifest.schema if f.name.endswith("_dv")]
    return tuple(p for p in prefixes if all(p + s in names for s in suffixes))


def training_twins(manifest: Manifest) -> tuple[str, ...]:
    """The twins ART learns from unless told otherwise: the stored ones but the references."""
    return tuple(p for p in art_twins(manifest) if p not in REFERENCE_TWINS)


def pooled_stats(stats: Sequence[Stats]) -> tuple[np.ndarray, np.ndarray]:
    """Per-element mean and std of the union of the samples behind ``stats``.

    Chan's parallel formula on (count, mean, std). A std equal to 1.0 exactly is taken as one
    that :mod:`scpformer.data.splits` floored (a constant element, variance ~0); the pooled std
    is floored the same way.
    """
    counts = np.stack([s.count for s in stats]).astype(float)
    means = np.stack([s.mean for s in stats])
    variances = np.stack([np.where(s.std == 1.0, 0.0, s.std**2) for s in stats])
    total = counts.sum(axis=0)
    weights = np.divide(counts, total, out=np.zeros_like(counts), where=total > 0)
    mean = (weights * means).sum(axis=0)
    var = (weights * (variances + (means - mean) ** 2)).sum(axis=0)
    std = np.sqrt(var)
    return mean, np.where(std < STD_FLOOR, 1.0, std)


class ArtSequenceDataset(_StoredView):
    """ART sequences (reward-to-go, constraint-to-go, state, action) of the rendezvous twins.

    Every sample of a rendezvous dataset holds trajectories of one instance, the convex
    (``cvx``, Problem 2) and the SCP (``scp``, Problem 3) twin, which ART trains on, and in
    newer datasets the TPBVP (``tpbvp``, Problem 1) twin, served only when ``twins`` names it
    (:data:`REFERENCE_TWINS`). Twins share the sample, hence its ``base_index``, so grouped
    splits never separate them.

    One item per (sample, twin) whose own status (``p_status``) is wanted, with N impulses:

    ==========  ========  =========================================================
    key         shape     meaning
    ==========  ========  =========================================================
    rtg         (N, 1)    reward-to-go ``R(t_k)`` [m/s], ``k = 0..N-1``
    ctg         (N, 1)    constraint-to-go ``C(t_k)``
    state       (N, 6)    state at ``t_k`` before the impulse, in ``frame``
    action      (N, 3)    impulse ``dv_k`` in RTN [m/s]
    t           (N,)      node times [s] (the horizon varies between instances)
    theta       (13,)     instance parameters
    twin        ()        index of the twin in :attr:`twins` (int64)
    base_index  ()        the solved instance (int64)
    ==========  ========  =========================================================

    All but ``twin`` and ``base_index`` are float32. With ``normalize``, ``state``, ``action``
    and ``theta`` are standardized per element with statistics of the training split only
    (``dataset split``); states and actions use the statistics pooled over the twins the view
    serves, so that one physical state has one normalized value whichever twin it is in.
    ``rtg`` and ``ctg`` are served raw, as ART conditions on them. With ``pairs`` there is one
    item per sample whose requested twins all have a wanted status, holding every key above
    prefixed by the twin (``scp_state``, ``cvx_state``, ...) plus ``base_index``.

    Parameters
    ----------
    folder
        Dataset folder (``rendezvous`` or ``robust-rendezvous``).
    split
        ``train``, ``validation``, ``test`` or None (every sample).
    frame
        State representation: ``rtn`` (Psi x, [m, m/s]) or ``roe`` (a dalpha, [m]).
    twins
        Which twins to serve (default: :func:`training_twins`, every stored twin but the
        Problem 1 reference).
    normalize, statuses
        As in the other views; ``statuses`` applies to each twin's own status.
    pairs
        One item per sample with all requested twins instead of one per twin.
    """

    def __init__(
        self,
        folder: Path | str,
        split: str | None = "train",
        *,
        frame: str = "rtn",
        twins: Sequence[str] | None = None,
        normalize: bool = True,
        statuses: Sequence[str] | None = None,
        pairs: bool = False,
    ) -> None:
        super().__init__(folder, split, normalize=normalize, statuses=statuses)
        manifest = self.samples.manifest
        if manifest.family not in ART_FAMILIES:
            raise DatasetError(
                f"ArtSequenceDataset reads {' or '.join(ART_FAMILIES)} data, not {manifest.family}"
            )
        if frame not in ART_FRAMES:
            raise ValueError(f"frame must be one of {ART_FRAMES}, got {frame!r}")
        stored = art_twins(manifest)
        self.twins = training_twins(manifest) if twins is None else tuple(twins)
        unknown = sorted(set(self.twins) - set(stored))
        if unknown or not self.twins:
            raise ValueError(f"twins must be a non-empty subset of {stored}, got {self.twins}")
        self.frame, self.pairs = frame, pairs
        self.n_steps = manifest.field(f"{self.twins[0]}_dv").shape[0]
        self.items = self._items()  # (items, 2): sample position, twin number (-1: pair)
        self.base_index = self.samples.column("base_index")  # small indexing column
        self._stats = self._pooled(self.twins) if normalize else {}

    def _items(self) -> np.ndarray:
        ok = np.stack([self._status_mask(f"{p}_status") & self.in_split for p in self.twins])
        if self.pairs:
            positions = np.flatnonzero(ok.all(axis=0))
            return np.stack([positions, np.full_like(positions, -1)], axis=1)
        twin, position = np.nonzero(ok)
        order = np.lexsort((twin, position))  # by sample, then twin: twins stay adjacent
        return np.stack([position[order], twin[order]], axis=1).astype(np.int64)

    def _pooled(self, stored: Sequence[str]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        out = {}
        for key, suffix in (("state", f"_{self.frame}"), ("action", "_dv")):
            names = [p + suffix for p in stored]
            missing = [n for n in names if n not in self.splits.stats]
            if missing:
                raise DatasetError(f"the splits hold no training statistics of {missing}")
            out[key] = pooled_stats([self.splits.stats[n] for n in names])
        return out

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        position, twin = (int(v) for v in self.items[i])
        base = torch.tensor(int(self.base_index[position]), dtype=torch.int64)
        if twin >= 0:
            return {**self._twin_item(position, twin), "base_index": base}
        items = {}
        for number, prefix in enumerate(self.twins):
            item = self._twin_item(position, number)
            items.update({f"{prefix}_{key}": value for key, value in item.items()})
        return {**items, "base_index": base}

    def _twin_item(self, position: int, twin: int) -> dict[str, torch.Tensor]:
        p, n = self.twins[twin], self.n_steps
        read = self.samples.read
        return {
            "rtg": _float32(read(f"{p}_rtg", position, slice(0, n))[:, None]),
            "ctg": _float32(read(f"{p}_ctg", position, slice(0, n))[:, None]),
            "state": self._standard("state", read(f"{p}_{self.frame}", position, slice(0, n))),
            "action": self._standard("action", read(f"{p}_dv", position)),
            "t": _float32(read("t", position, slice(0, n))),
            "theta": self._value("theta", position),
            "twin": torch.tensor(twin, dtype=torch.int64),
        }

    def _standard(self, key: str, value: np.ndarray) -> torch.Tensor:
        if key in self._stats:
            mean, std = self._stats[key]
            n = value.shape[0]
            value = (value - mean[:n]) / std[:n]
        return _float32(value)


def _float32(value: np.ndarray) -> torch.Tensor:
    return torch.as_tensor(np.asarray(value, dtype=np.float64), dtype=torch.float32)
