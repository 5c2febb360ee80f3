"""Splits grouped by base instance never leak; statistics come from training data only."""

import numpy as np
import pytest

from scpformer.data import storage
from scpformer.data.errors import DatasetError
from scpformer.data.family import COMMON_FIELDS, Field
from scpformer.data.splits import (
    SPLITS_NAME,
    SplitConfig,
    assign_groups,
    check_splits,
    leaking_groups,
    load_splits,
    make_splits,
    write_splits,
)

SCHEMA = (*COMMON_FIELDS, Field(name="theta", dtype="float64", shape=(2,), normalize=True))
COPIES = 8  # augmented copies per base instance


def grouped_dataset(folder, n_groups=30, per_shard=40):
    """``n_groups`` base instances with 8 copies each, over several shards."""
    rng = np.random.default_rng(1)
    total = n_groups * COPIES
    base = np.repeat(np.arange(n_groups), COPIES)
    status = np.where(rng.uniform(size=total) < 0.8, "ok", "bad").astype(object)
    theta = rng.normal(loc=3.0, scale=2.0, size=(total, 2))
    manifest = storage.Manifest(
        family="toy",
        seed=0,
        n=n_groups,
        shard_size=per_shard,
        config={},
        schema=SCHEMA,
        package_version="0",
        versions={},
        success_statuses=("ok",),
        kind="transformed",
        plan=tuple((a, a + per_shard) for a in range(0, total, per_shard)),
    )
    for number, start in enumerate(range(0, total, per_shard)):
        rows = slice(start, start + per_shard)
        columns = {
            "index": np.arange(total)[rows],
            "base_index": base[rows],
            "status": status[rows],
            "message": np.full(per_shard, "", dtype=object),
            "wall_time": np.zeros(per_shard),
            "theta": theta[rows],
        }
        info = storage.write_shard(
            folder / storage.shard_name(number),
            columns,
            SCHEMA,
            start=start,
            stop=start + per_shard,
            attrs={},
        )
        manifest = manifest.with_shard(info)
    storage.write_manifest(folder, manifest)
    return base, status, theta


@pytest.mark.parametrize("seed", range(5))
def test_grouped_splits_never_leak_and_cover_every_sample_once(seed):
    rng = np.random.default_rng(seed)
    groups = rng.integers(0, 40, size=300)
    indices = assign_groups(groups, (0.7, 0.1, 0.2), seed)
    every = np.concatenate(list(indices.values()))
    assert sorted(every) == list(range(300))
    assert leaking_groups(indices, groups).size == 0


def test_splits_cut_groups_by_the_fractions(tmp_path):
    grouped_dataset(tmp_path)
    splits = make_splits(tmp_path, SplitConfig(fractions=(0.6, 0.2, 0.2), seed=3))
    sizes = {k: len(v) // COPIES for k, v in splits.indices.items()}
    assert sizes == {"train": 18, "validation": 6, "test": 6}
    assert check_splits(tmp_path) == []


def test_statistics_come_from_solved_training_samples_only(tmp_path):
    _, status, theta = grouped_dataset(tmp_path)
    splits = make_splits(tmp_path)
    train = splits.indices["train"]
    chosen = train[status[train] == "ok"]
    stats = splits.stats["theta"]
    np.testing.assert_allclose(stats.mean, theta[chosen].mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(stats.std, theta[chosen].std(axis=0), rtol=1e-12)
    assert stats.count.tolist() == [len(chosen)] * 2
    reloaded = load_splits(tmp_path)
    np.testing.assert_array_equal(reloaded.stats["theta"].mean, stats.mean)
    assert {k: v.tolist() for k, v in reloaded.indices.items()} == {
        k: v.tolist() for k, v in splits.indices.items()
    }
    normalized = reloaded.normalize("theta", theta[chosen])
    np.testing.assert_allclose(normalized.mean(axis=0), 0.0, atol=1e-12)


def test_a_tampered_split_that_leaks_a_group_is_reported(tmp_path):
    grouped_dataset(tmp_path)
    splits = make_splits(tmp_path)
    moved = splits.indices["train"][0]
    splits.indices["train"] = splits.indices["train"][1:]
    splits.indices["test"] = np.sort(np.append(splits.indices["test"], moved))
    write_splits(tmp_path, splits)
    assert check_splits(tmp_path) == [f"{SPLITS_NAME}: 1 group(s) straddle splits"]


def test_splits_of_other_data_are_refused(tmp_path):
    grouped_dataset(tmp_path)
    make_splits(tmp_path)
    manifest = storage.read_manifest(tmp_path)
    storage.write_manifest(tmp_path, manifest.without_shard(storage.shard_name(0)))
    with pytest.raises(DatasetError, match=r"made for different data"):
        load_splits(tmp_path)


def test_split_settings_are_validated():
    for fractions in ((0.5, 0.5, 0.5), (float("nan"), 0.5, 0.5), (0.5, 0.5, float("nan"))):
        with pytest.raises(ValueError, match=r"fractions must be 3 nonnegative numbers summing"):
            SplitConfig(fractions=fractions)
