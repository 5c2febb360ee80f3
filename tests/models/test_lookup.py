"""Lookup-table baselines of T-SCvx (paper Sec. IV.C): fit, predict, save and load."""

from __future__ import annotations

import json

import numpy as np
import pytest
from fake_affine_pdg6dof import (
    BASE,
    DIRECTIONS,
    ITER_MAX,
    LATENT,
    N_NODES,
    FakePDGFamily,
    true_flags,
    true_solution,
)

from scpformer.cli.main import main
from scpformer.data.generate import GenerateConfig, generate
from scpformer.data.ood import ood_split
from scpformer.data.splits import SplitConfig, make_splits
from scpformer.data.torch_views import SolutionDataset, TightFlagsDataset
from scpformer.data.tscvx_arrays import flatten_solution, read_split_arrays
from scpformer.experiments.prediction_metrics import load_eval_set, measure_predictor
from scpformer.models.lookup import (
    LOOKUP_JSON,
    LOOKUP_NPZ,
    InterpolationTable,
    LookupConfig,
    LookupRunError,
    fit_lookup,
    load_lookup_predictor,
    save_lookup,
)

N_SAMPLES = 40


@pytest.fixture(scope="module")
def fake_pdg(tmp_path_factory):
    """40 fake 6-DoF samples, split 60/20/20 by instance."""
    folder = tmp_path_factory.mktemp("fake_pdg") / "ds"
    generate(FakePDGFamily(), GenerateConfig(n=N_SAMPLES, out=folder, shard_size=16, workers=1))
    make_splits(folder, SplitConfig(fractions=(0.6, 0.2, 0.2), seed=0))
    return folder


@pytest.fixture(scope="module")
def train(fake_pdg):
    return read_split_arrays(fake_pdg, "train")


