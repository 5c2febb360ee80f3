"""The ART view of rendezvous datasets: shapes, twins kept together, training-only statistics."""

import shutil

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="torch is not installed: the views are untested")

from toy_families import ToyFamily  # noqa: E402

from scpformer.data import storage  # noqa: E402
from scpformer.data.errors import DatasetError  # noqa: E402
from scpformer.data.generate import GenerateConfig, generate  # noqa: E402
from scpformer.data.splits import SplitConfig, Stats, leaking_groups, make_splits  # noqa: E402
from scpformer.data.torch_views import ArtSequenceDataset, pooled_stats  # noqa: E402

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def split_rdv(tmp_path_factory, rdv_dataset):
    folder = tmp_path_factory.mktemp("art") / "ds"
    shutil.copytree(rdv_dataset.folder, folder)
    return folder, make_splits(folder, SplitConfig(fractions=(0.5, 0.0, 0.5), seed=1))


def test_items_are_art_sequences_of_both_twins(split_rdv):
    folder, splits = split_rdv
    view = ArtSequenceDataset(folder, "train")
    assert view.twins == ("scp", "cvx") and len(view) == 2 * len(splits.indices["train"])
    item = view[0]
    shapes = {k: (tuple(v.shape), v.dtype) for k, v in item.items()}
    f32 = torch.float32
    assert shapes == {
        "rtg": ((100, 1), f32),
        "ctg": ((100, 1), f32),
        "state": ((100, 6), f32),
        "action": ((100, 3), f32),
        "t": ((100,), f32),
        "theta": ((13,), f32),
        "twin": ((), torch.int64),
        "base_index": ((), torch.int64),
    }


def test_the_tpbvp_twin_is_served_only_when_named_with_its_own_statistics(split_rdv):
    folder, splits = split_rdv
    view = ArtSequenceDataset(folder, "train", twins=["tpbvp"])
    assert view.twins == ("tpbvp",) and len(view) == len(splits.indices["train"])
    samples = storage.ShardedSamples(folder)
    position = int(view.items[0, 0])
    mean, std = pooled_stats([splits.stats["tpbvp_rtn"]])
    expected = (samples.read("tpbvp_rtn", position)[:100] - mean[:100]) / std[:100]
    np.testing.assert_allclose(view[0]["state"], expected, rtol=1e-5, atol=1e-5)


def test_raw_items_are_the_stored_sequences(split_rdv):
    folder, _ = split_rdv
    samples = storage.ShardedSamples(folder)
    for frame in ("rtn", "roe"):
        view = ArtSequenceDataset(folder, None, frame=frame, normalize=False)
        for i in (0, len(view) - 1):
            position, twin = view.items[i]
            p, item = view.twins[twin], view[i]
            np.testing.assert_allclose(item["state"], samples.read(f"{p}_{frame}", position)[:100])
            np.testing.assert_allclose(item["action"], samples.read(f"{p}_dv", position), 1e-6)
            np.testing.assert_allclose(item["rtg"][:, 0], samples.read(f"{p}_rtg", position)[:100])
            np.testing.assert_array_equal(
                item["ctg"][:, 0], samples.read(f"{p}_ctg", position)[:100]
            )


def test_twins_stay_in_one_split_and_pairs_serve_both(split_rdv):
    folder, splits = split_rdv
    groups = storage.ShardedSamples(folder).column("base_index")
    assert leaking_groups(splits.indices, groups).size == 0
    bases = {}
    for split in ("train", "test"):
        view = ArtSequenceDataset(folder, split)
        served = [(int(view[i]["base_index"]), int(view[i]["twin"])) for i in range(len(view))]
        bases[split] = {b for b, _ in served}
        assert sorted(served) == sorted((b, t) for b in bases[split] for t in (0, 1))
        pairs = ArtSequenceDataset(folder, split, pairs=True)
        assert len(pairs) == len(bases[split]) and {"scp_state", "cvx_ctg"} <= set(pairs[0])
    assert bases["train"] and bases["test"] and not bases["train"] & bases["test"]


def test_states_are_standardized_with_pooled_training_statistics_only(split_rdv):
    folder, splits = split_rdv
    samples = storage.ShardedSamples(folder)
    train = splits.indices["train"]
    states = np.concatenate(
        [[samples.read(f"{p}_rtn", int(i)) for i in train] for p in "scp cvx".split()]
    )
    mean, std = states.mean(axis=0), states.std(axis=0)
    std = np.where(std < 1e-12, 1.0, std)
    view = ArtSequenceDataset(folder, "test")
    position, twin = view.items[0]
    raw = samples.read(f"{view.twins[twin]}_rtn", int(position))[:100]
    expected = (raw - mean[:100]) / std[:100]
    np.testing.assert_allclose(view[0]["state"].double().numpy(), expected, rtol=1e-4, atol=1e-4)


def test_pooled_statistics_match_the_union():
    rng = np.random.default_rng(0)
    a, b = rng.normal(1.0, 2.0, (5, 3)), rng.normal(-1.0, 0.5, (7, 3))
    a[:, 2] = b[:, 2] = 4.0  # a constant element: stored std floored to 1
    stats = [
        Stats(x.mean(0), np.where(x.std(0) < 1e-12, 1.0, x.std(0)), np.full(3, len(x)))
        for x in (a, b)
    ]
    mean, std = pooled_stats(stats)
    union = np.concatenate([a, b])
    np.testing.assert_allclose(mean, union.mean(0))
    np.testing.assert_allclose(std[:2], union.std(0)[:2])
    assert std[2] == 1.0


def test_the_view_reads_lazily_and_batches(split_rdv):
    folder, _ = split_rdv
    view = ArtSequenceDataset(folder, None, twins=["cvx"])
    held = [a for a in vars(view).values() if isinstance(a, np.ndarray)]
    assert sum(a.nbytes for a in held) <= 64 * len(view.samples)  # indices, no sequences
    loader = torch.utils.data.DataLoader(view, batch_size=4)
    batch = next(iter(loader))
    assert batch["state"].shape == (4, 100, 6) and (batch["twin"] == 0).all()


def test_bad_views_are_clear_errors(tmp_path, split_rdv):
    folder, _ = split_rdv
    with pytest.raises(ValueError, match="frame must be one of"):
        ArtSequenceDataset(folder, frame="eci")
    with pytest.raises(ValueError, match="twins must be a non-empty subset"):
        ArtSequenceDataset(folder, twins=["ws"])
    generate(ToyFamily(), GenerateConfig(n=2, out=tmp_path / "toy", workers=1))
    with pytest.raises(DatasetError, match="reads rendezvous or robust-rendezvous data, not toy"):
        ArtSequenceDataset(tmp_path / "toy", None, normalize=False)
