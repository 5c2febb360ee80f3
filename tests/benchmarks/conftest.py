"""Shared helper of the benchmark-script tests: run a script of benchmarks/ as a user would."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def run_benchmark() -> Callable[..., subprocess.CompletedProcess]:
    """``run_benchmark("name.py", *args)``: the script's completed process (text output)."""

    def run(script: str, *args: str) -> subprocess.CompletedProcess:
        env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
        return subprocess.run(
            [sys.executable, str(ROOT / "benchmarks" / script), *args],
            capture_output=True,
            text=True,
            env=env,
            check=False,
        )

    return run