def test_split_arrays_hold_the_items_of_the_torch_views(fake_pdg, train):
    flags_view = TightFlagsDataset(fake_pdg, "train", normalize=False)
    solution_view = SolutionDataset(fake_pdg, "train", normalize=False)
    assert len(train.item_k) == len(flags_view) and len(train.theta) == len(solution_view)
    for i in (0, len(flags_view) // 2, len(flags_view) - 1):
        item = flags_view[i]
        assert item["k"].item() == train.item_k[i]
        np.testing.assert_array_equal(item["flags"].numpy().astype(bool), train.flags[i])
    item = solution_view[3]
    expected = flatten_solution(item["x"].numpy(), item["u"].numpy(), item["tf"].numpy())
    np.testing.assert_allclose(train.solution[3], expected, rtol=1e-6)


def test_kdtree_recalls_every_training_point_exactly(train):
    predictor = fit_lookup("kdtree", train)
    flags = predictor.predict_tight(train.item_theta, train.item_k)
    np.testing.assert_array_equal(flags, train.flags)
    x, u, tf = predictor.predict_solution(train.theta)
    np.testing.assert_allclose(flatten_solution(x, u, tf), train.solution, atol=1e-9)


def test_interpolation_reproduces_a_linear_function_inside_the_hull(train):
    predictor = fit_lookup("interp", train, LookupConfig(max_points=0))
    assert predictor.solution.inputs.dims == LATENT  # theta spans LATENT directions only
    rng = np.random.default_rng(5)
    weights = rng.dirichlet(np.ones(len(train.theta)), size=6)  # convex combinations
    theta = weights @ train.theta
    x, u, tf = predictor.predict_solution(theta)
    np.testing.assert_allclose(flatten_solution(x, u, tf), true_solution(theta), atol=1e-8)


def test_interpolation_falls_back_to_the_nearest_point_outside_the_hull(train):
    predictor = fit_lookup("interp", train, LookupConfig(max_points=0))
    far = BASE + 50.0 * DIRECTIONS[0]
    stats = train.splits.stats["theta"]  # nearest in standardized coordinates
    distance = np.linalg.norm((train.theta - far) / stats.std, axis=1)
    nearest = train.theta[np.argmin(distance)]
    x, u, tf = predictor.predict_solution(far)
    np.testing.assert_allclose(flatten_solution(x, u, tf), true_solution(nearest), atol=1e-8)


def test_interpolation_table_holds_max_points_training_points(train):
    predictor = fit_lookup("interp", train, LookupConfig(max_points=10, n_components=2))
    assert len(predictor.tight.table.points) == 10
    assert predictor.tight.inputs.dims == 2


def test_single_queries_return_unbatched_outputs_of_the_contract(train):
    predictor = fit_lookup("kdtree", train)
    assert predictor.n_nodes == N_NODES
    flags = predictor.predict_tight(train.theta[0], 2)
    proba = predictor.predict_tight_proba(train.theta[0], 2)
    assert flags.shape == proba.shape == (7 * N_NODES,) and flags.dtype == bool
    np.testing.assert_array_equal(flags, true_flags(train.theta[0], 2))
    x, u, tf = predictor.predict_solution(train.theta[0])
    assert x.shape == (N_NODES, 14) and u.shape == (N_NODES, 3) and isinstance(tf, float)
    batch = predictor.predict_tight(train.theta[:3], np.array([1, 2, 3]))
    assert batch.shape == (3, 7 * N_NODES)


@pytest.mark.parametrize(
    ("theta", "k", "error", "match"),
    [
        (np.zeros(15), 1, ValueError, r"theta must have shape \(16,\)"),
        (np.zeros((2, 3, 16)), 1, ValueError, r"theta must have shape"),
        (np.full(16, np.nan), 1, ValueError, r"theta must be finite"),
        ("abc", 1, TypeError, r"theta must be a numeric array"),
        (np.zeros(16), 1.5, TypeError, r"k must be an integer"),
        (np.zeros(16), 0, ValueError, r"k must be >= 1"),
        (np.zeros((2, 16)), np.array([1, 2, 3]), ValueError, r"k must be an int or have shape"),
        (np.zeros(16), np.array([1, 2]), ValueError, r"k must be an int for a single theta"),
    ],
)
def test_bad_queries_raise_naming_the_argument(train, theta, k, error, match):
    predictor = fit_lookup("kdtree", train)
    with pytest.raises(error, match=match):
        predictor.predict_tight(theta, k)


def test_bad_solution_query_raises(train):
    predictor = fit_lookup("kdtree", train)
    with pytest.raises(ValueError, match=r"theta must be finite"):
        predictor.predict_solution(np.r_[np.zeros(15), np.inf])


@pytest.mark.parametrize("kind", ["kdtree", "interp"])
def test_save_and_load_round_trip(tmp_path, train, kind):
    predictor = fit_lookup(kind, train, LookupConfig(max_points=20, n_components=3))
    save_lookup(predictor, tmp_path)
    loaded = load_lookup_predictor(tmp_path)
    assert loaded.kind == kind and loaded.config == predictor.config
    theta = train.theta[:5] + 0.01
    ks = np.arange(1, 6)
    np.testing.assert_array_equal(
        loaded.predict_tight_proba(theta, ks), predictor.predict_tight_proba(theta, ks)
    )
    for a, b in zip(loaded.predict_solution(theta), predictor.predict_solution(theta), strict=True):
        np.testing.assert_array_equal(a, b)
    meta = json.loads((tmp_path / LOOKUP_JSON).read_text())
    assert meta["pca_dims"] == {"tight": 3, "solution": 3}
    assert meta["dataset_content_id"] == train.content_id


def test_corrupt_or_mismatched_run_folders_fail_in_one_line(tmp_path, train):
    with pytest.raises(LookupRunError, match="no lookup table"):
        load_lookup_predictor(tmp_path)
    save_lookup(fit_lookup("kdtree", train), tmp_path)
    npz = tmp_path / LOOKUP_NPZ
    npz.write_bytes(npz.read_bytes()[:-10])
    with pytest.raises(LookupRunError, match="does not match") as info:
        load_lookup_predictor(tmp_path)
    assert "\n" not in str(info.value)
    (tmp_path / LOOKUP_JSON).write_text("{not json")
    with pytest.raises(LookupRunError, match="corrupt"):
        load_lookup_predictor(tmp_path)


def test_train_commands_write_loadable_run_folders(tmp_path, fake_pdg, capsys):
    for kind in ("kdtree", "interp"):
        out = tmp_path / kind
        args = ["train", kind, "--data", str(fake_pdg), "--out", str(out), "--n-components", "3"]
        assert main(args) == 0
        assert load_lookup_predictor(out).kind == kind
    assert "PCA dimensions" in capsys.readouterr().out


def test_train_command_rejects_bad_settings(tmp_path, fake_pdg, capsys):
    args = ["train", "interp", "--data", str(fake_pdg), "--out", str(tmp_path), "--max-points"]
    assert main([*args, "-1"]) == 2
    assert "max_points must be >= 0" in capsys.readouterr().err


def test_ood_split_marks_test_samples_beyond_the_training_percentile(fake_pdg, train):
    split = ood_split(fake_pdg, "test", percentile=50.0)
    reference = split.reference
    assert np.mean(reference.distance(train.theta) > reference.threshold) == pytest.approx(
        0.5, abs=1.0 / len(train.theta)
    )
    np.testing.assert_array_equal(split.ood, split.distance > reference.threshold)
    assert len(split.ood_positions) + len(split.in_distribution_positions) == len(split.positions)


def test_measurements_of_a_kdtree_on_its_own_training_split_are_exact(fake_pdg):
    predictor = fit_lookup("kdtree", fake_pdg)
    metrics = measure_predictor(predictor, load_eval_set(fake_pdg, "train"))
    assert metrics.tight_mse == 0.0 and metrics.tight_accuracy == 1.0
    assert metrics.solution_mse == pytest.approx(0.0, abs=1e-18)
    assert metrics.memory_bytes == predictor.memory_bytes() > 0
    assert metrics.n_items > metrics.n_samples > 0


def test_iterations_stay_within_iter_max(train):
    assert train.item_k.min() == 1 and train.item_k.max() <= ITER_MAX


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n_components": 0}, r"n_components must be >= 1"),
        ({"max_points": -1}, r"max_points must be >= 0"),
        ({"threshold": 1.0}, r"threshold must be in \(0, 1\)"),
        ({"leaf_size": 0}, r"leaf_size must be >= 1"),
    ],
)
def test_bad_lookup_settings_raise_naming_the_field(kwargs, match):
    with pytest.raises(ValueError, match=match):
        LookupConfig(**kwargs)


def test_unknown_kind_raises(train):
    with pytest.raises(ValueError, match=r"kind must be one of \('kdtree', 'interp'\)"):
        fit_lookup("tree", train)


def test_interpolation_needs_more_points_than_dimensions(train):
    with pytest.raises(ValueError, match=r"needs more than 3 points"):
        InterpolationTable(np.zeros((3, 3)), np.zeros((3, 2)))


def test_interpolation_in_one_dimension_is_refused_with_the_way_out():
    with pytest.raises(ValueError, match=r"at least 2 dimensions, the PCA kept 1; use n_comp"):
        InterpolationTable(np.arange(5.0)[:, None], np.zeros((5, 2)))
