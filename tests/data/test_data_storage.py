import errno
import os
import signal

import numpy as np
import pytest

from scpformer.cli.errors import Terminated, sigterm_raises
from scpformer.data import shards, storage
from scpformer.data.errors import DatasetError, DiskFullError
from scpformer.data.family import Field

SCHEMA = (
    Field(name="index", dtype="int64"),
    Field(name="status", dtype="str"),
    Field(name="x", dtype="float64", shape=(8, 3)),
    Field(name="flags", dtype="bool", shape=(5,)),
    Field(name="wall_time", dtype="float64", deterministic=False),
)


def columns(count=4, wall=0.0):
    rng = np.random.default_rng(0)
    return {
        "index": np.arange(count),
        "status": np.array(["ok"] * (count - 1) + ["failed"], dtype=object),
        "x": rng.normal(size=(count, 8, 3)),
        "flags": rng.uniform(size=(count, 5)) > 0.5,
        "wall_time": np.full(count, wall),
    }


def write(folder, number=0, wall=0.0):
    return storage.write_shard(
        folder / storage.shard_name(number),
        columns(wall=wall),
        SCHEMA,
        start=0,
        stop=4,
        attrs={"family": "toy", "seed": 0},
    )


def manifest_with(info):
    return storage.Manifest(
        family="toy",
        seed=0,
        n=4,
        shard_size=4,
        config={},
        schema=SCHEMA,
        package_version="0",
        versions={},
        success_statuses=("ok",),
        shards=(info,),
    )


def test_a_shard_reads_back_what_was_written(tmp_path):
    info = write(tmp_path)
    back = storage.read_columns(tmp_path / info.file, SCHEMA)
    for name, values in columns().items():
        np.testing.assert_array_equal(back[name], values)
    assert info.count == 4 and info.status_counts == {"failed": 1, "ok": 3}
    assert not list(tmp_path.glob("*.tmp"))


def test_content_digest_ignores_timings_but_not_values(tmp_path):
    a = storage.content_digest(columns(wall=1.0), SCHEMA)
    assert a == storage.content_digest(columns(wall=2.0), SCHEMA)
    changed = columns()
    changed["x"][0, 0, 0] += 1e-15
    assert a != storage.content_digest(changed, SCHEMA)


def test_verify_finds_nothing_wrong_in_an_intact_dataset(tmp_path):
    storage.write_manifest(tmp_path, manifest_with(write(tmp_path)))
    assert storage.verify_dataset(tmp_path) == []


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda p: p.write_bytes(p.read_bytes()[:-100]), "truncated"),
        (lambda p: p.write_bytes(p.read_bytes()[:500] + b"X" + p.read_bytes()[501:]), "corrupt"),
        (lambda p: p.unlink(), "missing"),
    ],
)
def test_verify_reports_a_damaged_shard(tmp_path, damage, message):
    info = write(tmp_path)
    storage.write_manifest(tmp_path, manifest_with(info))
    damage(tmp_path / info.file)
    problems = storage.verify_dataset(tmp_path)
    assert len(problems) == 1 and problems[0].startswith(info.file) and message in problems[0]


def test_verify_reports_leftover_and_unlisted_files(tmp_path):
    storage.write_manifest(tmp_path, manifest_with(write(tmp_path)))
    (tmp_path / "shard-00001.h5.tmp").write_bytes(b"half")
    write(tmp_path, number=2)
    problems = storage.verify_dataset(tmp_path)
    assert any("leftover temporary file" in p for p in problems)
    assert any("shard-00002.h5: shard file not listed" in p for p in problems)


@pytest.fixture
def foreground_sigint():
    """Python's own SIGINT handler for the test, as in a process started in the foreground (a
    shell starts background jobs with SIGINT ignored, and an ignored signal stays ignored)."""
    found = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, found)


