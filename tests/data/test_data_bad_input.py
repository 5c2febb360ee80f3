"""Every bad input of generation gets a clear message, and no finished shard is lost."""

import errno
import json

import numpy as np
import pytest
from toy_families import MisbehavingFamily, ToyFamily

from scpformer.data import shards, storage
from scpformer.data.errors import DatasetError, DiskFullError
from scpformer.data.generate import GenerateConfig, generate
from scpformer.data.pdg6dof_family import PDG6DoFFamily


def config(out, **kwargs):
    return GenerateConfig(**(dict(n=5, out=out, shard_size=2, workers=1) | kwargs))


@pytest.fixture
def toy_folder(tmp_path):
    generate(ToyFamily(), config(tmp_path / "ds"))
    return tmp_path / "ds"


def test_a_folder_holding_another_familys_dataset_is_refused(toy_folder):
    with pytest.raises(DatasetError, match=r"holds another dataset \(toy, seed 0.*family 'toy'"):
        generate(PDG6DoFFamily(), config(toy_folder))


def test_a_folder_holding_another_seeds_dataset_is_refused(toy_folder):
    with pytest.raises(DatasetError, match=r"differs in seed 0 .this run: 3.*another --out"):
        generate(ToyFamily(), config(toy_folder, seed=3))


def test_a_folder_holding_another_configuration_names_the_difference(toy_folder):
    with pytest.raises(DatasetError, match=r"config\.sleep: 0\.0 there, 0\.5 here"):
        generate(ToyFamily(sleep=0.5), config(toy_folder))


def test_a_smaller_n_is_refused_because_a_dataset_only_grows(toy_folder):
    before = {p.name: p.read_bytes() for p in toy_folder.iterdir()}
    with pytest.raises(DatasetError, match=r"holds 5 instances and a dataset only grows.*--n 5"):
        generate(ToyFamily(), config(toy_folder, n=4))
    assert {p.name: p.read_bytes() for p in toy_folder.iterdir()} == before


def test_a_refused_folder_is_left_untouched(toy_folder):
    before = {p.name: p.read_bytes() for p in toy_folder.iterdir()}
    with pytest.raises(DatasetError):
        generate(ToyFamily(), config(toy_folder, seed=3))
    assert {p.name: p.read_bytes() for p in toy_folder.iterdir()} == before


def test_a_non_empty_folder_without_a_manifest_is_refused(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(DatasetError, match=r"not empty and holds no dataset.*notes.txt"):
        generate(ToyFamily(), config(tmp_path))


def test_an_output_path_that_is_a_file_is_refused(tmp_path):
    (tmp_path / "file").write_text("")
    with pytest.raises(DatasetError, match=r"is a file, not a folder"):
        generate(ToyFamily(), config(tmp_path / "file"))


def test_a_corrupt_manifest_is_a_clear_error(toy_folder):
    (toy_folder / storage.MANIFEST_NAME).write_text('{"family": ')
    with pytest.raises(DatasetError, match=r"manifest.json: the manifest is damaged"):
        generate(ToyFamily(), config(toy_folder))


def test_a_manifest_missing_a_field_names_the_field(toy_folder):
    (toy_folder / storage.MANIFEST_NAME).write_text('{"format_version": 1}')
    damaged = r"manifest\.json: the manifest is damaged \(manifest lacks"
    with pytest.raises(DatasetError, match=damaged) as info:
        storage.read_manifest(toy_folder)
    assert "family, seed, n, shard_size" in str(info.value)  # every missing one, in order


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda m: m.update(schema=None), "field 'schema' must be a list, got NoneType"),
        (lambda m: m.update(shards=[1]), "field 'shards', entry 0: shard must be a JSON object"),
        (lambda m: m["shards"][0].pop("sha256"), "field 'shards', entry 0: shard lacks field"),
        (lambda m: m.update(extra=1), "unknown manifest field(s): extra"),
        (lambda m: m.update(success_statuses=[5]), "'success_statuses', entry 0: status must"),
        (lambda m: m.update(grown_from=[2.5]), "'grown_from', entry 0: value must be an integer"),
        (lambda m: m["schema"][0].pop("dtype"), "'schema', entry 0: schema entry lacks field"),
    ],
)
def test_a_manifest_field_of_the_wrong_kind_is_named(toy_folder, edit, message):
    _tampered(toy_folder, edit)
    with pytest.raises(DatasetError, match=r"manifest\.json: the manifest is damaged \(") as info:
        storage.read_manifest(toy_folder)
    assert message in str(info.value)


def _tampered(folder, edit):
    path = folder / storage.MANIFEST_NAME
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))


