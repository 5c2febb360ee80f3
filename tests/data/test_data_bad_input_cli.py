"""Bad datasets and bad ``generate``/``dataset`` input: one error line, no silent result.

Each case asserts the exit status, that stderr is one ``scpformer: error:`` line naming the
flag, shard or path, and that no file written before is changed. The toy family
solves in microseconds, so everything but the SIGTERM case runs in-process.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import toy_families  # noqa: F401  (registers the toy family)
from toy_families import ToyFamily

from scpformer.cli.data import main
from scpformer.data import shards, storage
from scpformer.data.errors import DatasetError
from scpformer.data.generate import GenerateConfig, generate

TOY = ["--n", "5", "--shard-size", "2", "--workers", "1", "--quiet"]


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def one_line_error(capsys, argv: list[str], status: int, *texts: str) -> str:
    assert main(argv) == status
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    line = lines[0]
    assert line.startswith("scpformer: error: "), line
    assert all(t in line for t in texts), line
    assert "Traceback" not in out + err
    return line


@pytest.fixture
def toy(tmp_path, capsys):
    """A finished toy dataset of 5 instances in 3 shards."""
    assert main(["generate", "toy", "--out", str(tmp_path / "ds"), *TOY]) == 0
    capsys.readouterr()
    return tmp_path / "ds"


def flip_one_value(shard: Path) -> None:
    """Change one stored value without changing the file's size (a silent corruption)."""
    data = bytearray(shard.read_bytes())
    theta = np.float64(np.random.default_rng(0).uniform()).tobytes()  # not in the file
    at = len(data) // 2
    data[at : at + 8] = theta
    shard.write_bytes(bytes(data))


# -- flags ---------------------------------------------------------------------------------
def gen(*extra: str, out: str = "{tmp}/x") -> list[str]:
    return ["generate", "toy", "--out", out, "--n", "2", *extra]


FLAG_CASES = {
    "generate-workers-zero": (gen("--workers", "0"), "--workers"),
    "generate-seed-negative": (gen("--seed", "-1"), "--seed"),
    "generate-n-negative": (gen("--n", "-4"), "--n"),
    "generate-shard-size-zero": (gen("--shard-size", "0"), "--shard-size"),
    "generate-time-limit-zero": (gen("--time-limit", "0"), "time_limit"),
    "generate-out-is-a-file": (gen(out="{tmp}/file.txt"), "is a file"),
    "generate-out-under-a-file": (gen(out="{tmp}/file.txt/ds"), "is a file"),
    "generate-out-not-empty": (gen(out="{tmp}/folder"), "not empty"),
    "generate-out-read-only": (gen(out="{ro}/ds"), "cannot write"),
    "generate-ray-unreachable": (gen("--ray", "127.0.0.1:9"), "--ray"),
    "generate-ray-malformed": (gen("--ray", "nowhere"), "--ray"),
    "augment-workers-zero": (
        ["dataset", "augment", "{tmp}/folder", "--out", "{tmp}/x", "--workers", "0"],
        "--workers",
    ),
    "augment-out-is-a-file": (
        ["dataset", "augment", "{tmp}/folder", "--out", "{tmp}/file.txt"],
        "is a file",
    ),
    "split-seed-negative": (["dataset", "split", "{tmp}/folder", "--seed", "-1"], "--seed"),
    "info-no-dataset": (["dataset", "info", "{tmp}/folder"], "no dataset in"),
    "repair-no-shards": (["dataset", "repair", "{tmp}/folder"], "no shard files"),
}


@pytest.mark.parametrize("argv, text", FLAG_CASES.values(), ids=FLAG_CASES.keys())
def test_a_bad_flag_is_one_line_naming_it_and_changes_no_file(tmp_path, capsys, argv, text):
    (tmp_path / "file.txt").write_text("precious")
    (tmp_path / "folder").mkdir()
    (tmp_path / "folder" / "notes.txt").write_text("mine")
    read_only = Path("/sys") if os.geteuid() == 0 else tmp_path / "read-only"
    if os.geteuid() != 0:
        read_only.mkdir(mode=0o555)
    before = snapshot(tmp_path)
    argv = [a.replace("{tmp}", str(tmp_path)).replace("{ro}", str(read_only)) for a in argv]
    one_line_error(capsys, argv, 2, text)
    assert snapshot(tmp_path) == before


# -- damaged datasets ----------------------------------------------------------------------
def test_split_of_a_dataset_with_a_corrupt_shard_stops_naming_it(toy, capsys):
    flip_one_value(toy / "shard-00001.h5")
    before = snapshot(toy)
    one_line_error(capsys, ["dataset", "split", str(toy)], 2, "shard-00001.h5", "corrupt")
    assert snapshot(toy) == before  # no splits.h5 computed from the bad shard


