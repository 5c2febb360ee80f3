"""The rendezvous dataset family: contents, determinism, failures, resumption, Ray, CLI."""

import dataclasses
import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
from conftest import N_RDV, RDV_SEED, RDV_SHARD

from scpformer.cli.data import main
from scpformer.data import storage
from scpformer.data.executors import instance_rng
from scpformer.data.family import DatasetFamily, build_family, full_schema
from scpformer.data.generate import GenerateConfig, generate
from scpformer.data.rendezvous_family import (
    THETA_NAMES,
    TWINS,
    RendezvousDataConfig,
    RendezvousFamily,
    instance_from_theta,
    theta_vector,
)
from scpformer.problems.rendezvous import RendezvousScenario, linear_model, solve
from scpformer.problems.rendezvous.instance import SampleRanges

pytestmark = pytest.mark.slow  # every test solves rendezvous instances (~0.3 s each)


def all_columns(folder):
    manifest = storage.read_manifest(folder)
    parts = [storage.read_columns(folder / s.file, manifest.schema) for s in manifest.shards]
    return {f.name: np.concatenate([p[f.name] for p in parts]) for f in manifest.schema}


def test_family_implements_the_protocol_and_rebuilds_from_its_manifest(rdv_dataset):
    family = RendezvousFamily()
    assert isinstance(family, DatasetFamily)
    config = storage.read_manifest(rdv_dataset.folder).config
    assert build_family("rendezvous", config) == family
    custom = RendezvousFamily(
        RendezvousDataConfig(ranges=SampleRanges(horizon_orbits=(1.0, 1.5)), warmstart="tpbvp")
    )
    assert build_family("rendezvous", json.loads(json.dumps(custom.config_dict()))) == custom
    with pytest.raises(ValueError, match="warmstart must be one of"):
        RendezvousDataConfig(warmstart="zero")


def test_theta_round_trips_through_the_instance():
    instance = RendezvousFamily().sample(np.random.default_rng(4))
    theta = theta_vector(instance)
    assert theta.shape == (len(THETA_NAMES),)
    assert instance_from_theta(theta) == instance
    with pytest.raises(ValueError, match=r"theta must have shape \(13,\)"):
        instance_from_theta(theta[:6])


def test_schema_holds_both_twins_with_sequences_of_the_horizon():
    schema = {f.name: f for f in full_schema(RendezvousFamily())}
    for p in TWINS:
        assert schema[f"{p}_roe"].shape == schema[f"{p}_rtn"].shape == (101, 6)
        assert schema[f"{p}_dv"].shape == (100, 3)
        assert schema[f"{p}_rtg"].shape == schema[f"{p}_ctg"].shape == (101,)
        assert not schema[f"{p}_solve_time"].deterministic
    assert schema["theta"].shape == (13,) and schema["ws_roe"].shape == (101, 6)


def test_samples_hold_consistent_twins_sequences_and_warm_start(rdv_dataset):
    data = all_columns(rdv_dataset.folder)
    assert list(data["index"]) == list(data["base_index"]) == list(range(N_RDV))
    assert (data["status"] == "converged").all() and (data["scp_status"] == "converged").all()
    for i in range(N_RDV):
        instance = RendezvousFamily().sample(instance_rng(RDV_SEED, i))
        np.testing.assert_array_equal(data["theta"][i], theta_vector(instance))
        model = linear_model(instance)
        for p in TWINS:
            roe, dv = data[f"{p}_roe"][i], data[f"{p}_dv"][i]
            np.testing.assert_allclose(data[f"{p}_rtn"][i], model.rtn(roe))
            norms = np.linalg.norm(dv, axis=1)
            np.testing.assert_allclose(-data[f"{p}_rtg"][i][:-1], np.cumsum(norms[::-1])[::-1])
            assert data[f"{p}_rtg"][i][0] == pytest.approx(-data[f"{p}_cost"][i])
            assert data[f"{p}_verified"][i]
        assert (data["scp_ctg"][i] == 0).all()  # Problem 3 keeps out of the keep-out zone
        assert data["c_cvx_t1"][i] == data["cvx_ctg"][i][0] >= 0
        assert data["warmstart"][i] == "convex"
        np.testing.assert_array_equal(data["ws_roe"][i], data["cvx_roe"][i])
        assert data["cost"][i] == data["scp_cost"][i] >= data["cvx_cost"][i] * (1 - 1e-6)
    assert (data["c_cvx_t1"] > 0).any()  # the convex twin crosses the zone: ctg labels it


def test_one_and_two_workers_write_the_same_bytes(tmp_path, rdv_family, rdv_dataset):
    config = GenerateConfig(n=N_RDV, out=tmp_path / "one", shard_size=RDV_SHARD, workers=1)
    one = generate(rdv_family, dataclasses.replace(config, seed=RDV_SEED))
    assert storage.content_id(one.manifest) == storage.content_id(rdv_dataset.manifest)
    a, b = all_columns(one.folder), all_columns(rdv_dataset.folder)
    for f in one.manifest.schema:
        if f.deterministic:
            np.testing.assert_array_equal(a[f.name], b[f.name], err_msg=f.name)


def test_failed_instances_are_stored_with_their_status(tmp_path):
    # With the cone vertex at the docking port Problem 2 is infeasible (see RendezvousScenario);
    # Clarabel reports it as a solver error.
    scenario = RendezvousScenario(cone_vertex_setback_m=0.0)
    family = RendezvousFamily(RendezvousDataConfig(scenario=scenario))
    report = generate(family, GenerateConfig(n=1, out=tmp_path / "ds", workers=1))
    data = all_columns(report.folder)
    assert data["status"][0] in {"infeasible_instance", "solver_failed"}
    assert data["cvx_status"][0] == data["status"][0] == data["scp_status"][0]
    assert "warm start failed" in data["message"][0]
    assert np.isnan(data["scp_roe"][0]).all() and np.isnan(data["cvx_dv"][0]).all()
    assert data["c_cvx_t1"][0] == -1 and np.isfinite(data["theta"][0]).all()
    assert report.manifest.counts()["failed"] == 1


