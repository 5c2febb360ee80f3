"""benchmarks/pdg6dof_embersarc.py: argument checking of --velocity-scale (no solve)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "pdg6dof_embersarc.py"


@pytest.mark.parametrize("scale", ["0", "-0.8", "nan"])
def test_a_nonpositive_velocity_scale_is_a_usage_error_naming_the_flag(scale):
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    done = subprocess.run(
        [sys.executable, str(SCRIPT), "--draws", "1", "--velocity-scale", scale],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    assert done.returncode == 2
    assert "--velocity-scale" in done.stderr
    assert "converged" not in done.stdout  # rejected before any solve
