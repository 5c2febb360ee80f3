"""``scpformer demo``: three problems, classical and pretrained warm starts, one table."""

from __future__ import annotations

import pytest

from scpformer.cli.main import main


def test_an_out_path_that_is_a_file_is_a_one_line_usage_error(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert main(["demo", "--out", str(blocker)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0] == f"scpformer: error: --out {blocker} is a file, not a folder"
    assert blocker.read_text() == ""


def test_figures_are_drawn_only_when_asked_for(tmp_path, capsys):
    from scpformer.cli.demo import FigureWriter
    from scpformer.cli.main import build_parser

    assert build_parser().parse_args(["demo"]).out is None  # the quick default: no figures
    none = FigureWriter(None)
    none.submit("scpformer.cli.demo:print_table", [])  # would print the table's header
    none.wait()
    assert none.path("a.png") is None
    assert capsys.readouterr().out == ""
    assert FigureWriter(tmp_path).path("a.png") == tmp_path / "a.png"


@pytest.mark.slow
# the demo shows the current API: a deprecated spelling in it fails the test
@pytest.mark.filterwarnings("error::DeprecationWarning:scpformer.cli.demo")
def test_demo_solves_every_problem_verified_and_writes_the_figures(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split()[:3] == ["problem", "instance", "warm"]
    rows = lines[2:10]
    assert [row.split()[-1] for row in rows] == ["yes"] * 8
    for name in ("CVX", "ART", "TPBVP", "cubic profile", "T-SCvx networks"):
        assert any(name in row for row in rows)
    # the robust rows: one instance where the Eq. 8 check accepts ART's guess, one where
    # it falls back to the TPBVP, each labelled
    robust = [row for row in rows if row.startswith("robust")]
    accepted = [row for row in robust if "check accepts" in row]
    rejected = [row for row in robust if "check rejects it -> TPBVP" in row]
    assert len(robust) == 4 and len(accepted) == 1 and len(rejected) == 1
    assert "(check passes)" in accepted[0] and "(check fails)" in rejected[0]
    # the legend names the units and what an iteration counts
    legend = "\n".join(lines[10:])
    for term in ("[mm/s]", "[U_M]", "U_M is", "iterations  convex subproblems", "time [s]"):
        assert term in legend
    total = [line for line in lines if line.startswith("total ")]
    assert len(total) == 1 and "warm-up" in total[0]
    figures = sorted(path.name for path in out.glob("*.png"))
    assert figures == sorted(
        [
            "rendezvous_cvx.png",
            "rendezvous_art.png",
            "robust_seed22_ps_cvx.png",
            "robust_seed22_ps_art.png",
            "robust_seed0_ps_cvx.png",
            "robust_seed0_ps_art.png",
            "landing_scvx.png",
            "landing_scvx_history.png",
            "landing_t_scvx.png",
            "landing_t_scvx_history.png",
        ]
    )
    assert all((out / name).stat().st_size > 0 for name in figures)
