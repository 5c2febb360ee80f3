import json
import math

import numpy as np
import pytest

from scpformer.problems.pdg6dof.constraints import (
    CONSTRAINT_NAMES,
    constraint_index,
    initial_state_violations,
)
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.sampling import PDGSampleRanges, sample_instances


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"r0": (1.0, float("nan"), 0.0)}, "r0 must be finite"),
        ({"v0": (1.0, 2.0)}, r"v0 must have shape \(3,\)"),
        ({"q0": (1.0, 0.1, 0.0, 0.0)}, "q0 must be a unit quaternion"),
        ({"m0": 2.0}, "must exceed the dry mass"),
        ({"m0": float("inf")}, "m0 must be finite"),
        ({"gamma_gs_deg": 90.0}, "gamma_gs_deg"),
        ({"theta_max_deg": -1.0}, "theta_max_deg"),
        ({"omega0_deg": "fast"}, "omega0_deg must be numeric"),
    ],
)
def test_bad_instance_fields_are_named_in_the_error(kwargs, message):
    with pytest.raises(ValueError, match=message):
        PDGInstance(**kwargs)


def test_unknown_fields_are_rejected():
    with pytest.raises(ValueError, match=r"unknown instance field.*r_0"):
        PDGInstance.from_dict({"r_0": [1, 2, 3]})
    with pytest.raises(ValueError, match=r"unknown constants field.*Tmax"):
        PDGInstance.from_dict({"constants": {"Tmax": 3}})


def test_malformed_json_file_gives_a_clear_error(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text("{r0: [1, 2")
    with pytest.raises(ValueError, match="malformed JSON"):
        PDGInstance.from_json(path)


def test_instance_round_trips_through_json(tmp_path):
    inst = PDGInstance(r0=(5.0, 1.0, -2.0), omega0_deg=(3.0, 2.0, 1.0), m0=2.9)
    path = tmp_path / "inst.json"
    path.write_text(json.dumps(inst.to_dict()))
    assert PDGInstance.from_json(path) == inst


def test_rotation_about_up_preserves_altitude_speed_and_tilt():
    inst = PDGInstance(
        q0=tuple(np.array([0.98, 0.1, 0.1, 0.13]) / np.linalg.norm([0.98, 0.1, 0.1, 0.13]))
    )
    rot = inst.rotated_about_up(math.radians(45.0))
    assert rot.r0[0] == pytest.approx(inst.r0[0])
    assert np.linalg.norm(rot.v0) == pytest.approx(np.linalg.norm(inst.v0))
    tilt = np.linalg.norm(inst.q0[2:]), np.linalg.norm(rot.q0[2:])
    assert tilt[1] == pytest.approx(tilt[0])


def test_sampler_is_reproducible_and_stays_in_range():
    a = sample_instances(np.random.default_rng(7), 5, PDGSampleRanges.table2())
    b = sample_instances(np.random.default_rng(7), 5, PDGSampleRanges.table2())
    assert a == b
    for inst in a:
        assert 0.003 <= inst.r0[0] <= 9.997 and inst.r0[1] >= 0.0 and inst.r0[2] >= 0.0
        assert inst.m0 > inst.constants.m_dry


def test_constraint_index_is_name_major_and_stable():
    index = constraint_index(4)
    assert len(index) == 4 * len(CONSTRAINT_NAMES)
    assert index[:5] == [("mass", 0), ("mass", 1), ("mass", 2), ("mass", 3), ("glideslope", 0)]


def test_initial_rate_above_omega_max_is_reported_infeasible():
    inst = PDGInstance(omega0_deg=(0.0, 100.0, 0.0))
    assert initial_state_violations(inst) == ["omega"]
    assert initial_state_violations(PDGInstance()) == []


def test_shipped_example_instance_is_valid():
    from pathlib import Path

    path = Path(__file__).parents[2] / "examples" / "pdg6dof_instance.json"
    inst = PDGInstance.from_json(path)
    assert inst.gamma_gs_deg == 15.0 and initial_state_violations(inst) == []


def test_a_huge_initial_state_is_refused_by_name_without_an_overflow_warning():
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's overflow RuntimeWarning would fail here
        with pytest.raises(ValueError, match="r0: norm inf exceeds"):
            PDGInstance(r0=(1e308, 1e308, 0.0))


def test_a_wet_mass_beyond_any_lander_is_refused_by_name():
    with pytest.raises(ValueError, match=r"m0 \(1e\+308\) exceeds 20 times the dry mass"):
        PDGInstance(m0=1e308)
