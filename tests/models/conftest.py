"""A small fake rendezvous dataset with splits, shared by the model tests."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def fake_rdv(tmp_path_factory):
    """12 fake rendezvous samples (2 twins each) split 50/25/25 by instance."""
    from fake_rendezvous import FakeRendezvousFamily

    from scpformer.data.generate import GenerateConfig, generate
    from scpformer.data.splits import SplitConfig, make_splits

    folder = tmp_path_factory.mktemp("fake_rdv") / "ds"
    generate(FakeRendezvousFamily(), GenerateConfig(n=12, out=folder, shard_size=6, workers=1))
    make_splits(folder, SplitConfig(fractions=(0.5, 0.25, 0.25), seed=0))
    return folder
