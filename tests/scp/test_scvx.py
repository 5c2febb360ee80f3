import pytest

from scpformer.scp.scvx import SCvxParameters, update_trust_radius

P = SCvxParameters()


@pytest.mark.parametrize(
    "rho, eta_after, accepted",
    [(-0.5, 1.0, False), (0.05, 1.0, True), (0.5, 2.0, True), (0.9, 4.0, True)],
)
def test_trust_region_update_follows_eq_15(rho, eta_after, accepted):
    assert update_trust_radius(2.0, rho, P) == (eta_after, accepted)


def test_trust_radius_stays_within_bounds():
    assert update_trust_radius(P.eta_ub, 0.99, P)[0] == P.eta_ub
    assert update_trust_radius(P.eta_lb, -1.0, P)[0] == P.eta_lb


def test_defaults_are_table_1():
    assert (P.lambda_, P.rho_0, P.rho_1, P.rho_2) == (500.0, 0.0, 0.1, 0.7)
    assert (P.eta_init, P.eta_lb, P.eta_ub, P.iter_max) == (2.0, 1e-3, 10.0, 20)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"rho_1": 0.9}, "rho"),
        ({"eta_init": 100.0}, "eta"),
        ({"solver": "gurobi"}, "solver"),
        ({"lambda_": -1.0}, "lambda_"),
        ({"iter_max": 0}, "iter_max"),
    ],
)
def test_bad_parameters_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        SCvxParameters(**kwargs)
