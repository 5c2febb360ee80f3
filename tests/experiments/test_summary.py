import json
import subprocess
from pathlib import Path

import pytest

from scpformer.cli.main import main
from scpformer.experiments.report import Comparison, Report
from scpformer.experiments.summary import (
    ResultsError,
    collect,
    render,
    stale_commits,
    write_summary,
)


def fake_experiment(results, name, reproduces, rows, command="scpformer experiment run x"):
    """A results folder as an experiment run writes it (report.md + results.json)."""
    report = Report(
        name=name,
        reproduces=reproduces,
        command=command,
        settings={},
        provenance=[f"scpformer generate rendezvous --n 10 --out /data/{name}"],
        comparisons=[Comparison(quantity=q, paper=p, ours=o, note=n) for q, p, o, n in rows],
    )
    folder = results / name
    folder.mkdir(parents=True)
    return report.write(folder).parent


def test_report_write_puts_the_comparison_rows_in_results_json(tmp_path):
    folder = fake_experiment(tmp_path, "exp-a", "ART paper Table 9", [("cost", "1.0", "2.0", "n")])
    data = json.loads((folder / "results.json").read_text())
    assert data["experiment"] == "exp-a"
    assert data["rows"] == [
        {
            "paper_item": "ART paper Table 9",
            "metric": "cost",
            "paper": "1.0",
            "ours": "2.0",
            "note": "n",
            "command": "scpformer experiment run x",
        }
    ]


def test_scpformer_report_tabulates_every_experiment_with_its_commands(tmp_path, capsys):
    results = tmp_path / "results"
    fake_experiment(
        results, "exp-a", "ART paper Table 9", [("cost [m/s]", "0.25", "0.27", "n = 5")],
        command="scpformer experiment run exp-a --n 5",
    )  # fmt: skip
    fake_experiment(
        results, "exp-b", "robust ART paper Fig. 11",
        [("rate [%]", "10", "12", ""), ("time [s]", "~2", "0.1", "mean")],
        command="scpformer experiment run exp-b --n 7",
    )  # fmt: skip
    out = tmp_path / "docs" / "RESULTS.md"
    out.parent.mkdir()
    assert main(["report", "--results", str(results), "--out", str(out)]) == 0
    text = out.read_text()
    a, b = text.index("## ART paper Table 9 (`exp-a`)"), text.index("## robust ART paper Fig. 11")
    assert a < b  # sorted by folder name
    # not in the registry, so no declared sources: staleness unknown, shown as stale
    assert "| cost [m/s] | 0.25 | 0.27 | reproduced (stale) | n = 5 |" in text[a:b]
    assert (
        "| rate [%] | 10 | 12 | reproduced (stale) |  |\n"
        "| time [s] | ~2 | 0.1 | not reproduced (stale) | mean |"
    ) in text[b:]
    assert "(`exp-b`) | partly (stale) |" in text[:a]  # the overview's status column
    assert "scpformer generate rendezvous --n 10 --out /data/exp-a\n" in text[a:b]
    assert "scpformer experiment run exp-a --n 5\n```" in text[a:b]
    assert "[../results/exp-b/report.md](../results/exp-b/report.md)" in text[b:]
    assert "`scpformer experiment run art-warmstart`" in text  # a registry entry not run here
    assert str(out) in capsys.readouterr().out


def test_a_report_without_results_json_is_an_error_naming_the_file(tmp_path, capsys):
    folder = fake_experiment(tmp_path, "exp-a", "Table 1", [("q", "1", "2", "")])
    (folder / "results.json").unlink()
    with pytest.raises(ResultsError, match=r"exp-a/results.json: missing"):
        collect(tmp_path)
    assert main(["report", "--results", str(tmp_path), "--out", str(tmp_path / "R.md")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "exp-a/results.json: missing" in err[0]
    assert not (tmp_path / "R.md").exists()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('{"rows": [', "not readable JSON"),
        ('["rows"]', "expected an object with a list 'rows'"),
        ('{"rows": [{"metric": "q", "paper": "1"}]}', "row 0 lacks paper_item, ours, command"),
    ],
)
def test_a_corrupt_results_json_is_an_error_naming_the_file(tmp_path, text, message):
    folder = fake_experiment(tmp_path, "exp-a", "Table 1", [("q", "1", "2", "")])
    (folder / "results.json").write_text(text)
    with pytest.raises(ResultsError, match=message) as info:
        write_summary(tmp_path, tmp_path / "R.md")
    assert str(folder / "results.json") in str(info.value)


