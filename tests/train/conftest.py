"""Tiny rendezvous-shaped datasets and the stand-in models API for the training tests."""

from __future__ import annotations

import shutil

import pytest

pytest.importorskip("torch", reason="torch is not installed: training is untested")

from train_standins import STANDIN_MODELS, ToyRendezvousFamily

from scpformer.data.generate import GenerateConfig, generate
from scpformer.data.splits import SplitConfig, make_splits

N_INSTANCES = 16


@pytest.fixture
def models():
    """The stand-in models API (in place of scpformer.models)."""
    return STANDIN_MODELS


def _generate(tmp_path_factory, family: ToyRendezvousFamily, name: str):
    out = tmp_path_factory.mktemp(name) / "ds"
    config = GenerateConfig(n=N_INSTANCES, out=out, shard_size=8, workers=1, seed=5)
    return generate(family, config).folder


@pytest.fixture(scope="session")
def toy_unsplit(tmp_path_factory):
    """16 toy rendezvous instances, not split."""
    return _generate(tmp_path_factory, ToyRendezvousFamily(), "toy-rdv")


def _split_copy(tmp_path_factory, source, name, fractions):
    folder = tmp_path_factory.mktemp(name) / "ds"
    shutil.copytree(source, folder)
    make_splits(folder, SplitConfig(fractions=fractions, seed=1))
    return folder


@pytest.fixture(scope="session")
def toy_rdv(tmp_path_factory, toy_unsplit):
    """The toy dataset split 0.5/0.25/0.25: with a validation split."""
    return _split_copy(tmp_path_factory, toy_unsplit, "toy-val", (0.5, 0.25, 0.25))


@pytest.fixture(scope="session")
def toy_rdv_no_val(tmp_path_factory, toy_unsplit):
    """The toy dataset split with the default fractions 0.8/0/0.2: no validation split."""
    return _split_copy(tmp_path_factory, toy_unsplit, "toy-noval", (0.8, 0.0, 0.2))


@pytest.fixture(scope="session")
def toy_rdv_tpbvp(tmp_path_factory):
    """Toy rendezvous data that also holds the Problem 1 twin (``tpbvp``), split."""
    family = ToyRendezvousFamily(twins=("scp", "cvx", "tpbvp"))
    folder = _generate(tmp_path_factory, family, "toy-tpbvp")
    make_splits(folder, SplitConfig(fractions=(0.5, 0.25, 0.25), seed=1))
    return folder


@pytest.fixture(scope="session")
def toy_robust(tmp_path_factory):
    """Toy robust-rendezvous data (twins ps/cvx), split with a validation split."""
    family = ToyRendezvousFamily(name="robust-rendezvous", twins=("ps", "cvx"))
    folder = _generate(tmp_path_factory, family, "toy-robust")
    make_splits(folder, SplitConfig(fractions=(0.5, 0.25, 0.25), seed=1))
    return folder


@pytest.fixture(scope="session")
def toy_other_family(tmp_path_factory):
    """A split dataset of a family ART does not train on."""
    folder = _generate(tmp_path_factory, ToyRendezvousFamily(name="pdg6dof"), "toy-other")
    make_splits(folder, SplitConfig(fractions=(0.5, 0.25, 0.25), seed=1))
    return folder
