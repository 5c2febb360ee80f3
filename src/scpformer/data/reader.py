"""Random access to a dataset's samples, read lazily from its shards."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from scpformer.data.errors import DatasetError, short_message
from scpformer.data.manifest import read_manifest
from scpformer.data.shards import read_field, require_intact


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
                    f"{self.folder / info.file} is corrupt or truncated ({short_message(err)}); "
                    f"run: scpformer dataset verify {self.folder}"
                ) from None
        return self._handles[shard]

    def read(self, name: str, position: int, *index: int | slice) -> np.ndarray:
        """One sample's value of field ``name`` (``index`` selects inside it, read lazily)."""
        shard, row = self.locate(position)
        return read_field(self._handle(shard), self.manifest.field(name), (row, *index))

    def column(self, name: str) -> np.ndarray:
        """A whole column, shard by shard (meant for small per-sample fields)."""
        f = self.manifest.field(name)
        parts = [read_field(self._handle(s), f, ()) for s in range(len(self.manifest.shards))]
        return np.concatenate(parts) if parts else f.empty(0)

    def close(self) -> None:
        """Close every open file."""
        for handle in self._handles.values():
            handle.close()
        self._handles = {}
