"""``scpformer solve rendezvous|robust-rendezvous --warmstart art --model RUN``."""

from __future__ import annotations

import numpy as np
import pytest
from warmstart_standins import AffineNormalization, replay_model

from scpformer.cli.main import main
from scpformer.pretrained import default_model
from scpformer.problems.rendezvous import linear_model, sample_instances, solve
from scpformer.problems.robust_rendezvous import RobustInstance, solve_tpbvp
from scpformer.warmstart import ArtWarmStart


@pytest.fixture
def checkpoint(monkeypatch, tmp_path):
    """Make ``ArtWarmStart.from_checkpoint`` replay ``u`` [and RTN ``states``] (set by the test);
    ``--model RUN`` names a folder in the working directory (``--model`` must exist)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "RUN").mkdir()
    norm = AffineNormalization.random(100, seed=5)
    asked = {}

    def from_checkpoint(cls, path, *, family=None, frame=None, device="cpu", **kwargs):
        asked.update(path=str(path), family=family, **kwargs)
        states = asked.get("states")
        model = replay_model(norm, asked["u"][None], None if states is None else states[None])
        return cls(model, norm, family=family, **kwargs)

    monkeypatch.setattr(ArtWarmStart, "from_checkpoint", classmethod(from_checkpoint))
    return asked


@pytest.mark.parametrize("model", [[], ["--model", "default"]])
def test_art_without_a_model_uses_the_verified_pretrained_default(model, checkpoint, capsys):
    instance = sample_instances(np.random.default_rng(0), 1)[0]
    cvx = solve(instance, "convex", verify=False).trajectory
    checkpoint["u"], checkpoint["states"] = cvx.u, linear_model(instance).rtn(cvx.x)[:100]
    argv = ["solve", "rendezvous", "--seed", "0", "--no-verify", "--warmstart", "art",
            "--art-mode", "transformer", "--rtg", "-0.3", *model]  # fmt: skip
    assert main(argv) == 0
    assert checkpoint["path"] == str(default_model("rendezvous"))
    assert checkpoint["path"].endswith("art-rendezvous")


def test_art_flags_without_art_are_a_usage_error(capsys, tmp_path):
    assert main(["solve", "rendezvous", "--model", str(tmp_path)]) == 2
    assert "--model: used with --warmstart art only" in capsys.readouterr().err
    assert main(["solve", "robust-rendezvous", "--rtg", "-2", "--art-mode", "dynamics"]) == 2
    assert "--art-mode, --rtg: used with --warmstart art only" in capsys.readouterr().err


def test_art_applies_to_the_scp_problem_only(capsys):
    argv = ["solve", "rendezvous", "--problem", "convex", "--warmstart", "art", "--model", "R"]
    assert main(argv) == 2
    assert "--warmstart art applies to --problem scp only" in capsys.readouterr().err


def test_rendezvous_art_summary_shows_the_warm_start_beside_the_scp(checkpoint, capsys):
    instance = sample_instances(np.random.default_rng(0), 1)[0]
    cvx = solve(instance, "convex", verify=False).trajectory
    checkpoint["u"], checkpoint["states"] = cvx.u, linear_model(instance).rtn(cvx.x)[:100]
    argv = ["solve", "rendezvous", "--seed", "0", "--no-verify", "--warmstart", "art", "--model",
            "RUN", "--art-mode", "transformer", "--rtg", "-0.3", "--ctg", "1"]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert checkpoint["path"] == "RUN" and checkpoint["family"] == "rendezvous"
    assert checkpoint["art_mode"] == "transformer"
    assert checkpoint["rtg"] == -0.3 and checkpoint["ctg"] == 1.0
    assert "warm start (art): accepted (no acceptance check)" in out
    assert "warm start (art)" in out and "SCP" in out and "constraint-to-go C(t_0)" in out
    assert "converged" in out


def test_robust_art_summary_reports_a_rejected_guess_and_its_fallback(checkpoint, capsys):
    checkpoint["u"] = np.zeros((100, 3))  # never burns: E_R = -1, rejected
    argv = ["solve", "robust-rendezvous", "--mode", "deterministic", "--warmstart", "art",
            "--model", "RUN"]  # fmt: skip
    assert main(argv) in (0, 1)
    out = capsys.readouterr().out
    assert checkpoint["family"] == "robust-rendezvous" and checkpoint["mode"] == "deterministic"
    assert "warm start (art): rejected, used tpbvp" in out
    assert "warm start (tpbvp)" in out and "rejected ART guess" in out
    tpbvp = solve_tpbvp(RobustInstance())
    assert f"{tpbvp.cost:.4f} m/s" in out  # the fallback's cost beside the SCP's
