"""ART inference (Algorithms 1-2), R/C bookkeeping and the post hoc acceptance check."""

from __future__ import annotations

import sys
import types

import numpy as np
import pytest
from warmstart_standins import AffineNormalization, ReplayModel, replay_model

from scpformer.data.rendezvous_family import sequence_fields
from scpformer.problems.rendezvous import linear_model, sample_instances, solve
from scpformer.problems.robust_rendezvous import RobustInstance, solve_tpbvp, trajectory_violations
from scpformer.problems.robust_rendezvous.plan_dynamics import linearize_dynamics
from scpformer.problems.robust_rendezvous.safety import linear_model as robust_linear_model
from scpformer.problems.robust_rendezvous.scenario import RobustSolverConfig
from scpformer.warmstart import AcceptanceCheck, ArtWarmStart, generate
from scpformer.warmstart.families import art_family

N = 100


@pytest.fixture(scope="module")
def rendezvous():
    """Two sampled instances and their convex (Problem 2) solutions; the first has C_CVX > 0."""
    instances = sample_instances(np.random.default_rng(0), 2)
    return instances, [solve(i, "convex", verify=False) for i in instances]


STM = RobustSolverConfig(dynamics="stm")  # the paper's plan model: exact replays to 1e-8 m


@pytest.fixture(scope="module")
def robust():
    # The TPBVP in the STM model, which ART's Algorithm 2 then follows (config=STM) exactly
    instance = RobustInstance()
    return instance, solve_tpbvp(instance, STM)


@pytest.fixture(scope="module", params=["stm", "nonlinear"])
def robust_plan(request, robust):
    """The default instance's TPBVP planned in each plan model ART's Algorithm 2 can follow."""
    if request.param == "stm":
        return robust
    instance = RobustInstance()
    return instance, solve_tpbvp(instance, RobustSolverConfig(dynamics=request.param))


@pytest.fixture(scope="module")
def norm():
    return AffineNormalization.random(N)


def _rollout(instances, model, norm, *, frame="rtn", art_mode="dynamics", rtg0, ctg0, mode=None,
             dynamics="nonlinear"):  # fmt: skip
    family = (art_family("robust-rendezvous", mode, dynamics) if mode
              else art_family("rendezvous"))  # fmt: skip
    batch = family.batch(instances)
    return generate(model, norm, batch, family, frame=frame, art_mode=art_mode,
                    rtg0=np.asarray(rtg0, float), ctg0=np.asarray(ctg0, float))  # fmt: skip


# -- Algorithm 2: dynamics in the loop ------------------------------------------------------
@pytest.mark.parametrize("frame", ["rtn", "roe"])
def test_dynamics_in_the_loop_replays_a_known_solution_exactly_through_the_stm(
    rendezvous, norm, frame
):
    (instance, _), (cvx, _) = rendezvous
    z = cvx.trajectory
    model = replay_model(norm, z.u[None])
    out = _rollout([instance], model, norm, frame=frame, rtg0=[-cvx.cost], ctg0=[0.0])
    assert np.allclose(out.u[0], z.u, rtol=0.0, atol=1e-15)
    assert np.abs(out.x[0] - z.x).max() < 1e-8  # metres, over the whole horizon
    expected = linear_model(instance).rtn(z.x)[:N] if frame == "rtn" else z.x[:N]
    fed = norm.decode("state", np.stack(model.fed["state"], axis=1)[0])
    assert np.allclose(fed, expected, rtol=1e-6, atol=1e-3)  # float32 tokens


