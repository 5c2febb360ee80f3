"""The T-SCvx rotation augmentation: a rotated solution solves the rotated instance."""

import dataclasses
import math
import shutil

import numpy as np
import pytest
from toy_families import ToyFamily

from scpformer.data import storage
from scpformer.data.augment import (
    CHECK_FAILED,
    RotationAugmentation,
    augment_dataset,
    check_rotated,
    rotate_sample,
    rotate_states,
    rotate_theta,
)
from scpformer.data.errors import DatasetError
from scpformer.data.generate import GenerateConfig, generate
from scpformer.data.pdg6dof_family import instance_from_theta, theta_vector
from scpformer.problems.pdg6dof.constraints import constraint_values, tight_flags
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.problem import verify_trajectory
from scpformer.scp.solution import Trajectory


def test_rotating_theta_matches_rotating_the_instance():
    instance = PDGInstance(r0=(4.0, 1.0, 2.0), v0=(-1.0, 0.3, -0.2), omega0_deg=(1.0, 2.0, 3.0))
    for angle in (45.0, 135.0, 315.0):
        expected = theta_vector(instance.rotated_about_up(math.radians(angle)))
        np.testing.assert_allclose(
            rotate_theta(theta_vector(instance), angle), expected, atol=1e-15
        )


def test_rotation_keeps_altitude_speed_attitude_tilt_and_body_quantities():
    x = np.random.default_rng(0).normal(size=(5, 14))
    y = rotate_states(x, 90.0)
    np.testing.assert_allclose(y[:, 0], x[:, 0])  # Up
    np.testing.assert_allclose(np.linalg.norm(y[:, 1:3], axis=1), np.linalg.norm(x[:, 1:3], axis=1))
    np.testing.assert_allclose(
        np.linalg.norm(y[:, 8:10], axis=1), np.linalg.norm(x[:, 8:10], axis=1)
    )
    np.testing.assert_array_equal(y[:, 10:], x[:, 10:])  # omega (body frame), mass
    np.testing.assert_allclose(rotate_states(x, 0.0), x)


@pytest.fixture(scope="module")
def augmented(tmp_path_factory, pdg_dataset):
    out = tmp_path_factory.mktemp("aug") / "ds"
    return augment_dataset(pdg_dataset.folder, out), out


def all_columns(folder):
    manifest = storage.read_manifest(folder)
    parts = [storage.read_columns(folder / s.file, manifest.schema) for s in manifest.shards]
    return {f.name: np.concatenate([p[f.name] for p in parts]) for f in manifest.schema}


@pytest.mark.slow
def test_every_rotated_solution_solves_its_rotated_instance_with_the_same_tight_rows(
    augmented, pdg_dataset, pdg_family
):
    _, folder = augmented
    data, base = all_columns(folder), all_columns(pdg_dataset.folder)
    assert len(data["index"]) == 8 * 4 and (data["status"] == "converged").all()
    solver, constants = pdg_family.config.solver, pdg_family.config.constants
    for row in range(len(data["index"])):
        b = int(data["base_index"][row])
        instance = instance_from_theta(data["theta"][row], constants)
        z = Trajectory(x=data["x"][row], u=data["u"][row], p=np.array([data["tf"][row]]))
        assert verify_trajectory(instance, z, solver).passed
        base_instance = instance_from_theta(base["theta"][b], constants)
        flags = tight_flags(constraint_values(instance, z.x, z.u), solver.tight_tol)
        base_flags = tight_flags(
            constraint_values(base_instance, base["x"][b], base["u"][b]), solver.tight_tol
        )
        np.testing.assert_array_equal(flags, base_flags)
        np.testing.assert_array_equal(data["tight_flags"][row], base["tight_flags"][b])
    assert sorted(set(data["rotation_deg"])) == [45.0 * k for k in range(8)]
    assert len(set(data["index"])) == 32 and storage.verify_dataset(folder) == []