KILLED_RUN = textwrap.dedent(
    """
    import sys
    from scpformer.data.generate import GenerateConfig, generate
    from scpformer.data.rendezvous_family import RendezvousFamily

    if __name__ == "__main__":
        config = GenerateConfig(n={n}, out=sys.argv[1], shard_size={shard}, workers=1, seed={seed})
        generate(RendezvousFamily(), config)
    """
)


def test_a_run_killed_mid_shard_resumes_to_the_same_bytes(tmp_path, rdv_family, rdv_dataset):
    script = tmp_path / "killed_run.py"
    script.write_text(KILLED_RUN.format(n=N_RDV, shard=RDV_SHARD, seed=RDV_SEED))
    out = tmp_path / "ds"
    proc = subprocess.Popen([sys.executable, str(script), str(out)], start_new_session=True)
    first = out / storage.shard_name(0)
    deadline = time.monotonic() + 120
    while not first.exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)  # the run and its worker, during shard 1
    proc.wait()
    assert first.exists() and not (out / storage.shard_name(1)).exists()
    kept = first.stat().st_ino, storage.file_sha256(first)
    config = GenerateConfig(n=N_RDV, out=out, shard_size=RDV_SHARD, workers=1, seed=RDV_SEED)
    resumed = generate(rdv_family, config)
    assert resumed.resumed == RDV_SHARD and resumed.generated == N_RDV - RDV_SHARD
    assert (first.stat().st_ino, storage.file_sha256(first)) == kept  # kept, not rewritten
    assert storage.content_id(resumed.manifest) == storage.content_id(rdv_dataset.manifest)
    assert storage.verify_dataset(out) == []


def test_ray_writes_the_same_bytes_as_the_local_pool(tmp_path, ray_local, rdv_dataset):
    config = GenerateConfig(
        n=N_RDV, out=tmp_path / "ray", shard_size=RDV_SHARD, seed=RDV_SEED, ray_address="auto"
    )
    on_ray = generate(RendezvousFamily(), config)
    assert on_ray.backend == "ray"
    assert storage.content_id(on_ray.manifest) == storage.content_id(rdv_dataset.manifest)


def test_cli_generates_describes_verifies_and_splits_a_rendezvous_dataset(tmp_path, capsys):
    out = tmp_path / "ds"
    argv = ["generate", "rendezvous", "--n", "2", "--out", str(out), "--workers", "1"]
    argv += ["--range-horizon-orbits", "1", "1.5", "--quiet"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "2 of 2 instances in 1 shard(s)" in text and "solved 2 (100.0%)" in text
    assert storage.read_manifest(out).config["ranges"]["horizon_orbits"] == [1.0, 1.5]
    assert main(["dataset", "info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "rendezvous (generated)" in text and "field cvx_ctg" in text and "(101,)" in text
    assert main(["dataset", "split", str(out), "--fractions", "0.5", "0", "0.5"]) == 0
    assert main(["dataset", "verify", str(out)]) == 0
    assert "ok:" in capsys.readouterr().out
    assert main([*argv, "--warmstart", "tpbvp"]) == 2  # another configuration, same folder
    assert "(config.warmstart: 'convex' there, 'tpbvp' here)" in capsys.readouterr().err


def test_the_tpbvp_twin_is_a_direct_problem_1_solve(rdv_dataset):
    data = all_columns(rdv_dataset.folder)
    for i in range(N_RDV):
        instance = RendezvousFamily().sample(instance_rng(RDV_SEED, i))
        direct = solve(instance, "tpbvp", verify=False)
        assert data["tpbvp_status"][i] == direct.status.value == "converged"
        np.testing.assert_allclose(data["tpbvp_dv"][i], direct.trajectory.u, atol=1e-9)
        np.testing.assert_allclose(data["tpbvp_roe"][i], direct.trajectory.x, atol=1e-6)
        assert data["tpbvp_cost"][i] == pytest.approx(direct.cost, rel=1e-9)
        # no waypoint, cone or keep-out zone: never dearer than Problem 2
        assert data["tpbvp_cost"][i] <= data["cvx_cost"][i] * (1 + 1e-6)


def test_a_manifest_from_before_the_tpbvp_twin_rebuilds_without_it():
    config = RendezvousFamily().config_dict()
    del config["tpbvp_twin"]  # what datasets made before the twin existed hold
    old = build_family("rendezvous", config)
    assert old.twins == ("scp", "cvx") and old == RendezvousFamily(
        RendezvousDataConfig(tpbvp_twin=False)
    )
    names = {f.name for f in full_schema(old)}
    assert "cvx_roe" in names and not any(n.startswith("tpbvp_") for n in names)


def test_cli_can_skip_the_tpbvp_twin(tmp_path):
    out = tmp_path / "ds"
    argv = ["generate", "rendezvous", "--n", "1", "--out", str(out), "--workers", "1"]
    assert main([*argv, "--no-tpbvp-twin", "--no-verify", "--quiet"]) == 0
    manifest = storage.read_manifest(out)
    assert manifest.config["tpbvp_twin"] is False
    names = {f.name for f in manifest.schema}
    assert "scp_dv" in names and "tpbvp_dv" not in names
