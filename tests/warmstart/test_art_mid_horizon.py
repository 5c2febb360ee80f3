"""ART started mid-horizon: the flown prefix as context, the rollout from node k (closed loop)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from scpformer.guidance.rendezvous_mpc import remaining_instance
from scpformer.pretrained import default_model
from scpformer.problems.rendezvous.linear_model import linear_model
from scpformer.rendezvous import RendezvousInstance
from scpformer.warmstart import (
    AcceptanceCheck,
    ArtPrefix,
    ArtWarmStart,
    FlownHistory,
    flown_prefix,
    generate,
    preferred_guess,
)

INSTANCE = RendezvousInstance()
RTG = -0.25  # R at the first generated node [m/s]: fixed, no convex solve in these tests
K = 40  # a node of the keep-out phase


@pytest.fixture(scope="module")
def art():
    torch.set_num_threads(1)
    return ArtWarmStart.from_checkpoint(default_model("rendezvous"), rtg=RTG)


@pytest.fixture(scope="module")
def full(art):
    """The shipped model's generation of the default instance from time step 0."""
    batch = art.adapter.batch([INSTANCE])
    return generate(art.model, art.normalization, batch, art.adapter, frame=art.frame,
                    art_mode="dynamics", rtg0=np.array([RTG]), ctg0=np.zeros(1))  # fmt: skip


def _remaining(k: int, estimate: np.ndarray) -> RendezvousInstance:
    return remaining_instance(INSTANCE, k, estimate, linear_model(INSTANCE).oe[k])


class _StepwiseModel:
    """The model without ``feed_prefix``: the prefix is fed one step at a time."""

    def __init__(self, model):
        self._model, self.config = model, model.config

    def __getattr__(self, name):
        if name == "feed_prefix":
            raise AttributeError(name)
        return getattr(self._model, name)


