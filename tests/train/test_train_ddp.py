"""DistributedDataParallel under torchrun: two CPU processes (gloo) train one model."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from train_standins import STANDIN_MODELS

import scpformer
from scpformer.train.checkpoint import load_checkpoint

pytestmark = pytest.mark.slow


def test_two_processes_train_one_model_and_process_zero_writes_the_run(toy_rdv, tmp_path):
    run = tmp_path / "run"
    script = Path(__file__).with_name("ddp_train_run.py")
    src = str(Path(scpformer.__file__).parents[1])
    env = os.environ | {"PYTHONPATH": os.pathsep.join([src, os.environ.get("PYTHONPATH", "")])}
    env |= {"OMP_NUM_THREADS": "1"}
    command = [sys.executable, "-m", "torch.distributed.run", "--standalone",
               "--nproc_per_node", "2", str(script), str(toy_rdv), str(run), "2"]  # fmt: skip
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    config = json.loads((run / "config.json").read_text())
    assert config["world_size"] == 2 and config["device"] == "cpu"
    with (run / "metrics.csv").open() as fh:
        assert [int(r["epoch"]) for r in csv.DictReader(fh)] == [1, 2]
    ranks = [torch.load(run / f"rank{r}.pt", weights_only=True) for r in (0, 1)]
    for name, value in ranks[0].items():  # gradients were averaged: one model on both ranks
        torch.testing.assert_close(ranks[1][name], value, rtol=0, atol=0)
    loaded = load_checkpoint(run, models=STANDIN_MODELS)
    for name, value in loaded.model.state_dict().items():
        torch.testing.assert_close(ranks[0][name], value, rtol=0, atol=0)