def test_augment_of_a_dataset_with_a_corrupt_shard_stops_naming_it(pdg_dataset, tmp_path, capsys):
    source = tmp_path / "src"
    shutil.copytree(pdg_dataset.folder, source)
    flip_one_value(source / "shard-00001.h5")
    before = snapshot(tmp_path)
    argv = ["dataset", "augment", str(source), "--out", str(tmp_path / "aug"), "--no-verify"]
    one_line_error(capsys, argv, 2, "shard-00001.h5", "corrupt")
    assert snapshot(tmp_path) == before


def test_reading_samples_from_a_corrupt_shard_raises_naming_it(toy):
    flip_one_value(toy / "shard-00001.h5")
    samples = storage.ShardedSamples(toy)
    assert samples.read("value", 0).shape == ()  # shard 0 is intact
    with pytest.raises(DatasetError, match=r"shard-00001.h5: corrupt"):
        samples.read("value", 2)


@pytest.mark.parametrize("damage", ["delete", "flip", "truncate"])
def test_info_reports_a_missing_or_damaged_shard_as_incomplete(toy, capsys, damage):
    shard = toy / "shard-00001.h5"
    if damage == "delete":
        shard.unlink()
    elif damage == "flip":
        flip_one_value(shard)
    else:
        shard.write_bytes(shard.read_bytes()[:-10])
    assert main(["dataset", "info", str(toy)]) == 0
    out = capsys.readouterr().out
    assert "(complete)" not in out
    assert "incomplete" in out and "shard-00001.h5" in out


# -- configuration digest ------------------------------------------------------------------
@pytest.mark.parametrize("family", ["bogus", "", 5, None])
def test_info_of_a_dataset_of_an_unknown_family_names_it_and_the_known_ones(toy, capsys, family):
    path = toy / "manifest.json"
    data = json.loads(path.read_text())
    data["family"] = family
    path.write_text(json.dumps(data))
    before = snapshot(toy)
    line = one_line_error(capsys, ["dataset", "info", str(toy)], 2, str(path))
    assert f"unknown dataset family {family!r} (known: pdg6dof, rendezvous," in line
    assert "toy" in line.split("known: ")[1]  # registered families count as known
    assert snapshot(toy) == before


def config(out, **kwargs):
    return GenerateConfig(**(dict(n=5, out=out, shard_size=2, workers=1) | kwargs))


def test_resume_does_not_adopt_a_shard_made_with_other_settings(tmp_path):
    other = generate(ToyFamily(sleep=0.001), config(tmp_path / "other"))
    ours = generate(ToyFamily(), config(tmp_path / "ours"))
    manifest = ours.manifest.without_shard("shard-00001.h5")  # as if killed before listing it
    storage.write_manifest(ours.folder, manifest)
    shutil.copy(other.folder / "shard-00001.h5", ours.folder / "shard-00001.h5")
    notices = []
    resumed = generate(ToyFamily(), config(ours.folder), on_notice=notices.append)
    assert resumed.generated == 2  # the foreign shard was redone
    assert any("shard-00001.h5" in n for n in notices)
    reference = generate(ToyFamily(), config(tmp_path / "reference"))
    assert storage.content_id(resumed.manifest) == storage.content_id(reference.manifest)
    assert storage.verify_dataset(ours.folder) == []


def test_verify_reports_a_listed_shard_made_with_other_settings(tmp_path):
    other = generate(ToyFamily(sleep=0.001), config(tmp_path / "other"))
    ours = generate(ToyFamily(), config(tmp_path / "ours"))
    shutil.copy(other.folder / "shard-00001.h5", ours.folder / "shard-00001.h5")
    entry = next(s for s in other.manifest.shards if s.file == "shard-00001.h5")
    storage.write_manifest(ours.folder, ours.manifest.with_shard(entry))  # checksums agree
    problems = storage.verify_dataset(ours.folder)
    assert problems == ["shard-00001.h5: made with another configuration than the manifest's"]


# -- a deleted manifest --------------------------------------------------------------------
@pytest.mark.parametrize("command", ["info", "verify", "split"])
def test_without_a_manifest_the_error_says_how_to_rebuild_it(toy, capsys, command):
    (toy / storage.MANIFEST_NAME).unlink()
    before = snapshot(toy)
    one_line_error(capsys, ["dataset", command, str(toy)], 2, "dataset repair")
    assert snapshot(toy) == before


def test_repair_rebuilds_the_deleted_manifest_from_the_shards(toy, capsys):
    original = storage.read_manifest(toy)
    (toy / storage.MANIFEST_NAME).unlink()
    assert main(["dataset", "repair", str(toy)]) == 0
    assert "3 of 3 shard(s), 5 samples" in capsys.readouterr().out
    rebuilt = storage.read_manifest(toy)
    assert rebuilt.shards == original.shards
    assert storage.identity_digest(rebuilt) == storage.identity_digest(original)
    assert main(["dataset", "verify", str(toy)]) == 0


