"""The 'feasible' sampling preset: consistent draws, documented ranges, rotation invariance."""

import dataclasses
import math

import numpy as np
import pytest

from scpformer.data.augment import ROTATION_ANGLES_DEG, rotate_theta
from scpformer.data.pdg6dof_family import (
    PDG6DoFDataConfig,
    instance_from_theta,
    theta_vector,
)
from scpformer.problems.pdg6dof import sampling as instance_module
from scpformer.problems.pdg6dof.constraints import initial_state_violations
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.sampling import (
    PDGSampleRanges,
    cubic_propellant,
    is_consistent_draw,
    sample_instances,
)

FEASIBLE = PDGSampleRanges.feasible()


@pytest.fixture(scope="module")
def draws():
    return sample_instances(np.random.default_rng(3), 150, FEASIBLE)


def test_feasible_preset_is_the_dataset_default_and_round_trips_through_a_manifest():
    config = PDG6DoFDataConfig()
    assert config.ranges == FEASIBLE
    assert PDG6DoFDataConfig.from_dict(dataclasses.asdict(config)) == config


def test_feasible_draws_violate_no_state_constraint_at_t0(draws):
    assert [initial_state_violations(inst) for inst in draws] == [[]] * len(draws)


def test_feasible_draws_keep_the_margins_of_the_docstring(draws):
    for inst in draws:
        r0 = np.asarray(inst.r0)
        assert inst.tan_gamma_gs * np.linalg.norm(r0[1:]) <= 0.9 * r0[0]
        tilt_deg = 2.0 * math.degrees(math.asin(min(1.0, np.linalg.norm(inst.q0[2:]))))
        assert tilt_deg <= 0.9 * min(inst.theta_max_deg, 180.0) + 1e-9
        assert np.linalg.norm(inst.omega0_deg) <= 0.9 * inst.constants.omega_max_deg
        assert inst.m0 - inst.constants.m_dry >= 1.25 * cubic_propellant(inst)


def test_feasible_draws_lie_in_the_preset_box_with_positive_east_and_north(draws):
    theta = np.array([theta_vector(inst) for inst in draws])
    low = [0.0, 10.0, 1.5, 0.0, 0.0, -1.3, -1.3, -1.3, -1, -1, -1, -1, -40, -40, -40, 2.2]
    high = [50.0, 359.4, 7.0, 6.0, 6.0, -0.1, 1.3, 1.3, 1, 1, 1, 1, 40, 40, 40, 3.0]
    assert (theta >= low).all() and (theta <= high).all()
    tilt_bound = math.sin(math.radians(FEASIBLE.q0_tilt_max_deg) / 2.0)
    assert (np.linalg.norm(theta[:, 10:12], axis=1) <= tilt_bound + 1e-12).all()


def test_rotations_about_up_of_feasible_draws_stay_consistent(draws):
    for inst in draws[:40]:
        for angle in ROTATION_ANGLES_DEG:
            theta = rotate_theta(theta_vector(inst), angle)
            rotated = instance_from_theta(theta, inst.constants)
            assert initial_state_violations(rotated) == []
            assert is_consistent_draw(rotated, 0.9, 1.25)
            assert cubic_propellant(rotated) == pytest.approx(cubic_propellant(inst), rel=1e-9)


def test_rotated_feasible_draws_fill_every_east_north_quadrant(draws):
    theta = np.array([theta_vector(inst) for inst in draws])
    rotated = np.concatenate([rotate_theta(theta, a) for a in ROTATION_ANGLES_DEG])
    signs = {tuple(s) for s in np.sign(rotated[:, 3:5]).astype(int)}
    assert {(1, 1), (1, -1), (-1, 1), (-1, -1)} <= signs


def test_cubic_propellant_grows_with_altitude_and_speed():
    base = PDGInstance(r0=(3.0, 1.0, 0.0), v0=(-0.5, 0.0, 0.0))
    higher = PDGInstance(r0=(6.0, 1.0, 0.0), v0=(-0.5, 0.0, 0.0))
    faster = PDGInstance(r0=(3.0, 1.0, 0.0), v0=(-0.5, 1.5, 0.0))
    assert 0.0 < cubic_propellant(base) < cubic_propellant(higher)
    assert cubic_propellant(base) < cubic_propellant(faster)


def test_the_consistent_draw_rejects_what_the_docstring_names():
    ok = PDGInstance(r0=(4.0, 1.0, 0.0), gamma_gs_deg=20.0)
    assert is_consistent_draw(ok, 0.9, 1.25)
    assert not is_consistent_draw(PDGInstance(r0=(1.0, 5.0, 0.0), gamma_gs_deg=20.0), 0.9, 1.0)
    assert not is_consistent_draw(PDGInstance(omega0_deg=(0.0, 85.0, 0.0)), 0.9, 1.0)
    tilted = PDGInstance(q0=(math.cos(0.35), 0.0, math.sin(0.35), 0.0), theta_max_deg=42.0)
    assert not is_consistent_draw(tilted, 0.9, 1.0)  # tilt 40.1 deg > 0.9 * 42
    assert not is_consistent_draw(PDGInstance(r0=(9.0, 9.0, 0.0), m0=2.1), 0.9, 1.0)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"consistent_margin": 0.0}, "consistent_margin must be positive"),
        ({"consistent_margin": 1.5}, r"consistent_margin must lie in \[0.0, 1.0\]"),
        ({"propellant_margin": -1.0}, "propellant_margin must lie in"),
    ],
)
def test_bad_margins_are_named_in_the_error(kwargs, message):
    with pytest.raises(ValueError, match=message):
        PDGSampleRanges(**{**FEASIBLE.__dict__, **kwargs})


def test_ranges_without_a_consistent_instance_are_a_clear_error(monkeypatch):
    monkeypatch.setattr(instance_module, "MAX_REJECTED_DRAWS", 20)
    starved = PDGSampleRanges(**{**FEASIBLE.__dict__, "m0": (2.001, 2.002)})
    with pytest.raises(ValueError, match="ranges: no consistent instance in 20 draws"):
        sample_instances(np.random.default_rng(0), 1, starved)
