"""PyTorch views for T-SCvx: (theta, k) -> tight flags and theta -> solution."""

import shutil

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="torch is not installed: the views are untested")

from torch.utils.data import DataLoader  # noqa: E402
from toy_families import ToyFamily  # noqa: E402

from scpformer.data import storage  # noqa: E402
from scpformer.data.errors import DatasetError  # noqa: E402
from scpformer.data.generate import GenerateConfig, generate  # noqa: E402
from scpformer.data.splits import SplitConfig, make_splits  # noqa: E402
from scpformer.data.torch_views import SolutionDataset, TightFlagsDataset  # noqa: E402

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def split_dataset(tmp_path_factory, pdg_dataset):
    folder = tmp_path_factory.mktemp("views") / "ds"
    shutil.copytree(pdg_dataset.folder, folder)
    splits = make_splits(folder, SplitConfig(fractions=(0.5, 0.0, 0.5)))
    return folder, splits


def test_flags_view_serves_one_item_per_sample_and_iteration(split_dataset):
    folder, splits = split_dataset
    view = TightFlagsDataset(folder, "train")
    samples = storage.ShardedSamples(folder)
    train = splits.indices["train"]
    iterations = samples.column("iterations")[train]
    assert len(view) == iterations.sum()
    item = view[len(view) - 1]
    assert item["theta"].shape == (16,) and item["flags"].shape == (350,)
    assert item["k"].item() == iterations[-1]
    stored = samples.read("tight_flags", int(train[-1]))[iterations[-1] - 1]
    np.testing.assert_array_equal(item["flags"].numpy().astype(bool), stored)


def test_solution_view_standardizes_with_training_statistics(split_dataset):
    folder, splits = split_dataset
    view = SolutionDataset(folder, "test")
    raw = SolutionDataset(folder, "test", normalize=False)
    assert len(view) == len(splits.indices["test"])
    item, plain = view[0], raw[0]
    assert {k: tuple(v.shape) for k, v in item.items()} == {
        "theta": (16,),
        "x": (50, 14),
        "u": (50, 3),
        "tf": (),
    }
    back = splits.denormalize("x", item["x"].double().numpy())
    np.testing.assert_allclose(back, plain["x"].double().numpy(), rtol=1e-5, atol=1e-5)


def test_views_batch_through_a_multiprocess_data_loader(split_dataset):
    folder, _ = split_dataset
    loader = DataLoader(TightFlagsDataset(folder, None), batch_size=8, num_workers=2)
    batch = next(iter(loader))
    assert batch["theta"].shape == (8, 16) and batch["flags"].shape == (8, 350)


def test_views_need_splits_and_their_own_family(tmp_path, pdg_dataset):
    with pytest.raises(DatasetError, match=r"run `scpformer dataset split"):
        SolutionDataset(pdg_dataset.folder, "train")
    generate(ToyFamily(), GenerateConfig(n=2, out=tmp_path / "toy", workers=1))
    with pytest.raises(DatasetError, match=r"reads pdg6dof data, not toy"):
        SolutionDataset(tmp_path / "toy", None, normalize=False)
