"""Table 2 of a pdg6dof dataset beside the paper's (`dataset info DIR --table2`)."""

import numpy as np
import pytest
from toy_families import ToyFamily

from scpformer.cli.data import main
from scpformer.data.generate import GenerateConfig, generate
from scpformer.data.pdg6dof_family import (
    PAPER_TABLE2,
    THETA_NAMES,
    dataset_table2_lines,
    table2_lines,
    table2_ranges,
)
from scpformer.data.storage import ShardedSamples


def test_table2_ranges_are_the_min_and_max_of_each_parameter_and_k_runs_from_one():
    theta = np.arange(48, dtype=float).reshape(3, 16)
    ranges = table2_ranges(theta, np.array([4, 9, 2]))
    assert ranges["K"] == (1.0, 9.0)
    assert ranges["gamma_gs_deg"] == (0.0, 32.0)
    assert ranges["m0"] == (15.0, 47.0)
    assert list(ranges) == ["K", *THETA_NAMES] == list(PAPER_TABLE2)


def test_table2_lines_put_the_paper_values_beside_ours():
    lines = table2_lines(np.full((2, 16), 0.5), np.array([3, 5]))
    assert len(lines) == 1 + len(PAPER_TABLE2)
    assert lines[1].split() == ["K", "1", "5", "1", "20"]
    assert lines[-1].split() == ["m0", "0.5", "0.5", "0.003", "3"]


@pytest.mark.parametrize(
    "theta, iterations", [(np.zeros((0, 16)), np.zeros(0)), (np.zeros((2, 16)), np.ones(3))]
)
def test_table2_of_no_or_mismatched_samples_is_a_clear_error(theta, iterations):
    with pytest.raises(ValueError, match="theta/iterations"):
        table2_ranges(theta, iterations)


def test_dataset_table2_counts_the_converged_samples_only(pdg_dataset):
    samples = ShardedSamples(pdg_dataset.folder)
    solved = samples.column("status") == "converged"
    lines = dataset_table2_lines(pdg_dataset.folder)
    assert f"{int(solved.sum())} converged samples of {len(solved)}" in lines[0]
    r_up = samples.column("theta")[solved, 2]
    row = next(line for line in lines if line.startswith("r0_up")).split()
    assert float(row[1]) == pytest.approx(r_up.min(), rel=1e-3)
    assert float(row[2]) == pytest.approx(r_up.max(), rel=1e-3)


def test_info_table2_prints_the_table_and_refuses_other_families(pdg_dataset, tmp_path, capsys):
    assert main(["dataset", "info", str(pdg_dataset.folder), "--table2"]) == 0
    out = capsys.readouterr().out
    assert "Table 2 of" in out and "paper max" in out and "omega0_y_deg" in out
    generate(ToyFamily(), GenerateConfig(n=2, out=tmp_path / "toy", workers=1))
    assert main(["dataset", "info", str(tmp_path / "toy"), "--table2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [err[-1]] and "needs a pdg6dof dataset" in err[-1]
