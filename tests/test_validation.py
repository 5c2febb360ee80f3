"""Error messages of the shared validation helpers print numbers, not numpy reprs."""

from __future__ import annotations

import numpy as np
import pytest

from scpformer.validation import (
    check_bool,
    check_finite,
    check_positive,
    check_type,
    shown,
    shown_as,
)

NAN, INF = np.float64(np.nan), np.float64(np.inf)


@pytest.mark.parametrize(
    ("check", "message"),
    [
        (lambda: check_finite("x", NAN), "x must be finite, got nan"),
        (lambda: check_finite("x", np.array([1.0, INF])), "x must be finite, got [1.0, inf]"),
        (lambda: check_finite("x", [np.float64(1), NAN]), "x must be finite, got [1.0, nan]"),
        (lambda: check_finite("x", (np.float32(-1),), nonnegative=True), "got (-1.0,)"),
        (lambda: check_finite("x", np.float64(-2), nonnegative=True), "nonnegative, got -2.0"),
        (lambda: check_finite("x", np.complex128(1j)), "real, not complex, got 1j"),
        (lambda: check_positive("x", NAN), "x must be finite, got nan"),
        (lambda: check_bool("x", np.float64(1)), "x must be true or false, got 1.0"),
        (lambda: check_type("x", np.int64(3), str), "x must be a str, got int64 3"),
    ],
)
def test_numpy_values_are_printed_as_plain_numbers(check, message):
    with pytest.raises(ValueError) as err:
        check()
    assert message in str(err.value)
    assert "np." not in str(err.value) and "array(" not in str(err.value)


def test_configuration_errors_from_numpy_inputs_print_plain_numbers():
    from scpformer.problems.rendezvous.scenario import RendezvousScenario, SCPParameters
    from scpformer.problems.robust_rendezvous.scenario import RobustScenario
    from scpformer.scp.scvx import SCvxParameters

    cases = [
        (lambda: SCvxParameters(lambda_=NAN), "lambda_ must be finite, got nan"),
        (
            lambda: RendezvousScenario(n_nodes=np.float64(50.5)),
            "n_nodes must be an integer <= 1000, got float64 50.5",
        ),
        (
            lambda: SCPParameters(K=np.float64(2.5)),
            "scp.K must be an integer >= 1, got float64 2.5",
        ),
        (
            lambda: RobustScenario(n_safety=np.float64(0.5)),
            "n_safety must be an integer >= 1, got float64 0.5",
        ),
    ]
    for make, message in cases:
        with pytest.raises(ValueError) as err:
            make()
        assert message in str(err.value) and "np." not in str(err.value)


def test_shown_keeps_other_values_as_repr():
    assert shown("+T") == "'+T'" and shown(None) == "None" and shown((1, "a")) == "(1, 'a')"
    assert shown(np.str_("+T")) == "'+T'" and shown(np.bool_(True)) == "True"


def test_shown_as_names_the_type_of_a_value_the_check_does_not_take():
    assert shown_as(np.int64(0), int) == "int64 0" and shown_as(np.float32(2), int | float) == (
        "float32 2.0"
    )
    assert shown_as(np.float64(-1), float) == "-1.0" and shown_as(True, int) == "True"
    assert shown_as("x", int) == "'x'" and shown_as(2.5, int) == "2.5"
