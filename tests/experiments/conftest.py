"""A tiny split rendezvous dataset and randomly initialized ART/GRU/LSTM checkpoints."""

from __future__ import annotations

import pytest

pytest.importorskip("torch", reason="torch is not installed: the ART experiments are untested")

from scpformer.data.generate import GenerateConfig, generate
from scpformer.data.rendezvous_family import RendezvousDataConfig, RendezvousFamily
from scpformer.data.splits import SplitConfig, make_splits

N_INSTANCES = 6
TINY = {
    "art": {"n_layer": 1, "n_head": 2, "n_embd": 16},
    "gru": {"n_layer": 1, "n_embd": 16},
    "lstm": {"n_layer": 1, "n_embd": 16},
}


@pytest.fixture(scope="session")
def tiny_data(tmp_path_factory):
    """6 rendezvous instances (no nonlinear replay), split 1/3 train, 2/3 test."""
    family = RendezvousFamily(RendezvousDataConfig(verify=False))
    out = tmp_path_factory.mktemp("exp-data") / "ds"
    generate(family, GenerateConfig(n=N_INSTANCES, out=out, shard_size=6, workers=2, seed=11))
    make_splits(out, SplitConfig(fractions=(0.34, 0.0, 0.66), seed=0))
    return out


@pytest.fixture(scope="session")
def tiny_data_without_tpbvp(tmp_path_factory):
    """4 rendezvous instances of a dataset without the Problem 1 twin (as made before it)."""
    family = RendezvousFamily(RendezvousDataConfig(verify=False, tpbvp_twin=False))
    out = tmp_path_factory.mktemp("exp-old") / "ds"
    generate(family, GenerateConfig(n=4, out=out, shard_size=4, workers=1, seed=11))
    make_splits(out, SplitConfig(fractions=(0.5, 0.0, 0.5), seed=0))
    return out


def _random_run(folder, data, kind):
    import torch

    from scpformer.data.torch_views import ArtSequenceDataset
    from scpformer.models import build_model, preset
    from scpformer.models.normalization import ArtNormalization
    from scpformer.train.checkpoint import manifest_digest, save_checkpoint

    torch.manual_seed(0)
    config = preset(kind, "small", **TINY[kind])
    view = ArtSequenceDataset(data, "train", frame="rtn", normalize=False)
    save_checkpoint(
        folder,
        model=build_model(kind, config),
        kind=kind,
        config=config,
        normalization=ArtNormalization.from_dataset(view),
        frame="rtn",
        family="rendezvous",
        manifest_digest=manifest_digest(data),
        seed=0,
        n_steps=100,
    )
    return folder


@pytest.fixture(scope="session")
def tiny_runs(tmp_path_factory, tiny_data):
    """Randomly initialized ART, GRU and LSTM run folders (kind -> folder)."""
    root = tmp_path_factory.mktemp("exp-runs")
    return {kind: _random_run(root / kind, tiny_data, kind) for kind in TINY}


@pytest.fixture(scope="session")
def tiny_robust(tmp_path_factory):
    """4 chance-constrained robust instances split 1/2 train, 1/4 test, and an RTN ART run."""
    from scpformer.cli.main import main
    from scpformer.data.robust_rendezvous_family import RobustDataConfig, RobustRendezvousFamily

    root = tmp_path_factory.mktemp("exp-robust")
    family = RobustRendezvousFamily(RobustDataConfig(verify=False))
    generate(family, GenerateConfig(n=4, out=root / "ds", shard_size=4, workers=2, seed=2))
    make_splits(root / "ds", SplitConfig(fractions=(0.5, 0.25, 0.25), seed=0))
    argv = [
        "train",
        "art",
        "--data",
        str(root / "ds"),
        "--out",
        str(root / "art-rtn"),
        "--epochs",
        "1",
        "--no-progress",
    ]
    assert main(argv) == 0
    return root / "ds", root / "art-rtn"
