import json
import os

import pytest

import scpformer
from scpformer.experiments.report import (
    NOT_RATED,
    NOT_REPRODUCED,
    PARTLY,
    REPRODUCED,
    Comparison,
    Report,
    experiment_status,
    portable_path,
    row_status,
    run_record,
)


@pytest.mark.parametrize(
    ("paper", "ours", "status"),
    [
        ("yes", "yes (8.46 vs 9.68, 9.45)", REPRODUCED),
        ("yes", "no (9.1 vs 8.4)", NOT_REPRODUCED),
        ("> 20", "28.6", REPRODUCED),
        ("> 20", "12", NOT_REPRODUCED),
        ("<= 0", "8.92e-05", REPRODUCED),  # within a solver's tolerance
        ("<= 0 (passively safe)", "0.319", NOT_REPRODUCED),
        ("~50", "47.2", REPRODUCED),
        ("66%", "71.9%", REPRODUCED),
        ("0.0657-0.0700", "0.0935", PARTLY),
        ("4.6-4.9 ms", "4.7 ms", REPRODUCED),
        ("4.6-4.9 ms", "0.599 ms", NOT_REPRODUCED),
        ("up to 35", "-144", NOT_REPRODUCED),
        ("0.44 vs 2.21 s", "0.0777 vs 0.123 s", PARTLY),
        ("0.44 vs 2.21 s", "0.4 vs 2.0 s", REPRODUCED),
        ("0.44 vs 0.28 s", "0.05 vs 0.09 s", NOT_REPRODUCED),
        ("n/a (not reported)", "17.5", NOT_RATED),
        ("Fig. 4 only", "0.224", NOT_RATED),
        ("highly correlated (Fig. 3 top; no number)", "0.536", NOT_RATED),
        ("lower with ART", "0.107 vs 0.043", NOT_RATED),
    ],
)
def test_row_status_follows_the_documented_rule(paper, ours, status):
    assert row_status(paper, ours) == status


def test_an_experiment_is_partly_reproduced_unless_every_rated_row_agrees():
    assert experiment_status([REPRODUCED, NOT_RATED]) == REPRODUCED
    assert experiment_status([NOT_REPRODUCED, NOT_RATED]) == NOT_REPRODUCED
    assert experiment_status([REPRODUCED, NOT_REPRODUCED]) == PARTLY
    assert experiment_status([NOT_RATED]) == NOT_RATED


def test_portable_path_makes_repository_and_data_paths_relative(monkeypatch, tmp_path):
    repo, data = tmp_path / "checkout", tmp_path / "datasets"
    monkeypatch.setenv("DATA", str(data))
    line = f"scpformer x --data {data}/rdv --out {repo}/docs/results/a --model {repo}"
    assert (
        portable_path(line, repo) == "scpformer x --data $DATA/rdv --out docs/results/a --model ."
    )
    assert portable_path(f"{repo}other/y", repo) == f"{repo}other/y"  # not inside the checkout


def test_a_report_records_version_commit_date_machine_and_commands(tmp_path):
    report = Report(
        name="exp-a",
        reproduces="Table 1",
        command="scpformer experiment run exp-a --n 3",
        settings={"workers": 2},
        provenance=["scpformer generate rendezvous --n 10 --seed 0 --out d"],
        comparisons=[
            Comparison(quantity="q", paper="lower with ART", ours="1 vs 2", status=PARTLY)
        ],
    )
    report.write(tmp_path)
    data = json.loads((tmp_path / "results.json").read_text())
    run = data["run"]
    assert run["version"] == scpformer.__version__
    assert run["machine"]["threads"] == 2 and run["machine"]["cores"] == os.cpu_count()
    assert run["date"][:2] == "20" and run["commit"]  # a hash, or "unknown" outside git
    assert run["commands"] == [*report.provenance, report.command]
    assert data["rows"][0]["status"] == PARTLY  # an experiment's own status is kept
    text = (tmp_path / "report.md").read_text()
    assert "## Provenance" in text and f"scpformer {scpformer.__version__}, commit" in text
    assert "| q | lower with ART | 1 vs 2 | partly |  |" in text


def test_run_record_of_a_ray_run_does_not_guess_its_threads():
    run = run_record({"workers": None, "ray": "auto"}, "scpformer experiment run x", [])
    assert run["machine"]["threads"] == "unknown"
    assert run["commands"] == ["scpformer experiment run x"]
