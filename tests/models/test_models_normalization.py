"""ArtNormalization: the view's own standardization, round trips, training-split scales."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from scpformer.data.storage import ShardedSamples  # noqa: E402
from scpformer.data.torch_views import ArtSequenceDataset  # noqa: E402
from scpformer.models.normalization import ArtNormalization  # noqa: E402


@pytest.fixture(scope="module")
def normalization(fake_rdv):
    return ArtNormalization.from_dataset(ArtSequenceDataset(fake_rdv, "train", normalize=False))


def test_encoding_equals_the_views_own_standardization(fake_rdv, normalization):
    samples = ShardedSamples(fake_rdv)
    view = ArtSequenceDataset(fake_rdv, "test")
    for i in range(len(view)):
        position, twin = view.items[i]
        p = view.twins[twin]
        state = samples.read(f"{p}_rtn", position)[: view.n_steps]  # float64, as stored
        action = samples.read(f"{p}_dv", position)
        np.testing.assert_allclose(normalization.encode("state", state), view[i]["state"], 1e-5)
        np.testing.assert_allclose(normalization.encode("action", action), view[i]["action"], 1e-5)


def test_statistics_do_not_depend_on_the_split_or_normalization_of_the_view(fake_rdv):
    a = ArtNormalization.from_dataset(ArtSequenceDataset(fake_rdv, "train", normalize=False))
    b = ArtNormalization.from_dataset(ArtSequenceDataset(fake_rdv, "validation"))
    assert a.to_dict() == b.to_dict()


def test_rtg_and_ctg_scales_are_their_training_root_mean_squares(fake_rdv, normalization):
    view = ArtSequenceDataset(fake_rdv, "train", normalize=False)
    rtg = np.concatenate([view[i]["rtg"].numpy().ravel() for i in range(len(view))])
    ctg = np.concatenate([view[i]["ctg"].numpy().ravel() for i in range(len(view))])
    assert normalization.rtg_scale == pytest.approx(np.sqrt(np.mean(rtg**2)), rel=1e-5)
    assert normalization.ctg_scale == pytest.approx(np.sqrt(np.mean(ctg**2)), rel=1e-5)


@pytest.mark.parametrize("key", ["state", "action", "rtg", "ctg"])
def test_decode_inverts_encode_for_numpy_and_torch_sequences_and_single_steps(normalization, key):
    rng = np.random.default_rng(0)
    width = {"state": 6, "action": 3}.get(key, 1)
    value = rng.normal(size=(2, 7, width)) * 50.0
    np.testing.assert_allclose(normalization.decode(key, normalization.encode(key, value)), value)
    tensor = torch.as_tensor(value, dtype=torch.float32)
    round_trip = normalization.decode(key, normalization.encode(key, tensor))
    assert round_trip.dtype == torch.float32
    torch.testing.assert_close(round_trip, tensor, rtol=1e-5, atol=1e-3)
    step = normalization.encode(key, tensor[:, 4], step=4)
    torch.testing.assert_close(step, normalization.encode(key, tensor)[:, 4])


def test_target_statistics_come_from_the_given_training_targets(fake_rdv):
    view = ArtSequenceDataset(fake_rdv, "train", normalize=False)
    targets = np.array([[1.0, 2, 3, 4, 5, 6], [3.0, 2, 1, 0, -1, -2]])
    norm = ArtNormalization.from_dataset(view, targets=targets)
    np.testing.assert_allclose(
        norm.encode("target", targets), [[-1, 0, 1, 1, 1, 1], [1, 0, -1, -1, -1, -1]]
    )
    with pytest.raises(ValueError, match="no target statistics"):
        ArtNormalization.from_dataset(view).encode("target", targets)


def test_dict_round_trip_and_bad_input(normalization):
    again = ArtNormalization.from_dict(normalization.to_dict())
    assert again.to_dict() == normalization.to_dict()
    with pytest.raises(ValueError, match="unknown keys \\['extra'\\]"):
        ArtNormalization.from_dict({**normalization.to_dict(), "extra": 1})
    with pytest.raises(ValueError, match="key must be one of"):
        normalization.encode("theta", np.zeros(3))
    with pytest.raises(ValueError, match="step must be an int"):
        normalization.encode("state", np.zeros(6), step=10_000)
    with pytest.raises(ValueError, match="step must be an int") as err:
        normalization.encode("state", np.zeros(6), step=np.int64(-1))
    assert "'state', got -1" in str(err.value) and "np." not in str(err.value)
    with pytest.raises(ValueError, match="rtg_scale must be a positive number"):
        ArtNormalization.from_dict({**normalization.to_dict(), "rtg_scale": 0.0})


def test_nearly_constant_steps_get_a_floor_of_the_elements_overall_spread():
    from scpformer.models.normalization import STEP_STD_FLOOR, _per_step_floor

    rng = np.random.default_rng(0)
    values = rng.normal(scale=0.02, size=(500, 10, 3))  # (samples, steps, elements) [m/s]
    values[:, 7:] = 1e-12 * rng.normal(size=(500, 3, 3))  # coasting steps: no impulse
    mean, std = values.mean(axis=0), values.std(axis=0)
    std = np.where(std < 1e-8, 1.0, std)  # the splits' marker of a constant element
    floored = _per_step_floor(mean, std)
    overall = values.reshape(-1, 3).std(axis=0)
    np.testing.assert_allclose(floored[7:], np.broadcast_to(STEP_STD_FLOOR * overall, (3, 3)),
                               rtol=1e-6)  # fmt: skip
    np.testing.assert_allclose(floored[:7], std[:7])  # ordinary steps keep their own std
