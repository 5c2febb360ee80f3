"""PyTorch ``Dataset`` views of stored datasets, read lazily from the HDF5 shards.

Nothing is loaded into RAM beyond the small per-sample columns used for indexing (status,
iteration counts); every item is read from its shard when asked for. With ``normalize`` the
fields that have training statistics (``DIR/splits.h5``, see :mod:`scpformer.data.splits`)
are standardized, as the T-SCvx paper does (Sec. III.E.3).

T-SCvx (6-DoF powered descent), one view per network:

* :class:`TightFlagsDataset` -- (theta, k) -> tight-constraint flags at SCvx iteration k, the
  input and target of the tight-constraint classifier;
* :class:`SolutionDataset` -- theta -> (x, u, t_f), those of the solution network.

Views of the rendezvous families (ART sequences) belong next to these when those land.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from scpformer.data.errors import DatasetError
from scpformer.data.splits import SPLIT_NAMES, Splits, load_splits
from scpformer.data.storage import ShardedSamples


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
        wanted = manifest.success_statuses if statuses is None else tuple(statuses)
        status = self.samples.column("status").astype(str)
        chosen = np.isin(status, list(wanted))
        if split is not None:
            in_split = np.zeros(len(self.samples), dtype=bool)
            in_split[self.splits.indices[split]] = True
            chosen &= in_split
        self.positions = np.flatnonzero(chosen)  # sample positions served by this view

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
        self,
        folder: Path | str,
        split: str | None = "train",
        *,
        normalize: bool = True,
        statuses: Sequence[str] | None = None,
        accepted_only: bool = False,
    ) -> None:
        super().__init__(folder, split, normalize=normalize, statuses=statuses)
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