def test_reward_and_constraint_to_go_follow_the_datasets_sequences(rendezvous, norm):
    (instance, _), (cvx, _) = rendezvous
    z = cvx.trajectory
    stored = sequence_fields("cvx", instance.scenario, linear_model(instance), z.x, z.u)
    assert stored["cvx_ctg"][0] > 0  # the convex solution crosses the keep-out zone
    model = replay_model(norm, z.u[None])
    out = _rollout([instance], model, norm, rtg0=stored["cvx_rtg"][:1],
                   ctg0=stored["cvx_ctg"][:1])  # fmt: skip
    assert stored["cvx_rtg"][0] == pytest.approx(-cvx.cost) and stored["cvx_rtg"][0] < 0
    assert np.allclose(out.rtg[0], stored["cvx_rtg"][:N], rtol=0.0, atol=1e-12)
    assert np.array_equal(out.ctg[0], stored["cvx_ctg"][:N])
    assert out.violations[0].sum() == stored["cvx_ctg"][0]
    fed_rtg = norm.decode("rtg", np.concatenate(model.fed["rtg"], axis=1)[0])
    fed_ctg = norm.decode("ctg", np.concatenate(model.fed["ctg"], axis=1)[0])
    assert np.allclose(fed_rtg, stored["cvx_rtg"][:N], rtol=1e-6)
    assert np.allclose(fed_ctg, stored["cvx_ctg"][:N], rtol=1e-6)


def _replay_tolerance(instance, z, dynamics):
    """How far a replay of plan ``z`` may drift from it [m]: its own largest one-step defect in
    ``dynamics`` (a conic solution obeys them to the solver's tolerance), carried over the
    horizon by a flow that keeps separations (at most N defects), plus rounding."""
    defect = linearize_dynamics(instance, robust_linear_model(instance), z.x, z.u, dynamics).defect
    return N * np.abs(defect).max() + 1e-8


def test_robust_replay_reproduces_the_tpbvp_and_its_eq7_budget_with_the_target_token(
    robust_plan, norm
):
    instance, tpbvp = robust_plan
    z, dynamics = tpbvp.trajectory, tpbvp.extras["dynamics"]
    tol = _replay_tolerance(instance, z, dynamics)
    for mode in ("chance", "deterministic"):
        budget = trajectory_violations(instance, z.x, z.u, mode, dynamics=dynamics)
        model = replay_model(norm, z.u[None])
        out = _rollout([instance], model, norm, rtg0=[-tpbvp.cost], ctg0=budget[:1], mode=mode,
                       dynamics=dynamics)  # fmt: skip
        assert np.abs(out.x[0] - z.x).max() < tol
        assert np.array_equal(out.ctg[0], budget[:N]) and out.violations[0].sum() == budget[0]
        assert budget[0] > 0  # the TPBVP is not passively safe
        target = norm.decode("target", model.fed["target"].double().numpy()[0])
        assert np.allclose(target, instance.xf_rtn, atol=1e-3)  # waypoint's RTN state
    out_roe = _rollout([instance], replay_model(norm, z.u[None]), norm, frame="roe",
                       rtg0=[-tpbvp.cost], ctg0=[0.0], mode="chance",
                       dynamics=dynamics)  # fmt: skip
    assert np.abs(out_roe.x[0] - z.x).max() < tol


def test_robust_rollout_through_the_stm_leaves_a_nonlinear_plan_it_follows_through_the_flow(norm):
    # The default plans obey the nonlinear mean-element flow: replaying a plan's impulses
    # through the STM drifts metres away from it (the model error ART's rollout must not add)
    instance = RobustInstance()
    z = solve_tpbvp(instance, RobustSolverConfig()).trajectory
    gaps = {}
    for dynamics in ("stm", "nonlinear"):
        out = _rollout([instance], replay_model(norm, z.u[None]), norm, rtg0=[-z.u.sum()],
                       ctg0=[0.0], mode="chance", dynamics=dynamics)  # fmt: skip
        gaps[dynamics] = np.abs(out.x[0] - z.x).max()
    assert gaps["nonlinear"] < _replay_tolerance(instance, z, "nonlinear")
    assert gaps["stm"] > 1.0  # metres: the STM's neglected second-order terms


