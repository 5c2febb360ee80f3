import dataclasses

import numpy as np
import pytest

from scpformer.data.errors import DatasetError
from scpformer.data.family import (
    BUILTIN_MODULES,
    COMMON_FIELDS,
    DatasetFamily,
    Field,
    build_family,
    dataclass_from_dict,
    family_names,
    full_schema,
    get_family_spec,
)
from scpformer.data.pdg6dof_family import (
    THETA_NAMES,
    PDG6DoFDataConfig,
    PDG6DoFFamily,
    instance_from_theta,
    theta_vector,
)
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.sampling import PDGSampleRanges


def test_every_planned_family_is_known_by_name():
    assert {"pdg6dof", "rendezvous", "robust-rendezvous"} <= set(family_names())


def test_a_family_that_has_not_landed_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(BUILTIN_MODULES, "future", "scpformer.data.future_family")
    with pytest.raises(DatasetError, match=r"'future' is not available yet"):
        get_family_spec("future")


def test_an_unknown_family_names_the_known_ones():
    with pytest.raises(DatasetError, match=r"unknown dataset family 'orbit'.*pdg6dof"):
        get_family_spec("orbit")


def test_pdg6dof_family_implements_the_protocol_and_rebuilds_from_its_config():
    family = PDG6DoFFamily(PDG6DoFDataConfig(ranges=PDGSampleRanges.nominal()))
    assert isinstance(family, DatasetFamily)
    rebuilt = build_family("pdg6dof", family.config_dict())
    assert rebuilt == family
    assert build_family("pdg6dof") == PDG6DoFFamily()  # Tables 1 and 2


def test_config_from_dict_rejects_unknown_keys():
    data = dataclasses.asdict(PDG6DoFDataConfig())
    data["solver"]["scvx"]["speed"] = 3
    with pytest.raises(ValueError, match=r"field\(s\) speed that this family does not know"):
        dataclass_from_dict(PDG6DoFDataConfig, data)


def test_theta_round_trips_through_the_instance():
    instance = PDGInstance().rotated_about_up(0.3)
    theta = theta_vector(instance)
    assert theta.shape == (len(THETA_NAMES),)
    assert instance_from_theta(theta, instance.constants) == instance


def test_schema_starts_with_the_common_fields_and_has_unique_names():
    schema = full_schema(PDG6DoFFamily())
    assert schema[: len(COMMON_FIELDS)] == COMMON_FIELDS
    flags = next(f for f in schema if f.name == "tight_flags")
    assert flags.shape == (PDG6DoFFamily().config.solver.scvx.iter_max, 7 * 50)


def test_field_coerces_values_and_rejects_wrong_shapes():
    field = Field(name="x", dtype="float32", shape=(2,))
    assert field.coerce([1, 2]).dtype == np.float32
    assert np.isnan(field.empty(3)).all()
    with pytest.raises(ValueError, match=r"field x: expected shape"):
        field.coerce([1, 2, 3])
    with pytest.raises(ValueError, match=r"dtype must be one of"):
        Field(name="y", dtype="complex128")