@pytest.mark.slow
def test_the_check_catches_a_copy_that_is_not_a_solution(pdg_dataset, pdg_family):
    base = {k: v[0] for k, v in all_columns(pdg_dataset.folder).items()}
    wrong = rotate_sample(base, 90.0, 8, 2)
    wrong["theta"] = base["theta"]  # trajectory rotated, instance not
    checked = check_rotated(pdg_family, base, wrong, verify=True)
    assert checked["status"] == CHECK_FAILED and "nonlinear check failed" in checked["message"]


@pytest.mark.slow
def test_augmenting_again_resumes_and_other_angles_are_refused(augmented, pdg_dataset):
    manifest, folder = augmented
    again = augment_dataset(pdg_dataset.folder, folder)
    assert storage.content_id(again) == storage.content_id(manifest)
    with pytest.raises(DatasetError, match=r"holds another dataset.*transform"):
        augment_dataset(pdg_dataset.folder, folder, RotationAugmentation(angles_deg=(0.0, 90.0)))


def test_only_complete_pdg6dof_datasets_are_augmented(tmp_path):
    generate(ToyFamily(), GenerateConfig(n=2, out=tmp_path / "toy", workers=1))
    with pytest.raises(DatasetError, match=r"for pdg6dof datasets, not toy"):
        augment_dataset(tmp_path / "toy", tmp_path / "out")
    with pytest.raises(ValueError, match=r"angles_deg must be distinct"):
        RotationAugmentation(angles_deg=(0.0, 0.0))


def test_the_first_instances_of_an_unfinished_dataset_are_augmented(pdg_dataset, tmp_path):
    manifest = storage.read_manifest(pdg_dataset.folder)
    boundary = manifest.shards[0].stop - manifest.shards[0].start  # one shard
    unfinished = dataclasses.replace(
        manifest, shards=tuple(s for s in manifest.shards if s.start == 0)
    )  # the generation of the other shards still running
    source = tmp_path / "src"
    shutil.copytree(pdg_dataset.folder, source)
    storage.write_manifest(source, unfinished)
    with pytest.raises(DatasetError, match=r"incomplete.*--first"):
        augment_dataset(source, tmp_path / "all")
    with pytest.raises(DatasetError, match="not all stored"):
        augment_dataset(source, tmp_path / "more", first=boundary + 1)
    with pytest.raises(ValueError, match="first must be"):
        augment_dataset(source, tmp_path / "zero", first=0)
    with pytest.raises(ValueError, match=r"first must be an integer from 1 to \d+, got 0$"):
        augment_dataset(source, tmp_path / "zero", first=np.int64(0))
    out = augment_dataset(source, tmp_path / "part", first=boundary)
    assert out.complete and out.source["n"] == boundary
    rotated = all_columns(tmp_path / "part")
    assert set(rotated["base_index"]) == set(range(boundary))
    # the same rotated samples as those of the whole dataset's first shard
    whole = augment_dataset(pdg_dataset.folder, tmp_path / "whole")
    (shard,) = [s for s in whole.shards if s.start == 0]
    first_shard = storage.read_columns(tmp_path / "whole" / shard.file, whole.schema)
    np.testing.assert_array_equal(rotated["theta"], first_shard["theta"])


def test_the_first_instances_of_a_grown_dataset_keep_its_uneven_shards(pdg_dataset):
    from scpformer.data.augment import _first_instances

    manifest = storage.read_manifest(pdg_dataset.folder)
    shard = manifest.shards[0]
    uneven = [(0, 2), (2, 3), (3, 5), (5, 7)]  # grown from 3 to 7 instances, shards of 2
    grown = dataclasses.replace(
        manifest,
        n=7,
        plan=tuple(uneven),
        grown_from=(3,),
        shards=tuple(dataclasses.replace(shard, start=a, stop=b) for a, b in uneven),
    )
    prefix = _first_instances(pdg_dataset.folder, grown, 5)
    assert prefix.complete and prefix.planned_ranges() == uneven[:3]
