"""The Ray backend on a local 2-CPU Ray instance: same data as the local pool."""

import numpy as np
import pytest
import toy_families
from toy_families import MisbehavingFamily, ToyFamily

from scpformer.data import storage
from scpformer.data.generate import GenerateConfig, generate

pytestmark = pytest.mark.slow  # starting Ray alone takes ~6 s


@pytest.fixture(scope="module")
def ray_toys(ray_local):
    ray_local.cloudpickle.register_pickle_by_value(toy_families)  # Ray workers lack tests/
    return ray_local


def config(out, **kwargs):
    return GenerateConfig(**(dict(n=5, out=out, shard_size=2, ray_address="local") | kwargs))


def test_ray_and_the_local_pool_write_the_same_data(tmp_path, ray_toys):
    on_ray = generate(ToyFamily(), config(tmp_path / "ray", workers=2))
    local = generate(ToyFamily(), config(tmp_path / "local", ray_address=None, workers=1))
    assert on_ray.backend == "ray" and on_ray.workers == 2
    assert storage.content_id(on_ray.manifest) == storage.content_id(local.manifest)


def test_ray_restarts_actors_that_hang_or_crash(tmp_path, ray_toys):
    family = MisbehavingFamily(hang_index=1, crash_index=3)
    report = generate(family, config(tmp_path / "ray", workers=2, time_limit=2.0))
    manifest = report.manifest
    parts = [storage.read_columns(report.folder / s.file, manifest.schema) for s in manifest.shards]
    status = np.concatenate([p["status"] for p in parts])
    assert status[1] == "timeout" and status[3] == "worker_crashed"
    assert set(np.delete(status, [1, 3])) <= {"ok", "bad"}


def test_pdg6dof_on_ray_matches_the_local_pool(tmp_path, ray_local, pdg_family, pdg_dataset):
    cfg = GenerateConfig(n=4, out=tmp_path / "ray", shard_size=2, seed=7, ray_address="auto")
    on_ray = generate(pdg_family, cfg)
    assert on_ray.workers == 2  # one actor per CPU of the cluster
    assert storage.content_id(on_ray.manifest) == storage.content_id(pdg_dataset.manifest)