@pytest.mark.parametrize(
    "name", ["../victim.h5", "/elsewhere/victim.h5", "sub/shard.h5", ".h5", None]
)
def test_a_manifest_naming_a_shard_outside_the_folder_is_corrupt_and_nothing_is_deleted(
    toy_folder, name
):
    victim = toy_folder.parent / "victim.h5"
    victim.write_text("not yours")
    _tampered(toy_folder, lambda data: data["shards"][0].update(file=name))
    damaged = r"manifest\.json: the manifest is damaged \(.*shard file"
    with pytest.raises(DatasetError, match=damaged):
        generate(ToyFamily(), config(toy_folder))
    assert victim.read_text() == "not yours"


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d["shards"][0].update(count="x"), r"count must be an integer >= 0, got 'x'"),
        (lambda d: d["shards"][0].update(stop=-1), r"stop must be an integer >= 0"),
        (lambda d: d.update(n="abc"), r"n must be an integer >= 0, got 'abc'"),
        (lambda d: d.update(shard_size=0), r"shard_size must be an integer >= 1, got 0"),
        (lambda d: d.update(format_version=99), r"format_version 99 is newer than this scpformer"),
    ],
)
def test_a_manifest_with_a_wrongly_typed_number_names_it(toy_folder, edit, message):
    _tampered(toy_folder, edit)
    damaged = r"manifest\.json: the manifest is damaged \(.*" + message
    with pytest.raises(DatasetError, match=damaged):
        storage.read_manifest(toy_folder)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"n": 0}, "n must be an integer >= 1"),
        ({"shard_size": 0}, "shard_size must be an integer >= 1"),
        ({"workers": 0}, "workers must be an integer >= 1"),
        ({"seed": -1}, "seed must be an integer >= 0"),
        ({"time_limit": 0.0}, "time_limit must be a positive number"),
        ({"start_method": "thread"}, "start_method must be one of"),
    ],
)
def test_invalid_settings_name_the_field(tmp_path, kwargs, message):
    with pytest.raises(ValueError, match=message):
        config(tmp_path, **kwargs)


def test_a_full_disk_stops_with_a_clear_message_and_keeps_finished_shards(tmp_path, monkeypatch):
    real_write = shards.write_bytes_atomic

    def fill_up_on_second_shard(path, data):
        if path.name == "shard-00001.h5":
            (path.parent / "shard-00001.h5.tmp").write_bytes(data[:100])  # a partial write
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_write(path, data)

    monkeypatch.setattr(shards, "write_bytes_atomic", fill_up_on_second_shard)
    with pytest.raises(DiskFullError, match=r"disk full while writing shard-00001.h5.*resume"):
        generate(ToyFamily(), config(tmp_path / "ds"))
    manifest = storage.read_manifest(tmp_path / "ds")
    assert [s.file for s in manifest.shards] == ["shard-00000.h5"]
    monkeypatch.setattr(shards, "write_bytes_atomic", real_write)
    resumed = generate(ToyFamily(), config(tmp_path / "ds"))
    reference = generate(ToyFamily(), config(tmp_path / "ref"))
    assert resumed.resumed == 2 and resumed.generated == 3
    assert storage.content_id(resumed.manifest) == storage.content_id(reference.manifest)


def statuses(report):
    manifest = report.manifest
    parts = [storage.read_columns(report.folder / s.file, manifest.schema) for s in manifest.shards]
    return {name: np.concatenate([p[name] for p in parts]) for name in ("status", "message")}


def test_a_hanging_instance_times_out_and_the_run_goes_on(tmp_path):
    notices = []
    report = generate(
        MisbehavingFamily(hang_index=1),
        config(tmp_path / "ds", workers=2, time_limit=1.0),
        on_progress=lambda p: p.result and notices.append(p.result.status),
    )
    got = statuses(report)
    assert got["status"][1] == "timeout" and "1 s time limit" in got["message"][1]
    assert set(np.delete(got["status"], 1)) <= {"ok", "bad"}
    assert report.manifest.complete and "timeout" in notices


def test_a_crashing_worker_is_recorded_and_replaced(tmp_path):
    report = generate(MisbehavingFamily(crash_index=2), config(tmp_path / "ds", workers=2))
    got = statuses(report)
    assert got["status"][2] == "worker_crashed" and "exit code 3" in got["message"][2]
    assert set(np.delete(got["status"], 2)) <= {"ok", "bad"}
    assert report.manifest.counts()["samples"] == 5


def test_an_exception_on_one_instance_is_a_status(tmp_path):
    got = statuses(generate(MisbehavingFamily(raise_index=0), config(tmp_path / "ds")))
    assert got["status"][0] == "error" and "ZeroDivisionError: toy bug" in got["message"][0]


def test_a_worker_that_cannot_warm_up_stops_the_run_clearly(tmp_path):
    with pytest.raises(DatasetError, match=r"worker failed to warm up: RuntimeError: toy warm-up"):
        generate(ToyFamily(fail_warm_up=True), config(tmp_path / "ds"))
