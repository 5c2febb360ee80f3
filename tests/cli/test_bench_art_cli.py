"""``scpformer bench art``: runs every mode on a short horizon; clear errors; torch stays lazy."""

import subprocess
import sys

import pytest

from scpformer.cli.main import main

pytest.importorskip("torch")


def test_bench_art_times_cached_and_uncached_generation(capsys):
    from scpformer.models.capabilities import low_precision_available

    argv = ["bench", "art", "--steps", "12", "--repeats", "1", "--batch", "3", "--target"]
    assert main([*argv, "--bf16", "--int8"]) == 0
    out = capsys.readouterr().out
    assert "ART small preset, random weights" in out and "median of 1 interleaved runs" in out
    here = {mode: low_precision_available(mode[-4:]) for mode in ("cached, bf16", "cached, int8")}
    for mode in ("cached", "cached, 2 calls", "cached, bf16", "cached, int8", "no cache"):
        assert (f"{mode:<17}     1" in out) is here.get(mode, True)
    for mode in ("cached", "cached, bf16", "cached, int8"):
        assert (f"{mode:<17}     3" in out) is here.get(mode, True)
    for mode, runs in here.items():  # a format this CPU lacks: one line, its rows skipped
        flag = mode[-4:]
        assert (f"--{flag}: {flag} generation is not available on this machine" in out) is not runs


def test_bench_art_without_bf16_kernels_says_so_in_one_line_and_times_the_rest(capsys, monkeypatch):
    monkeypatch.setenv("SCPFORMER_DISABLE_BF16", "1")
    argv = ["bench", "art", "--steps", "12", "--repeats", "1", "--batch", "1", "--bf16"]
    assert main([*argv, "--skip-uncached"]) == 0
    out = capsys.readouterr().out
    notes = [line for line in out.splitlines() if "bf16" in line]
    assert notes == [
        "--bf16: bf16 generation is not available on this machine "
        "(disabled by SCPFORMER_DISABLE_BF16=1); rows skipped"
    ]
    assert f"{'cached':<17}     1" in out and f"{'cached, 2 calls':<17}     1" in out


def test_bench_art_reports_the_speed_up_and_the_control_error_of_each_mode(capsys):
    assert main(["bench", "art", "--steps", "12", "--repeats", "1", "--batch", "1"]) == 0
    rows = {line[:17].strip(): line[17:].split() for line in capsys.readouterr().out.splitlines()}
    assert rows["cached"][-1].endswith("x")  # batch 1 once, with its speed-up over no cache
    assert float(rows["no cache"][-1]) < 1e-5  # same controls to float tolerance
    assert float(rows["cached, 2 calls"][-1]) < 1e-5


def test_rollout_with_and_without_the_cache_gives_the_same_controls():
    import torch

    from scpformer.cli import bench_art
    from scpformer.models import build_model, preset

    torch.manual_seed(0)
    model = build_model("art", preset("art", "small", n_layer=2, n_embd=32, n_head=2)).eval()
    dynamics = bench_art.rendezvous_dynamics(12, 0)
    norm = bench_art.unit_normalization(12, 6, 3)
    runs = []
    for policy in (
        bench_art.CachedPolicy(model, 2, 12, None, False),
        bench_art.UncachedPolicy(model, 2, 12, None),
    ):
        runs.append(bench_art.rollout(policy, dynamics, norm, "rtn", 2, 12))
    torch.testing.assert_close(runs[0][0], runs[1][0], rtol=1e-4, atol=1e-7)
    torch.testing.assert_close(runs[0][1], runs[1][1], rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--batch", "0"], "--batch must be at least 1"),
        (["--steps", "5"], "--steps must be at least 11"),
        (["--steps", "101"], "exceeds the model's context 100"),
    ],
)
def test_bad_bench_flags_end_with_one_line_error(capsys, flags, message):
    assert main(["bench", "art", "--repeats", "1", *flags]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("scpformer: error:") and message in err and "\n" not in err


def test_the_cli_starts_without_importing_torch():
    code = "import sys, scpformer.cli.main; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