def test_at_k0_with_no_prefix_the_mid_horizon_guess_is_the_full_generation(art, full):
    history = FlownHistory(INSTANCE, np.zeros((0, 6)), np.zeros((0, 3)))
    mid = art.guess(INSTANCE, history)
    np.testing.assert_allclose(mid.trajectory.u, full.u[0], rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(mid.trajectory.x, full.x[0], rtol=0.0, atol=1e-9)
    assert mid.record.details["k"] == 0 and mid.record.details["rtg0"] == RTG
    empty = ArtPrefix(np.zeros((1, 0, 6)), np.zeros((1, 0, 3)), np.zeros((1, 0)), np.zeros((1, 0)))
    batch = art.adapter.batch([INSTANCE])
    again = generate(art.model, art.normalization, batch, art.adapter, frame=art.frame,
                     art_mode="dynamics", rtg0=np.array([RTG]), ctg0=np.zeros(1),
                     prefix=empty)  # fmt: skip
    np.testing.assert_array_equal(again.u, full.u)


@pytest.mark.parametrize("stepwise", [False, True])
def test_fed_its_own_prefix_the_model_continues_its_full_generation(art, full, stepwise):
    """Teacher-forcing the first K steps of a generation and continuing from node K gives that
    generation's own impulses: the prefix tokens (frame, R and C recomputed along it), the
    time-step embedding and the normalization rows are those of the true time steps."""
    history = art.adapter.batch([INSTANCE])
    prefix = flown_prefix(history, art.adapter, full.x[:, :K], full.u[:, :K], frame=art.frame,
                          rtg_k=full.rtg[:, K], ctg_k=full.ctg[:, K])  # fmt: skip
    np.testing.assert_allclose(prefix.rtg, full.rtg[:, :K], rtol=0.0, atol=1e-12)
    np.testing.assert_array_equal(prefix.ctg, full.ctg[:, :K])
    np.testing.assert_allclose(prefix.states, full.states[:, :K], rtol=0.0, atol=1e-9)
    model = _StepwiseModel(art.model) if stepwise else art.model
    sub = art.adapter.batch([_remaining(K, full.x[0, K])])
    out = generate(model, art.normalization, sub, art.adapter, frame=art.frame,
                   art_mode="dynamics", rtg0=full.rtg[:, K], ctg0=full.ctg[:, K],
                   prefix=prefix)  # fmt: skip
    assert out.u.shape == (1, INSTANCE.n_nodes - K, 3)
    # float32 tokens (one pass instead of K calls; the remaining problem's own linear model,
    # 4e-5 m off the whole one's): the impulses agree to 1e-5 of the largest (0.3 um/s)
    np.testing.assert_allclose(out.u, full.u[:, K:], rtol=0.0, atol=1e-5 * np.abs(full.u).max())


def test_the_mid_horizon_rollout_obeys_the_linear_dynamics_from_the_estimate(art, full):
    estimate = full.x[0, K] + np.array([3.0, -5.0, 1.0, 2.0, -1.0, 0.5])  # a navigation error
    sub = _remaining(K, estimate)
    history = FlownHistory(INSTANCE, full.x[0, :K], full.u[0, :K])
    guess = art.guess(sub, history)
    x, u = guess.trajectory.x, guess.trajectory.u
    assert x.shape == (INSTANCE.n_nodes - K + 1, 6) and u.shape == (INSTANCE.n_nodes - K, 3)
    np.testing.assert_array_equal(x[0], estimate)
    assert linear_model(sub).residual(x, u) < 1e-9  # metres: x_{k+1} = Phi_k (x_k + B_k u_k)
    assert guess.record.details["k"] == K and guess.record.accepted


def test_a_batch_of_histories_with_two_node_counts_is_generated_per_node(art, full):
    nodes = (K, K + 10)
    subs = [_remaining(k, full.x[0, k]) for k in nodes]
    histories = [FlownHistory(INSTANCE, full.x[0, :k], full.u[0, :k]) for k in nodes]
    both = art.guess_batch(subs, histories)
    for sub, history, guess in zip(subs, histories, both, strict=True):
        alone = art.guess(sub, history)
        np.testing.assert_allclose(guess.trajectory.u, alone.trajectory.u, rtol=0, atol=1e-12)
        assert guess.record.details["k"] == history.k


def test_bad_histories_and_prefixes_are_clear_errors(art, full):
    x, u = full.x[0, :K], full.u[0, :K]
    with pytest.raises(ValueError, match=r"history x must be \(k, 6\)"):
        FlownHistory(INSTANCE, x[:, :5], u)
    with pytest.raises(ValueError, match=r"history u must be \(40, 3\)"):
        FlownHistory(INSTANCE, x, u[:-1])
    with pytest.raises(ValueError, match="must be 0 <= k < N = 100"):
        FlownHistory(INSTANCE, np.zeros((100, 6)), np.zeros((100, 3)))
    with pytest.raises(ValueError, match="finite"):
        FlownHistory(INSTANCE, np.full((K, 6), np.nan), u)
    sub = _remaining(K + 10, full.x[0, K + 10])
    with pytest.raises(ValueError, match="after k = 40 flown nodes: the history's N = 100 needs "
                                         "N - k = 60"):  # fmt: skip
        art.guess(sub, FlownHistory(INSTANCE, x, u))
    with pytest.raises(ValueError, match="1 histories for 2 instances"):
        art.guess_batch([sub, sub], [FlownHistory(INSTANCE, x, u)])
    history = art.adapter.batch([INSTANCE])
    rtg, ctg = np.array([RTG]), np.zeros(1)
    with pytest.raises(ValueError, match="must have 0 <= k < N = 100"):
        flown_prefix(history, art.adapter, np.zeros((1, 100, 6)), np.zeros((1, 100, 3)),
                     frame="rtn", rtg_k=rtg, ctg_k=ctg)  # fmt: skip
    with pytest.raises(ValueError, match=r"u must be \(1, 40, 3\)"):
        flown_prefix(history, art.adapter, x[None], u[None, :-1], frame="rtn", rtg_k=rtg,
                     ctg_k=ctg)  # fmt: skip
    with pytest.raises(ValueError, match=r"prefix actions must be \(1, 3, 3\)"):
        ArtPrefix(np.zeros((1, 3, 6)), np.zeros((1, 2, 3)), np.zeros((1, 3)), np.zeros((1, 3)))
    prefix = ArtPrefix(np.zeros((2, 3, 6)), np.zeros((2, 3, 3)), np.zeros((2, 3)), np.zeros((2, 3)))
    batch = art.adapter.batch([INSTANCE])
    with pytest.raises(ValueError, match="the prefix holds 2 histories, the batch 1"):
        generate(art.model, art.normalization, batch, art.adapter, frame="rtn",
                 art_mode="dynamics", rtg0=rtg, ctg0=ctg, prefix=prefix)  # fmt: skip
    prefix = ArtPrefix(np.zeros((1, 3, 6)), np.zeros((1, 3, 3)), np.zeros((1, 3)), np.zeros((1, 3)))
    with pytest.raises(ValueError, match="shorter than the horizon"):  # 3 + 100 steps > context
        generate(art.model, art.normalization, batch, art.adapter, frame="rtn",
                 art_mode="dynamics", rtg0=rtg, ctg0=ctg, prefix=prefix)  # fmt: skip


def test_the_preferred_guess_is_accepted_first_then_fewer_violations_then_nearer_cost():
    check = AcceptanceCheck()
    pick = lambda **c: preferred_guess(check, rtg_desired=-1.0, ctg_desired=0.0,  # noqa: E731
                                       candidates=c)[0]  # fmt: skip
    assert pick(art=(1.01, 0.0), previous=(1.02, 0.0)) == "art"
    assert pick(art=(1.10, 0.0), previous=(1.02, 0.0)) == "previous"  # 100 E_R = 10 > 3.5
    assert pick(art=(1.01, 1.0), previous=(1.02, 0.0)) == "previous"  # fewer violations
    assert pick(art=(1.01, 0.0), previous=(1.01, 0.0)) == "art"  # a tie keeps the order
    assert pick(art=(0.90, 0.0), previous=(1.20, 0.0)) == "art"  # neither: nearer cost
    with pytest.raises(ValueError, match="at least one"):
        pick()
