"""Shared datasets for the data tests: one small solved 6-DoF dataset per session."""

from __future__ import annotations

import importlib.util

import pytest

from scpformer.data.generate import GenerateConfig, generate

N_PDG = 4  # instances of the shared 6-DoF dataset
PDG_SHARD = 2


@pytest.fixture(scope="session")
def pdg_family():
    from scpformer.data.pdg6dof_family import PDG6DoFDataConfig, PDG6DoFFamily
    from scpformer.problems.pdg6dof.sampling import PDGSampleRanges

    family = PDG6DoFFamily(PDG6DoFDataConfig(ranges=PDGSampleRanges.nominal()))
    family.warm_up()  # build the on-disk subproblem cache once, before any worker needs it
    return family


@pytest.fixture(scope="session")
def pdg_dataset(tmp_path_factory, pdg_family):
    """4 nominal instances solved by 2 local workers, shards of 2."""
    out = tmp_path_factory.mktemp("pdg") / "ds"
    config = GenerateConfig(n=N_PDG, out=out, shard_size=PDG_SHARD, workers=2, seed=7)
    return generate(pdg_family, config)


@pytest.fixture(scope="session")
def ray_local():
    """A local 2-CPU Ray instance shared by the Ray tests."""
    if importlib.util.find_spec("ray") is None:
        pytest.skip("ray is not installed (pip install ray): the Ray backend is untested")
    import ray

    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()


N_RDV = 4  # instances of the shared rendezvous dataset
RDV_SHARD = 2
RDV_SEED = 3


@pytest.fixture(scope="session")
def rdv_family():
    from scpformer.data.rendezvous_family import RendezvousFamily

    family = RendezvousFamily()  # ART Table 1
    family.warm_up()  # build the on-disk subproblem cache once, before any worker needs it
    return family


@pytest.fixture(scope="session")
def rdv_dataset(tmp_path_factory, rdv_family):
    """4 sampled rendezvous instances solved by 2 local workers, shards of 2."""
    out = tmp_path_factory.mktemp("rdv") / "ds"
    config = GenerateConfig(n=N_RDV, out=out, shard_size=RDV_SHARD, workers=2, seed=RDV_SEED)
    return generate(rdv_family, config)
