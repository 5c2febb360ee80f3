import json

import numpy as np
import pytest

from scpformer.data.executors import instance_rng
from scpformer.experiments.runner import (
    ResultsCSV,
    RunOptions,
    check_settings,
    column,
    join_series,
    series,
    task_index,
)


def test_rows_survive_a_torn_last_line_and_appending_repairs_it(tmp_path):
    path = tmp_path / "results.csv"
    table = ResultsCSV(path, ["index", "cost", "ok"])
    table.append({"index": 3, "cost": 0.25, "ok": True})
    with path.open("a") as handle:
        handle.write("4,0.5")  # a killed run's half row
    assert table.done() == {3}
    table.append({"index": 4, "cost": 0.5, "ok": False})
    rows = table.rows()
    assert [r["index"] for r in rows] == ["3", "4"]
    np.testing.assert_array_equal(column(rows, "cost"), [0.25, 0.5])
    np.testing.assert_array_equal(column(rows, "ok"), [1.0, 0.0])


def test_a_table_with_other_columns_is_refused(tmp_path):
    ResultsCSV(tmp_path / "r.csv", ["index", "a"]).append({"index": 1, "a": 2})
    with pytest.raises(ValueError, match="columns differ"):
        ResultsCSV(tmp_path / "r.csv", ["index", "b"])
    with pytest.raises(ValueError, match="not in the results table"):
        ResultsCSV(tmp_path / "r.csv", ["index", "a"]).append({"index": 2, "zz": 1})


def test_settings_may_grow_n_but_not_change_the_seed(tmp_path):
    check_settings(tmp_path, {"seed": 0, "n": 10})
    check_settings(tmp_path, {"seed": 0, "n": 20})
    with pytest.raises(ValueError, match=r"other settings \(seed\)"):
        check_settings(tmp_path, {"seed": 1, "n": 20})


def test_a_growable_list_may_be_appended_to_but_not_reordered_or_shortened(tmp_path):
    check_settings(tmp_path, {"seed": 0, "warmstarts": ["cold", "previous"]}, grows=("warmstarts",))
    check_settings(tmp_path, {"seed": 0, "warmstarts": ["cold", "previous", "art"]},
                   grows=("warmstarts",))  # fmt: skip
    for other in (["previous", "cold", "art"], ["cold"], "cold"):
        with pytest.raises(ValueError, match=r"other settings \(warmstarts\)"):
            check_settings(tmp_path, {"seed": 0, "warmstarts": other}, grows=("warmstarts",))
    with pytest.raises(ValueError, match=r"other settings \(warmstarts\)"):  # not growable
        check_settings(tmp_path, {"seed": 0, "warmstarts": ["cold", "previous", "art", "best"]})


def test_a_moved_results_folder_resumes_and_records_where_it_is_now(tmp_path):
    check_settings(tmp_path / "a", {"seed": 0, "n": 10, "out": str(tmp_path / "a")})
    (tmp_path / "a").rename(tmp_path / "b")
    check_settings(tmp_path / "b", {"seed": 0, "n": 10, "out": str(tmp_path / "b")})
    recorded = json.loads((tmp_path / "b" / "config.json").read_text())
    assert recorded["out"] == str(tmp_path / "b")


def test_series_round_trip_exactly():
    values = [0.1, 1e-9, 2.0 / 3.0]
    np.testing.assert_array_equal(series(join_series(values)), values)


def test_the_task_index_is_recovered_from_the_executor_stream():
    assert task_index(instance_rng(7, 42)) == 42
    with pytest.raises(ValueError, match="spawn_key"):
        task_index(np.random.default_rng(0))


@pytest.mark.slow
def test_a_larger_n_extends_the_selection_of_a_smaller_one(tiny_data):
    from scpformer.data.splits import load_splits
    from scpformer.experiments.runner import select_test_instances

    small, large = (
        select_test_instances(tiny_data, 2, seed=5),
        select_test_instances(tiny_data, 10, seed=5),
    )
    test = load_splits(tiny_data).indices["test"]
    np.testing.assert_array_equal(large[:2], small)
    assert sorted(large) == sorted(test)  # n beyond the split: the whole test split


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("n", np.int64(0), "n must be an integer >= 1, got 0"),
        ("workers", np.int64(0), "workers must be an integer >= 1, got 0"),
        ("time_limit", np.float64(-1.0), "time_limit must be positive, got -1.0"),
    ],
)
def test_numpy_options_are_printed_as_plain_numbers(tmp_path, field, value, message):
    with pytest.raises(ValueError) as err:
        RunOptions(out=tmp_path, **{field: value})
    assert message in str(err.value) and "np." not in str(err.value)


def test_more_test_instances_than_the_split_holds_is_said_on_stderr(tiny_data, capsys):
    from scpformer.experiments.runner import select_test_instances

    few = select_test_instances(tiny_data, 3, seed=0)
    assert "warning" not in capsys.readouterr().err
    every = select_test_instances(tiny_data, 500, seed=0)
    err = capsys.readouterr().err
    assert f"--n 500: the test split of {tiny_data} holds {every.size} samples" in err
    assert list(every[: few.size]) == list(few)  # a larger --n extends the smaller selection
