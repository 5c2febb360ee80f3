"""Generation: determinism, independence of streams, resumption after a kill."""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from toy_families import ToyFamily

from scpformer.data import storage
from scpformer.data.executors import instance_rng
from scpformer.data.generate import GenerateConfig, generate

HERE = Path(__file__).parent


def run(out, family=None, on_notice=None, **kwargs):
    config = dict(n=7, out=out, shard_size=3, workers=1) | kwargs
    return generate(family or ToyFamily(), GenerateConfig(**config), on_notice=on_notice)


def all_columns(folder):
    manifest = storage.read_manifest(folder)
    parts = [storage.read_columns(folder / s.file, manifest.schema) for s in manifest.shards]
    return {f.name: np.concatenate([p[f.name] for p in parts]) for f in manifest.schema}


def test_same_seed_gives_the_same_data_for_any_worker_count(tmp_path):
    one = run(tmp_path / "one", workers=1)
    two = run(tmp_path / "two", workers=2)
    assert storage.content_id(one.manifest) == storage.content_id(two.manifest)
    assert [s.content_sha256 for s in one.manifest.shards] == [
        s.content_sha256 for s in two.manifest.shards
    ]


def test_instance_i_draws_from_child_i_of_the_seed_sequence(tmp_path):
    run(tmp_path / "ds", seed=5)
    theta = all_columns(tmp_path / "ds")["theta"]
    children = np.random.SeedSequence(5).spawn(7)
    expected = [np.random.default_rng(child).uniform(size=3) for child in children]
    np.testing.assert_array_equal(theta, expected)
    assert len({row.tobytes() for row in theta}) == 7  # no two samples repeat


def test_a_larger_dataset_extends_a_smaller_one_with_the_same_seed(tmp_path):
    small = all_columns(run(tmp_path / "small", n=4).folder)
    large = all_columns(run(tmp_path / "large", n=7).folder)
    np.testing.assert_array_equal(small["theta"], large["theta"][:4])
    assert not np.array_equal(
        instance_rng(0, 0).uniform(size=3), instance_rng(1, 0).uniform(size=3)
    )


def test_a_larger_n_grows_a_dataset_to_the_data_of_a_fresh_run(tmp_path):
    run(tmp_path / "ds", n=4)
    notices = []
    grown = run(tmp_path / "ds", n=11, on_notice=notices.append)
    fresh = run(tmp_path / "fresh", n=11)
    assert grown.generated == 7  # instances 4..10 only
    assert any("growing the dataset from 4 to 11" in n for n in notices)
    for name in ("index", "theta", "status"):
        np.testing.assert_array_equal(
            all_columns(tmp_path / "ds")[name], all_columns(tmp_path / "fresh")[name]
        )
    ranges = [(s.start, s.stop) for s in grown.manifest.shards]
    assert ranges == [(0, 3), (3, 4), (4, 7), (7, 10), (10, 11)]  # the partial shard is kept
    assert grown.manifest.grown_from == (4,) and grown.manifest.complete
    assert storage.verify_dataset(tmp_path / "ds") == []
    assert fresh.manifest.plan is None


def test_a_dataset_grown_twice_survives_the_loss_of_its_manifest(tmp_path, capsys):
    from scpformer.cli.main import main

    for n in (3, 5, 8):
        run(tmp_path / "ds", n=n)
    before = storage.read_manifest(tmp_path / "ds")
    assert before.grown_from == (3, 5)
    (tmp_path / "ds" / storage.MANIFEST_NAME).unlink()
    assert main(["dataset", "repair", str(tmp_path / "ds")]) == 0
    rebuilt = storage.read_manifest(tmp_path / "ds")
    assert rebuilt.shards == before.shards and rebuilt.n == 8
    assert storage.verify_dataset(tmp_path / "ds") == []


def test_growing_a_split_dataset_says_to_split_it_again(tmp_path):
    from scpformer.data.errors import DatasetError
    from scpformer.data.splits import load_splits, make_splits

    folder = run(tmp_path / "ds", n=4).folder
    make_splits(folder)
    notices = []
    run(folder, n=6, on_notice=notices.append)
    assert any("splits.h5 splits the first 4 instances only" in n for n in notices)
    with pytest.raises(DatasetError, match="different data"):
        load_splits(folder)


