"""The robust rendezvous dataset family: contents, determinism across workers, CLI."""

import dataclasses
import json

import numpy as np
import pytest

from scpformer.cli.data import main
from scpformer.data import storage
from scpformer.data.executors import instance_rng
from scpformer.data.family import DatasetFamily, build_family, full_schema
from scpformer.data.generate import GenerateConfig, generate
from scpformer.data.robust_rendezvous_family import (
    THETA_NAMES,
    TWINS,
    RobustDataConfig,
    RobustRendezvousFamily,
    instance_from_theta,
    theta_vector,
)
from scpformer.problems.robust_rendezvous import constraint_violation_budget
from scpformer.problems.robust_rendezvous.problem import STAGES
from scpformer.problems.robust_rendezvous.safety import linear_model, trajectory_violations

pytestmark = pytest.mark.slow  # every dataset test runs the three-stage solve (~0.5 s each)

N_ROBUST, SEED = 3, 5
DETERMINISTIC = RobustRendezvousFamily(RobustDataConfig(mode="deterministic"))


def all_columns(folder):
    manifest = storage.read_manifest(folder)
    parts = [storage.read_columns(folder / s.file, manifest.schema) for s in manifest.shards]
    return {f.name: np.concatenate([p[f.name] for p in parts]) for f in manifest.schema}


@pytest.fixture(scope="module")
def robust_dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("robust") / "ds"
    config = GenerateConfig(n=N_ROBUST, out=out, shard_size=2, workers=2, seed=SEED)
    return generate(DETERMINISTIC, config)


def test_family_implements_the_protocol_and_rebuilds_from_its_manifest(robust_dataset):
    assert isinstance(DETERMINISTIC, DatasetFamily)
    config = storage.read_manifest(robust_dataset.folder).config
    assert config["mode"] == "deterministic"
    assert build_family("robust-rendezvous", config) == DETERMINISTIC
    chance = RobustRendezvousFamily()
    assert build_family("robust-rendezvous", json.loads(json.dumps(chance.config_dict()))) == chance
    with pytest.raises(ValueError, match="mode must be one of deterministic, chance"):
        RobustDataConfig(mode="robust")


def test_theta_round_trips_through_the_instance():
    instance = DETERMINISTIC.sample(np.random.default_rng(2))
    theta = theta_vector(instance)
    assert theta.shape == (len(THETA_NAMES),)
    assert instance_from_theta(theta) == instance
    with pytest.raises(ValueError, match="waypoint code"):
        instance_from_theta(np.concatenate([theta[:6], [4.0], theta[7:]]))


def test_schema_holds_both_twins_and_the_stage_bookkeeping():
    schema = {f.name: f for f in full_schema(DETERMINISTIC)}
    for p in TWINS:
        assert schema[f"{p}_roe"].shape == schema[f"{p}_rtn"].shape == (101, 6)
        assert schema[f"{p}_dv"].shape == (100, 3)
        assert schema[f"{p}_rtg"].shape == schema[f"{p}_ctg"].shape == (101,)
    for s in STAGES:
        assert schema[f"stage_status_{s}"].dtype == "str"
        assert schema[f"stage_iterations_{s}"].dtype == "int64"
    assert schema["theta"].shape == (13,) and schema["c_cvx_t1"].dtype == "int64"


def test_samples_hold_the_kept_stage_and_the_eq7_budget(robust_dataset):
    data = all_columns(robust_dataset.folder)
    assert list(data["index"]) == list(range(N_ROBUST))
    assert (data["mode"] == "deterministic").all()
    for i in range(N_ROBUST):
        instance = DETERMINISTIC.sample(instance_rng(SEED, i))
        np.testing.assert_array_equal(data["theta"][i], theta_vector(instance))
        assert data["waypoint"][i] == instance.waypoint
        assert data["stage"][i] in STAGES
        assert data["stage_status_tpbvp"][i] == "converged"
        model = linear_model(instance)
        for p in TWINS:
            roe, dv = data[f"{p}_roe"][i], data[f"{p}_dv"][i]
            np.testing.assert_allclose(data[f"{p}_rtn"][i], model.rtn(roe))
            budget = trajectory_violations(instance, roe, dv, "deterministic")
            np.testing.assert_array_equal(data[f"{p}_ctg"][i], budget)  # Eq. 7, independently
            assert data[f"{p}_rtg"][i][0] == pytest.approx(-data[f"{p}_cost"][i])
        assert data["c_cvx_t1"][i] == data["cvx_ctg"][i][0] >= 0
        if data["status"][i] == "converged":
            assert data["stage"][i] == "passive_safety" and data["ps_verified"][i]
            assert (data["ps_ctg"][i] == 0).all()  # passively safe: no budget left to spend
            assert data["iterations"][i] == data["stage_iterations_passive_safety"][i] >= 1
        # The TPBVP is a lower bound up to SCvx*'s tolerances (boundary residual <= 1e-3 m).
        assert data["cost"][i] >= data["cvx_cost"][i] * (1 - 1e-4)
    assert (data["c_cvx_t1"] > 0).any()  # the TPBVP is not passively safe: the budget says so


def test_budget_counts_violated_nodes_from_the_end():
    h = np.array([0.5, -1.0, 2e-3, -0.1])
    np.testing.assert_array_equal(constraint_violation_budget(h), [2, 1, 1, 0, 0])


def test_one_and_two_workers_write_the_same_bytes(tmp_path, robust_dataset):
    config = GenerateConfig(n=N_ROBUST, out=tmp_path / "one", shard_size=2, workers=1)
    one = generate(DETERMINISTIC, dataclasses.replace(config, seed=SEED))
    assert storage.content_id(one.manifest) == storage.content_id(robust_dataset.manifest)


def test_cli_generates_a_chance_dataset_and_rejects_another_mode_in_the_folder(tmp_path, capsys):
    out = tmp_path / "ds"
    argv = ["generate", "robust-rendezvous", "--n", "1", "--out", str(out), "--workers", "1"]
    assert main([*argv, "--mode", "chance", "--quiet"]) == 0
    assert "1 of 1 instances in 1 shard(s)" in capsys.readouterr().out
    assert storage.read_manifest(out).config["mode"] == "chance"
    assert main(["dataset", "info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "robust-rendezvous (generated)" in text and "field stage_status_tpbvp" in text
    assert main([*argv, "--mode", "deterministic"]) == 2
    assert "(config.mode: 'chance' there, 'deterministic' here)" in capsys.readouterr().err
    assert main([*argv, "--mode", "robust"]) == 2  # argparse's one-line usage error


def test_the_art_view_serves_both_twins_with_the_budget_as_constraint_to_go(robust_dataset):
    pytest.importorskip("torch", reason="torch is not installed: the views are untested")
    from scpformer.data.splits import SplitConfig, make_splits
    from scpformer.data.torch_views import ArtSequenceDataset

    make_splits(robust_dataset.folder, SplitConfig(fractions=(1.0, 0.0, 0.0), seed=0))
    view = ArtSequenceDataset(robust_dataset.folder, "train", normalize=False)
    assert view.twins == TWINS
    samples = storage.ShardedSamples(robust_dataset.folder)
    for i in range(len(view)):
        position, twin = view.items[i]
        ctg = samples.read(f"{TWINS[twin]}_ctg", position)
        np.testing.assert_array_equal(view[i]["ctg"][:, 0].numpy(), ctg[:100])
