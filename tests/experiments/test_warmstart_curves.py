"""The paper's claims are read off its cumulative curves C_CVX(t_1) > x, as its Figs. 4-6."""

import math

from scpformer.experiments.warmstart_study import _curve_extreme


def point(x, improvement, n=5):
    return {"x": x, "improvement_vs_convex": improvement, "count_feasible": n}


CURVE = [point(-1, 3.0), point(0, 25.0), point(20, 60.0), point(30, 70.0, 4), point(35, 90.0, 2),
         point(40, float("nan"), 0), point(45, 99.0, 1)]  # fmt: skip


def test_up_to_is_the_largest_point_inside_the_range_only():
    assert _curve_extreme(CURVE, lambda s: s["improvement_vs_convex"], 30, 40) == (90.0, 35, 2)


def test_for_all_positive_x_is_the_least_point_from_x_0_and_skips_every_instance_and_nan():
    least = _curve_extreme(CURVE, lambda s: s["improvement_vs_convex"], 0, 10**6, min)
    assert least == (25.0, 0, 5)


def test_a_range_without_points_is_nan():
    value, _, n = _curve_extreme(CURVE, lambda s: s["improvement_vs_convex"], 100, 200)
    assert math.isnan(value) and n == 0