@pytest.mark.parametrize("text", ['{"rows": [', "", "\udcff".encode("utf-8", "surrogateescape")])
def test_an_unreadable_results_json_without_report_md_is_an_error_not_not_run(
    tmp_path, capsys, text
):
    folder = fake_experiment(tmp_path, "art-warmstart", "Figs. 4-6", [("q", "1", "2", "")])
    (folder / "report.md").unlink()  # e.g. a run stopped between the two files
    path = folder / "results.json"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    out = tmp_path / "R.md"
    out.write_text("the page written before")
    assert main(["report", "--results", str(tmp_path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{path}: not readable JSON (" in err[0], err
    assert out.read_text() == "the page written before"


def test_a_readable_results_json_without_report_md_is_listed_as_not_run(tmp_path):
    folder = fake_experiment(tmp_path, "art-warmstart", "Figs. 4-6", [("q", "1", "2", "")])
    (folder / "report.md").unlink()
    assert collect(tmp_path) == []
    text = write_summary(tmp_path, tmp_path / "R.md").read_text()
    assert "`scpformer experiment run art-warmstart`" in text.split("## Not run yet")[1]


def test_a_missing_results_folder_is_an_error_naming_it(tmp_path):
    with pytest.raises(ResultsError, match=r"--results .*nowhere: no such folder"):
        collect(tmp_path / "nowhere")


def test_every_committed_result_folder_has_readable_results_json_with_its_provenance():
    folder = Path(__file__).resolve().parents[2] / "docs" / "results"
    results = collect(folder)
    assert {r.experiment for r in results} >= {"art-warmstart", "art-forecast-scp"}
    for result in results:
        assert result.rows and result.command.startswith("scpformer experiment run")
        run = result.run
        assert set(run) >= {"version", "commit", "dirty", "date", "machine", "commands"}
        assert set(run["machine"]) >= {"cpu", "cores", "threads"}
        assert run["commands"][-1].startswith("scpformer experiment run"), result.folder


def git(repo, *args):
    return subprocess.run(
        ["git", "-C", str(repo), *args], capture_output=True, text=True, check=True
    ).stdout.strip()


def test_a_result_is_stale_when_a_later_commit_changes_a_declared_source(tmp_path):
    repo = tmp_path / "repo"
    (repo / "src").mkdir(parents=True)
    git(repo, "init", "-q")
    git(repo, "config", "user.email", "t@example.com")
    git(repo, "config", "user.name", "t")
    (repo / "src" / "algo.py").write_text("x = 1\n")
    (repo / "other.py").write_text("y = 1\n")
    git(repo, "add", ".")
    git(repo, "commit", "-q", "-m", "first")
    measured = git(repo, "rev-parse", "HEAD")
    (repo / "other.py").write_text("y = 2\n")
    git(repo, "commit", "-q", "-am", "unrelated")
    assert stale_commits(measured, ["src/algo.py"], repo) == []
    (repo / "src" / "algo.py").write_text("x = 2\n")
    git(repo, "commit", "-q", "-am", "the algorithm")
    later = stale_commits(measured, ["src"], repo)
    assert later == [git(repo, "rev-parse", "HEAD")]
    assert stale_commits("unknown", ["src"], repo) is None
    assert stale_commits(measured, ["src"], tmp_path / "not-a-repo") is None


def test_a_stale_result_says_stale_in_the_overview_heading_and_every_row(tmp_path):
    fake_experiment(tmp_path, "exp-a", "Table 1", [("q", "1", "1.1", ""), ("r", "yes", "no", "")])
    results = collect(tmp_path)
    text = render(results, tmp_path / "R.md", stale={"exp-a": "stale: 2 later commit(s)"})
    assert "## Table 1 (`exp-a`) - STALE" in text
    assert "| q | 1 | 1.1 | reproduced (stale) |" in text
    assert "| r | yes | no | not reproduced (stale) |" in text
    assert "| partly (stale) |" in text and "stale: 2 later commit(s)" in text
    current = render(results, tmp_path / "R.md", stale={"exp-a": ""})
    assert "stale" not in current.split("## Table 1")[1].lower()


def test_a_results_folder_without_experiments_leaves_the_page_as_it_is(tmp_path, capsys):
    empty = tmp_path / "results"
    (empty / "notes").mkdir(parents=True)  # a folder, but no experiment in it
    out = tmp_path / "RESULTS.md"
    out.write_text("the page written before")
    assert main(["report", "--results", str(empty), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds no experiment folders" in err[0], err
    assert out.read_text() == "the page written before"
