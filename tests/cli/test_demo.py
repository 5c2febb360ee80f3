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


@pytest.mark.slow
def test_demo_solves_every_problem_verified_and_writes_the_figures(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out)]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].split()[:2] == ["problem", "warm"]
    rows = [line for line in table[2:8]]
    assert [row.split()[-1] for row in rows] == ["yes"] * 6
    for name in ("CVX", "ART", "TPBVP", "ART", "cubic profile", "T-SCvx networks"):
        assert any(name in row for row in rows)
    figures = sorted(path.name for path in out.glob("*.png"))
    assert figures == sorted(
        [
            "rendezvous_cvx.png",
            "rendezvous_art.png",
            "robust_ps_cvx.png",
            "robust_ps_art.png",
            "landing_scvx.png",
            "landing_scvx_history.png",
            "landing_t_scvx.png",
            "landing_t_scvx_history.png",
        ]
    )