@pytest.mark.parametrize("text", ["", '{"family": ', "[]"], ids=["empty", "truncated", "list"])
def test_repair_rebuilds_an_unreadable_manifest_and_keeps_it_aside(toy, capsys, text):
    original = storage.read_manifest(toy)
    (toy / storage.MANIFEST_NAME).write_text(text)
    assert main(["dataset", "repair", str(toy)]) == 0
    assert "kept as manifest.json.corrupt" in capsys.readouterr().err
    assert (toy / "manifest.json.corrupt").read_text() == text
    assert storage.read_manifest(toy).shards == original.shards
    assert main(["dataset", "verify", str(toy)]) == 0


def test_resume_adopts_the_shards_of_a_deleted_manifest(toy, capsys):
    (toy / storage.MANIFEST_NAME).unlink()
    (toy / "shard-00002.h5").unlink()
    assert main(["generate", "toy", "--out", str(toy), *TOY]) == 0
    out = capsys.readouterr().out
    assert "this run: 1 instances" in out  # shards 0 and 1 were adopted, 2 redone
    assert storage.verify_dataset(toy) == []


def test_resume_without_manifest_refuses_another_datasets_shards(toy, capsys):
    (toy / storage.MANIFEST_NAME).unlink()
    before = snapshot(toy)
    argv = ["generate", "toy", "--out", str(toy), *TOY, "--seed", "9"]
    one_line_error(capsys, argv, 2, "another dataset", "dataset repair")
    assert snapshot(toy) == before


# -- two runs, a full disk, SIGTERM ---------------------------------------------------------
def test_a_second_generate_into_a_folder_in_use_is_refused(tmp_path, capsys):
    folder = tmp_path / "ds"
    folder.mkdir()
    with (folder / ".lock").open("a") as held:  # what a running generate holds
        fcntl.flock(held.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        one_line_error(capsys, ["generate", "toy", "--out", str(folder), *TOY], 2, "another")
    assert [p.name for p in folder.iterdir()] == [".lock"]


def test_a_full_disk_during_generate_is_one_line_and_the_run_resumes(tmp_path, capsys, monkeypatch):
    real_write = shards.write_bytes_atomic

    def fill_up_on_second_shard(path, data):
        if path.name == "shard-00001.h5":
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real_write(path, data)

    monkeypatch.setattr(shards, "write_bytes_atomic", fill_up_on_second_shard)
    argv = ["generate", "toy", "--out", str(tmp_path / "ds"), *TOY]
    one_line_error(capsys, argv, 1, "disk full", "shard-00001.h5", "resume")
    kept = snapshot(tmp_path / "ds")
    assert [s.file for s in storage.read_manifest(tmp_path / "ds").shards] == ["shard-00000.h5"]
    monkeypatch.setattr(shards, "write_bytes_atomic", real_write)
    assert main(argv) == 0
    assert storage.verify_dataset(tmp_path / "ds") == []
    shard0 = str(tmp_path / "ds" / "shard-00000.h5")
    assert snapshot(tmp_path / "ds")[shard0] == kept[shard0]  # finished shard intact


SLOW_TOY = """
import sys
import toy_families
from scpformer.cli.main import main
from scpformer.data.family import FamilySpec, register_family

register_family(
    FamilySpec(name="toy-slow", summary="slow toy",
               build=lambda _: toy_families.ToyFamily(sleep=0.2)),
    replace=True,
)
sys.exit(main(["generate", "toy-slow", "--n", "40", "--shard-size", "2", "--workers", "2",
               "--quiet", "--out", sys.argv[1]]))
"""


@pytest.mark.slow
def test_sigterm_during_generate_is_one_line_and_the_dataset_resumes(tmp_path):
    folder = tmp_path / "ds"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).parent), *sys.path])}
    command = [sys.executable, "-c", SLOW_TOY, str(folder)]
    proc = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not list(folder.glob("shard-*.h5")):
        time.sleep(0.2)
    assert list(folder.glob("shard-*.h5")), "no shard was written"
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    lines = err.decode().strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("scpformer: error: terminated"), err
    assert "resume" in lines[0]
    manifest = storage.read_manifest(folder)
    assert manifest.shards and not manifest.complete
    assert storage.verify_dataset(folder) == [
        f"incomplete: {len(manifest.shards)} of 20 shards finished "
        "(re-run the same generate command to finish)"
    ]
    done = subprocess.run(command, env=env, capture_output=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert storage.verify_dataset(folder) == []
    json.loads((folder / storage.MANIFEST_NAME).read_text())