def test_failed_instances_are_stored_with_their_status(tmp_path):
    report = run(tmp_path / "ds", n=20, shard_size=20)
    data = all_columns(tmp_path / "ds")
    bad = data["theta"][:, 0] >= 0.8
    assert bad.any() and (~bad).any()
    assert set(data["status"][bad]) == {"bad"} and set(data["status"][~bad]) == {"ok"}
    counts = report.manifest.counts()
    assert counts["failed"] == bad.sum() and counts["solved"] == (~bad).sum()


def test_rerunning_a_finished_dataset_solves_nothing(tmp_path):
    first = run(tmp_path / "ds")
    again = run(tmp_path / "ds")
    assert again.generated == 0 and again.resumed == 7
    assert storage.content_id(again.manifest) == storage.content_id(first.manifest)


KILLED_RUN = textwrap.dedent(
    """
    import sys
    from toy_families import ToyFamily
    from scpformer.data.generate import GenerateConfig, generate

    if __name__ == "__main__":
        config = GenerateConfig(n=8, out=sys.argv[1], shard_size=3, workers=2)
        generate(ToyFamily(sleep=0.3), config)
    """
)


def test_a_run_killed_mid_shard_resumes_to_the_same_bytes(tmp_path):
    script = tmp_path / "killed_run.py"
    script.write_text(KILLED_RUN)
    out = tmp_path / "ds"
    path = os.pathsep.join(filter(None, [str(HERE), os.environ.get("PYTHONPATH", "")]))
    env = {**os.environ, "PYTHONPATH": path}  # the script imports the toy families beside us
    proc = subprocess.Popen(
        [sys.executable, str(script), str(out)], start_new_session=True, env=env
    )
    first = out / storage.shard_name(0)
    deadline = time.monotonic() + 60
    while not first.exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)  # the run and its workers, mid-way through shard 1
    proc.wait()
    assert first.exists() and not (out / storage.shard_name(2)).exists()
    kept = first.stat().st_ino, storage.file_sha256(first)

    resumed = generate(ToyFamily(sleep=0.3), GenerateConfig(n=8, out=out, shard_size=3, workers=2))
    assert resumed.resumed == 3 and resumed.generated == 5
    assert (first.stat().st_ino, storage.file_sha256(first)) == kept  # kept, not rewritten
    reference = run(tmp_path / "ref", family=ToyFamily(sleep=0.3), n=8)
    assert storage.content_id(resumed.manifest) == storage.content_id(reference.manifest)
    assert storage.verify_dataset(out) == []


def test_resume_repairs_leftovers_adopts_unlisted_shards_and_redoes_corrupt_ones(tmp_path):
    reference = run(tmp_path / "ds")
    folder = tmp_path / "ds"
    manifest = storage.read_manifest(folder)
    storage.write_manifest(folder, manifest.without_shard(storage.shard_name(0)))  # unlisted
    (folder / "shard-00001.h5.tmp").write_bytes(b"half-written")  # killed during a write
    last = folder / storage.shard_name(2)
    last.write_bytes(last.read_bytes()[:-64])  # truncated
    notices = []
    again = generate(
        ToyFamily(),
        GenerateConfig(n=7, out=folder, shard_size=3, workers=1),
        on_notice=notices.append,
    )
    assert again.generated == 1  # only the truncated shard's single instance
    assert any("removed shard-00001.h5.tmp" in n for n in notices)
    assert any("shard-00002.h5: truncated" in n and "regenerating" in n for n in notices)
    assert storage.content_id(again.manifest) == storage.content_id(reference.manifest)
    assert storage.verify_dataset(folder) == []


@pytest.mark.slow
def test_pdg6dof_data_are_identical_with_one_and_two_workers(tmp_path, pdg_family, pdg_dataset):
    config = GenerateConfig(n=4, out=tmp_path / "one", shard_size=2, workers=1, seed=7)
    one = generate(pdg_family, config)
    assert storage.content_id(one.manifest) == storage.content_id(pdg_dataset.manifest)
    a, b = all_columns(one.folder), all_columns(pdg_dataset.folder)
    for name in ("theta", "x", "u", "tf", "tight_flags", "guess_x", "status", "iterations"):
        np.testing.assert_array_equal(a[name], b[name])
    assert (a["status"] == "converged").all()
    assert a["tight_flags"][np.arange(4), a["iterations"] - 1].any(axis=1).all()
