import csv

import pytest

from scpformer.cli.main import main
from scpformer.experiments.warmstart_study import COLUMNS, WARMSTARTS

pytestmark = pytest.mark.slow


def _rows(path):
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


@pytest.fixture(scope="module")
def warmstart_run(tmp_path_factory, tiny_data, tiny_runs):
    out = tmp_path_factory.mktemp("ws") / "art-warmstart"
    argv = [
        "experiment",
        "run",
        "art-warmstart",
        "--model",
        str(tiny_runs["art"]),
        "--data",
        str(tiny_data),
        "--n",
        "2",
        "--workers",
        "2",
        "--out",
        str(out),
    ]
    assert main(argv) == 0
    return out, argv


def test_run_writes_the_csv_the_figures_and_the_report(warmstart_run):
    out, _ = warmstart_run
    rows = _rows(out / "results.csv")
    assert len(rows) == 2 and list(rows[0]) == list(COLUMNS)
    for row in rows:
        assert row["status"] == "ok"
        assert float(row["j_cvx"]) > 0.0
        for ws in WARMSTARTS:  # the SCP ran from every warm start
            assert int(row[f"{ws}_iterations"]) >= 1
    for name in ("fig4_cost.png", "fig5_iterations.png", "fig6_runtime.png"):
        assert (out / name).stat().st_size > 1000
    text = (out / "report.md").read_text()
    assert "scpformer generate rendezvous --n 6 --seed 11" in text
    assert "| ART improvement of the gap vs CVX, every C_CVX(t_1) > x, x >= 0 [%] | > 20 |" in text
    assert "5 m behind the docking port" in text
    section = text.split("## Instance by instance against CVX")[1]
    assert "| draws (all, failures included) | 2 | 2 |" in section
    assert "**ART against CVX**" in section and "**CVX-TPBVP against CVX**" in section


def test_a_rerun_skips_done_instances_and_redoes_missing_ones(warmstart_run):
    out, argv = warmstart_run
    path = out / "results.csv"
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(lines[:2]) + lines[2][:25])  # header, one row, a torn row
    assert main(argv) == 0
    new = path.read_text().splitlines(keepends=True)
    assert new[:2] == lines[:2]  # the kept row was not recomputed (timings would differ)
    assert len(new) == 3 and new[2].split(",")[0] == lines[2].split(",")[0]


def test_a_rerun_with_other_settings_is_refused(warmstart_run, capsys):
    _out, argv = warmstart_run
    assert main([*argv, "--seed", "3"]) == 2
    assert "holds a run with other settings (seed)" in capsys.readouterr().err


def test_a_model_of_another_family_is_a_one_line_error(tmp_path, tiny_data, capsys):
    bad = tmp_path / "run"
    bad.mkdir()
    (bad / "checkpoint.pt").write_bytes(b"not a checkpoint")
    argv = [
        "experiment",
        "run",
        "art-warmstart",
        "--model",
        str(bad),
        "--data",
        str(tiny_data),
        "--out",
        str(tmp_path / "o"),
    ]
    assert main(argv) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_the_solves_run_on_ray_when_asked(tmp_path, tiny_data, tiny_runs):
    pytest.importorskip("ray", reason="ray is not installed: the Ray backend is untested")
    out = tmp_path / "ray"
    argv = [
        "experiment",
        "run",
        "art-warmstart",
        "--model",
        str(tiny_runs["art"]),
        "--data",
        str(tiny_data),
        "--n",
        "1",
        "--workers",
        "1",
        "--ray",
        "local",
        "--out",
        str(out),
    ]
    assert main(argv) == 0
    (row,) = _rows(out / "results.csv")
    assert row["status"] == "ok" and int(row["convex_iterations"]) >= 1
