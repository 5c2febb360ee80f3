"""``check_int``: numpy integers count as integers, bools and floats do not, and the
configurations that use it store plain Python ints (so that their dictionaries stay JSON)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from scpformer.validation import ArgumentTypeError, check_int

# ----------------------------------------------------------------------------------------
# the check itself
# ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("value", [3, np.int64(3), np.int32(3), np.uint8(3), np.int8(3)])
def test_python_and_numpy_integers_are_returned_as_python_ints(value):
    result = check_int("epochs", value, least=1)
    assert result == 3 and type(result) is int


@pytest.mark.parametrize(
    ("value", "shown"),
    [
        (True, "bool True"),
        (np.bool_(False), "bool False"),
        (3.0, "float 3.0"),
        (np.float64(3.0), "float64 3.0"),
        ("3", "'3'"),
        (None, "None"),
        (np.array(3), "ndarray 3"),
        (np.array([1, 2]), "ndarray [1, 2]"),
        ([3], "list [3]"),
    ],
)
def test_values_that_are_not_integers_are_refused_naming_their_type(value, shown):
    with pytest.raises(ArgumentTypeError) as err:
        check_int("epochs", value, least=1)
    assert str(err.value) == f"epochs must be an integer >= 1, got {shown}"
    assert isinstance(err.value, TypeError) and isinstance(err.value, ValueError)


@pytest.mark.parametrize(
    ("least", "most", "value", "message"),
    [
        (1, None, 0, "n must be an integer >= 1, got 0"),
        (0, None, np.int64(-1), "n must be an integer >= 0, got -1"),
        (None, 4, 5, "n must be an integer <= 4, got 5"),
        (17, 20, np.int16(16), "n must be an integer from 17 to 20, got 16"),
        (17, 20, 21, "n must be an integer from 17 to 20, got 21"),
    ],
)
def test_values_out_of_bounds_are_value_errors_that_print_the_plain_number(
    least, most, value, message
):
    with pytest.raises(ValueError) as err:
        check_int("n", value, least=least, most=most)
    assert str(err.value) == message and not isinstance(err.value, TypeError)


def test_bounds_are_inclusive_and_optional():
    assert check_int("n", 17, least=17, most=20) == 17
    assert check_int("n", np.int64(20), least=17, most=20) == 20
    assert check_int("n", -(10**30)) == -(10**30)
    with pytest.raises(ArgumentTypeError, match=r"n must be an integer, got float 0.5"):
        check_int("n", 0.5)


def test_a_long_value_is_cut_short_in_the_message():
    with pytest.raises(ArgumentTypeError) as err:
        check_int("n", np.arange(1000.0))
    assert len(str(err.value)) < 120


# ----------------------------------------------------------------------------------------
# call sites
# ----------------------------------------------------------------------------------------


def test_train_config_takes_numpy_epochs_and_stores_python_ints():
    from scpformer.train.config import TrainConfig

    config = TrainConfig(epochs=np.int64(3), batch_size=np.int32(8), accumulation=np.int64(1))
    assert (config.epochs, config.batch_size, config.accumulation) == (3, 8, 1)
    assert type(config.epochs) is int and type(config.batch_size) is int
    json.dumps(config.to_dict())
    with pytest.raises(ValueError, match="epochs must be an integer >= 1, got bool True"):
        TrainConfig(epochs=True)


def test_scvx_parameters_take_numpy_iter_max_and_refuse_bools_and_floats():
    from scpformer.scp.scvx import SCvxParameters

    assert SCvxParameters(iter_max=np.int64(5)).iter_max == 5
    assert SCvxParameters(stall_window=np.int64(0)).stall_window == 0
    with pytest.raises(ValueError, match="iter_max must be an integer >= 1, got bool True"):
        SCvxParameters(iter_max=True)
    with pytest.raises(ValueError, match=r"iter_max must be an integer >= 1, got float 5.0"):
        SCvxParameters(iter_max=5.0)
    with pytest.raises(ValueError, match="stall_window must be an integer >= 0, got -1"):
        SCvxParameters(stall_window=-1)


def test_scvx_star_and_tscvx_parameters_take_numpy_integers():
    from scpformer.problems.pdg6dof.tscvx import TscvxParameters
    from scpformer.scp.scvx_star import SCvxStarParameters

    assert SCvxStarParameters(iter_max=np.int64(7)).iter_max == 7
    with pytest.raises(ValueError, match="iter_max must be an integer >= 1, got bool True"):
        SCvxStarParameters(iter_max=True)
    assert TscvxParameters(max_repairs=np.int64(0)).max_repairs == 0
    with pytest.raises(ValueError, match="stall_rejections must be an integer >= 0, got float"):
        TscvxParameters(stall_rejections=1.5)


def test_generate_config_takes_numpy_workers_and_stores_python_ints(tmp_path):
    from scpformer.data.generate import GenerateConfig

    config = GenerateConfig(
        n=np.int64(10), out=tmp_path, seed=np.uint32(4), shard_size=np.int64(5),
        workers=np.int64(2),
    )  # fmt: skip
    values = (config.n, config.seed, config.shard_size, config.workers)
    assert values == (10, 4, 5, 2) and all(type(v) is int for v in values)
    with pytest.raises(ValueError, match="workers must be an integer >= 1, got bool True"):
        GenerateConfig(n=10, out=tmp_path, workers=True)
    with pytest.raises(ValueError, match=r"n must be an integer >= 1, got float 10.0"):
        GenerateConfig(n=10.0, out=tmp_path)


def test_manifest_numbers_from_numpy_stay_json_ready():
    from scpformer.data.storage import ShardInfo

    shard = ShardInfo(
        file="shard-00000.h5", start=np.int64(0), stop=np.int64(4), count=np.int64(4),
        sha256="", content_sha256="", bytes=np.int64(10),
    )  # fmt: skip
    assert type(shard.stop) is int and json.loads(json.dumps(shard.to_dict()))["stop"] == 4
    with pytest.raises(ValueError, match="count must be an integer >= 0, got bool True"):
        ShardInfo(file="s.h5", start=0, stop=1, count=True, sha256="", content_sha256="", bytes=1)


def test_model_configs_take_numpy_sizes_and_stay_json_ready():
    from scpformer.models.art import ArtConfig
    from scpformer.models.tscvx import TightConfig

    art = ArtConfig(n_layer=np.int64(2), n_head=np.int64(2), n_embd=np.int64(16))
    assert (art.n_layer, art.n_head) == (2, 2) and type(art.n_head) is int
    json.dumps(art.to_dict())
    tight = TightConfig(n_nodes=np.int64(10), iter_max=np.int64(5))
    assert type(tight.n_nodes) is int and type(tight.iter_max) is int
    json.dumps(tight.to_dict())
    with pytest.raises(TypeError, match="n_layer must be an integer >= 1, got bool True"):
        ArtConfig(n_layer=True)
    with pytest.raises(TypeError, match=r"iter_max must be an integer >= 2, got float 20.0"):
        TightConfig(iter_max=20.0)


def test_opset_and_run_options_take_numpy_integers(tmp_path):
    from scpformer.experiments.runner import RunOptions
    from scpformer.train.export import check_opset

    opset = check_opset(np.int64(17))
    assert opset == 17 and type(opset) is int
    with pytest.raises(ValueError, match="opset must be an integer from 17 to"):
        check_opset(True)
    options = RunOptions(out=tmp_path, n=np.int64(3), workers=np.int32(2))
    assert (options.n, options.workers) == (3, 2) and type(options.workers) is int
    with pytest.raises(ValueError, match="workers must be an integer >= 1, got bool True"):
        RunOptions(out=tmp_path, workers=True)


def test_robust_rendezvous_counts_refuse_bools():
    from scpformer.problems.robust_rendezvous.montecarlo import MonteCarloConfig
    from scpformer.problems.robust_rendezvous.scenario import RobustScenario

    assert RobustScenario(n_safety=np.int64(5)).n_safety == 5
    with pytest.raises(ValueError, match=r"scenario.n_safety must be an integer >= 1, got bool"):
        RobustScenario(n_safety=True)
    assert MonteCarloConfig(n_samples=np.int64(10)).n_samples == 10
    with pytest.raises(ValueError, match=r"monte_carlo.n_samples must be an integer from 1 to"):
        MonteCarloConfig(n_samples=np.bool_(True))
