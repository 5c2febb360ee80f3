import json

import pytest

from scpformer.cli.main import main


@pytest.mark.parametrize(
    "content, message",
    [
        ("{not json", "malformed JSON"),
        (json.dumps({"r0": [1, 2, 3], "speed": 3}), "unknown instance field(s): speed"),
        ('{"r0": [1, NaN, 3]}', "r0 must be finite"),
        (json.dumps({"r0": [1, "NaN", 3]}), "r0 must be numeric"),
        (json.dumps({"v0": [1, 2]}), "v0 must have shape (3,)"),
        (json.dumps({"m0": 1.5}), "must exceed the dry mass"),
        (json.dumps({"q0": [1, 1, 0, 0]}), "q0 must be a unit quaternion"),
    ],
)
def test_bad_instance_file_ends_with_one_line_error(tmp_path, capsys, content, message):
    path = tmp_path / "instance.json"
    path.write_text(content)
    assert main(["solve", "pdg6dof", "--instance", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("scpformer: error:") and message in err
    assert "\n" not in err and "Traceback" not in err


def test_missing_instance_file_is_a_clear_error(tmp_path, capsys):
    assert main(["solve", "pdg6dof", "--instance", str(tmp_path / "nope.json")]) == 2
    assert "instance file not found" in capsys.readouterr().err


def test_out_of_range_parameter_flag_is_a_clear_error(capsys):
    assert main(["solve", "pdg6dof", "--scvx-rho-1", "0.9"]) == 2
    assert "rho_0 <= rho_1 < rho_2" in capsys.readouterr().err


def test_an_instance_refused_before_solving_is_an_error_naming_the_constraint(tmp_path, capsys):
    """An initial state that already violates a constraint is bad input (exit 2, one line),
    not a solver outcome; the API reports it as status INFEASIBLE_INSTANCE."""
    path = tmp_path / "spin.json"
    path.write_text(json.dumps({"omega0_deg": [120.0, 0.0, 0.0]}))
    assert main(["solve", "pdg6dof", "--instance", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot be flown" in err[0] and "omega" in err[0]


def test_help_documents_the_defaults_and_table_1_where_they_differ(capsys):
    assert main(["solve", "pdg6dof", "--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "penalty weight lambda (Table 1: 500) (default: 2.0)" in out
    assert "--const-t-max" not in out  # Table 1's constants: in --print-config, not the help
    assert "see the module" not in out  # no pointers into the source


@pytest.mark.slow
def test_bench_writes_a_csv_row_per_instance_and_a_summary(tmp_path, capsys):
    import csv

    out = tmp_path / "bench.csv"
    assert main(["bench", "pdg6dof", "--n-nominal", "1", "--n-table2", "2", "--csv", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    assert [r["set"] for r in rows] == ["nominal", "table2", "table2"]
    assert {"status", "iterations", "wall_s", "solver_s", "discretization_s"} <= set(rows[0])
    text = capsys.readouterr().out
    assert "med s" in text and "p95 s" in text


def test_bench_summary_reports_median_and_max_propellant_gap():
    from scpformer.cli.pdg6dof import summarize

    rows = [
        {"set": "nominal", "status": "converged", "iterations": it, "conic_solves": it - 2,
         "wall_s": 1.0, "solver_s": 0.8, "discretization_s": 0.1, "verification_s": 0.05,
         "other_s": 0.05, "gap": gap}
        for it, gap in ((10, 0.001), (20, 0.002), (30, 0.006))
    ]  # fmt: skip
    text = "\n".join(summarize(rows))
    assert "median 0.200%" in text and "max 0.600%" in text
    # median records 20, median conic solves 18 (least-change corrections are not solves)
    assert " 20.0   18.0 " in text, text
    assert "conic solves p95 27" in text, text
