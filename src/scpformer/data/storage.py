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

Every file is written under a temporary name (``*.tmp``), flushed to disk and renamed
(:func:`scpformer.files.atomic_path`), so a killed process leaves either a whole file or a
temporary one that the next run deletes.

This module gathers the storage API in one import; each concept has its own module:

* :mod:`scpformer.data.manifest` -- the manifest and the digests (identity, content);
* :mod:`scpformer.data.locking` -- one writer per folder;
* :mod:`scpformer.data.shards` -- writing, reading and checking shard files;
* :mod:`scpformer.data.reader` -- :class:`ShardedSamples`, lazy random access to the samples.
"""

from __future__ import annotations

from scpformer.data.locking import LOCK_NAME, locked_folder
from scpformer.data.manifest import (
    FORMAT_VERSION,
    MANIFEST_NAME,
    SHARD_GLOB,
    TMP_SUFFIX,
    Manifest,
    ShardInfo,
    content_id,
    describe_mismatch,
    file_sha256,
    identity_digest,
    identity_digests,
    manifest_from_header,
    read_manifest,
    shard_header,
    shard_name,
    write_manifest,
)
from scpformer.data.reader import ShardedSamples
from scpformer.data.shards import (
    append_shard,
    check_shard,
    content_digest,
    read_columns,
    read_field,
    require_consistent,
    require_intact,
    shard_attrs,
    shard_damage,
    stack_records,
    stray_files,
    verify_dataset,
    write_shard,
)

__all__ = [
    "FORMAT_VERSION",
    "LOCK_NAME",
    "MANIFEST_NAME",
    "SHARD_GLOB",
    "TMP_SUFFIX",
    "Manifest",
    "ShardInfo",
    "ShardedSamples",
    "append_shard",
    "check_shard",
    "content_digest",
    "content_id",
    "describe_mismatch",
    "file_sha256",
    "identity_digest",
    "identity_digests",
    "locked_folder",
    "manifest_from_header",
    "read_columns",
    "read_field",
    "read_manifest",
    "require_consistent",
    "require_intact",
    "shard_attrs",
    "shard_damage",
    "shard_header",
    "shard_name",
    "stack_records",
    "stray_files",
    "verify_dataset",
    "write_manifest",
    "write_shard",
]
