"""benchmarks/pdg6dof_embersarc.py: argument checking, and a fixed-roll landing of its draw 0."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "pdg6dof_embersarc.py"


@pytest.mark.parametrize("scale", ["0", "-0.8", "nan"])
def test_a_nonpositive_velocity_scale_is_a_usage_error_naming_the_flag(scale, run_benchmark):
    done = run_benchmark("pdg6dof_embersarc.py", "--draws", "1", "--velocity-scale", scale)
    assert done.returncode == 2
    assert "--velocity-scale" in done.stderr
    assert "converged" not in done.stdout  # rejected before any solve


@pytest.mark.parametrize("scale", ["-0.1", "1.5", "nan"])
def test_an_attitude_scale_outside_0_1_is_a_usage_error_naming_the_flag(scale, run_benchmark):
    done = run_benchmark("pdg6dof_embersarc.py", "--draws", "1", "--attitude-scale", scale)
    assert done.returncode == 2
    assert "--attitude-scale" in done.stderr
    assert "converged" not in done.stdout


def test_the_attitude_scale_shrinks_the_tilt_about_its_axis_and_the_rates():
    from scpformer.dynamics import quaternion as quat

    script = _embersarc_script()
    state = script.draw_initial_state(np.random.default_rng(0))

    def angle_axis(s):
        q = quat.normalize(s["q"])
        return 2.0 * np.arctan2(np.linalg.norm(q[1:]), q[0]), q[1:] / np.linalg.norm(q[1:])

    same = script.scaled_attitude(state, 1.0)
    np.testing.assert_allclose(same["q"], state["q"], atol=1e-15)
    upright = script.scaled_attitude(state, 0.0)
    np.testing.assert_allclose(upright["q"], [1.0, 0.0, 0.0, 0.0], atol=1e-15)
    assert not upright["omega_deg"].any()
    half = script.scaled_attitude(state, 0.5)
    (angle, axis), (angle_half, axis_half) = angle_axis(state), angle_axis(half)
    assert angle > 0.1 and angle_half == pytest.approx(0.5 * angle, rel=1e-12)
    np.testing.assert_allclose(axis_half, axis, atol=1e-12)
    np.testing.assert_allclose(half["omega_deg"], 0.5 * state["omega_deg"])
    np.testing.assert_allclose(half["r"], state["r"])


def _embersarc_script():
    spec = importlib.util.spec_from_file_location("pdg6dof_embersarc", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_fixed_roll_landing_of_draw_0_converges_from_the_default_start(tmp_path):
    """EmbersArc's draw 0 (seed 0) with ``--fix-roll``, solved as ``scpformer solve`` does: the
    cubic profile's final time (1.04 U_T) is far too short, the first run's penalty stops
    falling (by less than 20% over 15 accepted iterations), SCvx restarts with 2 times that
    run's final time and lands at t_f ~ 2.4 U_T (15.7 s), verified, with no virtual control
    left (before the stall test and restart: 100 solves, max_iterations)."""
    from scpformer.cli.main import build_parser
    from scpformer.cli.pdg6dof import config_from_args, instance_from_args
    from scpformer.pdg6dof import solve
    from scpformer.scp.solution import Status

    script = _embersarc_script()
    state = script.draw_initial_state(np.random.default_rng(0))
    args = build_parser().parse_args(script.solve_arguments(state, tmp_path / "draw0.json"))
    config, instance = config_from_args(args), instance_from_args(args)
    assert config.fix_roll and config.n_nodes == 30
    solution = solve(instance, config)
    assert solution.status is Status.CONVERGED, solution.message
    assert solution.verification.passed
    assert solution.history[-1].virtual_control_norm < 1e-6
    assert 2.2 < solution.trajectory.p[0] < 2.6
    restart = solution.extras["restart"]
    assert "stalled" in restart["first_message"] and restart["tf_guess"] > 2.0
    assert solution.iterations == len(solution.history) <= config.scvx.iter_max
    assert restart["after"] < solution.iterations