# -- Algorithm 1: transformer only ----------------------------------------------------------
def test_transformer_only_takes_next_states_from_the_model_dynamics_mode_does_not(rendezvous, norm):
    (instance, _), (cvx, _) = rendezvous
    z = cvx.trajectory
    model_lm = linear_model(instance)
    predicted_rtn = model_lm.rtn(z.x)[:N] + np.array([1.0, -2.0, 0.5, 0.0, 0.0, 0.0])
    args = {"rtg0": [-cvx.cost], "ctg0": [0.0]}
    alg1 = _rollout([instance], replay_model(norm, z.u[None], predicted_rtn[None]), norm,
                    art_mode="transformer", **args)  # fmt: skip
    alg2 = _rollout([instance], replay_model(norm, z.u[None], predicted_rtn[None]), norm,
                    art_mode="dynamics", **args)  # fmt: skip
    assert np.abs(alg2.x[0] - z.x).max() < 1e-8
    assert np.allclose(model_lm.rtn(alg1.x[0])[1:N], predicted_rtn[1:], atol=1e-8)
    assert np.allclose(alg1.x[0, 0], z.x[0])  # x(t_1) is given
    last = model_lm.Phi[-1] @ (alg1.x[0, N - 1] + model_lm.B[-1] @ z.u[-1])
    assert np.allclose(alg1.x[0, N], last)  # x_N through the STM
    assert np.allclose(alg1.u, alg2.u)


# -- the provider ---------------------------------------------------------------------------
def test_default_rtg_is_minus_the_convex_cost_and_both_are_overridable(rendezvous, norm):
    (instance, _), (cvx, _) = rendezvous
    u = cvx.trajectory.u[None]
    default = ArtWarmStart(replay_model(norm, u), norm).guess(instance)
    assert default.record.details["rtg0"] == pytest.approx(-cvx.cost)
    assert default.record.details["ctg0"] == 0.0
    assert default.record.source == "art" and default.record.accepted
    assert default.record.cost == pytest.approx(cvx.cost)
    assert default.record.constraint_to_go == default.record.details["art_constraint_to_go"] > 0
    model = replay_model(norm, u)
    given = ArtWarmStart(model, norm, rtg=-0.5, ctg=3.0).guess(instance)
    assert given.record.details["rtg0"] == -0.5 and given.record.details["ctg0"] == 3.0
    assert norm.decode("rtg", model.fed["rtg"][0][0, 0]) == pytest.approx(-0.5)
    assert given.solution is None  # no convex solve was needed


def test_guess_batch_generates_every_instance_as_one_batch(rendezvous, norm):
    instances, solutions = rendezvous
    u = np.stack([s.trajectory.u for s in solutions])
    model = replay_model(norm, u)
    results = ArtWarmStart(model, norm).guess_batch(instances)
    assert len(model.fed["rtg"]) == N and model.fed["rtg"][0].shape == (2, 1)
    for result, sol in zip(results, solutions, strict=True):
        assert np.abs(result.trajectory.x - sol.trajectory.x).max() < 1e-8
        assert result.record.details["rtg0"] == pytest.approx(-sol.cost)


def test_rejected_guess_falls_back_to_the_convex_warm_start(robust, norm):
    instance, tpbvp = robust
    idle = ReplayModel(norm.encode("action", np.zeros((1, N, 3))))  # never burns: E_R = -1
    result = ArtWarmStart(idle, norm, family="robust-rendezvous", config=STM).guess(instance)
    record = result.record
    assert record.source == "art" and not record.accepted
    assert record.fallback_source == "tpbvp" and record.used == "tpbvp"
    assert record.details["E_R"] == pytest.approx(-1.0) and "not in" in record.reason
    assert record.cost == pytest.approx(tpbvp.cost) and record.details["art_cost"] < 1e-15
    assert np.allclose(result.trajectory.x, tpbvp.trajectory.x)
    assert result.record.to_dict()["used"] == "tpbvp"


