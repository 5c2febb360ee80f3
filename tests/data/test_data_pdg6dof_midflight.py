"""Mid-flight samples of the 6-DoF dataset (``PDG6DoFDataConfig.midflight_nodes``)."""

from __future__ import annotations

import numpy as np
import pytest

from scpformer.cli.main import main
from scpformer.data.executors import instance_rng
from scpformer.data.pdg6dof_family import PDG6DoFDataConfig, PDG6DoFFamily
from scpformer.data.storage import ShardedSamples
from scpformer.problems.pdg6dof.api import solve

NODES = (10, 30)


@pytest.fixture(scope="module")
def draws():
    """Two mid-flight samples with the optima of their base draws and their own."""
    midflight = PDG6DoFFamily(PDG6DoFDataConfig(midflight_nodes=NODES))
    base = PDG6DoFFamily()
    out = []
    for index in range(2):
        instance = midflight.sample(instance_rng(7, index))
        base_instance = base.sample(instance_rng(7, index))  # the same stream draws it first
        config = midflight.config.solver
        out.append((instance, solve(base_instance, config), solve(instance, config)))
    return out


def test_a_sample_starts_from_a_node_of_its_base_draws_optimum(draws):
    for instance, base, _ in draws:
        x = base.trajectory.x
        nodes = [k for k in range(NODES[0], NODES[1] + 1) if np.allclose(x[k], instance.x0)]
        assert len(nodes) == 1, "the initial state is one node of the base optimum in A..B"


def test_the_remaining_optimum_is_the_tail_of_the_base_optimum(draws):
    """Bellman: from a node of an optimal descent, the optimum of the remaining problem lands
    with the tail's propellant and time to go, up to the finer grid of the new problem (its N
    nodes over the remaining time) and SCvx's tolerance; never worse than the tail."""
    for instance, base, mid in draws:
        assert base.converged and mid.converged
        k = next(k for k in range(base.trajectory.x.shape[0])
                 if np.allclose(base.trajectory.x[k], instance.x0))  # fmt: skip
        n = base.trajectory.x.shape[0]
        tail_time = float(base.trajectory.p[0]) * (n - 1 - k) / (n - 1)
        assert mid.cost <= base.cost + 1e-6  # cost = -m(t_f): at least the tail's final mass
        assert mid.cost >= base.cost - 1e-3  # and the same optimum
        assert float(mid.trajectory.p[0]) == pytest.approx(tail_time, rel=1e-2)


@pytest.mark.parametrize("nodes", [(0, 5), (5, 4), (5, 49), (5,), (1.5, 3)])
def test_bad_node_ranges_are_refused(nodes):
    with pytest.raises(ValueError, match="midflight_nodes"):
        PDG6DoFDataConfig(midflight_nodes=nodes)


def test_generate_writes_mid_flight_samples_and_records_the_range(tmp_path, capsys):
    out = tmp_path / "mid"
    argv = ["generate", "pdg6dof", "--n", "2", "--seed", "7", "--midflight-nodes", "10", "30",
            "--out", str(out), "--workers", "1", "--quiet"]  # fmt: skip
    assert main(argv) == 0
    samples = ShardedSamples(out)
    assert samples.manifest.config["midflight_nodes"] == [10, 30]
    theta = samples.column("theta")
    expected = PDG6DoFFamily(PDG6DoFDataConfig(midflight_nodes=NODES)).sample(instance_rng(7, 0))
    np.testing.assert_allclose(theta[0, 2:5], expected.r0)  # theta: gamma, theta_max, r0, ...
    bad = ["generate", "pdg6dof", "--n", "2", "--midflight-nodes", "30", "10", "--out",
           str(tmp_path / "bad")]  # fmt: skip
    assert main(bad) != 0
    assert "midflight_nodes must be two integers" in capsys.readouterr().err
    assert not (tmp_path / "bad" / "manifest.json").exists()
