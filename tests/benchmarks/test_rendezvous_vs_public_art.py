"""benchmarks/rendezvous_vs_public_art.py without the public ART code: finding the checkout."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "rendezvous_vs_public_art.py"


def _script_module():
    spec = importlib.util.spec_from_file_location("rendezvous_vs_public_art", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up while defined
    spec.loader.exec_module(module)
    return module


def test_a_folder_without_ocp_py_is_a_usage_error_naming_the_missing_file(tmp_path, run_benchmark):
    done = run_benchmark("rendezvous_vs_public_art.py", "--art-repo", str(tmp_path), "--n", "1")
    assert done.returncode == 2
    assert "--art-repo" in done.stderr
    assert str(tmp_path / "optimization" / "ocp.py") in done.stderr


def test_the_repository_root_is_accepted_for_its_rpod_folder(tmp_path):
    ocp = tmp_path / "rpod" / "optimization" / "ocp.py"
    ocp.parent.mkdir(parents=True)
    ocp.write_text("")
    assert _script_module().art_root(tmp_path) == tmp_path / "rpod"


def test_an_empty_folder_raises_file_not_found_naming_both_places(tmp_path):
    with pytest.raises(FileNotFoundError, match="rpod"):
        _script_module().art_root(tmp_path)
