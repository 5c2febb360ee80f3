"""``scpformer solve pdg6dof --warmstart tscvx --model RUN``: T-SCvx from the command line."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from scpformer.cli.main import main
from scpformer.pretrained import default_model
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.problem import solve
from scpformer.warmstart.tscvx import TscvxWarmStart


class OraclePredictor:
    """The predictor API answering with a cold solve's final flags and optimum."""

    n_nodes = 50

    def __init__(self, solution):
        self.solution = solution

    def predict_tight(self, theta, k):
        return np.array([self.solution.history[-1].tight_flags for _ in np.atleast_1d(k)])

    def predict_solution(self, theta):
        z = self.solution.trajectory
        return z.x, z.u, float(z.p[0])


def _one_error_line(capsys) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1
    return lines[0]


def test_tscvx_without_a_model_loads_the_pretrained_default(monkeypatch):
    from scpformer.cli.parsers.pdg6dof import add_solve_parser
    from scpformer.cli.pdg6dof import warmstart_from_args

    loaded = []
    monkeypatch.setattr(
        TscvxWarmStart, "from_checkpoint", classmethod(lambda cls, run: loaded.append(run))
    )
    parser = argparse.ArgumentParser()
    add_solve_parser(parser.add_subparsers())
    for model in ([], ["--model", "default"]):
        warmstart_from_args(parser.parse_args(["pdg6dof", "--warmstart", "tscvx", *model]))
    assert loaded == [default_model("pdg6dof")] * 2


def test_a_missing_run_folder_is_a_one_line_error(tmp_path, capsys):
    missing = tmp_path / "no_run"
    assert main(["solve", "pdg6dof", "--warmstart", "tscvx", "--model", str(missing)]) == 2
    line = _one_error_line(capsys)
    assert line.startswith("scpformer: error: --model") and "no_run" in line


def test_a_corrupt_run_folder_is_a_one_line_error(tmp_path, capsys):
    run = tmp_path / "run"
    (run / "tight").mkdir(parents=True)
    (run / "tight" / "checkpoint.pt").write_bytes(b"not a checkpoint")
    assert main(["solve", "pdg6dof", "--warmstart", "tscvx", "--model", str(run)]) == 2
    assert _one_error_line(capsys).startswith("scpformer: error: --model")


def test_a_model_for_another_node_count_is_a_one_line_error(capsys):
    argv = ["solve", "pdg6dof", "--warmstart", "tscvx", "--model", "default", "--n-nodes", "20"]
    assert main(argv) == 2
    assert "predicts N = 50 nodes, the solve has 20" in _one_error_line(capsys)


def test_model_without_tscvx_is_refused(tmp_path, capsys):
    assert main(["solve", "pdg6dof", "--model", str(tmp_path)]) == 2
    assert "--warmstart tscvx, kdtree or interp only" in _one_error_line(capsys)


@pytest.mark.slow
def test_tscvx_solve_runs_algorithm_2_with_the_runs_predictor(tmp_path, monkeypatch, capsys):
    predictor = OraclePredictor(solve(PDGInstance()))
    loaded = {}

    def from_checkpoint(cls, run_dir, device="cpu", **kwargs):
        loaded["run"] = str(run_dir)
        return cls(predictor, **kwargs)

    monkeypatch.setattr(TscvxWarmStart, "from_checkpoint", classmethod(from_checkpoint))
    status = main(["solve", "pdg6dof", "--warmstart", "tscvx", "--model", str(tmp_path)])
    out = capsys.readouterr().out
    assert status == 0, out
    assert loaded["run"] == str(tmp_path)
    assert "T-SCvx rows kept" in out and "converged" in out


@pytest.mark.parametrize("kind", ["kdtree", "interp"])
def test_a_lookup_warm_start_needs_its_own_run(tmp_path, capsys, kind):
    assert main(["solve", "pdg6dof", "--warmstart", kind]) == 2
    assert f"--warmstart {kind} needs --model RUN" in _one_error_line(capsys)
    assert main(["solve", "pdg6dof", "--warmstart", kind, "--model", str(tmp_path)]) == 2
    assert "not a T-SCvx run" in _one_error_line(capsys)


def test_batched_tight_flags_are_the_networks_flags_at_each_iteration():
    # The warm start predicts TIGHT_BATCH iterations per forward pass; every k must still
    # get the network's flags for (theta, k), across the batch boundary too.
    from scpformer.data.pdg6dof_family import theta_vector
    from scpformer.warmstart.tscvx import TIGHT_BATCH

    provider = TscvxWarmStart.from_checkpoint(default_model("pdg6dof"))
    instance = PDGInstance()
    flags = provider.tight(instance)
    theta = theta_vector(instance)
    per_k = [provider.predictor.predict_tight(theta, k) for k in range(1, 2 * TIGHT_BATCH + 2)]
    assert len({f.tobytes() for f in per_k}) > 1  # the flags do change with k
    for k, expected in enumerate(per_k, start=1):
        np.testing.assert_array_equal(flags(k), expected)


def test_flags_of_the_wrong_size_are_refused():
    class WrongSize(OraclePredictor):
        def predict_tight(self, theta, k):
            return np.zeros((len(np.atleast_1d(k)), 7), dtype=bool)

    provider = TscvxWarmStart(WrongSize(None))
    with pytest.raises(ValueError, match=r"predict_tight gave flags of shape \(8, 7\)"):
        provider.tight(PDGInstance())(1)


def test_from_run_is_a_deprecated_alias_of_from_checkpoint(monkeypatch):
    calls = []

    def from_checkpoint(cls, path, device="cpu", **kwargs):
        calls.append((path, device, kwargs))
        return "provider"

    monkeypatch.setattr(TscvxWarmStart, "from_checkpoint", classmethod(from_checkpoint))
    with pytest.warns(DeprecationWarning, match="use TscvxWarmStart.from_checkpoint"):
        assert TscvxWarmStart.from_run("RUN", config=None) == "provider"
    assert calls == [("RUN", "cpu", {"config": None})]
