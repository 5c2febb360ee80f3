import csv

import pytest

from scpformer.cli.main import main
from scpformer.experiments.robust_studies import columns

pytestmark = pytest.mark.slow


def test_robust_warmstart_runs_scvx_star_from_cvx_and_art_in_both_modes(tmp_path, tiny_robust):
    data, run = tiny_robust
    out = tmp_path / "robust-warmstart"
    argv = [
        "experiment",
        "run",
        "robust-warmstart",
        "--model",
        str(run),
        "--data",
        str(data),
        "--n",
        "1",
        "--workers",
        "1",
        "--out",
        str(out),
    ]
    assert main(argv) == 0
    with (out / "results.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 1 and list(rows[0]) == list(columns(("rtn",)))
    row = rows[0]
    for mode in ("deterministic", "chance"):
        assert row[f"{mode}_cvx_status"] in ("converged", "max_iterations", "solver_failed")
        assert row[f"{mode}_art_rtn_accepted"] in ("True", "False")  # the Eq. 8 check ran
    assert (out / "fig5_deterministic.png").is_file() and (out / "fig6_chance.png").is_file()
    report = (out / "report.md").read_text()
    assert "PS-ART-C (RTN)" in report
    assert "instance by instance against PS-CVX-C (chance)" in report
    assert "**PS-ART-C (RTN) with the check against PS-CVX-C**" in report


def test_a_rendezvous_dataset_is_refused_by_robust_warmstart(
    tmp_path, tiny_data, tiny_runs, capsys
):
    argv = [
        "experiment",
        "run",
        "robust-warmstart",
        "--model",
        str(tiny_runs["art"]),
        "--data",
        str(tiny_data),
        "--out",
        str(tmp_path / "o"),
    ]
    assert main(argv) == 2
    assert "not robust-rendezvous" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("name", "files"),
    [
        ("robust-posthoc", ("fig9_posthoc_rtn.png", "fig10_posthoc_histogram_rtn.png")),
        ("robust-trajectory", ()),
    ],
)
def test_posthoc_and_trajectory_run_the_chance_constrained_study(
    tmp_path, tiny_robust, name, files
):
    data, run = tiny_robust
    out = tmp_path / name
    argv = [
        "experiment",
        "run",
        name,
        "--model",
        str(run),
        "--data",
        str(data),
        "--n",
        "1",
        "--workers",
        "1",
        "--out",
        str(out),
    ]
    assert main(argv) == 0
    with (out / "results.csv").open(newline="") as handle:
        (row,) = list(csv.DictReader(handle))
    assert "deterministic_cvx_status" not in row  # chance-constrained only
    assert row["chance_art_rtn_would_accept"] in ("True", "False")
    for file in files:
        assert (out / file).is_file()
    assert "## The paper's numbers beside ours" in (out / "report.md").read_text()
