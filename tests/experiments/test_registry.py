from pathlib import Path

import pytest

from scpformer.cli.main import main
from scpformer.experiments import EXPERIMENTS, RunOptions, get_experiment

PAPER_ITEMS = {
    "art-forecast-tpbvp": "Table 2",
    "art-forecast-scp": "Table 3",
    "robust-forecast": "Table 3's rows on the robust data",
    "art-conditioning": "Fig. 3",
    "art-warmstart": "Figs. 4-6",
    "robust-warmstart": "Figs. 5-6",
    "robust-trajectory": "Figs. 7-8",
    "robust-posthoc": "Figs. 9-10",
    "mpc-rendezvous": "closed-loop MPC: warm-start gains",
    "mpc-robust-rendezvous": "passively safe rendezvous",
    "mpc-pdg6dof": "T-SCvx against the classical re-plan starts",
    "tscvx-training": "Table 3",
    "tscvx-solve-time": "Fig. 2",
    "tscvx-trajectory": "Fig. 3",
    "tscvx-lookup": "Tables 4-5, Fig. 4",
}


def test_the_registry_has_one_entry_per_paper_table_or_figure():
    assert set(EXPERIMENTS) == set(PAPER_ITEMS)
    for name, item in PAPER_ITEMS.items():
        assert EXPERIMENTS[name].reproduces.endswith(item)


def test_every_declared_source_exists_so_staleness_can_see_it():
    """``depends_on`` decides when a committed result is stale: a path that does not exist
    (a file renamed or a typo) would hide every later change to the code it meant."""
    root = Path(__file__).resolve().parents[2]
    for name, entry in EXPERIMENTS.items():
        for pattern in entry.depends_on:
            assert list(root.glob(pattern)), f"{name}: {pattern} matches no file"


def test_closed_loop_results_go_stale_with_their_own_loop_only():
    """A closed-loop result declares the shared campaign and report code and its own
    family's loop, not another family's: a change to the landing loop leaves the rendezvous
    results current."""
    loops = {"mpc-rendezvous": "rendezvous_mpc.py", "mpc-robust-rendezvous":
             "robust_rendezvous_mpc.py", "mpc-pdg6dof": "pdg6dof_mpc.py"}  # fmt: skip
    for name, loop in loops.items():
        declared = EXPERIMENTS[name].depends_on
        assert f"src/scpformer/guidance/{loop}" in declared
        assert "src/scpformer/experiments/closed_loop.py" in declared
        others = {f"src/scpformer/guidance/{o}" for n, o in loops.items() if o != loop}
        others -= (
            {"src/scpformer/guidance/rendezvous_mpc.py"} if name.startswith("mpc-robust") else set()
        )  # the robust loop builds on the rendezvous one
        assert not others & set(declared), name


def test_experiment_list_names_every_experiment_and_what_it_reproduces(capsys):
    assert main(["experiment", "list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == len(PAPER_ITEMS)
    for name, item in PAPER_ITEMS.items():
        assert any(line.startswith(name) and item in line for line in lines)


def test_an_unknown_experiment_is_a_one_line_error(capsys):
    assert main(["experiment", "run", "art-nothing", "--out", "x"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown experiment 'art-nothing'" in err[0]
    with pytest.raises(ValueError, match="art-warmstart"):
        get_experiment("nope")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--model", "/nonexistent/run", "--data", "/nonexistent/ds"], "--data /nonexistent/ds"),
        ([], "--data DIR is required"),
    ],
)
def test_bad_paths_are_one_line_errors(tmp_path, capsys, argv, message):
    code = main(["experiment", "run", "art-warmstart", "--out", str(tmp_path / "o"), *argv])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_run_options_reject_a_nonpositive_n(tmp_path):
    with pytest.raises(ValueError, match="n must be an integer >= 1"):
        RunOptions(out=tmp_path, n=0)
