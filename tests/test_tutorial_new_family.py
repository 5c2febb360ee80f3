"""docs/new-family.md is a test: its code runs as written, and its excerpts are the file's."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TUTORIAL = ROOT / "docs" / "new-family.md"
FAMILY_FILE = ROOT / "examples" / "pdg3dof.py"
EXCERPT = "# examples/pdg3dof.py\n"


def python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", TUTORIAL.read_text(), flags=re.S)


def run_python(code: str, cwd: Path, timeout: float) -> subprocess.CompletedProcess:
    """``code`` in a fresh interpreter with src/ and examples/ on the path, as the doc says."""
    paths = [str(ROOT / "src"), str(ROOT / "examples"), os.environ.get("PYTHONPATH", "")]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, paths))}
    script = cwd / "tutorial.py"
    script.write_text(code)
    return subprocess.run(
        [sys.executable, str(script)], cwd=cwd, env=env, capture_output=True, text=True,
        timeout=timeout,
    )  # fmt: skip


def test_the_tutorial_excerpts_are_verbatim_parts_of_the_family_file():
    excerpts = [b for b in python_blocks() if b.startswith(EXCERPT)]
    assert len(excerpts) >= 4
    source = FAMILY_FILE.read_text()
    for block in excerpts:
        assert block[len(EXCERPT) :] in source, block


@pytest.mark.slow
def test_the_tutorial_runs_solve_generate_train_warmstart_and_export(tmp_path):
    code = "\n".join(b for b in python_blocks() if not b.startswith(EXCERPT))
    done = run_python(code, tmp_path, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    out = done.stdout
    # solved and verified; lossless: |T| == Gamma; the finer grid agrees (asserted in the doc)
    assert re.search(r"^converged: \d+\.\d+ kg of propellant", out, flags=re.M)
    gap = float(re.search(r"max \| \|T\| - Gamma \| / Gamma = (\S+)", out).group(1))
    assert gap < 1e-5
    coarse, fine = map(float, re.search(r"propellant: (\S+) kg \(N = 30\), (\S+) kg", out).groups())
    assert 0.0 <= coarse - fine < 0.005 * coarse
    # a dataset, a checkpoint, the learned warm start on the test split, an ONNX file
    assert "'by_status': {'converged': 160}" in out
    assert (tmp_path / "pdg3dof-data" / "splits.h5").is_file()
    assert (tmp_path / "pdg3dof-run" / "checkpoint.pt").is_file()
    assert re.search(r"16 test instances: mean solves \S+ from the minimum-mass", out)
    assert float(re.search(r"max \|onnxruntime - PyTorch\| = (\S+)", out).group(1)) < 1e-4


def test_a_bad_instance_or_configuration_is_an_error_naming_the_field(tmp_path):
    code = (
        "import pdg3dof\n"
        "for make in (lambda: pdg3dof.Instance(r0=(0.0, 1.0), v0=(0, 0, 0), m0=1.0),\n"
        "             lambda: pdg3dof.Instance(r0=(0, 0, 1), v0=(0, 0, 0), m0=-5.0),\n"
        "             lambda: pdg3dof.Config(tf=0.0), lambda: pdg3dof.Config(solver='x')):\n"
        "    try:\n"
        "        make()\n"
        "    except ValueError as err:\n"
        "        print(err)\n"
    )
    done = run_python(code, tmp_path, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    lines = done.stdout.splitlines()
    assert [line.split()[0] for line in lines] == ["r0", "m0", "tf", "solver"]
