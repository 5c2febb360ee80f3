"""benchmarks/pdg6dof_embersarc.py: argument checking of --velocity-scale (no solve)."""

from __future__ import annotations

import pytest


@pytest.mark.parametrize("scale", ["0", "-0.8", "nan"])
def test_a_nonpositive_velocity_scale_is_a_usage_error_naming_the_flag(scale, run_benchmark):
    done = run_benchmark("pdg6dof_embersarc.py", "--draws", "1", "--velocity-scale", scale)
    assert done.returncode == 2
    assert "--velocity-scale" in done.stderr
    assert "converged" not in done.stdout  # rejected before any solve