def test_replayed_tpbvp_is_accepted_when_safe_enough_and_rejected_by_a_stricter_check(robust, norm):
    instance, tpbvp = robust
    u = tpbvp.trajectory.u[None]
    budget = trajectory_violations(instance, tpbvp.trajectory.x, tpbvp.trajectory.u)[0]
    loose = AcceptanceCheck(e_c=(0.0, float(budget)))
    accepted = ArtWarmStart(replay_model(norm, u), norm, family="robust-rendezvous", config=STM,
                            acceptance=loose).guess(instance)  # fmt: skip
    assert accepted.record.accepted and accepted.record.details["E_R"] == pytest.approx(0.0)
    assert accepted.record.details["E_C"] == budget
    strict = ArtWarmStart(replay_model(norm, u), norm, family="robust-rendezvous", config=STM)
    rejected = strict.guess(instance)  # default check: E_C <= 2 < budget
    assert not rejected.record.accepted and rejected.record.fallback_source == "tpbvp"


@pytest.mark.parametrize(
    ("rtg", "ctg", "accepted"),
    [
        (-101.5, 0, True),  # 100 E_R = 1.5
        (-103.5, 0, True),  # 100 E_R = 3.5, upper bound
        (-98.5, 0, True),  # 100 E_R = -1.5, lower bound
        (-103.6, 0, False),
        (-98.4, 0, False),
        (-100.0, 2, True),  # E_C = 2, upper bound
        (-100.0, 3, False),
        (-100.0, -1, False),  # fewer violations than asked for: E_C < 0
    ],
)
def test_acceptance_check_holds_at_its_boundaries(rtg, ctg, accepted):
    decision = AcceptanceCheck().evaluate(
        rtg_desired=-100.0, ctg_desired=0.0, rtg_realized=rtg, ctg_realized=ctg
    )
    assert decision.accepted is accepted
    assert decision.E_R == pytest.approx((rtg + 100.0) / -100.0) and decision.E_C == ctg


def test_acceptance_check_rejects_bad_bounds():
    with pytest.raises(ValueError, match="e_r_percent must be finite"):
        AcceptanceCheck(e_r_percent=(3.5, -1.5))
    with pytest.raises(ValueError, match="e_c must be finite"):
        AcceptanceCheck(e_c=(0.0, float("nan")))


@pytest.mark.parametrize(
    ("bounds", "message"),
    [
        ({"e_r_percent": np.array([3.5, -1.5])}, "with low <= high, got [3.5, -1.5]"),
        ({"e_c": (np.float64(0.0), np.float64(np.nan))}, "got (0.0, nan)"),
    ],
)
def test_acceptance_bounds_print_numpy_numbers_plainly(bounds, message):
    with pytest.raises(ValueError) as err:
        AcceptanceCheck(**bounds)
    assert (
        message in str(err.value) and "np." not in str(err.value) and "array" not in str(err.value)
    )


def test_bad_arguments_are_clear_errors(rendezvous, robust, norm):
    _, (cvx, _) = rendezvous
    model = replay_model(norm, cvx.trajectory.u[None])
    cases = [
        ({"rtg": 0.3}, "rtg must be a finite R"),
        ({"ctg": -1.0}, "ctg must be a finite C"),
        ({"frame": "eci"}, "frame must be one of"),
        ({"art_mode": "both"}, "art_mode must be one of"),
        ({"family": "pdg6dof"}, "family must be one of"),
        ({"family": "robust-rendezvous", "mode": "maybe"}, "mode must be one of"),
        ({"acceptance": 3}, "acceptance must be an AcceptanceCheck"),
    ]
    for kwargs, message in cases:
        with pytest.raises(ValueError, match=message):
            ArtWarmStart(model, norm, **kwargs)
    with pytest.raises(ValueError, match="model must have the inference method start"):
        ArtWarmStart(object(), norm)
    with pytest.raises(ValueError, match="normalization must have an encode"):
        ArtWarmStart(model, object())
    with pytest.raises(ValueError, match="instance must be a RendezvousInstance"):
        ArtWarmStart(model, norm).guess(robust[0])


def test_a_model_with_a_short_context_is_refused(rendezvous, norm):
    (instance, _), (cvx, _) = rendezvous
    model = replay_model(norm, cvx.trajectory.u[None])
    model.config = types.SimpleNamespace(context=50)
    with pytest.raises(ValueError, match=r"context \(50 steps\) is shorter than the horizon"):
        ArtWarmStart(model, norm, rtg=-0.2).guess(instance)