@pytest.mark.parametrize("kind", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_a_signal_between_shard_and_manifest_waits_until_the_manifest_lists_the_shard(
    tmp_path, monkeypatch, kind, foreground_sigint
):
    empty = manifest_with(write(tmp_path)).without_shard("shard-00000.h5")
    real_write_shard = storage.write_shard

    def signalled_after_writing(*args, **kwargs):
        info = real_write_shard(*args, **kwargs)
        signal.raise_signal(kind)  # the shard is on disk, the manifest not yet rewritten
        return info

    monkeypatch.setattr(shards, "write_shard", signalled_after_writing)
    with pytest.raises((Terminated, KeyboardInterrupt)), sigterm_raises():
        storage.append_shard(
            tmp_path, empty, "shard-00001.h5", columns(), start=0, stop=4, attrs={}
        )
    listed = [s.file for s in storage.read_manifest(tmp_path).shards]
    assert listed == ["shard-00001.h5"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # restored


def test_reading_a_truncated_shard_lazily_is_a_clear_error(tmp_path):
    info = write(tmp_path)
    storage.write_manifest(tmp_path, manifest_with(info))
    path = tmp_path / info.file
    path.write_bytes(path.read_bytes()[:800])
    samples = storage.ShardedSamples(tmp_path)
    with pytest.raises(DatasetError, match=r"shard-00000.h5: truncated.*dataset verify"):
        samples.read("x", 0)


def test_a_full_disk_leaves_no_temporary_file_and_says_how_to_resume(tmp_path, monkeypatch):
    def no_space(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", no_space)  # the shard's bytes do not reach the disk
    with pytest.raises(DiskFullError, match=r"disk full while writing shard-00000.h5.*resume"):
        write(tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_a_missing_or_corrupt_manifest_is_a_clear_error(tmp_path):
    with pytest.raises(DatasetError, match=r"no dataset in"):
        storage.read_manifest(tmp_path)
    (tmp_path / storage.MANIFEST_NAME).write_text("{not json")
    with pytest.raises(DatasetError, match=r"manifest.json: the manifest is damaged"):
        storage.read_manifest(tmp_path)


def test_the_manifest_is_written_to_a_folder_given_as_a_string(tmp_path):
    storage.write_manifest(str(tmp_path), manifest_with(write(tmp_path)))
    assert storage.read_manifest(str(tmp_path)).shards[0].file == "shard-00000.h5"


def test_manifest_round_trips_through_json(tmp_path):
    manifest = manifest_with(write(tmp_path))
    storage.write_manifest(tmp_path, manifest)
    assert storage.read_manifest(tmp_path) == manifest


def test_sharded_samples_read_items_lazily_across_shards(tmp_path):
    a = write(tmp_path, 0)
    b = write(tmp_path, 1)
    manifest = manifest_with(a)
    manifest = manifest.with_shard(b)
    storage.write_manifest(tmp_path, manifest)
    samples = storage.ShardedSamples(tmp_path)
    assert len(samples) == 8
    assert samples.locate(5) == (1, 1)
    np.testing.assert_array_equal(samples.read("x", 5), columns()["x"][1])
    np.testing.assert_array_equal(samples.read("x", 5, 2), columns()["x"][1, 2])
    assert list(samples.column("status")) == ["ok", "ok", "ok", "failed"] * 2
    with pytest.raises(IndexError):
        samples.read("x", 8)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("start", np.int64(-1), "shard s.h5: start must be an integer >= 0, got -1"),
        ("count", np.float64(2.5), "shard s.h5: count must be an integer >= 0, got float64 2.5"),
    ],
)
def test_numpy_shard_counts_are_printed_as_plain_numbers(field, value, message):
    fields = dict(file="s.h5", start=0, stop=4, count=4, sha256="", content_sha256="", bytes=1)
    with pytest.raises(ValueError) as err:
        storage.ShardInfo(**(fields | {field: value}))
    assert message in str(err.value) and "np." not in str(err.value)