def test_from_checkpoint_wraps_the_checkpoints_model_frame_and_family(monkeypatch, robust, norm):
    instance, tpbvp = robust
    model = replay_model(norm, tpbvp.trajectory.u[None])
    asked = {}

    def load_checkpoint(path, *, family=None, frame=None, kind=None, device="cpu"):
        asked.update(path=path, family=family, frame=frame)
        return types.SimpleNamespace(model=model, normalization=norm, frame="roe",
                                     family="robust-rendezvous", config=STM)  # fmt: skip

    fake = types.ModuleType("scpformer.models.checkpoint")
    fake.load_checkpoint = load_checkpoint
    monkeypatch.setitem(sys.modules, "scpformer.models.checkpoint", fake)
    ws = ArtWarmStart.from_checkpoint(
        "RUN", family="robust-rendezvous", config=STM, acceptance=None
    )
    assert asked == {"path": "RUN", "family": "robust-rendezvous", "frame": None}
    assert ws.frame == "roe" and ws.family == "robust-rendezvous"
    result = ws.guess(instance)
    assert np.abs(result.trajectory.x - tpbvp.trajectory.x).max() < 1e-8
    assert robust_linear_model(instance).residual(result.trajectory.x, result.trajectory.u) < 1e-8


def test_dynamics_in_the_loop_agrees_with_the_linear_models_rollout_for_any_actions(
    rendezvous, norm
):
    instances, _ = rendezvous
    u = np.random.default_rng(7).normal(0.0, 0.01, (2, N, 3))
    out = _rollout(instances, ReplayModel(norm.encode("action", u)), norm, frame="roe",
                   rtg0=[-1.0, -2.0], ctg0=[0.0, 0.0])  # fmt: skip
    for j, instance in enumerate(instances):
        expected = linear_model(instance).rollout(instance.roe0, u[j])
        assert np.abs(out.x[j] - expected).max() < 1e-8
        steps = np.linalg.norm(u[j], axis=1)
        assert np.allclose(out.rtg[j], [-1.0, -2.0][j] + np.r_[0.0, np.cumsum(steps)[:-1]])


def test_generate_refuses_bad_conditioning(rendezvous, norm):
    (instance, _), (cvx, _) = rendezvous
    model = replay_model(norm, cvx.trajectory.u[None])
    with pytest.raises(ValueError, match=r"rtg0 must be finite with shape \(1,\)"):
        _rollout([instance], model, norm, rtg0=[-1.0, -1.0], ctg0=[0.0])
    with pytest.raises(ValueError, match="ctg0 must be finite"):
        _rollout([instance], model, norm, rtg0=[-1.0], ctg0=[np.nan])
    with pytest.raises(ValueError, match="art_mode must be one of"):
        _rollout([instance], model, norm, art_mode="greedy", rtg0=[-1.0], ctg0=[0.0])


def test_from_checkpoint_takes_a_loaded_checkpoint_and_checks_its_family(rendezvous, norm):
    (instance, _), (cvx, _) = rendezvous
    model = replay_model(norm, cvx.trajectory.u[None])
    ckpt = types.SimpleNamespace(model=model, normalization=norm, frame="rtn", family="rendezvous")
    ws = ArtWarmStart.from_checkpoint(ckpt, family="rendezvous", rtg=-cvx.cost)
    assert np.abs(ws.guess(instance).trajectory.x - cvx.trajectory.x).max() < 1e-8
    with pytest.raises(ValueError, match="a rendezvous checkpoint, not robust-rendezvous"):
        ArtWarmStart.from_checkpoint(ckpt, family="robust-rendezvous", config=STM)
    with pytest.raises(ValueError, match="holds no ART normalization"):
        ArtWarmStart.from_checkpoint(types.SimpleNamespace(**{**vars(ckpt), "normalization": None}))
